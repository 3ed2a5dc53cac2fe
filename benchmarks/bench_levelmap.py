"""Targets of issue 4 (level-map water caustics): medians after warm-up, PASS/MISS.

    python benchmarks/bench_levelmap.py [--repeats 5] [--out benchmarks/results]

1. Smart slicing changes no pixel (Luv difference exactly 0, Table 5-5) while
   using fewer planes than requested on the teapot and the sphere.
2. The level map is at least 2x faster than the volumetric baseline at 50
   planes on the teapot (Table 5-1).
3. Default scene (teapot, 128x128 water, 512x512 maps, 50 planes): <= 1 s;
   the per-ray variant <= 0.3 s with an error no worse than 50 planes.
4. Against the exact reference on a wavy pool floor: relative L1 of the
   caustic map (both blurred by one texel) <= 10 % at the default settings.

Writes ``bench_levelmap.json`` into the output folder.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numba
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import refraction_ref as rr  # noqa: E402
from refraction_ref.files import atomic_open  # noqa: E402
from refraction_ref.levelmap import default_scene  # noqa: E402
from refraction_ref.levelmap.pipeline import prepare, render_levelmap  # noqa: E402
from refraction_ref.metrics import luv_difference, relative_l1  # noqa: E402
from refraction_ref.scene import load_scene  # noqa: E402
from refraction_ref.warm import warm  # noqa: E402

from refraction_ref.tables.tipprasert import SUN_TOP, model_scene as _model_scene, uv_sphere  # noqa: E402,F401


def model_scene(mesh, planes=50, floor=False, sun=SUN_TOP, **lm):
    """One model (teapot, sphere or bunny) in a pool under the default waves, as the thesis's tables."""
    return _model_scene(mesh, planes, floor, sun, **lm)


def mesh_arg(name):
    return uv_sphere() if name == "sphere" else name


def timed(scene, repeats, fn=render_levelmap):
    ts = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn(scene, warm=False) if fn is render_levelmap else fn(scene)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out


def exact_maps(scene):
    res = rr.render(scene, method="exact")
    return res.arrays


def errors(arrays, exact, scene):
    ctx = prepare(scene)
    return [relative_l1(arrays[f"caustic_map_{r}"], exact[f"caustic_map_{r}"], ctx["pairs"][r][0].lm.own)
            for r in range(len(ctx["pairs"]))]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "results"))
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    warm("levelmap")
    print(f"numba threads: {numba.get_num_threads()}; medians of {a.repeats} runs after warm-up")
    res = {"numba_threads": numba.get_num_threads(), "repeats": a.repeats}
    ok_all = True

    def report(name, ok, text):
        nonlocal ok_all
        ok_all &= ok
        print(f"[{'PASS' if ok else 'MISS'}] {name}: {text}")
        res[name] = {"pass": bool(ok), "detail": text}

    # 1. smart slicing
    det = {}
    for mesh in ("teapot", "sphere"):
        sc = model_scene(mesh_arg(mesh), 50)
        t_n, (an, inn) = timed(load_scene(sc, {"levelmap.smart_slicing": False}), a.repeats)
        t_s, (as_, ins) = timed(load_scene(sc, {"levelmap.smart_slicing": True}), a.repeats)
        luv = luv_difference(an["image"], as_["image"], an["object_mask"])
        same = all(np.array_equal(an[k], as_[k]) for k in an if k.startswith("caustic_map"))
        det[mesh] = {"luv": luv, "identical_maps": same, "planes_used": ins["planes_used"],
                     "t_normal_s": t_n, "t_smart_s": t_s}
    ok = all(d["luv"] == 0 and d["identical_maps"] and d["planes_used"] < 50 for d in det.values())
    report("smart_slicing_no_change", ok, "; ".join(
        f"{m}: Luv {d['luv']:.3g}, maps identical {d['identical_maps']}, planes used {d['planes_used']}/50, "
        f"{d['t_normal_s']:.3f} s -> {d['t_smart_s']:.3f} s" for m, d in det.items()))

    # 2. level map vs volumetric at 50 planes on the teapot (normal slicing, Table 5-1)
    sc = model_scene("teapot", 50, smart_slicing=False)
    t_lm, _ = timed(sc, a.repeats)
    t_vol, _ = timed(load_scene(sc, {"levelmap.variant": "volumetric"}), a.repeats)
    report("levelmap_vs_volumetric", t_vol >= 2 * t_lm,
           f"level map {t_lm:.3f} s, volumetric {t_vol:.3f} s, speed-up {t_vol / t_lm:.2f}x (target >= 2x; "
           f"thesis 2.84x)")

    # 3. default scene timing and the per-ray variant
    sc = default_scene()
    t_def, (arr_lm, info) = timed(sc, a.repeats)
    t_pr, (arr_pr, _) = timed(load_scene(sc, {"levelmap.variant": "per_ray"}), a.repeats)
    ex = exact_maps(sc)
    e_lm = errors(arr_lm, ex, sc)
    e_pr = errors(arr_pr, ex, sc)
    res["default_stage_ms"] = info["timings_ms"]
    report("default_scene_time", t_def <= 1.0, f"{t_def:.3f} s (target <= 1 s); stages (ms): " +
           ", ".join(f"{k} {v:.0f}" for k, v in info["timings_ms"].items()))
    report("per_ray_time_and_error", t_pr <= 0.3 and e_pr[0] <= e_lm[0] * 1.001,
           f"{t_pr:.3f} s (target <= 0.3 s); rel. L1 floor {e_pr[0]:.4f} vs 50 planes {e_lm[0]:.4f}, "
           f"teapot {e_pr[1]:.4f} vs {e_lm[1]:.4f}")

    # 4. exact reference on a wavy pool floor (default settings)
    d = json.loads(json.dumps(sc.data, default=lambda o: None))
    d["receivers"] = d["receivers"][:1]
    floor = load_scene(d)
    _, (arr_f, _) = timed(floor, 1)
    e_floor = errors(arr_f, exact_maps(floor), floor)[0]
    report("exact_reference_pool_floor", e_floor <= 0.10,
           f"relative L1 {e_floor:.4f} on the pool floor alone (target <= 0.10); default scene: floor "
           f"{e_lm[0]:.4f}, teapot {e_lm[1]:.4f}")
    res["all_pass"] = bool(ok_all)
    with atomic_open(os.path.join(a.out, "bench_levelmap.json"), "w") as f:
        json.dump(res, f, indent=1, default=float)
    print("wrote", os.path.join(a.out, "bench_levelmap.json"))
    return 0 if ok_all else 1


if __name__ == "__main__":
    sys.exit(main())
