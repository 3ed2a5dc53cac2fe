"""Shading normals of the exact reference: how sharp the meshes are, and what the crease angle changes.

For the bunny (scanned), the teapot (coarse tessellation of smooth patches),
fandisk (CAD, sharp edges) and a cube (all edges 90 deg):

* the interior edges whose two face normals differ by more than 30, 45, 60
  and 90 degrees (:func:`refraction_ref.meshes.crease_edge_angles`);
* exact renders (``--method exact``) at 256x256 with the default camera, glass
  of IOR 1.5 and ``fit: 1.0`` (the cube turned by (20, 30, 0) degrees so
  that three faces and their edges face the camera), with
  ``exact.normals`` = face, smooth and crease at 20, 30, 45, 60 and 90
  degrees, compared pixel by pixel with the face-normal and the smooth
  renders: the median and 90th percentile of the angle between the exit
  directions (over the pixels that exit in both) and the fraction of the
  object's pixels (hit in either) that change by more than 1 degree (a
  pixel whose status differs counts as changed).

Writes ``results/normals.json`` and ``results/normals.md``.

    python benchmarks/bench_normals.py [--size 256] [--angles 20,30,45,60,90]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
if REPO not in sys.path:  # run as `python benchmarks/bench_normals.py` without installing
    sys.path.insert(0, REPO)

import refraction_ref as rr  # noqa: E402
from refraction_ref.contract import CONTRACT_VERSION, software_versions  # noqa: E402
from refraction_ref.exact.knobs import EXACT_DEFAULTS  # noqa: E402
from refraction_ref.meshes import corner_normals, crease_edge_angles, load_mesh  # noqa: E402

RESULTS = os.path.join(HERE, "results")
IOR = 1.5
CUBE_ROTATE = [20.0, 30.0, 0.0]
EDGE_THRESHOLDS = (30, 45, 60, 90)


def _cube():
    import trimesh

    m = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


MESHES = {  # name -> (mesh reference for the scene, rotation)
    "bunny": ("bunny", [0.0, 0.0, 0.0]),
    "teapot": ("teapot", [0.0, 0.0, 0.0]),
    "fandisk": ("fandisk", [0.0, 0.0, 0.0]),
    "cube": (None, CUBE_ROTATE),
}


def _scene(mesh, rotate, size):
    return {"camera": {"width": size, "height": size},
            "objects": [{"mesh": mesh, "fit": 1.0, "material": {"ior": IOR}, "transform": {"rotate": rotate}}],
            "lights": [], "receivers": []}


def _angle_deg(a, b):
    return np.degrees(2.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1)))


def _diff(a, b):
    """Exit-direction difference of two renders of one scene."""
    sa, sb = a["status"].ravel(), b["status"].ravel()
    both = (sa == 1) & (sb == 1)
    obj = a["hit"].ravel() | b["hit"].ravel()
    ang = _angle_deg(a["exit_dir"].reshape(-1, 3)[both], b["exit_dir"].reshape(-1, 3)[both])
    changed = np.zeros(len(sa), bool)
    changed[np.flatnonzero(both)[ang > 1.0]] = True
    changed |= obj & (sa != sb)
    n = max(int(obj.sum()), 1)
    return {"median_deg": float(np.median(ang)) if len(ang) else 0.0,
            "p90_deg": float(np.percentile(ang, 90)) if len(ang) else 0.0,
            "frac_changed_gt_1deg": float(changed.sum() / n),
            "status_differs": int(np.count_nonzero(obj & (sa != sb)))}


def bench_mesh(name, size, angles):
    ref, rotate = MESHES[name]
    v, f = _cube() if ref is None else load_mesh(ref)
    mesh = (v, f) if ref is None else ref
    ang = crease_edge_angles(v, f)
    t0 = time.perf_counter()
    corner_normals(v, f, 45.0)
    cn_ms = (time.perf_counter() - t0) * 1e3
    row = {"triangles": int(len(f)), "interior_edges": int(len(ang)),
           "edges_above_deg": {str(t): int(np.count_nonzero(ang > t)) for t in EDGE_THRESHOLDS},
           "corner_normals_ms": round(cn_ms, 2), "renders": {}}
    scene = _scene(mesh, rotate, size)
    modes = [("face", {"exact.normals": "face"}), ("smooth", {"exact.normals": "smooth"})]
    modes += [(f"crease {a:g}", {"exact.normals": "crease", "exact.crease_deg": float(a)}) for a in angles]
    arrays = {}
    for label, ov in modes:
        t0 = time.perf_counter()
        res = rr.render(scene, method="exact", overrides=ov)
        ms = (time.perf_counter() - t0) * 1e3
        arrays[label] = {k: res.arrays[k] for k in ("status", "hit", "exit_dir")}
        row["renders"][label] = {"render_ms": round(ms, 1), "object_pixels": int(res.arrays["hit"].sum()),
                                 "exited": int(np.count_nonzero(res.arrays["status"] == 1))}
        print(f"  {name:8s} {label:10s} {ms:8.0f} ms", flush=True)
    for label in row["renders"]:
        row["renders"][label]["vs_face"] = _diff(arrays[label], arrays["face"])
        row["renders"][label]["vs_smooth"] = _diff(arrays[label], arrays["smooth"])
    return row


def _markdown(out, angles):
    lines = ["# Shading normals of the exact reference (`benchmarks/bench_normals.py`)", "",
             f"{out['size']}x{out['size']} exact renders, default camera, IOR {IOR}, fit 1.0 (cube turned by "
             f"{CUBE_ROTATE} deg). Exit-direction difference over the pixels that exit in both renders "
             "(median / p90, degrees) and the fraction of the object's pixels that change by more than 1 degree "
             "(status changes included).", "",
             "## Edges sharper than an angle (angle between the two face normals)", "",
             "| mesh | triangles | interior edges | " + " | ".join(f"> {t} deg" for t in EDGE_THRESHOLDS) + " |",
             "|---|---:|---:|" + "---:|" * len(EDGE_THRESHOLDS)]
    for name, r in out["meshes"].items():
        lines.append(f"| {name} | {r['triangles']:,} | {r['interior_edges']:,} | "
                     + " | ".join(f"{r['edges_above_deg'][str(t)]:,}" for t in EDGE_THRESHOLDS) + " |")
    lines += ["", "## Effect on the render", "",
              "| mesh | normals | vs face: median / p90 deg | vs face: > 1 deg | vs smooth: median / p90 deg "
              "| vs smooth: > 1 deg |", "|---|---|---|---:|---|---:|"]
    for name, r in out["meshes"].items():
        for label, x in r["renders"].items():
            a, b = x["vs_face"], x["vs_smooth"]
            lines.append(f"| {name} | {label} | {a['median_deg']:.3f} / {a['p90_deg']:.2f} | "
                         f"{100 * a['frac_changed_gt_1deg']:.1f} % | {b['median_deg']:.3f} / {b['p90_deg']:.2f} | "
                         f"{100 * b['frac_changed_gt_1deg']:.1f} % |")
    lines += ["", f"Default chosen: `exact.crease_deg = {EXACT_DEFAULTS['crease_deg']:g}` "
              "(see `refraction_ref/exact/knobs.py`).", ""]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--angles", default="20,30,45,60,90")
    ap.add_argument("--meshes", default=",".join(MESHES))
    args = ap.parse_args(argv)
    angles = [float(a) for a in args.angles.split(",")]
    out = {"size": args.size, "ior": IOR, "angles": angles, "contract_version": CONTRACT_VERSION,
           "default_crease_deg": EXACT_DEFAULTS["crease_deg"], "software": software_versions(), "meshes": {}}
    for name in args.meshes.split(","):
        out["meshes"][name] = bench_mesh(name, args.size, angles)
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, "normals.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    md = _markdown(out, angles)
    with open(os.path.join(RESULTS, "normals.md"), "w") as fh:
        fh.write(md)
    print(md)


if __name__ == "__main__":
    main()
