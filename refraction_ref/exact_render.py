"""``--method exact``: the per-pixel keys from exact tracing through the real triangles."""

from __future__ import annotations

import time

import numpy as np

from .camera import Camera
from .environment import environment_lookup
from .meshes import eye_inside, scene_geometry, vertex_normals
from .scene import SceneError

__all__ = ["render_exact"]


def render_exact(scene, progress=False):
    """Trace every pixel's primary ray exactly (Embree) and shade like the image-space method.

    Returns
    -------
    arrays, info : dict, dict
        Same keys as :func:`~refraction_ref.imagespace.render_imagespace`.
    """
    from .exact import trace_exact

    p = scene.data["exact"]
    cam = Camera.from_dict(scene.data["camera"])
    H, W = cam.shape
    timings, plan = {}, []
    t0 = time.perf_counter()
    geom = scene_geometry(scene)
    if eye_inside(geom, cam.eye):
        raise SceneError("exact: the camera is inside a refractive object; the reference tracer starts "
                         "every ray in the outside medium. Move camera.eye outside the objects")
    origin, rdir = cam.primary_rays()
    n = H * W
    vn = None
    if len(geom.faces):
        vn = vertex_normals(geom.vertices, geom.faces)
        tr = trace_exact(geom.vertices, geom.faces, geom.face_object, geom.ior, geom.absorption,
                         origin.reshape(n, 3), rdir.reshape(n, 3), vertex_normals=vn,
                         smooth=p["normals"] == "smooth", outside_ior=float(scene.data["outside_ior"]),
                         max_bounces=int(p["max_bounces"]), progress=progress)
    else:
        tr = {"hit": np.zeros(n, bool), "exit_pos": np.full((n, 3), np.nan), "exit_dir": rdir.reshape(n, 3).copy(),
              "interfaces": np.zeros(n, np.int16), "path_length": np.zeros(n), "status": np.zeros(n, np.int8),
              "transmittance": np.ones((n, 3)), "last_dir": rdir.reshape(n, 3).copy()}
    timings["trace"] = (time.perf_counter() - t0) * 1e3
    plan.append({"stage": "trace", "ran": True,
                 "why": f"Embree, {p['normals']} normals, up to {p['max_bounces']} bounces"})
    t0 = time.perf_counter()
    image = environment_lookup(scene.data["environment"], tr["last_dir"], scene.base_dir)
    if np.any(geom.absorption > 0):
        image = (image * tr["transmittance"]).astype(np.float32)
        plan.append({"stage": "absorption", "ran": True, "why": "Beer-Lambert per segment"})
    else:
        plan.append({"stage": "absorption", "ran": False, "why": "absorption is zero"})
    timings["shade"] = (time.perf_counter() - t0) * 1e3
    arrays = {
        "ray_origin": origin,
        "ray_dir": rdir,
        "hit": tr["hit"].reshape(H, W),
        "exit_pos": tr["exit_pos"].reshape(H, W, 3),
        "exit_dir": tr["exit_dir"].reshape(H, W, 3),
        "interfaces": tr["interfaces"].reshape(H, W).astype(np.int16),
        "path_length": tr["path_length"].reshape(H, W),
        "status": tr["status"].reshape(H, W).astype(np.int8),
        "image": image.reshape(H, W, 3).astype(np.float32),
    }
    info = {"timings_ms": timings, "plan": plan, "triangles": int(len(geom.faces))}
    from .caustics.pipeline import caustics_exact, has_caustics, merge_caustics, skip_reason

    if has_caustics(scene):
        c_arrays, info["caustics"] = caustics_exact(scene, geom, cam, tr, origin, rdir, vn)
        merge_caustics(arrays, c_arrays)
        noise = ", ".join(f"{v:.3g}" for v in info["caustics"]["reference_noise_rel_l1"])
        plan.append({"stage": "caustics", "ran": True,
                     "why": f"exact photon reference: {p['photons']}x{p['photons']} jittered photons per light "
                            f"through the triangles, Embree receiver hits, no gathering; own noise (relative "
                            f"L1, one-texel blur) {noise}"})
    else:
        plan.append({"stage": "caustics", "ran": False, "why": skip_reason(scene)})
    return arrays, info
