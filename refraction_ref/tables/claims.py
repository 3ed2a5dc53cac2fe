"""A paper's claims as data: one row per quoted sentence and set-up, judged by one loop.

Each paper module declares its claims as a tuple of :class:`ClaimRow`: the
quoted sentence, where it stands, the verdict rule (fixed before measuring),
and a small named function, the row's *judge*, that reads the measurements
and returns a :class:`Finding` (the rule's outcome and the numbers that
decide it). :func:`evaluate` turns the rows into :class:`~.common.Claim`
objects in the order declared, so that every paper's claims are built the
same way.

Texts that name the run's set-up (a grid, a volume size, a threshold) are
templates: ``str.format_map`` fills them from the measurements' mapping, so a
row reads as the sentence the report prints.

References
----------
Chaudhari (2008) chs. 3, 4; Sun et al. (2008) §§4-7; Tipprasert (2006) chs. 5, 6
(the sentences quoted in each paper's claim rows).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from .common import HELD, NOT_HELD, Claim, straddles

__all__ = ["Finding", "ClaimRow", "evaluate", "ratio_text", "ratio_straddles"]


@dataclass(frozen=True)
class Finding:
    """What a row's judge found in the measurements.

    Attributes
    ----------
    held : bool or None
        The rule's outcome; it picks the row's verdict (held or not held) and
        its explanation; for a row whose verdict is fixed it picks only the
        explanation.
    measured : str
        The numbers that decide the verdict.
    why : str
        The explanation, where it depends on more than the outcome (else the row's).
    verdict : str
        A verdict that overrides the row's (e.g. not measured in a run without the set-up).
    straddles : bool
        Single rounds fall on both sides of the rule's threshold (:attr:`.common.Claim.straddles`).
    rule, construction, differs : str
        Texts that depend on the measurements (else the row's).
    """

    held: bool | None
    measured: str
    why: str = ""
    verdict: str = ""
    straddles: bool = False
    rule: str = ""
    construction: str = ""
    differs: str = ""


@dataclass(frozen=True)
class ClaimRow:
    """One claim of a paper, declared: the sentence, the rule and the judge that reads the measurements.

    Attributes
    ----------
    section : str
        Where the sentence stands (``"§4.2, Table 4.2"``).
    quote : str
        The sentence, verbatim.
    judge : callable
        ``judge(measurements) -> Finding``, or None where the run states no such row.
    rule : str
        The verdict rule, a template filled from the measurements (``{res}``).
    why : str or (str, str)
        The explanation: one text, or (held, not held) (templates).
    verdict : str
        A fixed verdict (not judged rows: by construction, not comparable); empty: judged.
    timing : bool
        A time decides the verdict (:attr:`.common.Claim.timing`).
    construction : str
        Why the outcome follows from how the code is built (a template).
    differs : str
        How the set-up differs from the paper's (a template).
    """

    section: str
    quote: str
    judge: Callable
    rule: str = ""
    why: str | tuple = ""
    verdict: str = ""
    timing: bool = False
    construction: str = ""
    differs: str = ""


def _fill(text, values):
    return text.format_map(values) if text and "{" in text else text


def evaluate(paper, rows, measurements):
    """The claims of ``rows`` judged on ``measurements``, in the order declared.

    Parameters
    ----------
    paper : str
        The paper's name (:attr:`.common.Claim.paper`).
    rows : sequence of ClaimRow
        The paper's declared claims.
    measurements : mapping
        What the paper's run measured, and its set-up (the templates' names).

    Returns
    -------
    list of Claim
    """
    out = []
    for row in rows:
        found = row.judge(measurements)
        if found is None:
            continue
        verdict = found.verdict or row.verdict or (HELD if found.held else NOT_HELD)
        why = found.why or _fill(row.why if isinstance(row.why, str) else row.why[0 if found.held else 1],
                                 measurements)
        out.append(Claim(paper, row.section, row.quote, verdict, found.measured, why,
                         rule=found.rule or _fill(row.rule, measurements), timing=row.timing,
                         straddles=found.straddles,
                         construction=found.construction or _fill(row.construction, measurements),
                         differs=found.differs or _fill(row.differs, measurements)))
    return out


def ratio_text(r):
    """``'<median>x (rounds <low>-<high>)'`` of a (median, lowest, highest) triple of per-round ratios."""
    return f"{r[0]:.2f}x (rounds {r[1]:.2f}-{r[2]:.2f})"


def ratio_straddles(r, *thresholds):
    """:func:`.common.straddles` of a (median, lowest, highest) triple of per-round ratios.

    Parameters
    ----------
    r : (float, float, float)
        Median, lowest and highest per-round ratio.
    *thresholds : float
        The rule's thresholds.

    Returns
    -------
    bool
    """
    return straddles(r[1], r[2], *thresholds)
