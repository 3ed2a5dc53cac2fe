"""Per-pass times of the WebGPU level map (examples/webgpu_backend/levelmap.py) beside the oracle's stages.

Renders the level map's default scene (``refraction_ref/data/levelmap_default.json``: the
pool, a teapot, 512x512 maps and camera, 128^2 water quads, 50 planes, smart slicing) with
the WebGPU backend on whatever adapter wgpu finds (Mesa's lavapipe on the CPU here): one
warm-up frame (pipeline compilation), then ``--repeats`` frames, per pass the median wall
time with the queue drained at both ends (read-backs of the stage buffers excluded, except
smart slicing's depth profile, which the pass itself reads back). The same frames with
``levelmap.culling = bounds`` (§6.1: each plane scissored to the texels it accepts; the maps
are identical). Beside them the oracle's ``timings_ms`` (Numba, after JIT warm-up) of
``refraction-ref render SCENE --method levelmap --keep stages`` (medians of ``--oracle-repeats``
renders, or an ``--oracle-npz`` written before). Writes a Markdown table (``--out``).

    python benchmarks/bench_webgpu_levelmap.py --out benchmarks/results/webgpu_levelmap.md
"""
import argparse
import importlib.util
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "refraction_ref", "data", "levelmap_default.json")

# the backend's passes -> the oracle's stage they do the work of
PASSES = [("water", "water"), ("planes", "planes"), ("level_map", "level_map"),
          ("smart_slicing", "caustics.smart_slicing"), ("caustics", "caustics"), ("casting", "casting"),
          ("image_direct", "image"), ("image_water", "image"), ("image_view", "image")]


def _backend():
    path = os.path.join(ROOT, "examples", "webgpu_backend", "levelmap.py")
    spec = importlib.util.spec_from_file_location("webgpu_levelmap", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def webgpu_times(mod, scene, repeats):
    """Per pass: the list of milliseconds over ``repeats`` frames after one warm-up frame; frame totals; the warm-up's."""
    gpu = mod.Gpu.get()
    t0 = time.perf_counter()
    mod.render(scene, timer=mod.Timer(gpu))                       # warm-up: shaders and pipelines
    first = (time.perf_counter() - t0) * 1e3
    per, totals = {}, []
    for _ in range(repeats):
        t = mod.Timer(gpu)
        t0 = time.perf_counter()
        mod.render(scene, timer=t)
        totals.append((time.perf_counter() - t0) * 1e3)
        for k, v in t.times.items():
            per.setdefault(k, []).append(v)
    return per, totals, first


def oracle_times(scene_path, repeats, npz=None, extra=()):
    """The oracle's stage -> list of ms (``timings_ms`` of its meta), its total_ms list and versions."""
    runs = []
    if npz:
        runs.append(json.loads(str(np.load(npz)["meta"])))
    else:
        for _ in range(repeats):
            with tempfile.TemporaryDirectory() as d:
                out = os.path.join(d, "pool")
                subprocess.run([sys.executable, "-m", "refraction_ref", "render", scene_path, "--method",
                                "levelmap", "--keep", "stages", "--out", out, *extra], check=True,
                               capture_output=True)
                runs.append(json.loads(str(np.load(out + ".npz")["meta"])))
    per = {}
    for m in runs:
        for k, v in m["timings_ms"].items():
            per.setdefault(k, []).append(v)
    return per, [m["total_ms"] for m in runs], runs[-1].get("versions", {}), runs[-1].get("numba_threads")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=SCENE)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--oracle-repeats", type=int, default=3)
    ap.add_argument("--oracle-npz", default=None, help="an oracle render (--keep stages) to take the times from")
    ap.add_argument("--out", default=None, help="Markdown file to write")
    a = ap.parse_args()
    mod = _backend()
    ok, why = mod.available()
    if not ok:
        sys.exit(why)
    with open(a.scene) as fh:
        scene = json.load(fh)
    none, none_tot, first_none = webgpu_times(mod, scene, a.repeats)
    sb = json.loads(json.dumps(scene))
    sb.setdefault("levelmap", {})["culling"] = "bounds"
    bounds, bounds_tot, _ = webgpu_times(mod, sb, a.repeats)
    load0 = os.getloadavg()[0]
    orc, orc_tot, versions, threads = oracle_times(a.scene, a.oracle_repeats, a.oracle_npz)
    orb, orb_tot, _, _ = oracle_times(a.scene, a.oracle_repeats, None, ("--set", "levelmap.culling=bounds"))
    load1 = os.getloadavg()[0]
    med = lambda v: float(np.median(v)) if v else float("nan")    # noqa: E731
    lines = [
        "# WebGPU level map: per-pass times on the default pool",
        "",
        f"Scene `{os.path.relpath(a.scene, ROOT)}` (512x512 camera and maps, 128^2 water quads (32768 beams), "
        "50 planes with smart slicing, floor and teapot receivers, one sun). WebGPU: "
        f"`examples/webgpu_backend/levelmap.py` on **{why}**, wgpu-py "
        f"{__import__('wgpu').__version__}; medians of {a.repeats} frames after one warm-up frame, each pass "
        "timed with the queue drained at both ends (stage read-backs excluded). Oracle: `refraction-ref render "
        f"--method levelmap --keep stages` `timings_ms` (Numba {versions.get('numba')}, {threads} threads, "
        f"after JIT warm-up), medians of {len(orc_tot)} renders. Machine: {versions.get('cpu', platform.processor())}, "
        f"{os.cpu_count()} cores, shared with other sessions (times vary by about 20 %).",
        "",
        "| pass (WebGPU) | what | WebGPU ms, culling none | WebGPU ms, culling bounds | oracle stage "
        "| oracle ms, culling none | oracle ms, culling bounds |",
        "|---|---|---|---|---|---|---|",
    ]
    what = {"water": "compute: vertices, eq. 2-8, beams (eq. 4-14)",
            "planes": "host float64: boxes and planes (set-up)",
            "level_map": "render: position, normal, diffuse maps (2 receivers)",
            "smart_slicing": "compute: depth profile (atomics), host plane layout, acceptance map",
            "caustics": "render: every beam on every plane, additive splat (+ plane_maps layers)",
            "casting": "compute: lights cast into light 0's frame",
            "image_direct": "render: receivers from the camera, eq. 4-19",
            "image_water": "render: water mesh into a face-id target",
            "image_view": "compute: re-based Moller-Trumbore, Snell, receiver ray cast, eq. 4-19"}
    seen = set()
    for p, st in PASSES:
        o = ob = ""
        if st not in seen:
            o, ob = f"{med(orc.get(st, [])):.1f}", f"{med(orb.get(st, [])):.1f}"
            seen.add(st)
        lines.append(f"| `{p}` | {what[p]} | {med(none.get(p, [])):.1f} | {med(bounds.get(p, [])):.1f} | "
                     f"`{st}` | {o} | {ob} |")
    if "plane_maps" in orc:
        lines.append(f"| (in `caustics`) | the per-plane maps are the splat's second target | | | `plane_maps` "
                     f"(inspection) | {med(orc['plane_maps']):.1f} | {med(orb.get('plane_maps', [])):.1f} |")
    lines += [
        f"| **frame** | wall time of `render()` (read-backs included) | {med(none_tot):.0f} | {med(bounds_tot):.0f} "
        f"| `total_ms` | {med(orc_tot):.0f} | {med(orb_tot):.0f} |",
        "",
        "Notes. The oracle's `caustics` includes its `caustics.smart_slicing` part; the WebGPU `caustics` "
        "includes the per-plane maps (the splat's second render target), whose oracle counterpart is the "
        "inspection stage `plane_maps`. The WebGPU frame includes reading back every stage buffer (the "
        "per-plane maps: 95 layers of 1 MiB). `caustics` is the thesis's cost: every beam's intersection "
        "triangle drawn on every plane (3.1 million triangles a frame here), which lavapipe sets up on the "
        "CPU; `culling = bounds` (§6.1) lists per plane, in a compute pass, the beams that reach it and can "
        "touch the texels it accepts, and draws the list indirectly, scissored to those texels (maps equal "
        "up to the blending order of folded beams). "
        f"First frame (pipelines compiled): {first_none:.0f} ms. "
        f"Load average (1 min) {load0:.1f} before the oracle's renders, {load1:.1f} after, on "
        f"{os.cpu_count()} cores. No GPU machine was lent to this task, so there are no GPU times to set "
        "beside Tipprasert's Table 5-1.",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if a.out:
        with open(a.out, "w") as fh:
            fh.write(text)
        with open(os.path.splitext(a.out)[0] + ".json", "w") as fh:
            json.dump({"webgpu_culling_none": none, "webgpu_culling_bounds": bounds, "oracle": orc,
                       "oracle_culling_bounds": orb,
                       "frames": {"none": none_tot, "bounds": bounds_tot, "oracle": orc_tot, "oracle_bounds": orb_tot},
                       "first_frame_ms": first_none, "adapter": why},
                      fh, indent=1)


if __name__ == "__main__":
    main()
