"""``--method exact``: the exact reference as a registered stage graph.

==================  ===========================================================
stage               pass
==================  ===========================================================
``geometry``        the objects' triangles and area-weighted vertex normals
``trace``           every pixel's ray through the real triangles (Embree hits,
                    float64 Möller-Trumbore, Snell / total internal reflection)
``shade``           environment look-up, Beer-Lambert per segment
==================  ===========================================================

With lights and receivers the exact photon reference follows
(:func:`refraction_ref.caustics.pipeline.exact_caustic_stages`). A scene with
``water`` is rendered by the exact water reference instead: the level map's
``water``, ``planes`` and ``level_map`` stages, then ``trace`` (jittered
samples of the analytic surface, Embree first hits;
:func:`refraction_ref.levelmap.exact_water.trace_water_photons`) and ``image``.
"""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .environment import environment_lookup
from .graph import Method, Stage, register_method, run_graph
from .meshes import eye_inside, scene_geometry, vertex_normals
from .scene import SceneError
from .status import MISSED

__all__ = ["render_exact", "METHOD"]


def _st_geometry(ctx):
    geom = scene_geometry(ctx.scene)
    ctx.stats["triangles"] = int(len(geom.faces))
    vn = vertex_normals(geom.vertices, geom.faces) if len(geom.faces) else None
    return {"geom": geom, "vertex_normals": vn}


def _st_trace(ctx):
    from .exact import trace_exact

    d = ctx.scene.data
    p = d["exact"]
    geom, vn = ctx.buf["geometry"]["geom"], ctx.buf["geometry"]["vertex_normals"]
    cam = Camera.from_dict(d["camera"])
    H, W = cam.shape
    if eye_inside(geom, cam.eye):
        raise SceneError("exact: the camera is inside a refractive object; the reference tracer starts "
                         "every ray in the outside medium. Move camera.eye outside the objects")
    origin, rdir = cam.primary_rays()
    n = H * W
    K = int(p["record"])
    if len(geom.faces):
        kw = {"record": K} if K else {}
        tr = trace_exact(geom.vertices, geom.faces, geom.face_object, geom.ior, geom.absorption,
                         origin.reshape(n, 3), rdir.reshape(n, 3), vertex_normals=vn,
                         smooth=p["normals"] == "smooth", outside_ior=float(d["outside_ior"]),
                         max_bounces=int(p["max_bounces"]), progress=ctx.progress, **kw)
    else:
        tr = {"hit": np.zeros(n, bool), "exit_pos": np.full((n, 3), np.nan), "exit_dir": rdir.reshape(n, 3).copy(),
              "interfaces": np.zeros(n, np.int16), "path_length": np.zeros(n), "status": np.full(n, MISSED, np.int8),
              "transmittance": np.ones((n, 3)), "last_dir": rdir.reshape(n, 3).copy()}
        if K:
            tr["path_pos"] = np.full((n, K, 3), np.nan)
            tr["path_dir"] = np.full((n, K, 3), np.nan)
    ctx.note(f"Embree, {p['normals']} normals, up to {p['max_bounces']} bounces")
    out = {"flat": tr, "ray_origin": origin, "ray_dir": rdir,
           "hit": tr["hit"].reshape(H, W),
           "exit_pos": tr["exit_pos"].reshape(H, W, 3),
           "exit_dir": tr["exit_dir"].reshape(H, W, 3),
           "interfaces": tr["interfaces"].reshape(H, W).astype(np.int16),
           "path_length": tr["path_length"].reshape(H, W),
           "status": tr["status"].reshape(H, W).astype(np.int8),
           "path_pos": None, "path_dir": None}
    if K and "path_pos" in tr:
        out["path_pos"] = tr["path_pos"].reshape(H, W, K, 3)
        out["path_dir"] = tr["path_dir"].reshape(H, W, K, 3)
    return out


def _st_shade(ctx):
    geom = ctx.buf["geometry"]["geom"]
    tr = ctx.buf["trace"]["flat"]
    H, W = ctx.buf["trace"]["status"].shape
    image = environment_lookup(ctx.scene.data["environment"], tr["last_dir"], ctx.scene.base_dir)
    if np.any(geom.absorption > 0):
        image = (image * tr["transmittance"]).astype(np.float32)
        ctx.note("environment look-up; Beer-Lambert per segment")
    else:
        ctx.note("environment look-up; absorption is zero")
    return {"image": image.reshape(H, W, 3).astype(np.float32)}


def _mesh_stages():
    return (
        Stage("geometry", _st_geometry, reads=("objects", "outside_ior"), makes=("geom", "vertex_normals"),
              doc="the objects' triangles and area-weighted vertex normals"),
        Stage("trace", _st_trace, reads=("camera", "outside_ior", "exact.normals", "exact.max_bounces",
                                         "exact.record"), after=("geometry",),
              makes=("hit", "exit_pos", "exit_dir", "interfaces", "path_length", "status", "path_pos", "path_dir"),
              doc="every pixel's ray through the real triangles (Embree, float64 Snell)"),
        Stage("shade", _st_shade, reads=("environment",), after=("geometry", "trace"), makes=("image",),
              doc="environment look-up, Beer-Lambert per segment"),
    )


# --------------------------------------------------------------------- water scenes
def _st_water_trace(ctx):
    from .levelmap.exact_water import trace_water_photons
    from .levelmap.planes import frame_of

    d = ctx.scene.data
    p = d["levelmap"]
    w = ctx.buf["water"]
    pairs = ctx.buf["level_map"]["pairs"]
    wctx = {"mesh": w["mesh"], "vols": w["vols"], "receivers": ctx.buf["planes"]["receivers"], "pairs": pairs,
            "eta": w["eta"], "K": w["K"]}
    R = len(pairs)
    out = [np.zeros(pairs[r][0].box.size) for r in range(R)]
    stats = [trace_water_photons(ctx.scene, wctx, l, int(p["exact_samples"]), int(p["exact_seed"]), out,
                                 ctx.progress) for l in range(len(d["lights"]))]
    ctx.stats["water_stats"] = stats
    M = int(p["exact_samples"])
    ctx.note(f"{M}x{M} jittered samples of the analytic surface per light, Embree first hits")
    res = {}
    for r in range(R):
        res[f"caustic_map_{r}"] = np.nan_to_num(out[r]).astype(np.float32)
        res[f"caustic_frame_{r}"] = frame_of(pairs[r][0].box)
    return res


def _water_stages(scene):
    from .levelmap.pipeline import shade_stage, shared_stages

    R = len(scene.data["receivers"])
    return shared_stages(scene) + (
        Stage("trace", _st_water_trace,
              reads=("water", "lights", "outside_ior", "levelmap.exact_samples", "levelmap.exact_seed"),
              after=("water", "planes", "level_map"), makes=tuple(f"caustic_map_{r}" for r in range(R)),
              doc="exact water photons: jittered samples of the analytic surface, Embree first hits"),
        Stage("image", lambda ctx: shade_stage(ctx, "trace"), reads=("camera", "levelmap.ambient"),
              after=("planes", "level_map", "trace"), makes=("image", "object_mask"),
              doc="eq. 4-19 with the exact maps"),
    )


# --------------------------------------------------------------------- the method
def _stages(scene):
    if scene.data.get("water") is not None:
        from .levelmap.pipeline import _check

        _check(scene)
        return _water_stages(scene)
    from .caustics.pipeline import exact_caustic_stages, has_caustics

    return _mesh_stages() + (exact_caustic_stages(scene) if has_caustics(scene) else ())


def _skipped(scene):
    if scene.data.get("water") is not None:
        return []
    from .caustics.pipeline import has_caustics, skip_reason

    return [] if has_caustics(scene) else [{"stage": "caustics", "ran": False, "why": skip_reason(scene)}]


def _assemble(scene, bufs, stats):
    if "water" in bufs:
        from .levelmap.pipeline import water_arrays

        return water_arrays(bufs, "trace"), {"stats": stats["water_stats"], "triangles": stats["triangles"]}
    tr = bufs["trace"]
    arrays = {k: tr[k] for k in ("ray_origin", "ray_dir", "hit", "exit_pos", "exit_dir", "interfaces",
                                 "path_length", "status")}
    arrays["image"] = bufs["shade"]["image"]
    info = {"triangles": stats["triangles"]}
    if "caustic_final" in bufs:
        from .caustics.pipeline import caustic_arrays, merge_caustics

        c_arrays, info["caustics"] = caustic_arrays(scene, "exact", bufs, stats)
        merge_caustics(arrays, c_arrays)
    return arrays, info


METHOD = register_method(Method(
    "exact", blocks=("exact",), stages=_stages, assemble=_assemble, skipped=_skipped,
    results=("trace", "shade", "level_map.pairs", "image", "receivers.rs", "gather", "caustic_final"),
    doc="the exact reference: Embree mesh tracing; for water scenes exact sampling of the analytic surface"))


def render_exact(scene, progress=False, cache=None, keep=None):
    """Trace every pixel's primary ray exactly (Embree) and shade like the image-space method.

    Returns
    -------
    arrays, info : dict, dict
        Same keys as :func:`~refraction_ref.imagespace.pipeline.render_imagespace`
        (for a water scene: as the level map).
    """
    return run_graph(METHOD, scene, cache=cache, keep=keep, progress=progress)
