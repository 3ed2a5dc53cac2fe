"""What every paper's tables module returns to ``refraction-ref tables``.

Each paper module (:mod:`.chaudhari_report`, :mod:`.sun`, :mod:`.tipprasert`)
exposes ``run(quick: bool, out: pathlib.Path, log=print) -> Report``: it measures
its tables, writes any plots into ``out`` (file names only in :attr:`Table.plot`)
and states the paper's claims checked against those measurements.
:mod:`.report` turns the reports into one Markdown file.

Ratios and trends are compared, never a CPU's absolute time with a GPU's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Table", "Claim", "Report", "HELD", "NOT_HELD", "NOT_MEASURED"]

HELD, NOT_HELD, NOT_MEASURED = "held", "not held", "not measured"


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
        :data:`HELD`, :data:`NOT_HELD` or :data:`NOT_MEASURED`.
    measured : str
        The measured number or ratio that decides it (``"1.9x (teapot, 101 planes)"``).
    why : str
        One sentence: why it holds or not here.
    """

    paper: str
    section: str
    quote: str
    verdict: str
    measured: str
    why: str


@dataclass
class Report:
    """One paper's tables and claims."""

    paper: str
    tables: list = field(default_factory=list)
    claims: list = field(default_factory=list)
    seconds: float = 0.0
