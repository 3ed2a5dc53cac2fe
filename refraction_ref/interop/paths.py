"""The paths cross-check: every pixel's ray through Mitsuba 3 against our exact method's exits.

Every pixel's ray goes through Mitsuba's own sensor, intersection
(``scene.ray_intersect``, float32) and shading normals (``si.sh_frame.n``),
refracted here by Snell's law in float64 with the exact references'
conventions (:func:`~refraction_ref.interop.rays.cross_interface`: shading
normal flipped to the geometric side, the geometric normal where the shading
normal sends the ray to the wrong side, total internal reflection followed,
the medium by the geometric normal), and is compared with our exact method's
``exit_dir``, ``exit_pos`` and ``status``: median, p99 and largest angle
between the exit directions where both exit, status agreement over all
pixels. The primary rays themselves are compared first (the camera
convention).

References
----------
.. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org.
.. [2] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
   ed., §8.2 (Snell's law, total internal reflection).
"""

from __future__ import annotations

import copy
import os
import time

import numpy as np

from ..camera import Camera
from ..compare import angular_error_deg
from ..golden.build import case_scene
from ..meshes import bounds, scene_geometry
from ..render import render
from ..status import EXITED, LIMIT, LOST, MISSED, TIR
from . import mitsuba as M
from .rays import cross_interface, merged_mesh, mitsuba_ray, pixel_centre_rays, points, sensor_dict, spawn_offset

__all__ = ["mitsuba_paths", "paths_case", "exact_arrays", "paths_only_scene"]


def exact_arrays(scene):
    """Our exact method's outputs for ``scene`` (the reference every cross-check compares with).

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    dict of str to ndarray
        The render's arrays (``image``, ``status``, ``exit_dir``, ...).
    """
    return render(scene, method="exact").arrays


def paths_only_scene(case, folder):
    """The case's scene without lights and receivers (the per-pixel trace does not read them).

    Parameters
    ----------
    case : dict
        A catalogue case.
    folder : str
        Where the scene's files are written (:func:`~refraction_ref.golden.build.case_scene`).

    Returns
    -------
    Scene
    """
    c = copy.deepcopy(case)
    c["scene"]["lights"] = []
    c["scene"]["receivers"] = []
    return case_scene(c, folder)


def _path_buffers(n, record):
    """The per-path state of :func:`mitsuba_paths`, every path outside every object."""
    return {"status": np.full(n, -1, np.int8), "exit_pos": np.full((n, 3), np.nan),
            "exit_dir": np.full((n, 3), np.nan), "interfaces": np.zeros(n, np.int16),
            "last_tir": np.zeros(n, bool), "pos_now": np.full((n, 3), np.nan),
            "path_pos": np.full((n, max(int(record), 1), 3), np.nan), "events": np.zeros(n, np.int32)}


def mitsuba_paths(scene, folder, variant="llvm_ad_rgb", max_bounces=None, spawn="line", record=0):
    """Every pixel's path through Mitsuba's sensor, intersections and shading normals.

    Parameters
    ----------
    scene : Scene
        A scene with refractive objects (no water).
    folder : str
        Where the exported mesh goes.
    variant : str
        A vectorised variant: ``llvm_ad_rgb`` (all pixels per call) or ``cuda_ad_rgb``.
    max_bounces : int, optional
        Interfaces a path may meet (default ``exact.max_bounces``).
    spawn : {'line', 'mitsuba'}
        How a ray leaves a surface: ``'line'`` from Mitsuba's hit point moved
        ``1e-5 scale`` along the new direction and ``1e-6 scale`` off the
        surface (the exact tracer's offset is ``1e-5 scale`` along both, and it
        then recomputes the hit from the un-offset point); ``'mitsuba'``
        Mitsuba's ``si.spawn_ray`` (``(1 + max |p|) 8.9e-5`` along the
        geometric normal: the next hit moves by about that much, which moves
        the exit directions by about 0.01 degrees, see docs/oracle.md).
    record : int
        Keep the first ``record`` hit points per path (``path_pos``, as the
        exact reference's ``exact.record``), to find where two paths part.

    Returns
    -------
    dict
        ``ray_origin``, ``ray_dir`` (H, W, 3) of Mitsuba's sensor; ``status``
        (H, W) int8 (:mod:`refraction_ref.status`), ``exit_pos``,
        ``exit_dir`` (H, W, 3), ``interfaces`` and ``events`` (H, W: refractions; refractions and
        total internal reflections).

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd ed., §8.2.
    """
    mi = M.require(variant)
    d = scene.data
    cam = Camera.from_dict(d["camera"])
    H, W = cam.height, cam.width
    meshes = M.object_meshes(scene)
    os.makedirs(folder, exist_ok=True)
    v, f, nrm, owner = merged_mesh(meshes)
    M.write_ply(os.path.join(folder, "objects.ply"), v, f, nrm)
    s = mi.load_dict({"type": "scene", "sensor": sensor_dict(mi, cam),
                      "objects": {"type": "ply", "filename": os.path.join(folder, "objects.ply"),
                                  "face_normals": nrm is None}})
    sensor = s.sensors()[0]
    n = H * W
    ior = np.array([m["ior"] for m in meshes] + [float(d["outside_ior"])])
    outside = len(meshes)
    max_bounces = int(d["exact"]["max_bounces"] if max_bounces is None else max_bounces)
    st = _path_buffers(n, record)
    medium = np.full(n, outside, np.int64)

    if variant.startswith("scalar"):
        raise ValueError("mitsuba_paths: use a vectorised variant (llvm_ad_rgb); scalar_rgb is for single rays")
    ray = pixel_centre_rays(mi, sensor, W, H)
    o0 = points(ray.o)
    dirn = points(ray.d)
    dirn /= np.linalg.norm(dirn, axis=1, keepdims=True)
    d0 = dirn.copy()
    eps, _ = spawn_offset(v)
    active = np.ones(n, bool)
    for b in range(max_bounces + 1):
        si = s.ray_intersect(ray, mi.Bool(active))
        valid = np.array(si.is_valid(), dtype=bool) & active
        miss = active & ~valid
        if b == 0:
            st["status"][miss] = MISSED
            st["exit_dir"][miss] = d0[miss]
        else:
            st["status"][miss] = EXITED
            st["exit_pos"][miss] = st["pos_now"][miss]
            st["exit_dir"][miss] = dirn[miss]
        act = valid
        if b == max_bounces:
            st["status"][act] = np.where(st["last_tir"][act], TIR, LIMIT)
            break
        if not act.any():
            break
        p = points(si.p)
        ng = points(si.n)
        a = np.flatnonzero(act)
        dd, g = dirn[a], ng[a]
        entering = np.sum(dd * g, axis=1) < 0
        obj = owner[np.array(si.prim_index, dtype=np.int64)[a]]
        eta = ior[medium[a]] / np.where(entering, ior[obj], ior[outside])
        out, tir, lost = cross_interface(dd, points(si.sh_frame.n)[a], g, eta)
        crossed = ~tir & ~lost
        medium[a[crossed]] = np.where(entering[crossed], obj[crossed], outside)
        st["interfaces"][a[crossed]] += 1
        st["last_tir"][a] = tir
        st["pos_now"][a] = p[a]
        st["events"][a] += 1
        if b < record:
            st["path_pos"][a, b] = p[a]
        dirn[a] = out
        st["status"][a[lost]] = LOST
        active = act.copy()
        active[a[lost]] = False
        if spawn == "mitsuba":
            dv = dirn.astype(np.float32).T
            ray = si.spawn_ray(mi.Vector3f(dv[0], dv[1], dv[2]))
        else:
            side = np.where((np.sum(out * g, axis=1) >= 0)[:, None], g, -g)
            org = st["pos_now"].copy()
            org[a] = p[a] + eps * out + (0.1 * eps) * side
            ray = mitsuba_ray(mi, np.nan_to_num(org), dirn)
    assert not np.any(st["status"] < 0)
    return {"ray_origin": o0.reshape(H, W, 3), "ray_dir": d0.reshape(H, W, 3), "status": st["status"].reshape(H, W),
            "exit_pos": st["exit_pos"].reshape(H, W, 3), "exit_dir": st["exit_dir"].reshape(H, W, 3),
            "interfaces": st["interfaces"].reshape(H, W), "events": st["events"].reshape(H, W),
            **({"path_pos": st["path_pos"].reshape(H, W, -1, 3)} if record else {})}


def _nan_stat(x, f):
    """``f(x)`` as a float, NaN for an empty ``x``."""
    return float(f(x)) if x.size else float("nan")


def _tir_rows(num, ang, both, tir_events):
    """The exit angles by count of total internal reflections on the path (none, 1-2, 3 and more) into ``num``.

    Where the two part: float32 hits differ by ~1e-7, and a chain of total internal reflections (thin
    walls, IOR 2.4) multiplies that at every event until the exits differ by degrees.
    """
    tir = tir_events
    for lab, sel in (("no_tir", both & (tir == 0)), ("tir_1_2", both & (tir >= 1) & (tir <= 2)),
                     ("tir_3_plus", both & (tir >= 3))):
        x = ang[sel]
        num[f"paths_{lab}"] = int(sel.sum())
        num[f"p99_deg_{lab}"] = _nan_stat(x, lambda y: np.percentile(y, 99))
        num[f"over_0_5_{lab}"] = int(np.count_nonzero(x > 0.5))


def paths_case(case, folder, variant="llvm_ad_rgb"):
    """The paths cross-check of one case: (numbers, arrays for the figures).

    Parameters
    ----------
    case : dict
        A catalogue case with an exact per-pixel reference.
    folder : str
        Scratch folder for the scene and Mitsuba's files.
    variant : str
        Mitsuba variant for the path tracing (:func:`mitsuba_paths`).

    Returns
    -------
    num : dict
        Angles between the exit directions where both exit (median, p99, max,
        by count of TIR events), exit-position differences relative to the
        scene diagonal, status and interface agreement, timings.
    figs : dict
        ``angle`` (H, W) float64 (NaN where not both exit), ``status_ours``
        and ``status_mitsuba`` (H, W).

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd ed., §8.2.
    """
    scene = paths_only_scene(case, os.path.join(folder, "scene"))
    t0 = time.perf_counter()
    ours = exact_arrays(scene)
    t1 = time.perf_counter()
    mit = mitsuba_paths(scene, os.path.join(folder, "mitsuba"), variant)
    t2 = time.perf_counter()
    cam = Camera.from_dict(scene.data["camera"])
    ray_ang = angular_error_deg(ours["ray_dir"], mit["ray_dir"])
    # Mitsuba's rays start on the near plane (NEAR_CLIP) along the same line
    off = mit["ray_origin"] - ours["ray_origin"]
    line = np.linalg.norm(np.cross(off, ours["ray_dir"]), axis=-1)
    both = (ours["status"] == EXITED) & (mit["status"] == EXITED)
    ang = angular_error_deg(ours["exit_dir"], mit["exit_dir"])
    a = ang[both]
    lo, hi = bounds(scene_geometry(scene).vertices)
    dp = np.linalg.norm(ours["exit_pos"] - mit["exit_pos"], axis=-1)[both] / float(np.linalg.norm(hi - lo))
    agree = ours["status"] == mit["status"]
    hit = (ours["status"] != MISSED) | (mit["status"] != MISSED)
    num = {
        "pixels": int(agree.size), "object_pixels": int(hit.sum()), "both_exit": int(both.sum()),
        "primary_ray_max_deg": float(ray_ang.max()), "primary_origin_off_line": float(line.max()),
        "median_deg": _nan_stat(a, np.median), "p99_deg": _nan_stat(a, lambda y: np.percentile(y, 99)),
        "max_deg": _nan_stat(a, np.max), "frac_over_0_5_deg": _nan_stat(a, lambda y: np.mean(y > 0.5)),
        "exit_pos_median_rel": _nan_stat(dp, np.median),
        "exit_pos_p99_rel": _nan_stat(dp, lambda y: np.percentile(y, 99)),
        "status_agree": float(agree.mean()),
        "status_agree_object_pixels": float(agree[hit].mean()) if hit.any() else 1.0,
        "status_ours": {int(k): int(v) for k, v in zip(*np.unique(ours["status"], return_counts=True))},
        "status_mitsuba": {int(k): int(v) for k, v in zip(*np.unique(mit["status"], return_counts=True))},
        "interfaces_agree_both_exit": float(np.mean((ours["interfaces"] == mit["interfaces"])[both]))
        if both.any() else float("nan"),
        "ours_s": t1 - t0, "mitsuba_s": t2 - t1, "camera": [cam.width, cam.height],
    }
    _tir_rows(num, ang, both, mit["events"] - mit["interfaces"])
    figs = {"angle": np.where(both, ang, np.nan), "status_ours": ours["status"], "status_mitsuba": mit["status"]}
    return num, figs
