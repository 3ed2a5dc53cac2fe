"""Every method's stages at 1, 2, ... threads: speed-up per stage and the serial fraction it implies.

    python benchmarks/bench_scaling.py [--threads 1,2,4,8,16] [--repeats 7] [--quick]

For each method's default scene (the image-space bunny 512^2, the caustics
scene, the level-map pool, the volumetric bunny, the exact reference of the
bunny, the exact photon reference of the caustics scene), renders after warm-up at each thread count (``numba.set_num_threads``;
the exact reference's Embree thread pool follows it), thread counts
alternating render by render so a slow spell of the machine hits every count
alike, and takes the median time of every stage. The serial fraction ``s`` of
a stage is the least-squares fit of Amdahl's law ``T(p) = T(1) (s + (1 - s) /
p)`` over the measured thread counts, and its projection is the speed-up
Amdahl's law gives at 16 threads, ``1 / (s + (1 - s) / 16)``.

Writes ``results/scaling.csv`` (method, stage, threads, median ms, speed-up),
``results/scaling.md`` (the table and the Amdahl fit) and ``results/scaling.png``
(speed-up per stage). Targets (issue "Use every core"): on 2 cores every stage
over 5 ms at least 1.6x faster with 2 threads than with 1, and the exact
reference at least 1.6x; no stage slower as threads are added.
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys

import numba
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common as C  # noqa: E402

from refraction_ref.files import atomic_open, savefig_atomic  # noqa: E402

rr = C.rr


def scenes(quick):
    res = 256 if quick else 512
    from refraction_ref.levelmap.pipeline import DEFAULT_SCENE_PATH

    data = os.path.join(os.path.dirname(DEFAULT_SCENE_PATH))
    cam = {"camera.width": res, "camera.height": res}
    return [
        ("imagespace", rr.load_scene(None, cam), "imagespace"),
        ("caustics", rr.load_scene(os.path.join(data, "caustics_default.json"),
                                   {**cam, **({"imagespace.photons": 256, "imagespace.caustic_map": 256} if quick else {})}),
         "imagespace"),
        ("levelmap", rr.load_scene(DEFAULT_SCENE_PATH, {**cam, **({"levelmap.map_size": 256} if quick else {})}),
         "levelmap"),
        ("volumetric", rr.load_scene(None, {**cam, "volumetric.resolution": 64 if quick else 128,
                                            "volumetric.photons": 256 if quick else 1024}), "volumetric"),
        ("exact", rr.load_scene(None, cam), "exact"),
        # the exact photon reference's caustic stages (receiver hits, splat, final pass: shared with the above)
        ("caustics_exact", rr.load_scene(os.path.join(data, "caustics_default.json"),
                                         {**cam, "exact.photons": 512 if quick else 1024,
                                          **({"imagespace.caustic_map": 256} if quick else {})}), "exact"),
    ]


def amdahl(threads, times):
    """Least-squares serial fraction of ``T(p) = T1 (s + (1 - s)/p)``, clamped to [0, 1]."""
    t1 = times[threads.index(1)]
    x = np.array([1.0 - 1.0 / p for p in threads])          # T(p)/T1 = 1 - (1 - s)(1 - 1/p)
    y = np.array([1.0 - t / t1 for t in times])
    if not np.any(x > 0):
        return float("nan")
    par = float(np.dot(x, y) / np.dot(x, x))
    return float(min(1.0, max(0.0, 1.0 - par)))


def measure(name, scene, method, threads, repeats, warmup, samples=None):
    before = numba.get_num_threads()
    per = {p: {} for p in threads}
    try:
        for p in threads:
            numba.set_num_threads(p)
            for _ in range(warmup):
                rr.render(scene, method=method)
        for _ in range(repeats):
            for p in threads:  # alternate: a slow spell of the machine hits every count alike
                numba.set_num_threads(p)
                res = rr.render(scene, method=method)
                for k, v in res.meta["timings_ms"].items():
                    per[p].setdefault(k, []).append(v)
                per[p].setdefault("total", []).append(res.meta["total_ms"])
    finally:
        numba.set_num_threads(before)
    if samples is not None:
        samples[name] = {str(p): d for p, d in per.items()}
    return {p: {k: statistics.median(v) for k, v in d.items()} for p, d in per.items()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ncpu = numba.config.NUMBA_NUM_THREADS
    default = [p for p in (1, 2, 4, 8, 16, 32, 64) if p <= ncpu]
    ap.add_argument("--threads", default=",".join(map(str, default)))
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", help="comma list of: imagespace, caustics, levelmap, volumetric, exact, caustics_exact")
    ap.add_argument("--tag", default="", help="suffix of the output names (results/scaling<tag>.*), so that a "
                    "partial or before/after run leaves the committed table alone")
    ap.add_argument("--samples", help="also write every render's stage times here (JSON), for "
                    "benchmarks/scaling_compare.py")
    a = ap.parse_args(argv)
    threads = sorted({int(x) for x in a.threads.split(",") if int(x) <= ncpu} | {1})
    rows, fits = [], []
    samples = {} if a.samples else None
    for name, scene, method in scenes(a.quick):
        if a.only and name not in a.only.split(","):
            continue
        print(f"{name}: threads {threads}", flush=True)
        m = measure(name, scene, method, threads, a.repeats, warmup=2 if a.quick else C.WARMUP, samples=samples)
        for stage in m[1]:
            times = [m[p].get(stage, 0.0) for p in threads]
            for p, t in zip(threads, times):
                rows.append({"method": name, "stage": stage, "threads": p, "median_ms": round(t, 3),
                             "speedup": round(times[0] / t, 3) if t > 0 else ""})
            if "." in stage:
                continue
            s = amdahl(threads, times) if len(threads) > 1 and times[0] > 0 else float("nan")
            fits.append({"method": name, "stage": stage, "ms_1": times[0], "ms": times,
                         "speedup": [times[0] / t if t else float("nan") for t in times], "serial_fraction": s,
                         "amdahl_16": 1.0 / (s + (1.0 - s) / 16.0) if s == s else float("nan")})
            sp = times[0] / times[-1] if times[-1] else float("nan")
            print(f"  {stage:>16}: " + ", ".join(f"{p}T {t:.1f} ms" for p, t in zip(threads, times))
                  + f"  speed-up {sp:.2f}x, serial fraction {s:.2f}", flush=True)
    if samples is not None:
        import json

        with atomic_open(a.samples, "w") as f:
            json.dump({"machine": C.machine_line(), "rev": C.git_rev(), "threads": threads, "samples": samples}, f)
    tag = ("_quick" if a.quick else "") + a.tag
    with atomic_open(C.results_path(f"scaling{tag}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    two = threads.index(2) if 2 in threads else None
    lines = [f"# Scaling ({C.machine_line()}, rev {C.git_rev()})", "",
             "| method | stage | " + " | ".join(f"{p} thr (ms)" for p in threads)
             + " | speed-up | serial fraction | Amdahl at 16 | 2-thread target |",
             "|---|---|" + "---|" * (len(threads) + 4)]
    for fit in fits:
        target = ""
        if two is not None and fit["ms_1"] > 5.0:
            target = "PASS" if fit["speedup"][two] >= 1.6 else f"MISS ({fit['speedup'][two]:.2f}x)"
        lines.append(f"| {fit['method']} | {fit['stage']} | " + " | ".join(f"{t:.1f}" for t in fit["ms"])
                     + f" | {fit['speedup'][-1]:.2f}x | {fit['serial_fraction']:.2f} | {fit['amdahl_16']:.1f}x "
                     f"| {target} |")
    with atomic_open(C.results_path(f"scaling{tag}.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 6))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for fit in fits:
        if fit["ms_1"] > 5.0:
            ax.plot(threads, fit["speedup"], marker="o", label=f"{fit['method']}.{fit['stage']}")
    ax.plot(threads, threads, "k--", lw=0.8, label="ideal")
    ax.set_xlabel("threads")
    ax.set_ylabel("speed-up over 1 thread")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    savefig_atomic(fig, C.results_path(f"scaling{tag}.png"), dpi=90)
    print("wrote " + ", ".join(C.results_path(f"scaling{tag}.{e}") for e in ("csv", "md", "png")))


if __name__ == "__main__":
    main()
