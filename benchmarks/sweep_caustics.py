"""Error against time of the image-space caustics (Chaudhari 2008, §4.1) as each knob varies.

    python benchmarks/sweep_caustics.py            # ~1.5 min
    python benchmarks/sweep_caustics.py --quick    # smoke test

The glass bunny (IOR 1.3, fit 1.0) over a 4x4 floor under a sun from straight
above (:func:`bench_caustics.caustics_scene`), 512x512 caustic map, camera
512x512. One knob varies at a time from the defaults (512x512 photons, 32
layers, 5 iterations, a 7-texel gathering window): ``photons``, ``layers``,
``iterations``, ``gather``. Error: relative L1 of ``caustic_map_0`` against
the exact photon reference (``--method exact``, 1536x1536 jittered photons),
both blurred by one texel. Time: the photon stages of
``meta['caustics']['timings_ms']`` (light passes, photon trace, receiver
hits, splat, gathering), median over renders after a warm-up.

Writes ``results/sweep_caustics.csv`` and ``results/sweep_caustics.png``.
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np  # noqa: E402

import refraction_ref as rr  # noqa: E402
from refraction_ref.files import atomic_open, savefig_atomic  # noqa: E402
from bench_caustics import RESULTS, caustics_scene, photon_ms  # noqa: E402
from refraction_ref.levelmap.metrics import relative_l1  # noqa: E402

SWEEPS = {
    "photons": [128, 256, 512, 1024],
    "layers": [2, 4, 8, 16, 32],
    "iterations": [1, 2, 3, 5, 8],
    "gather": [1, 3, 5, 7, 9, 11],
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args(argv)
    n = 128 if a.quick else 512
    nex = 256 if a.quick else 1536
    reps = 1 if a.quick else a.reps
    sweeps = {k: ([v for v in vals if v <= 2 * n] if k == "photons" else vals) for k, vals in SWEEPS.items()}
    ref = rr.render(caustics_scene("bunny", 1.3, n, n, n, exact_photons=nex), method="exact")
    B = ref["caustic_map_0"].astype(np.float64)
    noise = ref.meta["caustics"]["reference_noise_rel_l1"][0]
    print(f"reference: {nex}x{nex} photons, own noise {noise:.4f}")
    rows = []
    for knob, vals in sweeps.items():
        for v in vals:
            kw = {"photons": n, knob: v}
            sc = caustics_scene("bunny", 1.3, cmap=n, res=n, exact_photons=nex, **kw)
            rr.render(sc)  # warm-up
            runs = [rr.render(sc) for _ in range(reps)]
            ms = statistics.median(photon_ms(r) for r in runs)
            e = relative_l1(runs[-1]["caustic_map_0"].astype(np.float64), B, blur=1.0)
            rows.append({"knob": knob, "value": v, "rel_l1": e, "photon_ms": ms, "reference_noise": noise})
            print(f"  {knob:>10s} = {v:<5d} rel. L1 {e:6.3f}  {ms:7.1f} ms")
    os.makedirs(RESULTS, exist_ok=True)
    stem = "sweep_caustics_quick" if a.quick else "sweep_caustics"
    p = os.path.join(RESULTS, stem + ".csv")
    with atomic_open(p, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(sweeps), figsize=(4 * len(sweeps), 3.4))
    for ax, knob in zip(axes, sweeps):
        rr_ = [r for r in rows if r["knob"] == knob]
        x = [r["value"] for r in rr_]
        ax.plot(x, [r["rel_l1"] for r in rr_], "o-", color="C0")
        ax.axhline(noise, color="C0", ls=":", lw=0.8)
        ax.set_xlabel(knob)
        ax.set_ylabel("relative L1 vs exact", color="C0")
        if knob == "photons":
            ax.set_xscale("log", base=2)
        t = ax.twinx()
        t.plot(x, [r["photon_ms"] for r in rr_], "s--", color="C1")
        t.set_ylabel("photon stages (ms)", color="C1")
    fig.suptitle("Image-space caustics of the glass bunny against the exact photon reference")
    fig.tight_layout()
    png = os.path.join(RESULTS, stem + ".png")
    savefig_atomic(fig, png, dpi=90)
    print("wrote " + p + ", " + png)


if __name__ == "__main__":
    main()
