"""Measure the performance and accuracy targets in one run; print PASS/MISS per target.

    python benchmarks/bench_targets.py [--repeats 9] [--pipeline-target-ms MS] [--startup-target-s 10]

(a) bunny 512x512, 256 slices, 32 layers, 5 iterations: median of the sum of
    the stage timings (min/max pass to finished image), median ``total_ms``,
    per-stage medians;
(b) the exact Embree reference on the same scene, rendered alternately with the
    image-space method in one run, and the ratio of their medians (>= 10x; the
    pipeline's stage sum, as in (a); the ratio of ``total_ms``, which adds the
    scene set-up outside the pipeline, is printed for information);
(c) Igea (268,686 tris), same settings, ratio Igea/bunny (<= 1.3);
(d) accuracy against the exact reference on the default view: exit-direction
    error median and p90 for the faithful defaults and for depth='float'
    (median <= 1 deg), fraction of hit pixels with status 1 (>= 80%);
(e) start-up: wall time of a fresh ``python -c "import refraction_ref as rr; rr.render(...64x64...)"``
    (the second such process, so the Numba on-disk cache is warm).

Writes ``benchmarks/results/targets.json``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common as C  # noqa: E402
from common import rr  # noqa: E402

from refraction_ref.compare import compare_arrays  # noqa: E402

STARTUP_CODE = ("import refraction_ref as rr; "
                "rr.render(rr.load_scene({'camera': {'width': 64, 'height': 64}}))")


WARMUP = C.WARMUP  # warm-up renders before timing


def fmt(x, nd=1):
    return "n/a" if x is None else f"{x:.{nd}f}"


def verdict(ok):
    return "n/a" if ok is None else ("PASS" if ok else "MISS")


def startup_seconds():
    env = dict(os.environ)
    env["PYTHONPATH"] = C.REPO + os.pathsep + env.get("PYTHONPATH", "")
    C.wait_for_quiet()
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", STARTUP_CODE], cwd=C.REPO, env=env, capture_output=True,
                       text=True, timeout=900)
    dt = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"start-up process failed ({p.returncode}):\n{p.stderr[-2000:]}")
    return dt


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=15,
                    help="timed renders per measurement (after WARMUP warm-ups; >= 5)")
    ap.add_argument("--pipeline-target-ms", type=float, default=None,
                    help="optional PASS/MISS bound for (a) the bunny pipeline time; without it (a) is informational")
    ap.add_argument("--startup-target-s", type=float, default=10.0,
                    help="PASS/MISS bound for (e), seconds (default 10: 'seconds, not a minute of JIT')")
    args = ap.parse_args(argv)
    reps = max(5, args.repeats)
    t_start = time.perf_counter()
    out = {"machine": C.machine_line(), "git": C.git_rev(), "repeats": reps}
    rows = []  # (id, what, measured, target, verdict)
    print(f"# refraction_ref targets  ({out['machine']}; git {out['git']})")
    print(f"timings: median over {reps} renders after {WARMUP} warm-ups; pipeline = sum of meta['timings_ms']\n")

    settings = dict(layers=32, slices=256, iterations=5)
    # (a) --------------------------------------------------------------------
    bunny = C.bunny_scene(512, **settings)
    a = C.time_render(bunny, reps, warmup=WARMUP)
    out["a_bunny"] = {k: v for k, v in a.items() if k != "result"}
    out["a_bunny"]["triangles"] = C.triangles(bunny)
    stages = "  ".join(f"{k} {a['stages_ms'].get(k, 0.0):.1f}" for k in C.STAGES)
    print(f"(a) bunny 512x512x256, 32 layers, 5 it.: pipeline {a['pipeline_ms']:.1f} ms "
          f"(samples {', '.join(f'{s:.0f}' for s in a['samples'])}), total_ms {a['total_ms']:.1f}")
    print(f"    per-stage medians (ms): {stages}")
    tgt = args.pipeline_target_ms
    rows.append(("a", "bunny 512^2x256, 32 L, 5 it: pipeline ms (median)", fmt(a["pipeline_ms"]),
                 f"<= {tgt:g}" if tgt else "info (thesis GPU: 36 FPS = 27.8 ms)",
                 verdict(a["pipeline_ms"] <= tgt) if tgt else "info"))
    rows.append(("a", "bunny: render() total_ms (median)", fmt(a["total_ms"]), "info", "info"))
    rows.append(("a", "bunny: FPS from pipeline ms", fmt(1000.0 / a["pipeline_ms"]), "info", "info"))

    # (b) --------------------------------------------------------------------
    # the two methods alternate render by render ("in the same run"), so that a
    # slow spell of the machine weighs on both alike
    pair = C.time_interleaved(bunny, reps, methods=("imagespace", "exact"), warmup=WARMUP)
    im, ex = pair["imagespace"], pair["exact"]
    out["b_exact"] = dict({k: v for k, v in ex.items() if k != "result"}, other_load=pair["other_load"],
                          attempts=pair["attempts"],
                          imagespace_same_run={k: v for k, v in im.items() if k != "result"})
    r_pipe = ex["pipeline_ms"] / im["pipeline_ms"]
    r_tot = ex["total_ms"] / im["total_ms"]
    out["b_exact"].update(ratio_pipeline=r_pipe, ratio_total=r_tot)
    print(f"(b) exact Embree reference, alternating with the image-space method: exact stage sum "
          f"{ex['pipeline_ms']:.1f} ms (total_ms {ex['total_ms']:.1f}), image-space {im['pipeline_ms']:.1f} ms "
          f"(total_ms {im['total_ms']:.1f}); ratio {r_pipe:.2f}x (stage sums), {r_tot:.2f}x (total_ms)")
    rows.append(("b", "exact reference ms (median total_ms)", fmt(ex["total_ms"]), "info", "info"))
    rows.append(("b", "ratio exact / imagespace (stage sums)", f"{r_pipe:.2f}x", ">= 10x", verdict(r_pipe >= 10)))
    rows.append(("b", "ratio exact / imagespace (total_ms, incl. scene set-up)", f"{r_tot:.2f}x", "info",
                 "info"))

    # (c) --------------------------------------------------------------------
    try:
        igea = C.igea_scene(512, **settings)
        g = C.time_render(igea, reps, warmup=WARMUP)
        out["c_igea"] = {k: v for k, v in g.items() if k != "result"}
        out["c_igea"]["triangles"] = C.triangles(igea)
        ratio = g["pipeline_ms"] / a["pipeline_ms"]
        out["c_igea"]["ratio_pipeline"] = ratio
        out["c_igea"]["ratio_total"] = g["total_ms"] / a["total_ms"]
        stages = "  ".join(f"{k} {g['stages_ms'].get(k, 0.0):.1f}" for k in C.STAGES)
        print(f"(c) Igea ({out['c_igea']['triangles']:,} tris): pipeline {g['pipeline_ms']:.1f} ms, "
              f"total_ms {g['total_ms']:.1f}; ratio Igea/bunny {ratio:.2f} (stage sums), "
              f"{out['c_igea']['ratio_total']:.2f} (total_ms)")
        print(f"    per-stage medians (ms): {stages}")
        rows.append(("c", "Igea 512^2x256: pipeline ms (median)", fmt(g["pipeline_ms"]), "info", "info"))
        rows.append(("c", "ratio Igea / bunny (stage sums)", f"{ratio:.2f}", "<= 1.3", verdict(ratio <= 1.3)))
        rows.append(("c", "ratio Igea / bunny (total_ms)", f"{out['c_igea']['ratio_total']:.2f}", "info", "info"))
    except C.Skip as e:
        print(f"(c) skipped: {e}")
        out["c_igea"] = {"skipped": str(e)}
        rows.append(("c", "ratio Igea / bunny", "skipped", "<= 1.3", "n/a"))

    # (d) --------------------------------------------------------------------
    default = rr.load_scene()
    ref = rr.render(default, method="exact").arrays
    out["d_accuracy"] = {}
    for label, over in (("faithful defaults", {}), ("depth=float (A-buffer)", {"imagespace.depth": "float"})):
        res = rr.render(default, overrides=over or None)
        c = compare_arrays(res.arrays, ref)
        e = c["exit_dir_deg"]
        hits = c["pixels"]
        frac1 = c["status_a"][1] / hits if hits else float("nan")
        out["d_accuracy"][label] = {"exit_dir_deg": e, "status_a": c["status_a"], "status_b": c["status_b"],
                                    "hit_pixels": hits, "fraction_status1": frac1,
                                    "interfaces_agree": c["interfaces_agree"], "status_agree": c["status_agree"]}
        print(f"(d) {label}: exit-dir error median {e['median']:.3f} deg, p90 {e['p90']:.3f}, p99 {e['p99']:.3f}; "
              f"status 1 on {100 * frac1:.1f}% of {hits} hit pixels (status 0..4 {c['status_a']})")
        rows.append(("d", f"{label}: exit-dir median deg", f"{e['median']:.3f}", "<= 1", verdict(e["median"] <= 1.0)))
        rows.append(("d", f"{label}: exit-dir p90 deg", f"{e['p90']:.3f}", "info", "info"))
        rows.append(("d", f"{label}: hit pixels with status 1", f"{100 * frac1:.1f}%", ">= 80%",
                     verdict(frac1 >= 0.8)))

    # (e) --------------------------------------------------------------------
    first = startup_seconds()   # makes sure the on-disk cache is populated
    second = startup_seconds()
    out["e_startup_s"] = {"first": first, "second": second}
    print(f"(e) start-up of a fresh process rendering 64x64: first {first:.2f} s, second {second:.2f} s")
    rows.append(("e", "fresh-process start-up, 2nd run (s)", f"{second:.2f}", f"<= {args.startup_target_s:g}",
                 verdict(second <= args.startup_target_s)))

    print()
    print(C.md_table(["", "target", "measured", "goal", "result"], rows))
    out["table"] = [dict(zip(("id", "what", "measured", "goal", "result"), r)) for r in rows]
    out["elapsed_s"] = time.perf_counter() - t_start
    p = C.write_json("targets.json", out)
    print(f"\nwrote {os.path.relpath(p, C.REPO)}; script took {out['elapsed_s']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
