"""Error against run time of the image-space method, knob by knob.

    python benchmarks/sweep_imagespace.py [--quick] [--repeats 3] [--res 256 512]

Each knob family is swept one at a time around the faithful defaults
(5 iterations, delta 2, 256 slices, 32 layers, bitmask depth, central
normals, MIP bounds, local slicing) on the default bunny view, at each image resolution:

  iterations             binary-search iterations 1..10
  iterations, float      the same with depth='float' (A-buffer: no slice quantisation)
  iterations, global     the same with bounds='global' (loose bound: the thesis's "more iterations
                         instead of parallel reduction" comparison, §4.2)
  delta                  central-difference step 1, 2, 3 (eq. 3.2)
  slices                 64, 128, 256, 512 (and 1024 at 512x512)
  slices, global slicing the same with slicing='global' (one depth range for the whole object: with the
                         default per-pixel 'local' range the front and back layers are exact, so on
                         this view, mostly two layers deep, the slice count barely shows)
  layers                 8, 16, 32
  depth                  bitmask, float
  normals                forward, central, mesh3x3
  normals, delta=1       the same with delta 1
  bounds                 mip, global

Each point: median pipeline time (sum of ``timings_ms`` over ``--repeats``
renders after two warm-ups) and the error against the exact Embree reference
rendered at the same resolution: exit-direction median / p90 (deg) over pixels
where both exited, and the fraction of hit pixels with status 1.

Writes ``benchmarks/results/sweep_imagespace.csv`` and ``sweep_imagespace.png``
(``*_quick.*`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common as C  # noqa: E402
from common import rr  # noqa: E402

from refraction_ref.compare import compare_arrays  # noqa: E402
from refraction_ref.files import atomic_open, savefig_atomic  # noqa: E402

BASE = {"iterations": 5, "delta": 2, "slices": 256, "layers": 32, "depth": "bitmask", "normals": "central",
        "bounds": "mip", "slicing": "local"}
KNOBS = tuple(BASE)


def families(res, quick):
    """[(family, knob shown on the plot, [overrides of BASE])] for one resolution."""
    if quick:
        return [("iterations", "iterations", [{"iterations": i} for i in (1, 5, 10)]),
                ("slices", "slices", [{"slices": s} for s in (128, 256)]),
                ("depth", "depth", [{"depth": d} for d in ("bitmask", "float")]),
                ("normals", "normals", [{"normals": n} for n in ("forward", "central")]),
                ("bounds", "bounds", [{"bounds": b} for b in ("mip", "global")])]
    its = range(1, 11)
    slices = (64, 128, 256, 512, 1024) if res >= 512 else (64, 128, 256, 512)
    return [("iterations", "iterations", [{"iterations": i} for i in its]),
            ("iterations, float", "iterations", [{"iterations": i, "depth": "float"} for i in its]),
            ("iterations, global", "iterations", [{"iterations": i, "bounds": "global"} for i in its]),
            ("delta", "delta", [{"delta": d} for d in (1, 2, 3)]),
            ("slices", "slices", [{"slices": s} for s in slices]),
            ("slices, global slicing", "slices", [{"slices": s, "slicing": "global"} for s in slices]),
            ("layers", "layers", [{"layers": n} for n in (8, 16, 32)]),
            ("depth", "depth", [{"depth": d} for d in ("bitmask", "float")]),
            ("normals", "normals", [{"normals": n} for n in ("forward", "central", "mesh3x3")]),
            ("normals, delta=1", "normals", [{"normals": n, "delta": 1} for n in ("forward", "central", "mesh3x3")]),
            ("bounds", "bounds", [{"bounds": b} for b in ("mip", "global")])]


def measure(res, cfg, ref, repeats):
    scene = C.bunny_scene(res, **cfg)
    t = C.time_render(scene, repeats)
    c = compare_arrays(t["result"].arrays, ref)
    e = c["exit_dir_deg"]
    hits = c["pixels"]
    row = {"res": res, **cfg, "pipeline_ms": t["pipeline_ms"], "total_ms": t["total_ms"],
           "other_load": t["other_load"], "attempts": t["attempts"]}
    row.update({f"ms_{k}": t["stages_ms"].get(k, 0.0) for k in C.STAGES})
    row.update(err_median=e["median"], err_p90=e["p90"], err_p99=e["p99"], err_mean=e["mean"],
               frac_status1=c["status_a"][1] / hits if hits else float("nan"),
               status_agree=c["status_agree"], interfaces_agree=c["interfaces_agree"],
               both_exited=c["both_exited"], hit_pixels=hits)
    return row


def pareto(rows):
    """Points not beaten in both time and median error by another point."""
    pts = sorted(rows, key=lambda r: (r["pipeline_ms"], r["err_median"]))
    front, best = [], float("inf")
    for r in pts:
        if r["err_median"] < best:
            front.append(r)
            best = r["err_median"]
    return front


def cfg_label(r):
    diff = [f"{k}={r[k]}" for k in KNOBS if r[k] != BASE[k]]
    return ", ".join(diff) if diff else "defaults"


def plot(rows, fams_by_res, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker  # noqa: F401

    ress = sorted({r["res"] for r in rows})
    fig, axes = plt.subplots(1, len(ress), figsize=(8.5 * len(ress), 7), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    markers = "os^vD<>ph*"
    for ax, res in zip(axes[0], ress):
        for k, (fam, knob, pts) in enumerate(fams_by_res[res]):
            sel = [r for r in rows if r["res"] == res and r["family"] == fam]
            sel.sort(key=lambda r: (str(type(r[knob])), r[knob]))
            xs = [r["pipeline_ms"] for r in sel]
            ys = [r["err_median"] for r in sel]
            numeric = all(isinstance(r[knob], (int, float)) for r in sel)
            ax.plot(xs, ys, marker=markers[k % len(markers)], color=colors[k % len(colors)], lw=1, ms=6,
                    ls="-" if numeric else "none", label=fam, alpha=0.85)
            for r, x, y in zip(sel, xs, ys):
                ax.annotate(str(r[knob]), (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7,
                            color=colors[k % len(colors)])
        base = [r for r in rows if r["res"] == res and cfg_label(r) == "defaults"]
        if base:
            ax.scatter([base[0]["pipeline_ms"]], [base[0]["err_median"]], s=160, facecolors="none",
                       edgecolors="k", lw=1.5, zorder=5, label="faithful defaults")
        ax.set_xscale("log")
        ax.set_yscale("log")
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
            axis.set_minor_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ax.set_xlabel("pipeline time, ms (sum of timings_ms, median)")
        ax.set_ylabel("exit-direction error vs exact, median (deg)")
        ax.set_title(f"bunny {res}x{res}: error against time, one knob at a time")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    savefig_atomic(fig, path, dpi=90)
    plt.close(fig)


def _typed(v):
    for t in (int, float):
        try:
            return t(v)
        except ValueError:
            pass
    return v


def plot_only(quick):
    suffix = "_quick" if quick else ""
    csv_path = C.results_path(f"sweep_imagespace{suffix}.csv")
    with open(csv_path) as f:
        rows = [{k: _typed(v) for k, v in r.items()} for r in csv.DictReader(f)]
    fams_by_res = {}
    for r in rows:
        fams = fams_by_res.setdefault(r["res"], [])
        if r["family"] not in [x[0] for x in fams]:
            knob = [x for x in families(r["res"], quick) if x[0] == r["family"]]
            fams.append((r["family"], knob[0][1] if knob else "iterations", []))
    png_path = C.results_path(f"sweep_imagespace{suffix}.png")
    plot(rows, fams_by_res, png_path)
    print(f"redrew {os.path.relpath(png_path, C.REPO)} from {os.path.relpath(csv_path, C.REPO)}")
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="reduced sweep at 256x256 for smoke testing")
    ap.add_argument("--repeats", type=int, default=None, help="timed renders per point (>= 3; default 3 quick, 7 full)")
    ap.add_argument("--res", type=int, nargs="+", default=None, help="image resolutions (default 256 512; quick: 256)")
    ap.add_argument("--plot-only", action="store_true", help="redraw the PNG from the existing CSV, measure nothing")
    args = ap.parse_args(argv)
    if args.plot_only:
        return plot_only(args.quick)
    reps = max(3, args.repeats or (3 if args.quick else 7))
    ress = args.res or ([256] if args.quick else [256, 512])
    suffix = "_quick" if args.quick else ""
    t_start = time.perf_counter()
    print(f"# image-space sweep ({'quick' if args.quick else 'full'}; {C.machine_line()}; git {C.git_rev()})")
    print(f"time: median pipeline ms over {reps} renders after two warm-ups; error vs exact at the same resolution\n")

    rows, fams_by_res = [], {}
    for res in ress:
        t0 = time.perf_counter()
        ref = rr.render(C.bunny_scene(res), method="exact").arrays
        print(f"exact reference {res}x{res}: {1e3 * (time.perf_counter() - t0):.0f} ms")
        cache = {}
        fams_by_res[res] = families(res, args.quick)
        for fam, knob, pts in fams_by_res[res]:
            for over in pts:
                cfg = dict(BASE, **over)
                key = tuple(cfg[k] for k in KNOBS)
                if key not in cache:
                    cache[key] = measure(res, cfg, ref, reps)
                row = dict(cache[key], family=fam)
                rows.append(row)
                print(f"  {res:4d}  {fam:<22s} {knob + '=' + str(cfg[knob]):<18s} {row['pipeline_ms']:8.1f} ms   "
                      f"median {row['err_median']:6.3f}  p90 {row['err_p90']:7.3f} deg   "
                      f"status1 {100 * row['frac_status1']:5.1f}%", flush=True)

    cols = ["family", "res", *KNOBS, "pipeline_ms", "total_ms", *[f"ms_{k}" for k in C.STAGES], "err_median",
            "err_p90", "err_p99", "err_mean", "frac_status1", "status_agree", "interfaces_agree", "both_exited",
            "hit_pixels", "other_load", "attempts"]
    csv_path = C.results_path(f"sweep_imagespace{suffix}.csv")
    with atomic_open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    png_path = C.results_path(f"sweep_imagespace{suffix}.png")
    plot(rows, fams_by_res, png_path)

    print("\n## best points (Pareto front of time vs median error, unique configurations)")
    for res in ress:
        uniq = {tuple(r[k] for k in KNOBS): r for r in rows if r["res"] == res}.values()
        front = pareto(list(uniq))
        print(f"\n### {res}x{res}")
        print(C.md_table(["config (vs defaults)", "pipeline ms", "median deg", "p90 deg", "status 1"],
                         [[cfg_label(r), f"{r['pipeline_ms']:.1f}", f"{r['err_median']:.3f}", f"{r['err_p90']:.3f}",
                           f"{100 * r['frac_status1']:.1f}%"] for r in front]))
        base = [r for r in uniq if cfg_label(r) == "defaults"][0]
        best = min(uniq, key=lambda r: r["err_median"])
        print(f"defaults: {base['pipeline_ms']:.1f} ms, median {base['err_median']:.3f} deg; lowest median error: "
              f"{cfg_label(best)} ({best['pipeline_ms']:.1f} ms, {best['err_median']:.3f} deg)")
    el = time.perf_counter() - t_start
    print(f"\nwrote {os.path.relpath(csv_path, C.REPO)} and {os.path.relpath(png_path, C.REPO)}; "
          f"{len(rows)} rows; script took {el:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
