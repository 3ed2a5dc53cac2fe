"""Error against run time for the volumetric photon marcher (issue 3): a Luneburg-lens sweep.

Varies ds_min, eps, photon count, N and the integrator one at a time around
a base setting, and records the median miss distance of the exit lines from
the antipodal point (in voxels), the steps and the marching time. Writes
``benchmarks/results/sweep_volumetric.csv`` and ``.png``.

Usage: ``python benchmarks/sweep_volumetric.py [--quick]``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_volumetric import OUT, luneburg_miss  # noqa: E402
from refraction_ref.files import atomic_open, savefig_atomic  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    base = {"N": 64 if a.quick else 128, "M": 64, "integrator": "euler", "ds_min": 1.0, "eps": 0.005}
    grid = {"ds_min": [0.5, 1.0, 2.0, 4.0, 8.0], "eps": [0.001, 0.005, 0.02, 0.05],
            "M": [32, 64, 128], "N": [32, 48, 64] + ([] if a.quick else [96, 128]),
            "integrator": ["euler", "rk4"]}
    rows = []
    luneburg_miss(32, 8, "euler", 1.0)  # warm-up
    for integ in ("euler", "rk4"):
        for knob, values in grid.items():
            for val in values:
                p = dict(base, integrator=integ)
                p[knob] = val
                r = luneburg_miss(p["N"], p["M"], p["integrator"], p["ds_min"], eps=p["eps"])
                rows.append({"varied": knob, **p, "median_miss_vox": r["median_miss_vox"],
                             "p90_miss_vox": r["p90_miss_vox"], "steps": r["steps"], "seconds": r["seconds"]})
                print(rows[-1])
    os.makedirs(OUT, exist_ok=True)
    tag = "_quick" if a.quick else ""
    path = os.path.join(OUT, f"sweep_volumetric{tag}.csv")
    with atomic_open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    for integ, mk in (("euler", "o"), ("rk4", "s")):
        for knob in grid:
            pts = [r for r in rows if r["integrator"] == integ and r["varied"] == knob]
            axes[0].plot([r["seconds"] for r in pts], [r["median_miss_vox"] for r in pts], mk + "-",
                         label=f"{integ}: {knob}")
            axes[1].plot([r["steps"] for r in pts], [r["median_miss_vox"] for r in pts], mk + "-",
                         label=f"{integ}: {knob}")
    for ax, xl in zip(axes, ("marching time (s)", "photon steps")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xl)
        ax.set_ylabel("median miss distance (voxels)")
        ax.grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=6, ncol=2)
    fig.suptitle(f"Luneburg lens: error vs cost (base N={base['N']}, {base['M']}^2 photons, ds_min=1, eps=0.005)")
    fig.tight_layout()
    savefig_atomic(fig, os.path.join(OUT, f"sweep_volumetric{tag}.png"), dpi=120)
    print("wrote", path)


if __name__ == "__main__":
    main()
