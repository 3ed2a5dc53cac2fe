"""A sweep on dask.distributed against the same tasks one after another (issue: past one machine).

Runs ``specs/imagespace_knobs.json`` (40 tasks: 2 scenes x 10 iteration
counts x 2 difference steps, 384x384, 5 timed renders each after a warm-up,
one Numba thread per task, errors against the exact reference) twice in one
run: on a fresh ``LocalCluster`` of 2 single-thread worker processes
(cluster start-up and the workers' kernel loading included), and in this
process with one thread. Target: the cluster's wall time at most 0.7x the
sequential one. Writes ``results/sweep_overhead.json``.
"""

from __future__ import annotations

import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common as C  # noqa: E402

from refraction_ref.sweep import load_spec, run_reference, run_task, sweep, tasks_of  # noqa: E402

SPEC = os.path.join(C.HERE, "specs", "imagespace_knobs.json")


def sequential(spec):
    t0 = time.perf_counter()
    refs, rows = {}, []
    for t in tasks_of(spec):
        key = t["scene_name"]
        if key not in refs:
            refs[key] = run_reference(t["scene"], spec["reference"], spec["base"], 1)
        rows.append(run_task(t, spec["base"], spec["repeats"], 1, refs[key]))
    return rows, time.perf_counter() - t0


def main():
    spec = load_spec(SPEC)
    n = len(tasks_of(spec))
    rows_c, paths, wall_c = sweep(spec, out=C.results_dir(), workers=2, threads_per_worker=1)
    rows_s, wall_s = sequential(spec)
    ok_c = sum(r["status"] == "ok" for r in rows_c)
    ratio = wall_c / wall_s
    print(f"{n} tasks: LocalCluster (2 workers x 1 thread, start-up included) {wall_c:.1f} s, one process "
          f"{wall_s:.1f} s: ratio {ratio:.2f} (target <= 0.7) {'PASS' if ratio <= 0.7 else 'MISS'}; "
          f"{ok_c} ok; overhead per task {(wall_c - wall_s / 2) / n * 1e3:.0f} ms over the ideal halving")
    C.write_json("sweep_overhead.json", {"tasks": n, "cluster_s": wall_c, "sequential_s": wall_s, "ratio": ratio,
                                         "target": 0.7, "pass": ratio <= 0.7, "machine": C.machine_line(),
                                         "rev": C.git_rev(), "outputs": paths})


if __name__ == "__main__":
    main()
