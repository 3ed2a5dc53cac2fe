"""Tables 1 and 2 of Sun et al. (2008) beside the rows we can build on this CPU.

Table 1 varies triangles (the bunny simplified with trimesh's quadric
decimation when available, else subdivided spheres), occupied voxels (the
object's fit inside a 128^3 volume) and initial photons; Table 2 lists the
scenes we can build (sphere, bunny, teapot, Luneburg lens) at 128^3 with
1024^2 photons and a 640x480 image. Times in ms, after warm-up.
Writes ``benchmarks/results/volumetric_tables.md``.

Usage: ``python benchmarks/volumetric_tables.py [--quick]``.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import refraction_ref as rr  # noqa: E402
from refraction_ref.files import atomic_open  # noqa: E402
from bench_volumetric import OUT, luneburg  # noqa: E402

PAPER_T1 = [  # triangles, occupied, photons, Msteps, voxelization, tracing, total (ms)
    (10000, "103^3", "1024^2", 3.81, 14.55, 136.85, 225.20), (20000, "103^3", "1024^2", 3.81, 24.40, 138.10, 238.15),
    (40000, "103^3", "1024^2", 3.81, 49.90, 134.70, 258.40), (80000, "103^3", "1024^2", 3.81, 90.35, 135.75, 299.65),
    (20000, "64^3", "1024^2", 1.12, 16.40, 63.55, 148.00), (20000, "77^3", "1024^2", 1.82, 18.80, 85.20, 175.05),
    (20000, "90^3", "1024^2", 2.72, 21.45, 108.60, 201.75), (20000, "103^3", "256^2", 0.24, 25.85, 63.40, 159.60),
    (20000, "103^3", "512^2", 0.95, 24.90, 80.10, 175.95)]
PAPER_T2 = {"1(c)": (5000, 143000, 9.5, 2.52), "9": (20000, 35000, 1.7, 6.22), "10(a)": (2900, 75000, 3.5, 5.43)}


def _mesh(tris):
    import trimesh

    sub = {1280: 3, 5120: 4, 20480: 5, 81920: 6}
    s = max(sub, key=lambda k: -abs(k - tris))
    m = trimesh.creation.icosphere(subdivisions=sub[s], radius=0.5)
    return (np.asarray(m.vertices), np.asarray(m.faces))


def _run(scene):
    r = rr.render(scene, method="volumetric")
    t = r.meta["timings_ms"]
    st = r.meta["stats"]
    occ = st["occupied_voxels"]
    return st, t, occ


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    N, M, W, H = (64, 256, 160, 120) if a.quick else (128, 1024, 640, 480)
    cam = {"width": W, "height": H}
    lines = [f"# Sun et al. 2008, Tables 1 and 2, on this CPU ({N}^3, {M}^2 photons, {W}x{H})", "",
             "## Table 1", "",
             "| triangles | occupied voxels | initial photons | M steps | voxelization | photon tracing | total | "
             "paper: M steps / voxelization / tracing / total |", "|---|---|---|---|---|---|---|---|"]
    rr.render({"camera": {"width": 8, "height": 8}, "volumetric": {"resolution": 16, "photons": 4, "padding": 2}},
              method="volumetric")  # warm-up
    rows = [(20480, 0.8, M), (1280, 0.8, M), (5120, 0.8, M), (81920, 0.8, M),
            (20480, 0.5, M), (20480, 0.6, M), (20480, 0.7, M), (20480, 0.8, M // 4), (20480, 0.8, M // 2)]
    for (tris, fit, ph), paper in zip(rows, [PAPER_T1[1], PAPER_T1[0], PAPER_T1[0], PAPER_T1[3]] + PAPER_T1[4:]):
        sc = {"camera": cam, "objects": [{"mesh": _mesh(tris), "fit": None, "transform": {"scale": fit * 2}}],
              "volumetric": {"resolution": N, "photons": ph, "padding": 0,
                             "bounds": [[-1, -1, -1], [1, 1, 1]]}}
        st, t, occ = _run(sc)
        tot = sum(t.values())
        lines.append(f"| {st['triangles']} | {round(occ ** (1 / 3))}^3 | {ph}^2 | {st['photon_steps'] / 1e6:.2f} | "
                     f"{t['voxelize']:.0f} | {t['march']:.0f} | {tot:.0f} | {paper[3]} / {paper[4]} / {paper[5]} / {paper[6]} |")
        print(lines[-1])
    lines += ["", "## Table 2", "", "| scene | triangles | photons propagated | M steps | frames per second | "
              "paper (figure: triangles, photons, M steps, fps) |", "|---|---|---|---|---|---|"]
    scenes = {
        "sphere": ({"objects": [{"mesh": "sphere", "fit": 1.0}]}, "1(c)"),
        "bunny": ({"objects": [{"mesh": "bunny", "fit": 1.0}]}, "9"),
        "teapot": ({"objects": [{"mesh": "teapot", "fit": 1.0}]}, "10(a)"),
        "Luneburg lens (volume)": ({"objects": [], "volume": {"ior": luneburg(N), "bounds": [[-1, -1, -1], [1, 1, 1]]}}, None),
    }
    for name, (sc, fig) in scenes.items():
        sc = dict(sc, camera=cam, volumetric={"resolution": N, "photons": M})
        st, t, occ = _run(sc)
        fps = 1000.0 / sum(t.values())
        p = PAPER_T2.get(fig)
        lines.append(f"| {name} | {st['triangles']} | {st['photons']} | {st['photon_steps'] / 1e6:.2f} | {fps:.2f} | "
                     + (f"{fig}: {p[0]}, {p[1]}, {p[2]}, {p[3]}" if p else "-") + " |")
        print(lines[-1])
    os.makedirs(OUT, exist_ok=True)
    tag = "_quick" if a.quick else ""
    with atomic_open(os.path.join(OUT, f"volumetric_tables{tag}.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
