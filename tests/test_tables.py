"""``refraction-ref tables``: the report's assembly, the low-poly bunny, and a quick Chaudhari run."""

import csv

import numpy as np
import pytest

from refraction_ref.tables.common import HELD, NOT_HELD, Claim, Report, Table
from refraction_ref.tables.report import TablesError, markdown, run_tables, write_report


def _fake():
    t = Table("p_1", "Table 1: a thing", ["row", "paper ms", "ours ms"], [["a", 1.5, None], ["b", 12345, 2.0]],
              note="a note", plot="p.png")
    c = [Claim("P 2000", "§1", "It is fast.", HELD, "2.0x", "because"),
         Claim("P 2000", "§2", "It is | small.", NOT_HELD, "0.5x", "because not")]
    return [Report("P 2000", [t], c, 1.0), Report("Q 2001")]


def test_report_markdown_and_csv(tmp_path):
    reps = _fake()
    write_report(reps, tmp_path)
    md = (tmp_path / "tables.md").read_text()
    assert "1 held, 1 not held, 0 not measured." in md
    assert "“It is \\| small.”" in md            # a pipe in a quote does not break the table
    assert "| b | 12,345 | 2 |" in md and "| a | 1.5 | — |" in md
    assert "## Q 2001\n\nNot measured in this build." in md
    assert "![Table 1: a thing](p.png)" in md
    rows = list(csv.reader(open(tmp_path / "p_1.csv")))
    assert rows == [["row", "paper ms", "ours ms"], ["a", "1.5", ""], ["b", "12345", "2.0"]]
    claims = list(csv.DictReader(open(tmp_path / "claims.csv")))
    assert [c["verdict"] for c in claims] == [HELD, NOT_HELD]
    assert markdown(reps, quick=True).count("Quick run") == 1


def test_unknown_paper_is_named(tmp_path):
    with pytest.raises(TablesError, match="unknown paper 'nope'.*chaudhari"):
        run_tables(tmp_path, quick=True, only=["nope"])


def test_decimate_lands_near_target():
    from refraction_ref.meshes import load_mesh
    from refraction_ref.tables.chaudhari_report import decimate

    v, f = load_mesh("bunny")
    nv, nf, method = decimate(v, f, 15000)
    assert abs(len(nf) - 15000) <= 0.02 * 15000
    assert nf.min() >= 0 and nf.max() < len(nv)
    # the decimated mesh keeps the bunny's extent (within a cell or so)
    ext, next_ = np.ptp(np.asarray(v), axis=0), np.ptp(nv, axis=0)
    assert np.allclose(next_, ext, rtol=0.05)


def test_cli_tables_quick_chaudhari(tmp_path):
    from refraction_ref.cli import main

    assert main(["tables", "--quick", "--only", "chaudhari", "--out", str(tmp_path), "--quiet"]) == 0
    md = (tmp_path / "tables.md").read_text()
    assert "Table 4.1" in md and "Table 4.2" in md and "## Claims" in md
    rows = list(csv.DictReader(open(tmp_path / "chaudhari_4_1.csv")))
    assert {r["model"] for r in rows} >= {"Bunny-lowpoly", "Bunny I"}
    # our triangle counts are the meshes' own
    bunny = next(r for r in rows if r["model"] == "Bunny I")
    assert int(bunny["our triangles"]) == 69451
    claims = list(csv.DictReader(open(tmp_path / "claims.csv")))
    assert len(claims) == 5 and all(c["verdict"] in (HELD, NOT_HELD) for c in claims)
    assert (tmp_path / "chaudhari_tables.png").stat().st_size > 5000
