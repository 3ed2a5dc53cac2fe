"""Stiff cases: the paper's stepping (§4.4, §5.3) against the robust extensions, measured on closed forms.

``volumetric.stepping = 'paper'`` clamps the octree step to ``[ds_min,
ds_max]`` and applies eqs. 4-5 at every step, on an octree whose level-0
ranges are single voxels; ``'robust'`` adds the stiffness cap and step
halving at index jumps and the 26-neighbour dilation of the octree (constant
nodes crossed in one straight step). Both with forward Euler (eqs. 4-5),
``ds_min`` = 1 voxel, ``eps`` = 0.005, ``eps'`` = 0.02, ``ds_max`` = 8, on a
64^3 volume spanning [-1, 1]^3, unblurred index volumes:

* sharp sphere: n = 1.5 inside r = 0.5 (a step of 0.5 in one voxel),
  photons from above; closed form :func:`refraction_ref.analytic.sphere_refraction`
  (two Snell refractions), photons within 0.9 of the radius;
* index step: n = 1 above z = 0, 1.5 below, photons at 30 degrees from
  the normal; closed form Snell, ``sin t = sin 30 / 1.5``;
* grazing: the same step at 80 degrees;
* total internal reflection: photons inside the n = 1.5 half at 60 degrees
  towards the interface (critical angle 41.8 degrees): closed form the
  mirror direction;
* Luneburg lens (smooth, n = sqrt(2 - (r/R)^2), R = 0.8): exit lines must
  pass through the antipodal focus; the error is the miss distance in
  voxels (photons within 0.7 R of the axis).

Errors are the median and 90th percentile angle (degrees) between each
photon's exit direction and the closed form (photons that exited), with the
fraction of photons that exited, were lost (|v| collapsed) or stopped, the
steps, and the largest relative ``| |v| - n | / n``.

Usage: ``python benchmarks/volumetric_stepping.py [--quick]`` (quick: 32^3).
Writes ``benchmarks/results/volumetric_stepping.csv`` and ``.md``.
"""

from __future__ import annotations

import argparse
import csv
import os

import numpy as np

from refraction_ref.analytic import sphere_refraction
from refraction_ref.files import atomic_open
from refraction_ref.volumetric.gradient import gradient_field
from refraction_ref.volumetric.knobs import march_knobs, octree_dilations
from refraction_ref.volumetric.march import STATUS, march_grid, march_photons
from refraction_ref.volumetric.octree import build_octree

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
B = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def _centres(N):
    c = (np.arange(N) + 0.5) / N * 2.0 - 1.0
    return np.meshgrid(c, c, c, indexing="ij")


def _grid_starts(n, lo, hi):
    s = np.linspace(lo, hi, n)
    a, b = np.meshgrid(s, s, indexing="ij")
    return a.ravel(), b.ravel()


def _angle(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))


def cases(N):
    """(name, ior, pos, dirs, closed form: f(info, pos) -> errors in the case's unit)."""
    X, Y, Z = _centres(N)
    out = []
    # sharp sphere
    ior = np.where(X ** 2 + Y ** 2 + Z ** 2 < 0.25, 1.5, 1.0)
    a, b = _grid_starts(40, -0.45, 0.45)
    keep = a ** 2 + b ** 2 < 0.45 ** 2
    pos = np.stack([a[keep], np.full(keep.sum(), 0.999), b[keep]], axis=1)
    dirs = np.tile([0.0, -1.0, 0.0], (len(pos), 1))
    ref = sphere_refraction(pos, dirs, [0, 0, 0], 0.5, 1.5)["exit_dir"]
    out.append(("sharp sphere n=1.5", ior, pos, dirs, lambda info, ref=ref: _angle(info["exit_dir"], ref), "deg"))
    # index step, refraction at 30 and 80 degrees
    step = np.where(Z < 0, 1.5, 1.0)
    for th in (30.0, 80.0):
        t = np.radians(th)
        d = np.array([np.sin(t), 0.0, -np.cos(t)])
        a, b = _grid_starts(16, -0.9, 0.9)
        x0 = -0.95 if th > 45 else a
        pos = np.stack([np.broadcast_to(x0, a.shape).copy() if th > 45 else a, b,
                        np.full(a.shape, 0.2 if th > 45 else 0.999)], axis=1)
        tt = np.arcsin(np.sin(t) / 1.5)
        refd = np.array([np.sin(tt), 0.0, -np.cos(tt)])
        name = "index step 1 -> 1.5, 30 deg" if th < 45 else "grazing: index step at 80 deg"
        out.append((name, step, pos, np.tile(d, (len(pos), 1)),
                    lambda info, refd=refd: _angle(info["exit_dir"], np.broadcast_to(refd, info["exit_dir"].shape)),
                    "deg"))
    # total internal reflection inside the dense half
    t = np.radians(60.0)
    d = np.array([np.sin(t), 0.0, np.cos(t)])
    a, b = _grid_starts(16, -0.9, 0.9)
    pos = np.stack([np.full(a.shape, -0.95), b, np.full(a.shape, -0.25)], axis=1)
    refd = np.array([np.sin(t), 0.0, -np.cos(t)])
    out.append(("TIR at 60 deg (critical 41.8)", step, pos, np.tile(d, (len(pos), 1)),
                lambda info, refd=refd: _angle(info["exit_dir"], np.broadcast_to(refd, info["exit_dir"].shape)),
                "deg"))
    # Luneburg lens
    R = 0.8
    r2 = (X ** 2 + Y ** 2 + Z ** 2) / R ** 2
    lun = np.where(r2 < 1, np.sqrt(np.maximum(2 - r2, 1.0)), 1.0)
    a, b = _grid_starts(24, -0.7 * R, 0.7 * R)
    pos = np.stack([a, b, np.full(a.shape, 0.999)], axis=1)
    dirs = np.tile([0.0, 0.0, -1.0], (len(pos), 1))

    def miss(info, N=N):
        F = np.array([0.0, 0.0, -R])
        p, dd = info["exit_pos"], info["exit_dir"]
        w = F - p
        return np.linalg.norm(w - np.sum(w * dd, axis=1)[:, None] * dd, axis=1) / (2.0 / N)

    out.append(("Luneburg lens (focus miss)", lun, pos, dirs, miss, "voxels"))
    return out


def run(N):
    rows = []
    for name, ior, pos, dirs, err_fn, unit in cases(N):
        field = gradient_field(ior, B)
        ext = np.zeros(ior.shape + (3,), np.float32)
        for stepping in ("paper", "robust"):
            level, smax, _ = build_octree(ior, dilate=octree_dilations(stepping)[0])
            _, info = march_photons(march_grid(field, ext, level, smax, B), (pos, dirs, np.ones_like(pos)),
                                    march_knobs({"stepping": stepping, "stop_fraction": 0.0}))
            st = info["status"]
            ex = st == STATUS["exited"]
            e = err_fn(info)[ex]
            e = e[np.isfinite(e)]
            rows.append({"case": name, "stepping": stepping, "unit": unit, "photons": len(pos),
                         "median_error": float(np.median(e)) if len(e) else float("nan"),
                         "p90_error": float(np.percentile(e, 90)) if len(e) else float("nan"),
                         "exited": float(ex.mean()), "lost": float(np.mean(st == STATUS["lost"])),
                         "stopped": float(np.mean(st == STATUS["stopped"])),
                         "steps": int(info["total_steps"]), "drift_max": float(info["drift_max"])})
            print(rows[-1])
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    N = 32 if a.quick else 64
    rows = run(N)
    os.makedirs(OUT, exist_ok=True)
    tag = "_quick" if a.quick else ""
    with atomic_open(os.path.join(OUT, f"volumetric_stepping{tag}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = [f"# Stiff cases: stepping 'paper' against 'robust' ({N}^3, Euler, ds_min 1 voxel)", "",
             "Generated by `benchmarks/volumetric_stepping.py`; errors against the closed forms (module "
             "docstring): exit-direction angle in degrees, or the Luneburg focus miss in voxels.", "",
             "| case | stepping | median error | p90 error | exited | lost | steps | max relative drift of v |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['stepping']} | {r['median_error']:.3g} {r['unit']} | "
                     f"{r['p90_error']:.3g} {r['unit']} | {100 * r['exited']:.1f}% | {100 * r['lost']:.1f}% | "
                     f"{r['steps']} | {r['drift_max']:.3g} |")
    with atomic_open(os.path.join(OUT, f"volumetric_stepping{tag}.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
