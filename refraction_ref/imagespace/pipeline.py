"""The image-space multiple-refraction pipeline (Chaudhari 2008, ch. 3), pass by pass.

======================  ===========================================  =========
stage (``timings_ms``)  pass                                          section
======================  ===========================================  =========
``minmax``              min / max depth, per-pixel local bounds       §3.3
``voxelize``            bitmask voxelization (or the float A-buffer)  §3.3
``peel``                layered depth images                          §3.4
``reduce``              search bounds per layer                       §3.7
``trace``               binary search + Snell at every interface      §3.6-3.7
``shade``               environment look-up, Beer-Lambert absorption  §3.8
======================  ===========================================  =========
"""

from __future__ import annotations

import time

import numpy as np

from ..camera import Camera
from ..environment import environment_lookup
from ..meshes import eye_inside, scene_geometry
from ..optics import beer_lambert
from ..raster import raster_setup
from ..scene import SceneError
from .depth_bounds import depth_bounds, global_bounds
from .peel import POPCOUNT8, SELECT8, depth_complexity, peel_layers
from .search_bounds import search_bounds
from .trace import exit_thresholds, trace_layers
from .voxelize import collect_depths, slice_bounds, voxelize_bitmask

__all__ = ["render_imagespace", "check_materials", "layered_trace"]


def check_materials(geom):
    """The bitmask cannot tell objects apart: all must share ior and absorption (§4.1)."""
    if len(geom.ior) == 0:
        return 1.0, np.zeros(3)
    if np.ptp(geom.ior) > 0 or np.ptp(geom.absorption, axis=0).max() > 0:
        raise SceneError("imagespace: objects have different materials "
                         f"(ior {geom.ior.tolist()}); the occupancy bitmask cannot tell objects apart "
                         "(Chaudhari 2008, §4.1). Give all objects the same material, or use --method exact")
    return float(geom.ior[0]), geom.absorption[0]


def layered_trace(geom, cam, p, ior, outside, timings, plan):
    """Min/max, voxelization, peeling, reduction and trace in one view (§3.3-3.7).

    The passes of chapter 3 for any view of the refractive objects: the
    eye's (perspective), or a light's (perspective for a point light,
    orthographic for a directional one: the photon pass of §4.1, which
    traces one photon per texel with the very same kernels).

    Parameters
    ----------
    geom : Geometry
    cam : Camera
    p : dict
        The ``imagespace`` knobs.
    ior, outside : float
    timings : dict
        Filled with ``minmax``, ``voxelize``, ``peel``, ``reduce``, ``trace`` (ms).
    plan : list
        Appended with one entry per stage.

    Returns
    -------
    dict
        ``trace`` (:func:`trace_layers` output, world space), ``total``
        (H, W) layers per pixel, ``ldi``, ``zmin``, ``zmax`` (the min/max
        pass: ``zmin`` doubles as a shadow map in a light's view),
        ``pixels_over_layer_limit``.
    """
    H, W = cam.shape
    tic = time.perf_counter
    t0 = tic()
    tri_view = raster_setup(cam.world_to_view(geom.vertices), cam, faces=geom.faces)
    mm = depth_bounds(tri_view, cam, keep_fragments=p["depth"] == "bitmask")
    zmin, zmax, frags = mm if len(mm) == 3 else (*mm, None)
    gmin, gmax = global_bounds(zmin, zmax)
    timings["minmax"] = (tic() - t0) * 1e3
    plan.append({"stage": "minmax", "ran": True, "why": "per-pixel Zmin/Zmax (§3.3)"})
    S = int(p["slices"])
    L = int(p["layers"])

    t0 = tic()
    lut = None
    if p["depth"] == "bitmask":
        zlo, zhi = slice_bounds(zmin, zmax, p["slicing"])
        bits = voxelize_bitmask(tri_view if frags is None else frags, cam, zlo, zhi, S, p["blend"])
        timings["voxelize"] = (tic() - t0) * 1e3
        plan.append({"stage": "voxelize", "ran": True,
                     "why": f"{S} slices, {p['slicing']} bounds, {p['blend']} blending (§3.3)"})
        t0 = tic()
        total = depth_complexity(bits)
        if p["peeling"] == "separate":
            ldi, total = peel_layers(bits, zlo, zhi, S, L, total)
            plan.append({"stage": "peel", "ran": True,
                         "why": f"{ldi.shape[0]} layers peeled: the scene's depth complexity is "
                                f"{int(total.max(initial=0))}, the limit {L} (§3.4.2)"})
        else:
            Lr = int(min(L, total.max(initial=0)))
            ldi = np.broadcast_to(np.float32(np.inf), (Lr, H, W))
            lut = (True, bits, np.ascontiguousarray(zlo), np.ascontiguousarray(zhi), S, POPCOUNT8, SELECT8)
            plan.append({"stage": "peel", "ran": False,
                         "why": "on-the-fly peeling with 8-bit look-up tables during the trace (§3.4.1)"})
        timings["peel"] = (tic() - t0) * 1e3
    else:
        ldi, total = collect_depths(tri_view, cam, L)
        Lr = int(min(L, total.max(initial=0)))
        ldi = np.ascontiguousarray(ldi[:Lr])
        timings["voxelize"] = (tic() - t0) * 1e3
        timings["peel"] = 0.0
        plan.append({"stage": "voxelize", "ran": True,
                     "why": "float depth: exact fragment depths kept per pixel (A-buffer), no bitmask"})
        plan.append({"stage": "peel", "ran": False, "why": "the A-buffer is already sorted into layers"})
        zlo, zhi = zmin, zmax  # the grid the early-termination threshold counts in

    t0 = tic()
    if lut is not None:
        # no LDI to reduce: the exact global bound serves every layer
        bhi = np.full(ldi.shape[0], gmax)
        blo = np.full(ldi.shape[0], gmin)
        plan.append({"stage": "reduce", "ran": False,
                     "why": "on-the-fly peeling has no LDI: the global Zmax bounds every layer"})
    else:
        margin = float(p["bound_margin"]) * (gmax - gmin) if np.isfinite(gmax) else 0.0
        bhi, blo = search_bounds(ldi, p["bounds"], int(p["mip_size"]), margin)
        plan.append({"stage": "reduce", "ran": True,
                     "why": (f"max-reduction of the {p['mip_size']}x{p['mip_size']} MIP level + margin "
                             f"{margin:.3g} (§3.7)") if p["bounds"] == "mip" else "exact per-layer maxima"})
    timings["reduce"] = (tic() - t0) * 1e3

    t0 = tic()
    thr = exit_thresholds(zlo, zhi, S, p["exit_threshold"])
    tr = trace_layers(ldi, total, zmax, thr, bhi, blo, None, cam, ior=ior, outside_ior=outside, world=True,
                      iterations=int(p["iterations"]), normals=p["normals"], delta=int(p["delta"]),
                      tir=bool(p["tir"]), max_interfaces=int(p["max_interfaces"]), layer_limit=L, lut=lut)
    timings["trace"] = (tic() - t0) * 1e3
    plan.append({"stage": "trace", "ran": True,
                 "why": f"{p['iterations']} binary-search iterations per interface, {p['normals']} normals"
                        + (", total internal reflection followed" if p["tir"] else "")})

    n_over = int(np.count_nonzero(total > L))  # for the plan and meta: not part of the pipeline
    return {"trace": tr, "total": total, "ldi": ldi, "zmin": zmin, "zmax": zmax,
            "pixels_over_layer_limit": n_over}


def render_imagespace(scene, warm=True):
    """Render a scene with the image-space method.

    Parameters
    ----------
    scene : Scene
        A validated scene (:func:`~refraction_ref.scene.load_scene`).
    warm : bool
        Compile (or load from the cache) every kernel on a tiny scene first,
        so that ``timings_ms`` measure run time, not JIT time.

    Returns
    -------
    arrays : dict
        The ORACLE.md per-pixel keys plus ``depth_complexity``.
    info : dict
        ``timings_ms``, ``plan`` and method statistics for ``meta``.

    References
    ----------
    Chaudhari (2008), chapter 3.
    """
    if warm:
        from .. import _warmup

        _warmup.imagespace()
    p = scene.data["imagespace"]
    cam = Camera.from_dict(scene.data["camera"])
    H, W = cam.shape
    timings, plan = {}, []
    tic = time.perf_counter

    geom = scene_geometry(scene)
    ior, absorption = check_materials(geom)
    outside = float(scene.data["outside_ior"])
    if eye_inside(geom, cam.eye):
        raise SceneError("imagespace: the camera is inside a refractive object; the image-space method "
                         "needs the viewer outside (its first layer is the front face). Move camera.eye "
                         "outside the objects")
    for k, nb in enumerate(geom.boundary_edges):
        if nb:
            plan.append({"stage": "geometry", "ran": True,
                         "why": f"object {k} is open ({int(nb)} boundary edges): pixels can see an odd number "
                                "of layers, and inside/outside then follows layer parity"})
    for k, nd in enumerate(geom.degenerate):
        if nd:
            plan.append({"stage": "geometry", "ran": True,
                         "why": f"object {k} has {int(nd)} zero-area triangles; they produce no fragments"})

    tv = layered_trace(geom, cam, p, ior, outside, timings, plan)
    tr, total, ldi, n_over = tv["trace"], tv["total"], tv["ldi"], tv["pixels_over_layer_limit"]
    L = int(p["layers"])

    t0 = tic()
    status = tr["status"]
    hit = status != 0
    exit_dir, exit_pos = tr["exit_dir"], tr["exit_pos"]
    env = scene.data["environment"]
    image = environment_lookup(env, tr["last_dir"], scene.base_dir)
    if np.any(absorption > 0):
        trans = beer_lambert(absorption, tr["path_length"], ior)
        image = (image * trans).astype(np.float32)
        plan.append({"stage": "absorption", "ran": True, "why": "I = I0 exp(-alpha l eta) (§3.8)"})
    else:
        plan.append({"stage": "absorption", "ran": False, "why": "absorption is zero"})
    timings["shade"] = (tic() - t0) * 1e3
    from ..caustics.pipeline import caustics_imagespace, has_caustics, merge_caustics, skip_reason

    caustics = None
    if has_caustics(scene):
        c_arrays, caustics = caustics_imagespace(scene, geom, cam, tv, ior, outside, absorption)
        plan.append({"stage": "caustics", "ran": True,
                     "why": f"{p['photons']}x{p['photons']} photons per light through all layers (§4.1), "
                            f"{p['receiver_hit']} receiver hits, {p['caustic_map']}^2 maps, gathering window "
                            f"{p['gather']}; timings in meta['caustics']"})
    else:
        plan.append({"stage": "caustics", "ran": False, "why": skip_reason(scene)})

    origin, rdir = cam.primary_rays()
    arrays = {
        "ray_origin": origin,
        "ray_dir": rdir,
        "hit": hit,
        "exit_pos": exit_pos,
        "exit_dir": exit_dir,
        "interfaces": tr["interfaces"],
        "path_length": tr["path_length"],
        "status": status,
        "image": image,
        "depth_complexity": total.astype(np.int16),
    }
    if caustics is not None:
        merge_caustics(arrays, c_arrays)
    info = {
        "timings_ms": timings,
        "plan": plan,
        "layers_used": int(ldi.shape[0]),
        "pixels_over_layer_limit": n_over,
        "depth_complexity_max": int(total.max(initial=0)),
        "triangles": int(len(geom.faces)),
    }
    if caustics is not None:
        info["caustics"] = caustics
    return arrays, info
