"""``refraction-ref tables``: the report's assembly, the low-poly bunny, and a quick Chaudhari run."""

import csv

import numpy as np
import pytest

from refraction_ref.tables.common import (BUSY, BY_CONSTRUCTION, HELD, NOT_COMPARABLE, NOT_HELD, NOT_MEASURED, SPLIT,
                                          VERDICTS, Claim, LoadProbe, Report, Table, other_load)
from refraction_ref.tables.report import (TablesError, markdown, run_tables, sentence_verdict, sentences, summary,
                                          summary_line, write_report)


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
    assert "2 quoted sentences in 2 rows" in md and "1 held, 1 not held, 0 split" in md
    assert "Rows: 1 held, 1 not held, 0 not comparable, 0 not measured, 0 by construction" in md
    assert "“It is \\| small.”" in md            # a pipe in a quote does not break the table
    assert "| b | 12,345 | 2 |" in md and "| a | 1.5 | — |" in md
    assert "## Q 2001\n\nNot measured in this build." in md
    assert "![Table 1: a thing](p.png)" in md
    rows = list(csv.reader(open(tmp_path / "p_1.csv")))
    assert rows == [["row", "paper ms", "ours ms"], ["a", "1.5", ""], ["b", "12345", "2.0"]]
    claims = list(csv.DictReader(open(tmp_path / "claims.csv")))
    assert [c["verdict"] for c in claims] == [HELD, NOT_HELD]
    assert [c["sentence"] for c in claims] == ["S1", "S2"]
    assert markdown(reps, quick=True).count("Quick run") == 1


def _rows(spec):
    """Claims of one paper from ``{quote: [verdict, ...]}``; by-construction rows carry their reason."""
    return [Claim("P 2000", f"§{k}", q, v, "1.0x", "because", rule="held if > 1",
                  construction="the code computes it" if v == BY_CONSTRUCTION else "")
            for k, (q, vs) in enumerate(spec.items()) for v in vs]


def test_each_sentence_counts_once_with_its_sub_verdicts(tmp_path):
    spec = {"A is by design.": [BY_CONSTRUCTION],
            "B holds.": [HELD, BY_CONSTRUCTION],
            "C holds here, not there.": [HELD, NOT_HELD],
            "D is fast, and faster.": [NOT_COMPARABLE, HELD],
            "E fails.": [NOT_HELD, BY_CONSTRUCTION],
            "F is not measured.": [BY_CONSTRUCTION, NOT_MEASURED]}
    rep = [Report("P 2000", [], _rows(spec), 1.0)]
    ss = sentences(rep)
    assert [s["id"] for s in ss] == ["S1", "S2", "S3", "S4", "S5", "S6"]
    assert [s["verdict"] for s in ss] == [BY_CONSTRUCTION, HELD, SPLIT, HELD, NOT_HELD, NOT_MEASURED]
    assert [len(s["rows"]) for s in ss] == [1, 2, 2, 2, 2, 2]
    sm = summary(rep)
    assert (sm["sentences"], sm["rows"], sm["evidence_rows"]) == (6, 11, 5)
    assert sm["sentence_counts"] == {HELD: 2, NOT_HELD: 1, SPLIT: 1, NOT_COMPARABLE: 0, NOT_MEASURED: 1,
                                     BY_CONSTRUCTION: 1}
    assert sm["row_counts"] == {HELD: 3, NOT_HELD: 2, NOT_COMPARABLE: 1, NOT_MEASURED: 1, BY_CONSTRUCTION: 4}
    assert summary_line(rep).startswith("6 quoted sentences: 2 held, 1 not held, 1 split, 0 not comparable, "
                                        "1 not measured, 1 by construction only; 11 rows (3 held")
    write_report(rep, tmp_path)
    md = (tmp_path / "tables.md").read_text()
    assert "6 quoted sentences in 11 rows" in md and "### Sentences" in md
    assert "| S3 | P 2000 | §2 | held / not held | **split** |" in md
    assert md.count("the code computes it") == 4          # every by-construction row shows its reason
    rows = list(csv.DictReader(open(tmp_path / "claims.csv")))
    assert [r["sentence"] for r in rows] == ["S1", "S2", "S2", "S3", "S3", "S4", "S4", "S5", "S5", "S6", "S6"]
    assert {r["sentence_verdict"] for r in rows if r["sentence"] == "S2"} == {HELD}


def test_a_by_construction_row_is_never_counted_as_evidence():
    # whatever a by-construction row shows, the sentence's verdict and the evidence count do not move
    for other in (HELD, NOT_HELD):
        base = _rows({"It holds.": [other]})
        more = _rows({"It holds.": [other, BY_CONSTRUCTION, BY_CONSTRUCTION]})
        a, b = summary([Report("P", [], base)]), summary([Report("P", [], more)])
        assert a["sentence_counts"] == b["sentence_counts"] and a["evidence_rows"] == b["evidence_rows"] == 1
        assert b["row_counts"][BY_CONSTRUCTION] == 2
    assert sentence_verdict([BY_CONSTRUCTION]) == BY_CONSTRUCTION
    assert sentence_verdict([BY_CONSTRUCTION, NOT_COMPARABLE]) == NOT_COMPARABLE
    assert sentence_verdict([BY_CONSTRUCTION, NOT_HELD]) == NOT_HELD
    # a by-construction verdict needs its reason; a verdict outside the list is refused
    with pytest.raises(ValueError, match="reason"):
        Claim("P", "§1", "q", BY_CONSTRUCTION, "1", "w")
    with pytest.raises(ValueError, match="choose from"):
        Claim("P", "§1", "q", "probably", "1", "w")
    assert SPLIT not in VERDICTS          # a sentence's verdict, never a row's


def test_busy_machine_marks_timing_verdicts_unreliable(tmp_path):
    c = [Claim("P 2000", "§1", "It is fast.", HELD, "2.0x", "because", rule="held if > 1.5x", timing=True),
         Claim("P 2000", "§2", "It is exact.", HELD, "0 ulp", "because", rule="held if equal")]
    busy, idle = Report("P 2000", [], c, 1.0, other_load=BUSY + 0.3), Report("Q 2001", [], c[:1], 1.0, other_load=0.0)
    write_report([busy, idle], tmp_path)
    md = (tmp_path / "tables.md").read_text()
    assert "Warning: the machine was busy" in md and "P 2000" in md.split("## Claims")[0]
    assert "1 timing verdicts unreliable" in md and "held if > 1.5x" in md
    rows = list(csv.DictReader(open(tmp_path / "claims.csv")))
    # only the busy paper's timing claim is unreliable; its exactness claim and the idle paper's timing claim stand
    assert [(r["section"], r["timing"], r["reliable"], r["other_load"]) for r in rows] == [
        ("§1", "yes", "no", "0.45"), ("§2", "no", "yes", "0.45"), ("§1", "yes", "yes", "0.00")]
    assert rows[0]["rule"] == "held if > 1.5x"
    write_report([idle], tmp_path)
    assert "busy" not in (tmp_path / "tables.md").read_text()


def test_a_verdict_whose_rounds_straddle_its_threshold_says_so(tmp_path):
    from refraction_ref.tables.claims import ratio_straddles
    from refraction_ref.tables.common import straddles

    assert ratio_straddles((1.02, 0.97, 1.08), 1.0) and not ratio_straddles((1.05, 1.01, 1.08), 1.0)
    assert ratio_straddles((1.0, 0.6, 0.9), 0.67, 1.5) and not ratio_straddles((1.0, 0.8, 1.2), 0.67, 1.5)
    assert straddles(0.97, 1.08, 1.0) and not straddles(1.01, 1.08, 1.0)
    c = [Claim("P 2000", "§1", "It is fast.", HELD, "1.02x", "because", rule="held if > 1", timing=True,
               straddles=True),
         Claim("P 2000", "§2", "It is faster.", HELD, "2.0x", "because", rule="held if > 1", timing=True)]
    write_report([Report("P 2000", [], c, 1.0)], tmp_path)
    md = (tmp_path / "tables.md").read_text()
    assert md.count("a re-run may flip it") == 1 and "1 timing verdicts decided by a median" in md
    rows = list(csv.DictReader(open(tmp_path / "claims.csv")))
    assert [r["straddles"] for r in rows] == ["yes", "no"]


def test_other_load_share():
    hz = __import__("os").sysconf("SC_CLK_TCK")
    # 2 s of wall on 2 CPUs = 4 CPU-seconds; the machine was busy 3 s of them, 1 s ours: others took 50 %
    assert other_load((0, 0), (3 * hz, 1 * hz), 2.0, cpus=2) == 0.5
    assert other_load((0, 0), (hz, hz), 2.0, cpus=2) == 0.0
    assert other_load(None, (hz, 0), 1.0) == 0.0
    # a window shorter than one tick of the counters: one tick of another process is not 700 machines' worth
    assert other_load((0, 0), (1, 0), 1e-5, cpus=2) == 1.0
    assert 0.0 <= LoadProbe().stop() <= 1.0


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


@pytest.mark.slow  # CI runs `refraction-ref tables --quick` itself (its own step); this checks the report's content
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
    assert len(claims) == 25 and all(c["verdict"] in VERDICTS for c in claims)
    # a by-construction row always carries its reason
    assert all(c["construction"] for c in claims if c["verdict"] == BY_CONSTRUCTION)
    assert all(c["rule"] for c in claims)                    # every verdict has its rule
    # a GPU's frame rate is not judged on a CPU; the quick run has one grid, so the trend is not measured
    assert [c["verdict"] for c in claims if c["section"] == "§4.1"] == [NOT_COMPARABLE, NOT_MEASURED]
    # Table 4.2's one bunny and two are filmed with one camera: one bunny is traced on fewer interfaces
    t42 = {r["stage"]: r for r in csv.DictReader(open(tmp_path / "chaudhari_4_2.csv"))}
    assert int(t42["Interfaces (ours only)"]["ours II-A 256"]) < int(t42["Interfaces (ours only)"]["ours I-A 256"])
    # the depth-complexity study: equal triangles, twice the layers
    dc = list(csv.DictReader(open(tmp_path / "chaudhari_depth.csv")))
    assert dc[0]["triangles"] == dc[1]["triangles"] == "4096"
    assert (int(dc[0]["max fragments/pixel"]), int(dc[1]["max fragments/pixel"])) == (2, 4)
    assert (tmp_path / "chaudhari_tables.png").stat().st_size > 5000
    # nothing but the report: the decimated bunny stays in memory
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "chaudhari_3_5.csv", "chaudhari_3_7.csv", "chaudhari_4_1.csv", "chaudhari_4_2.csv", "chaudhari_depth.csv",
        "chaudhari_more.csv", "chaudhari_readings.csv", "chaudhari_tables.png", "claims.csv", "tables.md"]


def test_component_box_reads_eq_4_3_along_each_axis():
    """The eq. 4-3 study's component-wise box: a receiver symmetric about its origin gets the tight box's extents,
    while the default full-norm reading takes the farthest vertices' whole lengths (larger in every axis)."""
    from refraction_ref.levelmap.planes import reference_box
    from refraction_ref.tables.tipprasert_placement import component_box

    floor = np.array([[x, -1.0, z] for x in (-2.0, 2.0) for z in (-2.0, 2.0)])
    T0 = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])
    origin = np.array([0.0, -1.0, 0.0])
    comp = component_box(floor, T0, 64, "thesis", origin)
    tight = reference_box(floor, T0, 64, "tight")
    full = reference_box(floor, T0, 64, "thesis", origin)
    assert np.allclose([comp.w, comp.h, comp.d], [tight.w, tight.h, tight.d])
    assert np.allclose(comp.center, origin) and np.allclose(comp.V, full.V)
    assert all(f > c + 0.1 for f, c in zip((full.w, full.h, full.d), (comp.w, comp.h, comp.d)))
    assert np.isclose(full.h, 2 * np.sqrt(8.0))  # |P| of a corner: 2 sqrt(2^2 + 2^2) = 5.66
    # other placements pass through unchanged
    same = component_box(floor, T0, 64, "tight")
    assert all(np.array_equal(x, y) for x, y in zip(same, tight))


def test_chaudhari_quality_normals_and_bounds():
    """§3.5/§3.7 studies: the hand-run tight bound is the renderer's trace; eq. 3.1 is worse than eq. 3.2."""
    from refraction_ref.render import render
    from refraction_ref.tables import chaudhari_quality as Q

    d, _ = Q.study_scene("bunny", 64)
    r = render(d)
    tr = Q.layered(Q.PreparedScene(d), "tight", 5)
    assert np.array_equal(tr["status"], r["status"])
    assert np.array_equal(tr["exit_dir"], r["exit_dir"], equal_nan=True)
    rows = {x["option"]: x for x in Q.normals_study(64, scenes=("bunny",))}
    assert all(np.isfinite(x["normal_median"]) and np.isfinite(x["exit_p90"]) and x["pixels"] > 500
               for x in rows.values())
    assert rows["forward (eq. 3.1)"]["normal_median"] > 2 * rows["central delta=2 (thesis)"]["normal_median"]


def test_time_rounds_median_and_spread_with_a_fake_timer():
    import numba

    from refraction_ref.tables.common import TABLE_THREADS, Spread, ratio_spread, spread, time_rounds

    # a fake clock: each call of a callable advances it by the next of its scripted durations
    clock = [0.0]
    seen_threads = []

    def make(durations):
        it = iter(durations)

        def fn():
            seen_threads.append(numba.get_num_threads())
            clock[0] += next(it)
            return clock[0]
        return fn

    # one warm-up call each (its 100 s is not a sample), then 5 interleaved rounds
    a = make([100.0, 3.0, 1.0, 2.0, 9.0, 4.0])
    b = make([100.0, 1.0, 1.0, 1.0, 3.0, 2.0])
    before = numba.get_num_threads()
    ta, tb = time_rounds([a, b], repeats=5, warmup=1, timer=lambda: clock[0])
    assert numba.get_num_threads() == before                      # restored after
    assert set(seen_threads) == {min(TABLE_THREADS, numba.config.NUMBA_NUM_THREADS)}
    assert ta == [3.0, 1.0, 2.0, 9.0, 4.0] and tb == [1.0, 1.0, 1.0, 3.0, 2.0]
    assert spread(ta) == Spread(3.0, 1.0, 9.0, 5)
    # per-round ratios 3, 1, 2, 3, 2: median 2 (the ratio of the medians would be 3 / 1)
    assert ratio_spread(ta, tb) == Spread(2.0, 1.0, 3.0, 5)
    assert spread(ta).text("x", 1) == "3.0x (1.0-9.0, n = 5)"
    # the sample read from the return value (a stage's own time) instead of the clock
    stage_ms = iter([50.0, 8.0, 6.0, 7.0])
    assert time_rounds([lambda: {"march": next(stage_ms)}], repeats=3, warmup=1, sample=lambda r: r["march"],
                       timer=lambda: clock[0]) == [[8.0, 6.0, 7.0]]
    with pytest.raises(ValueError, match="repeats"):
        time_rounds([a], repeats=0)
    with pytest.raises(ValueError, match="rounds"):
        ratio_spread([1.0], [1.0, 2.0])


def test_chaudhari_fps_trend_is_a_median_of_per_round_ratios():
    from refraction_ref.tables.chaudhari_models import fps_ratio

    # frames = pipeline samples + the cell's photon generation (frame_ms - pipeline_ms, 2 and 5 ms)
    lo = {"pipeline_ms": 10.0, "frame_ms": 12.0, "samples": [10.0, 11.0, 9.0]}
    hi = {"pipeline_ms": 40.0, "frame_ms": 45.0, "samples": [40.0, 44.0, 31.0]}
    s = fps_ratio(lo, hi)
    assert (s.n, s.low, s.high) == (3, 36.0 / 11.0, 49.0 / 13.0) and s.median == 45.0 / 12.0
    # cells not timed in the same rounds: one sample, the ratio of the medians
    assert fps_ratio(dict(lo, samples=[10.0]), hi).n == 1 and fps_ratio(dict(lo, samples=[10.0]), hi).median == 3.75


def test_no_gain_is_evidence_only_where_fewer_iterations_reach_similar_output():
    """§4.2: a loose run of 5 or more iterations skips only the reduction, so its ratio is by construction; only
    a run with fewer iterations that reaches similar output can show a gain (numbers, not times)."""
    from refraction_ref.tables.chaudhari_claims import NO_GAIN, claim_no_gain

    five = {"bunny": {"n_loose": 5, "ratio": (0.99, 0.97, 1.02), "reduce_share": 0.012},
            "sphere": {"n_loose": None}}
    c = claim_no_gain(five, "a set-up")
    assert c.verdict == BY_CONSTRUCTION and "bunny 1.2%" in c.construction and "cannot be run" in c.measured
    assert claim_no_gain({"sphere": {"n_loose": None}}, "x").verdict == BY_CONSTRUCTION
    gain = dict(five, bunny={"n_loose": 4, "ratio": (0.90, 0.85, 0.97), "reduce_share": 0.012})
    assert claim_no_gain(gain, "x").verdict == NOT_HELD
    near = dict(five, bunny={"n_loose": 3, "ratio": (0.97, 0.93, 1.02), "reduce_share": 0.012})
    c = claim_no_gain(near, "x")
    assert c.verdict == HELD and c.straddles and 0.93 < NO_GAIN < 1.02
    # the by-construction outcome never counts for the sentence; the exercised one does
    assert summary([Report("C", [], [claim_no_gain(five, "x")])])["evidence_rows"] == 0
    assert summary([Report("C", [], [claim_no_gain(gain, "x")])])["sentence_counts"][NOT_HELD] == 1


def test_table_1_photon_half_is_by_construction_and_the_voxel_half_is_judged():
    from refraction_ref.tables.claims import evaluate
    from refraction_ref.tables.sun_claims import QUOTE_T1, TABLE_CLAIMS

    # the sentence's two counted halves (photons, occupied voxels); its timed triangle half reads the timings
    scaling = [r for r in TABLE_CLAIMS if r.quote == QUOTE_T1 and not r.timing]

    M = 64

    def row(tris, fit, ph, steps, occ):
        return {"tris": tris, "fit": fit, "ph": ph, "a": {"photon_steps": steps, "occupied_voxels": occ}}

    for small_steps, verdict in ((100, HELD), (6000, NOT_HELD)):
        t1 = [row(20480, 0.8, M, 8000, 27000), row(20480, 0.8, M // 4, 500, 27000), row(20480, 0.5, M, small_steps,
                                                                                        8000)]
        photons, voxels = evaluate("Sun et al. 2008", scaling, {"t1": t1, "M": M})
        assert photons.verdict == BY_CONSTRUCTION and "x16.0" in photons.measured
        assert voxels.verdict == verdict and photons.quote == voxels.quote
        s = sentences([Report("Sun", [], [photons, voxels])])
        assert len(s) == 1 and s[0]["verdict"] == verdict
