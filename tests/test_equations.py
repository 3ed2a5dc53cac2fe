"""docs/equations.md, the index from the papers' equations to the functions citing them, follows the code.

``python tools/equations.py`` writes it from the numpydoc ``References`` sections; the first test
fails when the committed file is stale (run the tool and commit). The others pin the parser on
small synthetic docstrings: each paper's way of numbering, ranges, and which paper a citation
belongs to.
"""

from __future__ import annotations

import os
import sys
import textwrap

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))

import equations  # noqa: E402
from equations import Citation  # noqa: E402


def labels(refs, paper, kind="equation"):
    return [c.label for c in equations.citations(refs) if c.paper == paper and c.kind == kind]


def test_committed_index_is_current():
    text = equations.render(equations.collect(ROOT)) + "\n"
    diff = equations.check(ROOT, text)
    assert diff == "", "docs/equations.md is stale: run python tools/equations.py\n" + diff[:4000]


# ---- the three numbering styles --------------------------------------------------------------

def test_tipprasert_labels_ranges_and_slashes():
    refs = "Tipprasert (2006), §4.7.2, eqs. 4-21/4-22; §4.2.2, eqs. 4-10 to 4-13, Figs. 5-1 to 5-3."
    assert labels(refs, "tipprasert") == ["4-21", "4-22", "4-10", "4-11", "4-12", "4-13"]
    assert labels(refs, "tipprasert", "figure") == ["5-1", "5-2", "5-3"]
    assert labels(refs, "tipprasert", "section") == ["4.7.2", "4.2.2"]
    # "4-18" is one equation of chapter 4, not a range
    assert labels("Tipprasert (2006), eq. 4-18 (its numerator), eqs. 2-7 and 2-8.", "tipprasert") == \
        ["4-18", "2-7", "2-8"]


def test_sun_numbers_and_ranges():
    refs = "Sun et al. (2008), §3 eqs. 1-3, Eq. (5) and Fig. 9; §4.4, eqs. 4-6."
    assert labels(refs, "sun") == ["1", "2", "3", "5", "4", "6"]
    assert labels(refs, "sun", "figure") == ["9"]
    assert labels(refs, "sun", "section") == ["3", "4.4"]


def test_chaudhari_numbers_and_sections():
    refs = "Chaudhari 2008, §3.5, eqs. 3.1 and 3.2, Fig. 3.4; §§3.2-3.4, 4.2."
    assert labels(refs, "chaudhari") == ["3.1", "3.2"]
    assert labels(refs, "chaudhari", "figure") == ["3.4"]
    assert labels(refs, "chaudhari", "section") == ["3.5", "3.2", "3.3", "3.4", "4.2"]
    # a range across levels keeps its ends
    assert labels("Chaudhari (2008), §4.2.1 to §4.3.", "chaudhari", "section") == ["4.2.1", "4.3"]


# ---- which paper a citation belongs to -------------------------------------------------------

def test_other_papers_cite_nothing():
    refs = ("Sun et al. (2008), §3 eqs. 1-3; Hairer, Norsett, Wanner (1993), §II.4-II.10, eq. 4.7.\n"
            "M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd ed., §8.2, eq. 8.4.")
    assert equations.citations(refs) == [Citation("sun", "section", "3")] + \
        [Citation("sun", "equation", n) for n in "123"]


def test_a_clause_without_a_name_is_the_previous_papers():
    refs = "Tipprasert (2006), §4.2.1, eqs. 4-6 to 4-7; §4.4, eq. 4-15; Iwasaki et al. (2003), eq. 4-16."
    assert labels(refs, "tipprasert") == ["4-6", "4-7", "4-15"]


def test_numbered_entries_start_afresh():
    refs = textwrap.dedent("""\
        .. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene with
           Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
           University, 2006, eq. 2-8, §4.5.
        .. [2] J. Pineda, "A Parallel Algorithm for Polygon Rasterization", SIGGRAPH
           1988, §2, eq. 3-1.
        .. [3] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
           Objects", M.S. thesis, UMBC, 2008, §3.3.""")
    assert equations.citations(refs) == [Citation("tipprasert", "equation", "2-8"),
                                         Citation("tipprasert", "section", "4.5"),
                                         Citation("chaudhari", "section", "3.3")]


def test_each_place_once_per_function():
    assert labels("Sun et al. (2008), eq. 6; §4.5 and eq. 6.", "sun") == ["6"]


def test_references_section_ends_at_the_next_section():
    doc = "Summary.\n\nReferences\n----------\nSun et al. (2008), eq. 5.\n\nExamples\n--------\n>>> eq. 7\n"
    assert equations.references_section(doc).strip() == "Sun et al. (2008), eq. 5."
    assert equations.references_section("No references here.") == ""


# ---- the index --------------------------------------------------------------------------------

SOURCE = '''\
"""A module (its own References are not a function's)."""


def b():
    """B.

    References
    ----------
    Tipprasert (2006), eqs. 4-9, 4-10.
    """


class K:
    def a(self):
        """A.

        References
        ----------
        Tipprasert (2006), eq. 4-10; Sun et al. (2008), eq. 2.
        """
'''


@pytest.fixture()
def tree(tmp_path):
    pkg = tmp_path / "refraction_ref" / "sub"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "m.py").write_text(SOURCE)
    (tmp_path / "docs").mkdir()
    return tmp_path


def test_rows_name_the_function_its_file_and_line_sorted_by_number(tree):
    rows = equations.collect(str(tree))
    got = [(equations.cell(r.citation), r.function, r.path, r.line) for r in rows]
    assert got == [
        ("eq. 2", "refraction_ref.sub.m.K.a", "refraction_ref/sub/m.py", 14),
        ("eq. 4-9", "refraction_ref.sub.m.b", "refraction_ref/sub/m.py", 4),  # 4-9 before 4-10: by number
        ("eq. 4-10", "refraction_ref.sub.m.K.a", "refraction_ref/sub/m.py", 14),
        ("eq. 4-10", "refraction_ref.sub.m.b", "refraction_ref/sub/m.py", 4),
    ]
    assert equations.shared(rows) == {Citation("tipprasert", "equation", "4-10"):
                                      ["refraction_ref.sub.m.K.a", "refraction_ref.sub.m.b"]}
    text = equations.render(rows)
    assert "| eq. 4-10 | `refraction_ref.sub.m.b` | `refraction_ref/sub/m.py` | 4 |" in text
    assert text == equations.render(equations.collect(str(tree)))  # deterministic


def test_check_exits_1_on_a_stale_index_and_0_once_written(tree, capsys):
    assert equations.main(["--check", "--root", str(tree)]) == 1  # missing
    assert equations.main(["--root", str(tree)]) == 0
    assert equations.main(["--check", "--root", str(tree)]) == 0
    (tree / "refraction_ref" / "sub" / "m.py").write_text(SOURCE.replace("eqs. 4-9, 4-10", "eq. 4-11"))
    capsys.readouterr()
    assert equations.main(["--check", "--root", str(tree)]) == 1
    out = capsys.readouterr().out
    assert "+| eq. 4-11 | `refraction_ref.sub.m.b`" in out and "-| eq. 4-9 | `refraction_ref.sub.m.b`" in out
