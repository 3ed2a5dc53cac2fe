"""Targets of the caustics issue (Chaudhari 2008, §4.1): speed, accuracy against the
exact photon reference, and what each approximation contributes.

    python benchmarks/bench_caustics.py            # ~2 min (the exact reference takes most of it)
    python benchmarks/bench_caustics.py --quick    # smoke test, small sizes

Targets
-------
* 512x512 photons through the bunny plus gathering on a 512x512 receiver map:
  at most 0.3 s. Timed: the light's passes (min/max, voxelization, peeling,
  reduction), the photon trace, the receiver hits, the splat and the
  gathering (``meta['caustics']['timings_ms']`` without ``final`` and
  ``receiver_depth``); median over renders after a warm-up.
* Relative L1 error of the glass sphere's caustic map against the exact
  reference, both blurred by one texel: at most 15 % with the faithful method
  (bitmask depth, estimated normals, eye-space receiver hits, 7x7 gathering).
  Each approximation is then replaced by its better counterpart, one at a
  time, to show what it contributes.

Writes ``results/bench_caustics.json`` and prints a table.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numba  # noqa: E402
import numpy as np  # noqa: E402

import refraction_ref as rr  # noqa: E402
from refraction_ref.files import atomic_open  # noqa: E402
from refraction_ref.caustics.splat import gather_gaussian  # noqa: E402
from refraction_ref.metrics import relative_l1  # noqa: E402

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
PHOTON_STAGES = ("light_minmax", "light_voxelize", "light_peel", "light_reduce", "photon_trace",
                 "receiver_hit", "splat", "gather")


def caustics_scene(mesh="sphere", ior=1.5, photons=512, cmap=512, res=512, exact_photons=2048, **im):
    """An object (fit 1.0) over a 4x4 floor at y = -0.6, sun from straight above, camera looking down at 45 deg."""
    return rr.load_scene({
        "camera": {"width": res, "height": res, "eye": [0.0, 2.4, 2.4], "target": [0.0, -0.5, 0.0], "fov_y": 45.0},
        "objects": [{"mesh": mesh, "fit": 1.0, "material": {"ior": ior}}],
        "lights": [{"type": "directional", "direction": [0.0, -1.0, 0.0]}],
        "receivers": [{"mesh": "plane", "size": [4.0, 4.0], "transform": {"translate": [0.0, -0.6, 0.0]}}],
        "imagespace": dict({"photons": photons, "caustic_map": cmap}, **im),
        "exact": {"photons": exact_photons}})


def photon_ms(res):
    t = res.meta["caustics"]["timings_ms"]
    return float(sum(t.get(k, 0.0) for k in PHOTON_STAGES))


def timed(scene, reps):
    rr.render(scene)  # warm-up (JIT cache, Embree)
    runs = [rr.render(scene) for _ in range(reps)]
    ms = [photon_ms(r) for r in runs]
    stages = {k: statistics.median(r.meta["caustics"]["timings_ms"].get(k, 0.0) for r in runs)
              for k in runs[0].meta["caustics"]["timings_ms"]}
    return statistics.median(ms), ms, stages, runs[-1]


VARIANTS = [
    ("faithful (bitmask, central normals, eye-space hits, gather 7)", {}),
    ("float depth instead of the bitmask", {"depth": "float"}),
    ("mesh3x3 normals instead of central differences", {"normals": "mesh3x3", "delta": 1}),
    ("central differences, delta 1", {"delta": 1}),
    ("exact (Embree) receiver hits instead of eye space", {"receiver_hit": "exact"}),
    ("no gathering (window 1)", {"gather": 1}),
    ("float depth + exact hits + no gathering", {"depth": "float", "receiver_hit": "exact", "gather": 1}),
]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args(argv)
    n = 128 if a.quick else 512
    nex = 256 if a.quick else 2048
    reps = 2 if a.quick else a.reps
    out = {"numba_threads": int(numba.get_num_threads()), "photons": n, "caustic_map": n}

    # -- target 1: speed through the bunny -------------------------------------------------
    med, ms, stages, res = timed(caustics_scene("bunny", 1.3, n, n, n, exact_photons=nex), reps)
    out["bunny"] = {"photon_ms": med, "samples_ms": ms, "stages_ms": stages, "target_ms": 300.0,
                    "pass": med <= 300.0, "lights": res.meta["caustics"]["lights"]}
    print(f"bunny, {n}x{n} photons + gathering on a {n}x{n} map: {med:.0f} ms median "
          f"(target 300 ms) {'PASS' if med <= 300 else 'MISS'}; threads {out['numba_threads']}")
    print("  stages (ms): " + ", ".join(f"{k} {v:.1f}" for k, v in stages.items()))

    # -- target 2: accuracy of the sphere's caustic map -------------------------------------
    t0 = time.perf_counter()
    ref = rr.render(caustics_scene("sphere", 1.5, n, n, n, exact_photons=nex), method="exact")
    t_ref = time.perf_counter() - t0
    B = ref["caustic_map_0"].astype(np.float64)
    noise = ref.meta["caustics"]["reference_noise_rel_l1"][0]
    out["reference"] = {"photons": nex, "noise_rel_l1": noise, "seconds": t_ref}
    print(f"\nexact reference: {nex}x{nex} jittered photons, {t_ref:.1f} s, own noise {noise:.4f} (rel. L1)")
    rows = []
    for name, over in VARIANTS:
        sc = caustics_scene("sphere", 1.5, n, n, n, exact_photons=nex, **over)
        r = rr.render(sc)
        A = r["caustic_map_0"].astype(np.float64)
        e = relative_l1(A, B, blur=1.0)
        g = int(r.meta["caustics"]["gather"])
        eg = relative_l1(A, gather_gaussian(B, g), blur=1.0)
        rows.append({"variant": name, "overrides": over, "rel_l1": e, "rel_l1_vs_gathered_reference": eg,
                     "photon_ms": photon_ms(r), "peak": float(A.max()), "peak_reference": float(B.max())})
        print(f"  {name:<62s} rel. L1 {e:6.3f}   (vs the reference gathered alike {eg:6.3f})   "
              f"{photon_ms(r):6.0f} ms")
    out["sphere"] = rows
    out["sphere_target"] = {"rel_l1": rows[0]["rel_l1"], "target": 0.15, "pass": rows[0]["rel_l1"] <= 0.15}
    print(f"faithful rel. L1 {rows[0]['rel_l1']:.3f} (target 0.15) {'PASS' if rows[0]['rel_l1'] <= 0.15 else 'MISS'}")
    os.makedirs(RESULTS, exist_ok=True)
    p = os.path.join(RESULTS, "bench_caustics_quick.json" if a.quick else "bench_caustics.json")
    with atomic_open(p, "w") as f:
        json.dump(out, f, indent=1, default=float)
    print("wrote " + p)


if __name__ == "__main__":
    main()
