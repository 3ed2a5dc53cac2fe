"""The exact photon reference's caustic stages (mesh scenes with lights and receivers).

==================  ==============================================================
stage               pass
==================  ==============================================================
``receivers``       receiver triangles and their caustic-map frames (the caustics
                    service's stage, :mod:`refraction_ref.caustics.pipeline`)
``photon_trace``    ``exact.photons`` squared jittered photons per light through
                    the light's window, traced through the real triangles
                    (:func:`~refraction_ref.exact.trace.trace_exact`)
``receiver_hit``    Embree on the receivers' triangles
``splat``           bilinear splat without gathering; the reference's own noise
                    from its two interleaved halves
``gather``          the sum over lights (no gathering)
``caustic_final``   receivers lit directly (exact shadow rays) and by the
                    caustics, the object traced exactly
==================  ==============================================================

The generic stages (receivers, receiver hits, splat, gather) are the caustics
service's; this module holds the two that only the exact reference has, and the
gathers and scatters of their rows, each a kernel on every thread that keeps
NumPy's arithmetic and order (the same bits whatever the thread count).

References
----------
.. [1] docs/oracle.md, "Caustics on receivers" (the outputs) and the ``exact``
   block (``photons``, ``photon_seed``, ``max_bounces``).
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §4.1 (the caustics this is the reference
   for: photons refracted through every interface by Snell's law, without
   Fresnel losses, splatted onto diffuse receivers).
.. [3] J. Arvo, "Backward Ray Tracing", SIGGRAPH '86 course notes (light
   tracing into illumination maps).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..caustics.light import window_samples
from ..caustics.pipeline import (camera_array, gather_names, gather_stage, per_light_names, photon_buffer_names,
                                 receiver_hit_stage, receiver_stages, splat_stage)
from ..caustics.exact_hits import IndexedTriangles, hit_exact
from ..caustics.receivers import ReceiverHitMode
from ..caustics.shade import ReceiverLighting, shade_rays
from ..caustics.shadow import exact_visibility
from ..embree import mesh_scene
from ..environment import environment_lookup
from ..graph import Stage
from ..kernels import put_rows, take_rows
from ..lights import light_camera
from ..status import EXITED
from .knobs import exact_knobs
from .trace import ExactMesh, trace_exact

__all__ = ["exact_caustic_stages"]


@nb.njit(cache=True, parallel=True)
def _ray_points_kernel(o, t, d, idx, out):
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        i = idx[k]
        for c in range(3):
            out[k, c] = o[i, c] + t[i] * d[i, c]


def _ray_points(o, t, d, idx):
    """``o[idx] + t[idx, None] * d[idx]`` on every thread."""
    out = np.empty((len(idx), 3))
    if len(idx):
        _ray_points_kernel(o, np.ascontiguousarray(t, dtype=np.float64), d, np.ascontiguousarray(idx, np.int64),
                           out)
    return out


@nb.njit(cache=True, parallel=True)
def _scale_rows_kernel(a, idx, vals):
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        i = idx[k]
        for c in range(a.shape[1]):
            a[i, c] *= vals[i, c]


def _scale_rows(a, idx, vals):
    """``a[idx] *= vals[idx]`` on every thread."""
    if len(idx):
        _scale_rows_kernel(a, np.ascontiguousarray(idx, np.int64), vals)


@nb.njit(cache=True, parallel=True)
def _distance_kernel(hp, o, out):
    # np.where(isfinite(hp[:, 0]), np.linalg.norm(hp - o, axis=1), inf): sqrt((x x + y y) + z z)
    for k0 in nb.prange(hp.shape[0]):
        k = np.int64(k0)
        if not math.isfinite(hp[k, 0]):
            out[k] = np.inf
            continue
        x = hp[k, 0] - o[k, 0]
        y = hp[k, 1] - o[k, 1]
        z = hp[k, 2] - o[k, 2]
        out[k] = np.sqrt((x * x + y * y) + z * z)


def _st_photon_trace_exact(ctx):
    """Every light's jittered photons through the real triangles (:func:`~refraction_ref.exact.trace.trace_exact`).

    References
    ----------
    .. [1] Chaudhari (2008), §4.1 (the caustics this is the reference for); docs/oracle.md, "Caustics on
       receivers".
    """
    d = ctx.scene.data
    knobs = exact_knobs(d, "photons", "photon_seed", "max_bounces")
    g = ctx.buf["geometry"]
    geom = g["geom"]
    n = knobs.photons
    out = {"lights": [], **dict.fromkeys(photon_buffer_names(len(d["lights"]), False))}
    mesh = ExactMesh.of(geom, g["normals"], g["smooth"], d["outside_ior"])
    for l, light in enumerate(d["lights"]):
        if not len(geom.faces):
            out["lights"].append(None)
            continue
        lcam = light_camera(light, geom.vertices, n)
        o, dd, flux0, half = window_samples(lcam, n, knobs.photon_seed + l)
        traced = trace_exact(mesh, o, dd, max_bounces=knobs.max_bounces)
        st = traced["status"].astype(np.int8)
        ex = np.flatnonzero(st == EXITED)
        # the exited photons' rows, gathered on every thread; the buffers are those arrays
        eo, ed = take_rows(traced["exit_pos"], ex), take_rows(traced["exit_dir"], ex)
        out["lights"].append({"cam": lcam, "status": st, "flux0": flux0, "ex": ex,
                              "trans": take_rows(traced["transmittance"], ex), "o": eo, "d": ed, "half": half[ex]})
        out[f"camera_{l}"] = camera_array(lcam)
        out[f"exit_pos_{l}"] = eo
        out[f"exit_dir_{l}"] = ed
    ctx.note(f"exact photon reference: {n}x{n} jittered photons per light through the triangles")
    return out


def _st_final_exact(ctx):
    """The image with caustics: receivers lit directly (exact shadow rays) and by the caustic maps.

    References
    ----------
    .. [1] Chaudhari (2008), §4.1 (receivers lit by the caustics); docs/oracle.md, "Caustics on receivers".
    """
    d = ctx.scene.data
    b = ctx.buf
    geom = b["geometry"]["geom"]
    lights = d["lights"]
    rs = b["receivers"]["rs"]
    rgb_maps = b["gather"]["rgb_maps"]
    eye_traced = b["trace"]["flat"]
    origin, rdir = b["trace"]["ray_origin"], b["trace"]["ray_dir"]
    # the objects' triangles read in place, and the exact tracer's scene of them (cached by
    # content: primitive k is face k); building vertices[faces] was serial work every render
    obj_tris = IndexedTriangles(geom.vertices, geom.faces)
    obj_scene = mesh_scene(geom.vertices, geom.faces) if len(geom.faces) else None
    scale = max(obj_tris.abs_max(), 1.0)

    def vis(l, pts, nrm):
        return exact_visibility(obj_tris, lights[l], pts, nrm, scene=obj_scene, scale=scale)

    H, W = origin.shape[:2]
    o = np.ascontiguousarray(origin.reshape(-1, 3), dtype=np.float64)
    dd = np.ascontiguousarray(rdir.reshape(-1, 3), dtype=np.float64)
    t_rec, f_rec = hit_exact(rs.tris, o, dd)
    hp = eye_traced.get("hit_pos")
    t_obj = np.full(len(o), np.inf)
    if hp is not None:  # np.where(isfinite(hp[:, 0]), np.linalg.norm(hp - o, axis=1), inf), on every thread
        _distance_kernel(np.ascontiguousarray(hp, dtype=np.float64), o, t_obj)
    rec = np.isfinite(t_rec) & (t_rec < t_obj)
    img = np.zeros((len(o), 3))
    obj = np.isfinite(t_obj) & ~rec
    bg = ~rec & ~obj
    env = d["environment"]
    if bg.any():
        img[bg] = environment_lookup(env, dd[bg], ctx.scene.base_dir)
    st = eye_traced["status"]
    ex = obj & (st == EXITED)
    # the receivers seen directly (o + t d) and the exit rays' receivers in one shading call
    # (every point's colour is its own): one pass of shadow rays, one of map look-ups
    ri, xi = np.flatnonzero(rec), np.flatnonzero(ex)
    if len(ri) or len(xi):
        direct = (_ray_points(o, t_rec, dd, ri), f_rec[ri], take_rows(dd, ri))
        c, cd = shade_rays(ctx.scene, ReceiverLighting(rs, d["lights"], rgb_maps, vis), ReceiverHitMode("exact"),
                           take_rows(eye_traced["exit_pos"], xi), take_rows(eye_traced["exit_dir"], xi), direct)
        put_rows(img, ri, cd)
        put_rows(img, xi, c)
    stuck = obj & (st != EXITED)
    if stuck.any():
        img[stuck] = environment_lookup(env, eye_traced["last_dir"][stuck], ctx.scene.base_dir)
    _scale_rows(img, np.flatnonzero(obj), np.ascontiguousarray(eye_traced["transmittance"], dtype=np.float64))
    ctx.note("receivers lit directly (exact shadow rays) and by the caustics; the object traced exactly")
    return {"image_caustics": img.reshape(H, W, 3).astype(np.float32)}


def exact_caustic_stages(scene):
    """The caustic stages of the exact reference for a scene with lights and receivers.

    Parameters
    ----------
    scene : Scene
        A mesh scene with at least one light and one receiver
        (:func:`refraction_ref.caustics.pipeline.has_caustics`).

    Returns
    -------
    tuple of Stage
        ``receivers``, ``photon_trace``, ``receiver_hit``, ``splat``, ``gather``
        and ``caustic_final``, to follow the exact method's ``geometry``,
        ``trace`` and ``shade`` stages.

    References
    ----------
    .. [1] docs/oracle.md, "Caustics on receivers" and the ``exact`` block.
    .. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1 (the caustics it is the reference for).
    """
    nl, nr = len(scene.data["lights"]), len(scene.data["receivers"])
    return receiver_stages(nr)[:1] + (
        Stage("photon_trace", _st_photon_trace_exact,
              reads=("lights", "outside_ior", "exact.photons", "exact.photon_seed", "exact.max_bounces"),
              after=("geometry",),
              makes=photon_buffer_names(nl, False),
              doc="exact photons through the triangles (Embree)"),
        Stage("receiver_hit", lambda ctx: receiver_hit_stage(ctx, False), after=("receivers", "photon_trace"),
              makes=per_light_names("hit_pos", nl) + per_light_names("hit_face", nl),
              doc="Embree on the receivers' triangles"),
        Stage("splat", lambda ctx: splat_stage(ctx, True), reads=("caustics.map_size", "exact.photons"),
              after=("receivers", "photon_trace", "receiver_hit"), makes=per_light_names("splat", nr),
              doc="bilinear splat; the reference's own noise from two interleaved halves"),
        Stage("gather", lambda ctx: gather_stage(ctx, False), reads=("lights",), after=("receivers", "splat"),
              makes=gather_names(nr), doc="sum over lights, no gathering"),
        Stage("caustic_final", _st_final_exact, reads=("environment", "lights"),
              after=("geometry", "trace", "receivers", "gather"), makes=("image_caustics",),
              doc="receivers lit directly and by caustics, the object traced exactly"),
    )
