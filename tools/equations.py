"""The index from the three papers' equations, figures and sections to the functions that cite them.

Run ``python tools/equations.py`` from the repository root to write
``docs/equations.md``; ``python tools/equations.py --check`` exits 1, and
says what differs, when the committed file is not what the code gives;
``--shared`` lists the equations cited by more than one function.

It reads the source of ``refraction_ref`` (with :mod:`ast`; it imports
nothing of the package) and, in the numpydoc ``References`` section of
every function and method, finds the places of the three papers it cites:

========== ===================================== ================================
paper      equations, figures                    how a citation is written
========== ===================================== ================================
Chaudhari  ``eq. 3.2``, ``Fig. 3.4``             chapter.number
Sun        ``eq. 5``, ``Eq. (3)``, ``Fig. 9``    number; ``eqs. 4-6`` is a range
Tipprasert ``eq. 4-18``, ``Fig. 4-15``           chapter-number; ranges written
                                                 ``4-10 to 4-13``, ``4-21/4-22``
========== ===================================== ================================

and sections (``§4.2.1``, ``§§3.2-3.7``, ``§4.3-§4.5``, ``chapter 4``) for
all three. A citation belongs to the paper named last before it
(``Chaudhari``, ``Sun et al.``/``X. Sun``, ``Tipprasert``); a numbered entry
(``.. [2]``) or a clause after ``;`` naming a year of its own (another
paper: ``Iwasaki et al. (2003)``) ends that paper's scope. The output is
sorted (paper, kind, number, function), so it depends only on the source.
"""

from __future__ import annotations

import argparse
import ast
import difflib
import os
import re
import sys
from typing import NamedTuple

PKG = "refraction_ref"
OUTPUT = os.path.join("docs", "equations.md")

#: paper key -> (heading, pattern naming it in a reference)
PAPERS = {
    "chaudhari": ("P. Chaudhari, \"Real-Time Multiple Refractions Through Deformable Objects\", "
                  "M.S. thesis, UMBC, 2008",
                  r"Chaudhari|Real-Time Multiple Refractions"),
    "sun": ("X. Sun, K. Zhou, E. Stollnitz, J. Shi, B. Guo, \"Interactive Relighting of Dynamic Refractive "
            "Objects\", ACM TOG 27(3), 2008",
            r"\bSun et al\b|\bX\. Sun\b|\bSun \(?2008|Interactive Relighting of Dynamic Refractive"),
    "tipprasert": ("N. Tipprasert, \"An Interactive Rendering Method for Water-Side Scene with Caustics Using "
                   "Level Map Method\", M.Eng. thesis, Chulalongkorn University, 2006",
                   r"Tipprasert|Level Map Method"),
}
PAPER_ORDER = ("chaudhari", "sun", "tipprasert")

#: how each paper numbers its equations and figures (one label)
LABEL = {"chaudhari": r"\d+\.\d+", "sun": r"\(\d+\)|\d+", "tipprasert": r"\d+-\d+"}
#: what joins two labels into a range: Sun's "eqs. 4-6" is eqs. 4 to 6, Tipprasert's "4-6" is one label
RANGE = {"chaudhari": r"\s*(?:-|–|\bto\b)\s*", "sun": r"\s*(?:-|–|\bto\b)\s*", "tipprasert": r"\s+to\s+"}
SECTION = r"\d+(?:\.\d+)*"
LIST_SEP = r"\s*(?:,|/|&|\band\b)\s*"

KINDS = ("equation", "figure", "section")
#: word before the numbers -> kind
_KIND_WORD = re.compile(
    r"(?P<eq>\b[Ee]q(?:uation)?s?\.?(?=[\s(\d])\s*)|(?P<fig>\b[Ff]ig(?:ure)?s?\.?\s*)|(?P<sec>§§?\s*|\bch(?:apter|\.)\s*)")
_YEAR = re.compile(r"\b(?:1[89]|20)\d\d\b")
#: a clause opening with an author ("Pharr, ...", "Iwasaki et al.", "Amanatides and Woo"): another paper
_OTHER = re.compile(r"^\s*(?:[A-Z]\.\s*)*[A-Z][\w'\-]+(?:,|\s+et al\b|\s+and\s+[A-Z]|\s+&\s+[A-Z])")
_ENTRY = re.compile(r"^\s*\.\. \[\d+\]", re.M)


class Citation(NamedTuple):
    """One place of one paper cited by one function."""

    paper: str  # key of PAPERS
    kind: str  # 'equation', 'figure' or 'section'
    label: str  # as the paper numbers it: '3.2', '4-18', '5', '4.2.1'


class Row(NamedTuple):
    """A citation and the function whose References section makes it."""

    citation: Citation
    function: str  # module.qualname
    path: str  # relative, with '/'
    line: int  # of the ``def``


# ---------------------------------------------------------------------------
# parsing a References section
# ---------------------------------------------------------------------------

def _key(label):
    """Sort key of a label: its numbers."""
    return tuple(int(x) for x in re.findall(r"\d+", label))


def _expand(paper, kind, a, b):
    """The labels from ``a`` to ``b`` (both ends), when they differ only in their last number; else both ends."""
    ka, kb = _key(a), _key(b)
    if len(ka) != len(kb) or ka[:-1] != kb[:-1] or ka[-1] > kb[-1]:
        return [a, b]
    sep = "-" if paper == "tipprasert" and kind != "section" else "."
    head = sep.join(str(x) for x in ka[:-1])
    return [(head + sep if head else "") + str(n) for n in range(ka[-1], kb[-1] + 1)]


def _numbers(text, pos, paper, kind):
    """The labels of the list starting at ``pos``: ``a``, ``a-b`` / ``a to b`` (a range), joined by , / and."""
    if kind == "section":
        label, rng = r"§?" + SECTION, r"\s*(?:-|–|\bto\b)\s*"
    else:
        label, rng = LABEL[paper], RANGE[paper]
    item = re.compile(rf"(?P<a>{label})(?:{rng}(?P<b>{label}))?")
    sep = re.compile(LIST_SEP)
    out = []
    m = item.match(text, pos)
    while m:
        a = m.group("a").strip("§()")
        b = m.group("b")
        out += _expand(paper, kind, a, b.strip("§()")) if b else [a]
        pos = m.end()
        s = sep.match(text, pos)
        if not s:
            break
        m = item.match(text, s.end())
    return out


def _spans(references):
    """``(paper or None, text)`` pieces of a References section: each piece cites one paper or none."""
    entries = _ENTRY.split(references)
    markers = re.compile("|".join(f"(?P<{k}>{PAPERS[k][1]})" for k in PAPER_ORDER))
    spans = []
    for entry in entries:
        paper = None  # a numbered entry starts afresh
        for clause in entry.split(";"):
            found = list(markers.finditer(clause))
            if not found:
                if _YEAR.search(clause) or _OTHER.match(clause):
                    paper = None  # another paper's clause
                spans.append((paper, clause))
                continue
            spans.append((paper if not _YEAR.search(clause[:found[0].start()]) else None, clause[:found[0].start()]))
            for i, m in enumerate(found):
                paper = m.lastgroup
                end = found[i + 1].start() if i + 1 < len(found) else len(clause)
                spans.append((paper, clause[m.end():end]))
    return spans


def citations(references):
    """Every place of the three papers a References section cites, in order, without repeats.

    Parameters
    ----------
    references : str
        The text of a numpydoc ``References`` section.

    Returns
    -------
    list of Citation
    """
    out = []
    for paper, text in _spans(references):
        if paper is None:
            continue
        for m in _KIND_WORD.finditer(text):
            kind = "equation" if m.group("eq") else "figure" if m.group("fig") else "section"
            for label in _numbers(text, m.end(), paper, kind):
                c = Citation(paper, kind, label)
                if c not in out:
                    out.append(c)
    return out


def references_section(doc):
    """The text of a numpydoc docstring's ``References`` section ('' when it has none)."""
    m = re.search(r"^References\n-{4,}\n", doc, re.M)
    if not m:
        return ""
    rest = doc[m.end():]
    nxt = re.search(r"^\S[^\n]*\n-{4,}\n", rest, re.M)  # the next section, if any
    return rest[:nxt.start()] if nxt else rest


# ---------------------------------------------------------------------------
# walking the package
# ---------------------------------------------------------------------------

def _functions(tree):
    """(qualname, node) of every function and method of a module, nested ones included."""
    out = []

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                q = prefix + child.name
                out.append((q, child))
                visit(child, q + ".<locals>.")
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".")
    visit(tree, "")
    return out


def source_files(root):
    """The package's ``.py`` files, relative to ``root`` with '/', sorted."""
    out = []
    for dirpath, dirnames, files in os.walk(os.path.join(root, PKG)):
        dirnames[:] = [d for d in dirnames if d != "__pycache__"]
        for f in files:
            if f.endswith(".py"):
                out.append(os.path.relpath(os.path.join(dirpath, f), root).replace(os.sep, "/"))
    return sorted(out)


def module_name(path):
    """``refraction_ref/raster/draw.py`` -> ``refraction_ref.raster.draw`` (a package: its ``__init__`` dropped)."""
    name = path[:-3].replace("/", ".")
    return name[: -len(".__init__")] if name.endswith(".__init__") else name


def collect(root):
    """Every (citation, function) pair of the package, sorted by paper, kind, number, function.

    Parameters
    ----------
    root : str
        The repository root (holding ``refraction_ref/``).

    Returns
    -------
    list of Row
    """
    rows = []
    for path in source_files(root):
        with open(os.path.join(root, path), encoding="utf-8") as f:
            tree = ast.parse(f.read(), filename=path)
        for qual, node in _functions(tree):
            doc = ast.get_docstring(node)
            if not doc:
                continue
            for c in citations(references_section(doc)):
                rows.append(Row(c, f"{module_name(path)}.{qual}", path, node.lineno))
    return sorted(set(rows), key=lambda r: (PAPER_ORDER.index(r.citation.paper), KINDS.index(r.citation.kind),
                                            _key(r.citation.label), r.citation.label, r.function, r.line))


# ---------------------------------------------------------------------------
# writing docs/equations.md
# ---------------------------------------------------------------------------

_TITLE = {"equation": "Equations", "figure": "Figures", "section": "Sections"}


def cell(c):
    """How a citation is written in the index: ``eq. 3.2``, ``Fig. 4-15``, ``§4.2.1``."""
    return {"equation": "eq. ", "figure": "Fig. ", "section": "§"}[c.kind] + c.label


def render(rows):
    """The text of ``docs/equations.md`` for the rows of :func:`collect`."""
    lines = ["# Equations, figures and sections of the papers, and the functions that cite them", "",
             "Generated by `python tools/equations.py` from the `References` sections of the functions in",
             "`refraction_ref/` (do not edit by hand; `python tools/equations.py --check` fails when this",
             "file is stale). One row per place cited and function citing it, sorted by number; a function",
             "cites a place it computes, or one it relies on.", ""]
    for paper in PAPER_ORDER:
        mine = [r for r in rows if r.citation.paper == paper]
        lines += [f"## {PAPERS[paper][0]}", ""]
        for kind in KINDS:
            these = [r for r in mine if r.citation.kind == kind]
            if not these:
                continue
            places = len({r.citation for r in these})
            lines += [f"### {_TITLE[kind]} ({places} cited)", "",
                      f"| {kind} | function | file | line |", "| --- | --- | --- | --- |"]
            lines += [f"| {cell(r.citation)} | `{r.function}` | `{r.path}` | {r.line} |" for r in these]
            lines.append("")
    return "\n".join(lines)


def shared(rows):
    """Equations cited by more than one function: ``{citation: [function, ...]}``, in the index's order."""
    out = {}
    for r in rows:
        if r.citation.kind == "equation":
            out.setdefault(r.citation, []).append(r.function)
    return {c: fs for c, fs in out.items() if len(fs) > 1}


def check(root, text):
    """The differences between the committed index and ``text`` (a unified diff; '' when none)."""
    path = os.path.join(root, OUTPUT)
    try:
        with open(path, encoding="utf-8") as f:
            old = f.read()
    except FileNotFoundError:
        return f"{OUTPUT} is missing: run python tools/equations.py\n"
    if old == text:
        return ""
    return "".join(difflib.unified_diff(old.splitlines(True), text.splitlines(True),
                                        f"{OUTPUT} (committed)", f"{OUTPUT} (from the code)"))


def main(argv=None):
    """Write the index, check it (``--check``), or list the shared equations (``--shared``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 when docs/equations.md is stale")
    ap.add_argument("--shared", action="store_true", help="list the equations cited by more than one function")
    ap.add_argument("--root", default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    a = ap.parse_args(argv)
    rows = collect(a.root)
    text = render(rows) + "\n"
    if a.shared:
        for c, fs in shared(rows).items():
            print(f"{PAPERS[c.paper][0].split(',')[0]} {cell(c)}: {', '.join(fs)}")
        return 0
    if a.check:
        diff = check(a.root, text)
        if diff:
            sys.stdout.write(diff)
            print(f"{OUTPUT} is stale: run python tools/equations.py", file=sys.stderr)
            return 1
        print(f"{OUTPUT} is up to date ({len(rows)} rows)")
        return 0
    with open(os.path.join(a.root, OUTPUT), "w", encoding="utf-8") as f:
        f.write(text)
    print(f"wrote {OUTPUT} ({len(rows)} rows)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
