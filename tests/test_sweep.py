"""``refraction-ref sweep``: a grid of renders on a dask LocalCluster of two single-thread workers."""

from __future__ import annotations

import csv

import pytest

from refraction_ref import cli
from refraction_ref.sweep import SweepError, load_spec, run_task, sweep, tasks_of

SPEC = {"name": "t", "scenes": {"bunny": None, "sphere": {"objects": [{"mesh": "sphere", "fit": 1.0}]}},
        "methods": ["imagespace"], "grid": {"imagespace.iterations": [1, 5]},
        "base": {"camera.width": 32, "camera.height": 32}, "repeats": 1}


def test_a_sweep_runs_on_two_single_thread_workers_and_reports_a_failed_task(tmp_path):
    spec = load_spec(SPEC)
    spec["scenes"]["broken"] = {"objects": [{"mesh": "sphere", "fit": 1.0}], "camera": {"eye": [0, 0, 0.1]}}
    rows, paths, wall = sweep(spec, out=str(tmp_path), workers=2, threads_per_worker=1)
    assert len(rows) == len(tasks_of(spec)) == 6
    ok = [r for r in rows if r["status"] == "ok"]
    assert len(ok) == 4 and all(r["threads"] == 1 for r in ok)
    assert len({r["worker"] for r in ok}) >= 1 and all(r["worker"].startswith("tcp://") for r in ok)
    # more iterations: no worse against the exact reference (the same scene and camera)
    for sc in ("bunny", "sphere"):
        e = {r["imagespace.iterations"]: r["exit_dir_median_deg"] for r in ok if r["scene"] == sc}
        assert e[5] <= e[1] + 1e-9
    failed = [r for r in rows if r["status"] != "ok"]
    assert len(failed) == 2 and all("inside a refractive object" in r["status"] for r in failed)
    with open(paths[0]) as f:
        assert len(list(csv.DictReader(f))) == 6


def test_a_task_is_the_same_in_a_worker_and_in_process():
    t = tasks_of(load_spec(SPEC))[0]
    row = run_task(t, SPEC["base"], 1, 1)
    assert row["status"] == "ok" and row["worker"] == "local" and row["total_ms"] > 0


def test_bad_specs_are_refused_by_key(tmp_path, capsys):
    for bad, msg in (({"methods": ["nope"]}, "nope"), ({"grid": {"imagespace.iterations": []}}, "grid"),
                     ({"colour": 1}, "colour"), ({"grid": {"imagespace.iterations": [-3]}}, "imagespace.iterations")):
        with pytest.raises(SweepError, match=msg):
            load_spec({**SPEC, **bad})
    assert cli.main(["sweep", str(tmp_path / "missing.json")]) == 2
    assert "does not exist" in capsys.readouterr().err
