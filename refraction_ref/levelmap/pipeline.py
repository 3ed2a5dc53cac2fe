"""The level-map water-caustics pipeline (Tipprasert 2006, ch. 4), pass by pass.

=====================  ===============================================  ===========
stage (``timings_ms``)  pass                                             section
=====================  ===============================================  ===========
``water``               water mesh, refraction at vertices (eq. 2-8),    §2.6, §4.3
                        illumination volumes (eq. 4-14)
``planes``              reference boxes and slicing (eqs. 4-1 to 4-9)    §4.2.1
``level_map``           position and diffuse maps (eqs. 4-10 to 4-13)    §4.2.2
``smart_slicing``       depth profile, sub-boxes (eqs. 4-21, 4-22)       §4.7.2
``caustics``            intersection test (eq. 4-15) and caustics map    §4.4, §4.5
                        (eq. 4-18); or the volumetric baseline's slices  §5.2.1
                        and caustics; or the per-ray variant             §6.3
``casting``             several lights into one map (eq. 4-20)           §4.7.1
``image``               camera view shaded with caustics (eq. 4-19)      §4.6
=====================  ===============================================  ===========

One set of planes, one box and one level map per (receiver, light) pair.
``caustic_map_r`` is in the frame of receiver r's box for the first light.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from ..camera import Camera
from ..meshes import object_mesh
from ..scene import SceneError, load_scene
from .caustics_map import beams_in_map, cull_beams, splat_plane
from .casting import cast_between, shade_image
from .illumination import illumination_volumes
from .intersection import plane_index_map, plane_rects
from .maps import Receivers, level_map
from .per_ray import per_ray_caustics
from .planes import frame_of, reference_box, refracted_axis, slice_planes
from .smart_slicing import smart_planes
from .volumetric import volumetric_caustics
from .water import water_mesh

__all__ = ["render_levelmap", "default_scene", "receivers_of", "prepare", "DEFAULT_SCENE_PATH"]

DEFAULT_SCENE_PATH = os.path.join(os.path.dirname(os.path.dirname(__file__)), "data", "levelmap_default.json")

_warm = set()


def default_scene(overrides=None):
    """The default level-map scene: the teapot on a pool floor under a wavy surface in sunlight."""
    return load_scene(DEFAULT_SCENE_PATH, overrides)


def receivers_of(scene):
    """All receiver triangles of a scene (:class:`~.maps.Receivers`)."""
    tris, owner, alb, verts = [], [], [], []
    for k, rc in enumerate(scene.data["receivers"] or []):
        v, f = object_mesh(rc, scene.base_dir)
        tris.append(v[f])
        owner.append(np.full(len(f), k, np.int64))
        alb.append(np.asarray(rc["albedo"], dtype=np.float64))
        verts.append(v)
    if not tris:
        raise SceneError("levelmap: the scene has no receivers; add at least one entry to 'receivers' "
                         "(e.g. a pool floor: {\"mesh\": \"plane\", \"size\": [4, 4]})")
    t = np.concatenate(tris)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)
    return Receivers(t, np.concatenate(owner), n, np.stack(alb), verts)


class _Pair:
    """Box, raster set-up and level map of one (receiver, light) pair."""

    def __init__(self, box, sel, setup, lm):
        self.box, self.sel, self.setup, self.lm = box, sel, setup, lm


def _check(scene):
    w = scene.data["water"]
    if w is None:
        raise SceneError("levelmap: the scene has no 'water' block; add one, e.g. "
                         "\"water\": {\"size\": [4, 4], \"height\": 0, \"waves\": []}")
    if not scene.data["lights"]:
        raise SceneError("levelmap: the scene has no lights; add a directional or point light above the water")


def prepare(scene, timings=None):
    """Water beams per light, and box, set-up and level map per (receiver, light).

    Returns
    -------
    dict
        ``mesh``, ``vols`` (per light), ``receivers``, ``pairs[r][l]``,
        ``eta``, ``K``.
    """
    _check(scene)
    timings = {} if timings is None else timings
    p = scene.data["levelmap"]
    water = scene.data["water"]
    eta = float(scene.data["outside_ior"]) / float(water["ior"])
    tic = time.perf_counter()
    mesh = water_mesh(water)
    vols = [illumination_volumes(lt, mesh, eta) for lt in scene.data["lights"]]
    timings["water"] = timings.get("water", 0.0) + (time.perf_counter() - tic) * 1e3
    tic = time.perf_counter()
    rec = receivers_of(scene)
    boxes = []
    for r, v in enumerate(rec.vertices):
        centre = (v.min(axis=0) + v.max(axis=0)) / 2.0
        boxes.append([reference_box(v, refracted_axis(lt, water, eta, centre), int(p["map_size"]))
                      for lt in scene.data["lights"]])
    timings["planes"] = timings.get("planes", 0.0) + (time.perf_counter() - tic) * 1e3
    tic = time.perf_counter()
    pairs = []
    for r in range(len(rec.vertices)):
        row = []
        for box in boxes[r]:
            lm, sel, setup = level_map(rec, r, box, bool(p["shadows"]))
            row.append(_Pair(box, sel, setup, lm))
        pairs.append(row)
    timings["level_map"] = timings.get("level_map", 0.0) + (time.perf_counter() - tic) * 1e3
    return {"mesh": mesh, "vols": vols, "receivers": rec, "pairs": pairs, "eta": eta,
            "K": float(water["absorption"])}


def _caustics_pair(ctx, r, l, p, variant, timings, stats):
    pair = ctx["pairs"][r][l]
    box, lm = pair.box, pair.lm
    n = int(p["planes"])
    K = ctx["K"]
    out = np.zeros(box.size)
    tic = time.perf_counter()
    beams = beams_in_map(ctx["vols"][l], box)
    cand = cull_beams(beams, box, -box.h / 2.0, box.h / 2.0)
    st = {"receiver": r, "light": l, "candidate_beams": int(len(cand)), "box": [box.w, box.h, box.d]}
    if variant == "levelmap":
        pidx = plane_index_map(lm, box, n)
        zeta, _, eps = slice_planes(box, n)
        st["eps"] = eps
        t_s = time.perf_counter()
        if p["smart_slicing"]:
            keep, sinfo = smart_planes(lm, box, n, int(p["depth_levels"]), pidx)
            st["smart"] = {"sub_boxes": sinfo["sub_boxes"], "empty_levels": sinfo["empty_levels"]}
        else:
            keep = np.arange(n)
        timings["smart_slicing"] = timings.get("smart_slicing", 0.0) + (time.perf_counter() - t_s) * 1e3
        rects = plane_rects(pidx, n)
        drawn = 0
        for i in keep:
            drawn += splat_plane(beams, cand, box, zeta[i], K, rects[i], pidx, int(i), lm.depth, lm.normal, out)
        st["planes_used"] = int(len(keep))
        st["triangles_drawn"] = drawn
    elif variant == "volumetric":
        st.update(volumetric_caustics(beams, cand, box, ctx["receivers"], r, pair.sel, pair.setup, n, K, out))
        st["planes_used"] = n
    else:
        st.update(per_ray_caustics(beams, cand, lm, box, K, out))
        st["planes_used"] = 0
    timings["caustics"] = timings.get("caustics", 0.0) + (time.perf_counter() - tic) * 1e3
    stats.append(st)
    return out


def warm_up():
    """Compile (or load from Numba's cache) every kernel on a tiny scene, once per process."""
    if "levelmap" in _warm:
        return
    _warm.add("levelmap")
    base = {"camera": {"width": 8, "height": 8, "eye": [0, 2, 2], "target": [0, -1, 0]},
            "objects": [],
            "receivers": [{"mesh": "plane", "size": [1, 1], "transform": {"translate": [0, -0.5, 0]}}],
            "water": {"size": [1, 1], "resolution": 4, "absorption": 0.1,
                      "waves": [{"amplitude": 0.01, "wavelength": 0.5}]},
            "lights": [{"type": "directional", "direction": [0.1, -1, 0]}],
            "levelmap": {"planes": 3, "map_size": 8}}
    for v in ("levelmap", "volumetric", "per_ray"):
        render_levelmap(load_scene(base, {"levelmap.variant": v}), warm=False)


def render_levelmap(scene, warm=True):
    """Render water caustics with the level-map method (or its baseline / per-ray variant).

    Parameters
    ----------
    scene : Scene
        With a ``water`` block, receivers and lights above the water.
    warm : bool
        Load every kernel first so that ``timings_ms`` exclude JIT time.

    Returns
    -------
    arrays : dict
        ``caustic_map_r`` (Hc, Wc) float32 irradiance and ``caustic_frame_r``
        (4, 3) per receiver r (ORACLE.md), ``image`` (H, W, 3) float32 and
        ``object_mask`` (H, W) bool (the pixels showing a receiver).
    info : dict
        ``timings_ms``, ``plan``, ``planes_requested``, ``planes_used`` (the
        most any receiver used), ``planes_used_per_receiver`` (per light),
        ``stats`` per (receiver, light).

    References
    ----------
    Tipprasert (2006), chapter 4; Figs. 4-15 and 4-17.
    """
    if warm:
        warm_up()
    p = scene.data["levelmap"]
    variant = p["variant"]
    timings, plan, stats = {}, [], []
    ctx = prepare(scene, timings)
    L = len(scene.data["lights"])
    R = len(ctx["pairs"])
    arrays = {}
    maps = []
    used = []
    for r in range(R):
        E0 = _caustics_pair(ctx, r, 0, p, variant, timings, stats)
        used_r = [stats[-1]["planes_used"]]
        total = E0.copy()
        for l in range(1, L):
            El = _caustics_pair(ctx, r, l, p, variant, timings, stats)
            used_r.append(stats[-1]["planes_used"])
            t_c = time.perf_counter()
            cast_between(El, ctx["pairs"][r][l].box, ctx["pairs"][r][l].lm,
                         ctx["pairs"][r][0].box, ctx["pairs"][r][0].lm, total)
            timings["casting"] = timings.get("casting", 0.0) + (time.perf_counter() - t_c) * 1e3
        used.append(used_r)
        total = np.nan_to_num(total, nan=0.0, posinf=0.0, neginf=0.0)
        arrays[f"caustic_map_{r}"] = total.astype(np.float32)
        arrays[f"caustic_frame_{r}"] = frame_of(ctx["pairs"][r][0].box)
        maps.append(arrays[f"caustic_map_{r}"])
    tic = time.perf_counter()
    cam = Camera.from_dict(scene.data["camera"])
    image, mask = shade_image(cam, ctx["receivers"], [ctx["pairs"][r][0].box for r in range(R)], maps,
                              ctx["receivers"].albedo, float(p["ambient"]))
    arrays["image"] = image
    arrays["object_mask"] = mask
    timings["image"] = (time.perf_counter() - tic) * 1e3
    nmesh = int(scene.data["water"]["resolution"])
    plan.append({"stage": "water", "ran": True,
                 "why": f"{nmesh}x{nmesh} quads, {len(ctx['mesh'].faces)} beams per light, {L} light(s)"})
    plan.append({"stage": "planes", "ran": variant != "per_ray",
                 "why": (f"{p['planes']} planes per (receiver, light)" if variant != "per_ray"
                         else "per-ray variant: planes replaced by a per-ray search (boxes still built)")})
    plan.append({"stage": "level_map", "ran": True, "why": f"{p['map_size']}^2 orthographic maps, "
                 f"{'receivers shadow each other' if p['shadows'] else 'each receiver alone'}"})
    plan.append({"stage": "smart_slicing", "ran": bool(p["smart_slicing"]) and variant == "levelmap",
                 "why": (f"{p['depth_levels']} depth levels" if p["smart_slicing"] and variant == "levelmap"
                         else ("off (levelmap.smart_slicing is false)" if variant == "levelmap"
                               else f"not used by the {variant} variant"))})
    plan.append({"stage": "caustics", "ran": True, "why": {
        "levelmap": "intersection triangles on every plane, depth-tested against the position map",
        "volumetric": "one slice image per sample plane (Iwasaki et al.), composited front to back",
        "per_ray": "each beam drawn once where its rays hit (§6.3)"}[variant]})
    plan.append({"stage": "casting", "ran": L > 1,
                 "why": f"{L - 1} more light(s) cast into the first light's frame" if L > 1 else "one light"})
    plan.append({"stage": "image", "ran": True, "why": "eq. 4-19 with ambient " + str(p["ambient"])})
    info = {"timings_ms": timings, "plan": plan, "planes_requested": int(p["planes"]),
            "planes_used": int(max(max(u) for u in used)), "planes_used_per_receiver": used,
            "variant": variant, "stats": json.loads(json.dumps(stats, default=float)),
            "triangles": int(len(ctx["receivers"].tris))}
    return arrays, info
