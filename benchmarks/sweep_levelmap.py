"""Error against time for the level-map variants, one knob at a time.

    python benchmarks/sweep_levelmap.py [--repeats 3] [--out benchmarks/results]

From the default scene (teapot on a pool floor, 128x128 water, 512x512 maps,
50 planes), vary ``planes``, ``map_size``, ``water.resolution`` and
``variant`` (level map, per-ray, volumetric). Error: relative L1 of the
caustic maps (floor and teapot, both blurred by one texel) against the exact
Embree reference rendered at the same map size; time: median after warm-up.
Writes ``levelmap_sweep.csv`` and ``levelmap_sweep.png``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_levelmap import errors, exact_maps, timed  # noqa: E402
from refraction_ref.files import atomic_open, savefig_atomic  # noqa: E402

from refraction_ref.levelmap import default_scene  # noqa: E402
from refraction_ref.levelmap.pipeline import warm_up  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(HERE, "results"))
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    warm_up()
    runs = []
    for v in ("levelmap", "per_ray", "volumetric"):
        for n in ((5, 10, 20, 50, 100, 200) if v != "per_ray" else (50,)):
            if v == "volumetric" and n > 100:
                continue
            runs.append({"variant": v, "planes": n, "map_size": 512, "resolution": 128})
    for v in ("levelmap", "per_ray"):
        for m in (256, 1024):
            runs.append({"variant": v, "planes": 50, "map_size": m, "resolution": 128})
        for res in (64, 256):
            runs.append({"variant": v, "planes": 50, "map_size": 512, "resolution": res})
    exact = {}
    rows = []
    for r in runs:
        over = {"levelmap.variant": r["variant"], "levelmap.planes": r["planes"],
                "levelmap.map_size": r["map_size"], "water.resolution": r["resolution"]}
        sc = default_scene(over)
        if r["map_size"] not in exact:
            exact[r["map_size"]] = exact_maps(default_scene({"levelmap.map_size": r["map_size"]}))
        t, (arr, info) = timed(sc, a.repeats)
        e = errors(arr, exact[r["map_size"]], sc)
        row = dict(r, time_s=t, error_floor=e[0], error_teapot=e[1], planes_used=info["planes_used"])
        rows.append(row)
        print(", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()), flush=True)
    p = os.path.join(a.out, "levelmap_sweep.csv")
    with atomic_open(p, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("wrote", p)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    for ax, key in zip(axs, ("error_floor", "error_teapot")):
        for v, mk in (("levelmap", "o"), ("per_ray", "*"), ("volumetric", "s")):
            rs = [r for r in rows if r["variant"] == v]
            ax.scatter([r["time_s"] for r in rs], [r[key] for r in rs], marker=mk, label=v, s=40)
            for r in rs:
                ax.annotate(f"{r['planes']}p/{r['map_size']}/{r['resolution']}", (r["time_s"], r[key]),
                            fontsize=6, xytext=(3, 2), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("time per frame, s (median)")
        ax.set_ylabel("relative L1 vs exact (1-texel blur)")
        ax.set_title(key.replace("error_", ""))
        ax.legend(fontsize=8)
    fig.suptitle("Level-map water caustics: error against time (labels: planes / map size / water resolution)")
    fig.tight_layout()
    p = os.path.join(a.out, "levelmap_sweep.png")
    savefig_atomic(fig, p, dpi=90)
    print("wrote", p)


if __name__ == "__main__":
    main()
