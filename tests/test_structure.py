"""The package's structure holds the redesign's floor (``python tools/structure.py`` prints the numbers).

Two redesign steps set it: no import circle, at most 4 arrows running back up between rooms, no
function over 150 lines; no Python function over 8 parameters and at most 10 kernels over 10 (a knob
travels as one typed value, not as loose parameters); no module over 800 lines; no test importing a
private name of the package (tests use what users can use).
"""

from __future__ import annotations

import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))

import structure  # noqa: E402


@pytest.fixture(scope="module")
def report():
    return structure.report(ROOT, passes=True)


def test_no_import_circle_and_few_arrows_back_up(report):
    assert report["circles"] == []
    assert len(report["arrows_back_up"]) <= 4, report["arrows_back_up"]


def test_no_long_function(report):
    assert report["long_functions"] == []


def test_parameters(report):
    assert report["many_parameters"] == [], "a knob travels as one typed value, not as loose parameters"
    assert len(report["wide_kernels"]) <= structure.MAX_WIDE_KERNELS, report["wide_kernels"]


def test_module_size(report):
    big = [(n, m) for n, m in report["module_lines"] if n > structure.MAX_MODULE_LINES]
    assert big == []


def test_tests_use_public_names(report):
    assert report["tests_importing_private"] == []


def test_passes_cite_the_papers(report):
    assert report["passes_without_references"] == []
    assert report["parameters_share"] >= 0.9


def test_the_counters_count(tmp_path):
    """The gates can fail: a synthetic package with one wide function, one wide kernel, a long module."""
    pkg = tmp_path / "refraction_ref"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    params = ", ".join(f"a{i}" for i in range(11))
    (pkg / "m.py").write_text(
        "import numba as nb\n"
        f"def wide({params}):\n    pass\n"
        f"@nb.njit(cache=True)\ndef kern({params}):\n    pass\n"
        f"def fine(a, b, *, c=1):\n    pass\n" + "x = 1\n" * 801)
    tests = tmp_path / "tests"
    tests.mkdir()
    (tests / "test_x.py").write_text("from refraction_ref.m import _private\nimport refraction_ref.m as m\nm._kern\n")
    r = structure.report(str(tmp_path))
    assert r["many_parameters"] == ["refraction_ref.m.wide (11)"]
    assert r["wide_kernels"] == ["refraction_ref.m.kern (11)"]
    assert r["module_lines"][0][0] > 800
    assert r["tests_importing_private"] == ["tests/test_x.py: m._kern, refraction_ref.m._private"]
