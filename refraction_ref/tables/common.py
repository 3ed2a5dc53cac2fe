"""What every paper's tables module returns to ``refraction-ref tables``.

Each paper module (:mod:`.chaudhari_report`, :mod:`.sun`, :mod:`.tipprasert`)
exposes ``run(quick: bool, out: pathlib.Path, log=print) -> Report``: it measures
its tables, writes any plots into ``out`` (file names only in :attr:`Table.plot`)
and states the paper's claims checked against those measurements.
:mod:`.report` turns the reports into one Markdown file.

Ratios and trends are compared, never a CPU's absolute time with a GPU's: a claim
about a GPU's absolute frame rate is :data:`NOT_COMPARABLE`, and the trend it
implies is judged in a claim of its own. Every claim states its verdict rule
(:attr:`Claim.rule`: the quantity, the threshold, the set-up) before it is
measured. A claim decided by a timing is marked :attr:`Claim.timing`; when
other processes took more than :data:`BUSY` of the CPUs while a paper was
measured (:class:`LoadProbe`), its timing verdicts are reported as unreliable.
"""

from __future__ import annotations

import contextlib
import os
import statistics
import time
from dataclasses import dataclass, field

__all__ = ["Table", "Claim", "Report", "HELD", "NOT_HELD", "NOT_MEASURED", "NOT_COMPARABLE", "BY_CONSTRUCTION", "SPLIT",
           "VERDICTS", "EVIDENCE", "BUSY", "LoadProbe", "straddles",
           "cpu_jiffies", "other_load", "TABLE_THREADS", "table_threads", "Spread", "spread", "ratio_spread",
           "time_rounds", "readings_table"]

HELD, NOT_HELD, NOT_MEASURED, NOT_COMPARABLE = "held", "not held", "not measured", "not comparable"
#: a row whose outcome follows from how the code is built (a formula the tables compute, code the two sides
#: share, a count that cannot differ): shown with its numbers and its reason, never counted as evidence
BY_CONSTRUCTION = "by construction"
#: a sentence whose evidence rows disagree (held on one set-up or part, not held on another); never a row's verdict
SPLIT = "split"
#: the verdicts a row may carry
VERDICTS = (HELD, NOT_HELD, NOT_COMPARABLE, NOT_MEASURED, BY_CONSTRUCTION)
#: the verdicts that count as evidence for or against a sentence
EVIDENCE = (HELD, NOT_HELD)

#: share of the machine's CPUs other processes may take while a paper is measured before its timing
#: verdicts are marked unreliable (on a 2-core machine one busy process elsewhere is 0.5)
BUSY = 0.15


@dataclass
class Table:
    """One of a paper's tables with our numbers beside the paper's.

    Attributes
    ----------
    key : str
        Short, file-safe name (``"sun_1"``, ``"tipprasert_5_1"``); the CSV is ``<key>.csv``.
    title : str
        The paper's caption, e.g. ``"Table 1: performance against triangles, voxels and photons"``.
    columns : list of str
        Column headers; name the paper's columns ``paper ...`` and ours ``ours ...``.
    rows : list of list
        Cells (numbers or strings); ``None`` prints as an em dash.
    note : str
        What our rows are (meshes, sizes, machine) and how they differ from the paper's.
    plot : str or None
        File name (inside the output folder) of a figure for this table.
    """

    key: str
    title: str
    columns: list
    rows: list
    note: str = ""
    plot: str | None = None


@dataclass
class Claim:
    """A claim of a paper, quoted from its seed, checked against our measurements.

    Attributes
    ----------
    paper : str
        ``"Chaudhari 2008"``, ``"Sun et al. 2008"`` or ``"Tipprasert 2006"``.
    section : str
        Where the quote stands (``"§5, Table 3"``).
    quote : str
        The claim, verbatim from the seed.
    verdict : str
        One of :data:`VERDICTS`: :data:`HELD`, :data:`NOT_HELD`, :data:`NOT_COMPARABLE`,
        :data:`NOT_MEASURED` or :data:`BY_CONSTRUCTION` (the outcome follows from how the code is
        built; shown, never counted as evidence).
    measured : str
        The measured number or ratio that decides it (``"1.9x (teapot, 101 planes)"``).
    why : str
        One sentence: why it holds or not here.
    rule : str
        The verdict rule, fixed before measuring: the quantity, the threshold and the set-up.
    timing : bool
        Whether a time decides the verdict (then a loaded machine makes it unreliable).
    straddles : bool
        A timing whose single rounds fall on both sides of the rule's
        threshold decides the verdict: the median decides it, and the report
        says that a re-run may give the other verdict (the threshold is not
        moved to avoid it).
    construction : str
        Why the row's outcome follows from how the code is built (required when
        the verdict is :data:`BY_CONSTRUCTION`).
    differs : str
        How the set-up differs from the paper's (empty: the paper's set-up, as
        far as we have it).
    """

    paper: str
    section: str
    quote: str
    verdict: str
    measured: str
    why: str
    rule: str = ""
    timing: bool = False
    straddles: bool = False
    construction: str = ""
    differs: str = ""

    def __post_init__(self):
        if self.verdict not in VERDICTS:
            raise ValueError(f"Claim: verdict {self.verdict!r}; choose from {', '.join(VERDICTS)}")
        if self.verdict == BY_CONSTRUCTION and not self.construction:
            raise ValueError(f"Claim ({self.paper} {self.section}): a by-construction verdict needs its reason "
                             "(construction)")


@dataclass
class Report:
    """One paper's tables and claims."""

    paper: str
    tables: list = field(default_factory=list)
    claims: list = field(default_factory=list)
    seconds: float = 0.0
    other_load: float = 0.0  # share of the CPUs other processes used while it was measured (LoadProbe)


def cpu_jiffies():
    """(busy jiffies of the whole machine, jiffies of this process and its threads), or None off Linux."""
    try:
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
        busy = sum(v) - v[3] - (v[4] if len(v) > 4 else 0)  # minus idle and iowait
        with open("/proc/self/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return busy, int(fields[11]) + int(fields[12])  # utime + stime
    except (OSError, ValueError, IndexError):
        return None


def other_load(before, after, wall_s, cpus=None):
    """Share of the machine's CPU capacity other processes used between two :func:`cpu_jiffies`.

    Parameters
    ----------
    before, after : tuple of int or None
        :func:`cpu_jiffies` at the start and the end.
    wall_s : float
        Wall-clock seconds between them.
    cpus : int, optional
        CPUs of the machine (default ``os.cpu_count()``).

    Returns
    -------
    float
        Fraction in ``[0, 1]``; 0 when either reading is missing. The
        counters tick ``SC_CLK_TCK`` times a second, so over a window of a
        few ticks one tick is a large share: the result is clipped to the
        machine's capacity (a paper's run lasts seconds, hundreds of ticks).
    """
    if before is None or after is None or wall_s <= 0:
        return 0.0
    hz = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    others = (after[0] - before[0]) - (after[1] - before[1])
    return min(1.0, max(0.0, others / hz / (wall_s * (cpus or os.cpu_count() or 1))))


#: Numba threads every paper's timings are taken with. One: on a shared machine a process on another core
#: makes every parallel region of a multi-threaded render wait for its preempted worker (fork-join), so a
#: two-thread time swings severalfold with the other load while a single thread's barely moves.
TABLE_THREADS = 1


class table_threads:
    """Context manager: Numba's thread count set to :data:`TABLE_THREADS` inside, restored after."""

    def __enter__(self):
        import numba

        self._before = numba.get_num_threads()
        numba.set_num_threads(min(TABLE_THREADS, numba.config.NUMBA_NUM_THREADS))
        return self

    def __exit__(self, *exc):
        import numba

        numba.set_num_threads(self._before)
        return False


class LoadProbe:
    """What other processes took of the CPUs between :meth:`start` and :meth:`stop`.

    From ``/proc/stat`` less this process's own CPU time (a process of another
    session may be invisible to ``ps`` but not to the kernel's counters);
    where ``/proc`` is missing, the 1-minute load average above this
    process's share (``os.getloadavg``), less exact but never silent.
    """

    def __init__(self):
        self.start()

    def start(self):
        self._j, self._t = cpu_jiffies(), time.perf_counter()
        return self

    def stop(self):
        """The share of the CPUs (0..1) other processes used since :meth:`start`."""
        wall = time.perf_counter() - self._t
        if self._j is not None:
            return other_load(self._j, cpu_jiffies(), wall)
        try:
            n = os.cpu_count() or 1
            return max(0.0, (os.getloadavg()[0] - 1.0) / n)
        except (OSError, AttributeError):
            return 0.0


@dataclass(frozen=True)
class Spread:
    """A timing (or a ratio of timings) over repeats: the median and the run-to-run spread.

    Attributes
    ----------
    median, low, high : float
        Median, smallest and largest of the samples.
    n : int
        Number of samples.
    """

    median: float
    low: float
    high: float
    n: int

    def text(self, unit="", nd=2):
        """``'<median><unit> (<low>-<high>, n = <n>)'``, e.g. ``'1.50x (1.20-1.90, n = 5)'``."""
        return f"{self.median:.{nd}f}{unit} ({self.low:.{nd}f}-{self.high:.{nd}f}, n = {self.n})"


def spread(samples):
    """The :class:`Spread` (median, min, max, count) of a non-empty sequence of numbers.

    Parameters
    ----------
    samples : sequence of float
        Per-repeat values.

    Returns
    -------
    Spread
    """
    x = [float(v) for v in samples]
    if not x:
        raise ValueError("spread: no samples (repeats must be at least 1)")
    return Spread(statistics.median(x), min(x), max(x), len(x))


def straddles(low, high, *thresholds):
    """Whether single rounds ranging over ``[low, high]`` fall on both sides of any threshold.

    A verdict decided by the median of such rounds could go the other way on
    a re-run (:attr:`Claim.straddles`).

    Parameters
    ----------
    low, high : float
        The smallest and largest single-round values (a :class:`Spread`'s ``low`` and ``high``).
    *thresholds : float
        The rule's thresholds.

    Returns
    -------
    bool
    """
    return any(low < t < high for t in thresholds)


def ratio_spread(a, b):
    """The :class:`Spread` of the per-round ratios ``a[i] / b[i]`` of two series timed round by round.

    A ratio taken within each round (both sides timed within moments of each
    other) and then its median leaves out a slow spell of a shared machine,
    which a ratio of two medians does not.

    Parameters
    ----------
    a, b : sequence of float
        Samples of the same rounds (equal lengths).

    Returns
    -------
    Spread
    """
    if len(a) != len(b):
        raise ValueError(f"ratio_spread: {len(a)} against {len(b)} rounds; time both sides in the same rounds")
    return spread([x / y for x, y in zip(a, b)])


def time_rounds(fns, repeats, warmup=1, sample=None, timer=time.perf_counter, threads=True):
    """Time callables round by round after warm-up, on :data:`TABLE_THREADS` Numba thread.

    Every callable is first called ``warmup`` times untimed (JIT, caches,
    buffers); then each of ``repeats`` rounds calls every callable in turn,
    so that a slow spell of the machine lands on all of them alike and the
    medians (or the per-round ratios, :func:`ratio_spread`) leave it out.
    Numba's thread count is :data:`TABLE_THREADS` around the whole of it and
    restored after (:class:`table_threads`).

    Parameters
    ----------
    fns : sequence of callable
        Called with no argument.
    repeats : int
        Timed rounds (at least 1).
    warmup : int
        Untimed calls of each callable first.
    sample : callable, optional
        ``sample(return value) -> float``: the sample is read from what the
        callable returns (e.g. one stage's milliseconds out of a render's
        timings); by default it is the wall time of the call, in seconds, by ``timer``.
    timer : callable
        A clock in seconds (``time.perf_counter``; tests pass a fake one).
    threads : bool
        Set the thread count (False: leave it as it is, e.g. inside a caller's own :class:`table_threads`).

    Returns
    -------
    list of list of float
        Per callable, its ``repeats`` samples in round order (:func:`spread` gives the median and spread).
    """
    repeats = int(repeats)
    if repeats < 1:
        raise ValueError(f"time_rounds: repeats = {repeats}; give at least 1")
    ctx = table_threads() if threads else contextlib.nullcontext()
    with ctx:
        for fn in fns:
            for _ in range(max(0, int(warmup))):
                fn()
        out = [[] for _ in fns]
        for _ in range(repeats):
            for k, fn in enumerate(fns):
                t0 = timer()
                r = fn()
                t1 = timer()
                out[k].append(float(sample(r)) if sample is not None else t1 - t0)
    return out


def readings_table(key, paper, rows):
    """A paper's "readings in use": where a knob's default or a tables set-up rests on our reading of the paper.

    Parameters
    ----------
    key : str
        The table's file-safe key (``"<paper>_readings"``).
    paper : str
        The paper's name, for the title.
    rows : list of (str, str, str, str)
        (knob or set-up and its value, what the paper says, our reading, the rows it decides and what the
        other reading gives where measured).

    Returns
    -------
    Table
    """
    return Table(key, f"Readings in use ({paper}): where a default or a set-up is our reading of the paper",
                 ["knob or set-up (value)", "the paper", "our reading", "rows it decides; the other reading"],
                 [list(r) for r in rows],
                 note=("Every reading the claims above rest on, whether or not docs/oracle.md's table 'Where a "
                       "default is our reading of the paper' lists it; the numbers are this run's."))
