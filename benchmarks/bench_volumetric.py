"""Targets of the volumetric method (issue 3), medians after warm-up, PASS/MISS lines.

1. Adaptive marching with deposition on a 128^3 smoothed sphere, 1024x1024
   photons: >= 10 million photon steps per second (Sun et al. 2008: 27.6 M on
   a GeForce 8800 Ultra).
2. Luneburg lens at ds_min = 1 voxel with Euler: median miss distance of the
   exit lines from the antipodal point <= 0.6 voxel; RK4 reaches the same
   accuracy with >= 3x fewer steps.
3. A camera-only change re-renders in <= 1/10 of the full pipeline's time.

Usage: ``python benchmarks/bench_volumetric.py [--quick]`` (quick: 64^3, 256^2 photons).
Writes ``benchmarks/results/bench_volumetric.json`` and ``.txt``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numba
import numpy as np

import refraction_ref as rr
from refraction_ref.files import atomic_open  # noqa: E402
from refraction_ref.meshes import scene_geometry
from refraction_ref.volumetric.gradient import gradient_field
from refraction_ref.volumetric.knobs import march_knobs
from refraction_ref.volumetric.march import STATUS, march_grid, march_photons
from refraction_ref.volumetric.octree import build_octree
from refraction_ref.volumetric.photons import generate_photons
from refraction_ref.volumetric.voxelize import voxelize_objects

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


def sphere_volume(N):
    sc = rr.load_scene({"objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.5, "absorption": [0, 0, 0]}}]})
    ior, _, b, _ = voxelize_objects(scene_geometry(sc), 1.0, N, 6, 4, 9)
    return ior, b


def bench_steps(N, M, reps, threads=None):
    ior, b = sphere_volume(N)
    field = gradient_field(ior, b)
    level, smax, _ = build_octree(ior, dilate=True)
    ext = np.full(ior.shape + (3,), 0.2, np.float32)
    grid, robust = march_grid(field, ext, level, smax, b), march_knobs({"stepping": "robust"})
    pos, dirs, rad, _, _ = generate_photons([{"type": "directional", "direction": [0, -1, 0],
                                              "radiance": [1, 1, 1]}], b, ior.shape, M)
    old = numba.get_num_threads()
    if threads:
        numba.set_num_threads(threads)
    try:
        march_photons(grid, (pos[:1000], dirs[:1000], rad[:1000]), robust)  # warm-up
        times, steps = [], 0
        for _ in range(reps):
            t0 = time.perf_counter()
            _, info = march_photons(grid, (pos, dirs, rad), robust._replace(ds_min=1.0))
            times.append(time.perf_counter() - t0)
            steps = info["total_steps"]
        nthreads = numba.get_num_threads()
    finally:
        numba.set_num_threads(old)
    t = statistics.median(times)
    return {"N": N, "photons": len(pos), "steps": steps, "seconds": t, "msteps_per_s": steps / t / 1e6,
            "threads": nthreads, "all_seconds": times}


def luneburg(N, R=0.8):
    h = 2.0 / N
    c = (np.arange(N) + 0.5) * h - 1.0
    X, Y, Z = np.meshgrid(c, c, c, indexing="ij")
    r2 = (X ** 2 + Y ** 2 + Z ** 2) / R ** 2
    return np.where(r2 < 1, np.sqrt(np.maximum(2 - r2, 1.0)), 1.0)


def luneburg_miss(N, M, integrator, ds_min, R=0.8, eps=0.005, ds_max=8.0):
    b = np.array([[-1.0, -1, -1], [1, 1, 1]])
    ior = luneburg(N, R)
    field = gradient_field(ior, b)
    level, smax, _ = build_octree(ior, eps, max(eps, 0.02), ds_max, dilate=True)
    ext = np.zeros(ior.shape + (3,), np.float32)
    pos, dirs, rad, _, _ = generate_photons([{"type": "directional", "direction": [0, 0, -1],
                                              "radiance": [1, 1, 1]}], b, ior.shape, M)
    t0 = time.perf_counter()
    _, info = march_photons(march_grid(field, ext, level, smax, b), (pos, dirs, rad),
                            march_knobs({"stepping": "robust", "ds_min": ds_min, "integrator": integrator}))
    t = time.perf_counter() - t0
    sel = (info["status"] == STATUS["exited"]) & (np.hypot(pos[:, 0], pos[:, 1]) < 0.7 * R)
    F = np.array([0.0, 0.0, -R])
    p, d = info["exit_pos"][sel], info["exit_dir"][sel]
    w = F - p
    miss = np.linalg.norm(w - np.sum(w * d, axis=1)[:, None] * d, axis=1) / (2.0 / N)
    return {"integrator": integrator, "ds_min": ds_min, "median_miss_vox": float(np.median(miss)),
            "p90_miss_vox": float(np.percentile(miss, 90)), "steps": info["total_steps"], "seconds": t,
            "drift_max": info["drift_max"]}


def bench_session(N, M, W, reps):
    scene = {"camera": {"width": W, "height": W}, "volumetric": {"resolution": N, "photons": M}}
    s = rr.Session(scene)
    s.render("volumetric")  # warm-up (JIT, caches)
    # the full pipeline, end to end (every stage runs: nothing cached), median of `reps` renders
    fulls = []
    for _ in range(reps):
        s.clear()
        t0 = time.perf_counter()
        full = s.render("volumetric")
        fulls.append(time.perf_counter() - t0)
        assert [p["stage"] for p in full.meta["plan"] if p["ran"]] == list(rr.volumetric.pipeline.STAGES)
    t_full = statistics.median(fulls)
    cams = []
    for k in range(reps):
        s.update({"camera.eye": [0.3 * np.sin(k + 1), 0.2, 2.6]})
        t0 = time.perf_counter()
        r = s.render("volumetric")
        cams.append(time.perf_counter() - t0)
        assert [p["stage"] for p in r.meta["plan"] if p["ran"]] == ["view"]
    t_cam = statistics.median(cams)
    return {"N": N, "photons_side": M, "image": W, "full_s": t_full, "camera_only_s": t_cam,
            "ratio": t_cam / t_full, "full_timings_ms": full.meta["timings_ms"],
            "camera_timings_ms": r.meta["timings_ms"], "all_full_s": fulls, "all_camera_s": cams,
            "threads": numba.get_num_threads()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    N, M, W, reps = (64, 256, 256, 3) if a.quick else (128, 1024, 512, 3)
    os.makedirs(OUT, exist_ok=True)
    res, lines = {}, []

    res["load_before"] = os.getloadavg()
    r = bench_steps(N, M, reps)
    res["steps"] = r
    ok = r["msteps_per_s"] >= 10.0
    lines.append(f"{'PASS' if ok else 'MISS'} photon marching: {r['msteps_per_s']:.2f} M steps/s "
                 f"({r['steps']} steps, {r['photons']} photons, {N}^3 smoothed sphere, {r['threads']} threads, "
                 f"median {r['seconds']:.2f} s; target >= 10, paper 27.6)")
    r1 = bench_steps(N, M, reps, threads=1)
    res["steps_1thread"] = r1
    lines.append(f"info photon marching on 1 thread: {r1['msteps_per_s']:.2f} M steps/s (median {r1['seconds']:.2f} s)")

    e = luneburg_miss(N, 64, "euler", 1.0)
    rk = [luneburg_miss(N, 64, "rk4", ds) for ds in (1.0, 2.0, 4.0, 8.0, 16.0)]
    good = [x for x in rk if x["median_miss_vox"] <= e["median_miss_vox"]]
    best = min(good, key=lambda x: x["steps"]) if good else None
    res["luneburg"] = {"euler": e, "rk4": rk}
    lines.append(f"{'PASS' if e['median_miss_vox'] <= 0.6 else 'MISS'} Luneburg {N}^3, Euler ds_min = 1 voxel: "
                 f"median miss {e['median_miss_vox']:.3f} voxel (p90 {e['p90_miss_vox']:.3f}; target <= 0.6), "
                 f"{e['steps']} steps")
    if best:
        ratio = e["steps"] / best["steps"]
        lines.append(f"{'PASS' if ratio >= 3 else 'MISS'} RK4 at ds_min = {best['ds_min']:g}: median miss "
                     f"{best['median_miss_vox']:.3f} voxel with {best['steps']} steps = {ratio:.2f}x fewer than "
                     "Euler (target >= 3x)")
    else:
        lines.append("MISS RK4 never reached Euler's accuracy")

    s = bench_session(N, M, W, reps)
    res["session"] = s
    lines.append(f"{'PASS' if s['ratio'] <= 0.1 else 'MISS'} camera-only re-render: {s['camera_only_s']:.3f} s vs "
                 f"full pipeline {s['full_s']:.3f} s = {s['ratio']:.3f} (target <= 0.1; {W}x{W}, {N}^3, {M}^2 photons, "
                 f"{s['threads']} threads; medians of {reps})")
    res["load_after"] = os.getloadavg()
    lines.append(f"info load average (1, 5, 15 min) before {res['load_before'][0]:.2f} {res['load_before'][1]:.2f} "
                 f"{res['load_before'][2]:.2f}, after {res['load_after'][0]:.2f} {res['load_after'][1]:.2f} "
                 f"{res['load_after'][2]:.2f} on {os.cpu_count()} CPUs")
    txt = "\n".join(lines)
    print(txt)
    tag = "_quick" if a.quick else ""
    with atomic_open(os.path.join(OUT, f"bench_volumetric{tag}.json"), "w") as f:
        json.dump(res, f, indent=1, default=float)
    with atomic_open(os.path.join(OUT, f"bench_volumetric{tag}.txt"), "w") as f:
        f.write(txt + "\n")


if __name__ == "__main__":
    main()
