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

import os
import time
from dataclasses import dataclass, field

__all__ = ["Table", "Claim", "Report", "HELD", "NOT_HELD", "NOT_MEASURED", "NOT_COMPARABLE", "BUSY", "LoadProbe",
           "cpu_jiffies", "other_load", "TABLE_THREADS", "table_threads"]

HELD, NOT_HELD, NOT_MEASURED, NOT_COMPARABLE = "held", "not held", "not measured", "not comparable"

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
        :data:`HELD`, :data:`NOT_HELD`, :data:`NOT_COMPARABLE` or :data:`NOT_MEASURED`.
    measured : str
        The measured number or ratio that decides it (``"1.9x (teapot, 101 planes)"``).
    why : str
        One sentence: why it holds or not here.
    rule : str
        The verdict rule, fixed before measuring: the quantity, the threshold and the set-up.
    timing : bool
        Whether a time decides the verdict (then a loaded machine makes it unreliable).
    """

    paper: str
    section: str
    quote: str
    verdict: str
    measured: str
    why: str
    rule: str = ""
    timing: bool = False


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
        Fraction in ``[0, ...)``; 0 when either reading is missing.
    """
    if before is None or after is None or wall_s <= 0:
        return 0.0
    hz = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    others = (after[0] - before[0]) - (after[1] - before[1])
    return max(0.0, others / hz / (wall_s * (cpus or os.cpu_count() or 1)))


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
