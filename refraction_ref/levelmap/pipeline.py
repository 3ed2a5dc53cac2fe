"""The level-map water-caustics pipeline (Tipprasert 2006, ch. 4), pass by pass.

=====================  ===============================================  ===========
stage (``timings_ms``)  pass                                             section
=====================  ===============================================  ===========
``water``               water mesh, refraction at vertices (eq. 2-8),    §2.6, §4.3
                        illumination volumes (eq. 4-14)
``planes``              reference boxes and slicing (eqs. 4-1 to 4-9)    §4.2.1
``level_map``           position and diffuse maps (eqs. 4-10 to 4-13)    §4.2.2
``caustics``            per (receiver, light): smart slicing             §4.7.2,
                        (``caustics.smart_slicing``, eqs. 4-21, 4-22),   §4.4, §4.5
                        intersection test (eq. 4-15) and caustics map
                        (eq. 4-18); or the volumetric baseline's slices  §5.2.1
                        and caustics; or the per-ray variant             §6.3
``casting``             several lights into one map (eq. 4-20)           §4.7.1
``image``               camera view through the water (eq. 2-8, eye      §4.6, §2.6
                        rays refracted at the mesh) and directly, shaded
                        with caustics (eq. 4-19; :mod:`.view`)
=====================  ===============================================  ===========

A registered stage graph (:data:`METHOD`): a camera change re-runs
``image`` only; a level-map knob the stages from ``caustics`` on; a light
or water change everything but nothing of the camera. The exact water
reference (:mod:`refraction_ref.exact.water`) shares ``water``, ``planes`` and
``level_map``.

One set of planes, one box and one level map per (receiver, light) pair.
``caustic_map_r`` is in the frame of receiver r's box for the first light.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from ..camera import Camera
from ..graph import Method, Stage, register_method, run_graph
from ..caustics.receivers import receiver_soup
from ..validation import SceneError
from ..scene import load_scene
from ..warm import warmer
from .caustics_map import beams_in_map, cull_beams, splat_plane, splat_planes
from .casting import cast_between
from .illumination import illumination_volumes
from .intersection import plane_index_map, plane_rects
from .maps import level_map
from .per_ray import per_ray_caustics
from .planes import CENTRED, frame_of, plane_lattice, receiver_origin, reference_box, refracted_axis
from .smart_slicing import respaced_planes, smart_planes
from .volumetric import volumetric_caustics
from .water import water_mesh

__all__ = ["render_levelmap", "default_scene", "receivers_of", "prepare", "DEFAULT_SCENE_PATH", "METHOD",
           "water_pass", "planes_pass", "level_map_pass", "check_water_scene", "shared_stages", "shade_stage",
           "water_arrays", "IMAGE_BUFFERS"]

DEFAULT_SCENE_PATH = os.path.join(os.path.dirname(os.path.dirname(__file__)), "data", "levelmap_default.json")


def default_scene(overrides=None):
    """The default level-map scene: the teapot on a pool floor under a wavy surface in sunlight."""
    return load_scene(DEFAULT_SCENE_PATH, overrides)


def receivers_of(scene):
    """All receiver triangles of a scene (:class:`~refraction_ref.caustics.receivers.Receivers`)."""
    return receiver_soup(scene, "levelmap")


class _Pair:
    """Box, raster set-up and level map of one (receiver, light) pair."""

    def __init__(self, box, sel, setup, lm):
        self.box, self.sel, self.setup, self.lm = box, sel, setup, lm


def check_water_scene(scene):
    """Refuse a water scene the level map (and the exact water reference) cannot render.

    Parameters
    ----------
    scene : Scene
        The scene; raises :class:`~refraction_ref.validation.SceneError` when it has no
        ``water`` block or no lights.
    """
    w = scene.data["water"]
    if w is None:
        raise SceneError("levelmap: the scene has no 'water' block; add one, e.g. "
                         "\"water\": {\"size\": [4, 4], \"height\": 0, \"waves\": []}")
    if not scene.data["lights"]:
        raise SceneError("levelmap: the scene has no lights; add a directional or point light above the water")


def prepare(scene, timings=None):
    """Water beams per light, and box, set-up and level map per (receiver, light).

    The ``water``, ``planes`` and ``level_map`` stages in one call (tests,
    benchmarks).

    Returns
    -------
    dict
        ``mesh``, ``vols`` (per light), ``receivers``, ``pairs[r][l]``,
        ``eta``, ``K``, ``placement`` (``caustics.placement``).
    """
    check_water_scene(scene)
    timings = {} if timings is None else timings
    tic = time.perf_counter()
    w = water_pass(scene)
    timings["water"] = timings.get("water", 0.0) + (time.perf_counter() - tic) * 1e3
    tic = time.perf_counter()
    pl = planes_pass(scene)
    timings["planes"] = timings.get("planes", 0.0) + (time.perf_counter() - tic) * 1e3
    tic = time.perf_counter()
    pairs = level_map_pass(pl["receivers"], pl["boxes"], bool(scene.data["caustics"]["shadows"]))
    timings["level_map"] = timings.get("level_map", 0.0) + (time.perf_counter() - tic) * 1e3
    return {"mesh": w["mesh"], "vols": w["vols"], "receivers": pl["receivers"], "pairs": pairs,
            "eta": w["eta"], "K": w["K"], "placement": scene.data["caustics"]["placement"]}


def water_pass(scene):
    """The water mesh and each light's illumination volumes (eqs. 2-8, 4-14)."""
    water = scene.data["water"]
    eta = float(scene.data["outside_ior"]) / float(water["ior"])
    mesh = water_mesh(water)
    vols = [illumination_volumes(lt, mesh, eta) for lt in scene.data["lights"]]
    return {"mesh": mesh, "vols": vols, "eta": eta, "K": float(water["absorption"]),
            "water_vertices": mesh.vertices, "water_normals": mesh.normals}


def planes_pass(scene):
    """Receivers and one reference box per (receiver, light) (eqs. 4-1 to 4-9).

    With ``caustics.placement = "component"`` or ``"thesis"`` each box is
    centred on the receiver's origin (eqs. 4-2, 4-3), and a point light's axis aims at that
    origin (Fig. 4-7); with ``"tight"`` on the tight box's centre.
    """
    water = scene.data["water"]
    p = scene.data["caustics"]
    placement = p["placement"]
    eta = float(scene.data["outside_ior"]) / float(water["ior"])
    rec = receivers_of(scene)
    boxes = []
    for r, v in enumerate(rec.vertices):
        if placement in CENTRED:
            centre = receiver_origin(scene.data["receivers"][r])
        else:
            centre = (v.min(axis=0) + v.max(axis=0)) / 2.0
        boxes.append([reference_box(v, refracted_axis(lt, water, eta, centre), int(p["map_size"]), placement, centre)
                      for lt in scene.data["lights"]])
    return {"receivers": rec, "boxes": boxes, "water_block": water, "eta": eta}


def level_map_pass(rec, boxes, shadows):
    """Position and diffuse maps per (receiver, light) (eqs. 4-10 to 4-13): ``pairs[r][l]``."""
    pairs = []
    for r in range(len(rec.vertices)):
        row = []
        for box in boxes[r]:
            lm, sel, setup = level_map(rec, r, box, shadows)
            row.append(_Pair(box, sel, setup, lm))
        pairs.append(row)
    return pairs


def _caustics_pair(ctx, r, l, p, variant, timings, stats, extra=None, per_plane=None):
    """The caustics map of one (receiver, light); ``extra`` gets the planes' offsets ``zeta`` and the
    indices ``used`` (level map), and with ``per_plane`` (a list) each used plane's own map is appended
    as ``(index, zeta, map)`` instead of being summed (the ``plane_maps`` inspection stage).

    ``levelmap.culling = "none"`` (the thesis's cost, Figs. 4-15, 5-7): every beam's intersection
    triangle is drawn over the whole map on every plane drawn, each fragment depth-tested;
    ``"bounds"`` (§6.1's bounding-volume test): beams that cannot reach the box are culled and each
    plane is scissored to the texels it accepts. The maps are identical; only the work differs.
    """
    pair = ctx["pairs"][r][l]
    box, lm = pair.box, pair.lm
    n = int(p["planes"])
    K = ctx["K"]
    placement, culling = ctx["placement"], p["culling"]
    Hc, Wc = box.size
    out = np.zeros(box.size)
    tic = time.perf_counter()
    beams = beams_in_map(ctx["vols"][l], box)
    if culling == "bounds":
        cand = cull_beams(beams, box, -box.h / 2.0, box.h / 2.0)
    else:
        cand = np.flatnonzero(beams.flux > 0).astype(np.int64)
    st = {"receiver": r, "light": l, "candidate_beams": int(len(cand)), "box": [box.w, box.h, box.d]}
    if variant == "levelmap":
        lat = plane_lattice(box, n, placement)
        st["eps"] = lat.s / 2.0
        t_s = time.perf_counter()
        if p["smart_slicing"] and p["smart_spacing"] == "respace":
            zeta, pidx, sinfo = respaced_planes(lm, box, n, int(p["depth_levels"]), placement)
            keep = np.arange(len(zeta))
            st["smart"] = {"sub_boxes": sinfo["sub_boxes"], "empty_levels": sinfo["empty_levels"]}
        else:
            zeta = lat.zeta
            pidx = plane_index_map(lm, box, n, placement)
            if p["smart_slicing"]:
                keep, sinfo = smart_planes(lm, box, n, int(p["depth_levels"]), pidx, placement)
                st["smart"] = {"sub_boxes": sinfo["sub_boxes"], "empty_levels": sinfo["empty_levels"]}
            else:
                keep = np.arange(n)
        timings["smart_slicing"] = timings.get("smart_slicing", 0.0) + (time.perf_counter() - t_s) * 1e3
        if culling == "bounds":
            rects = plane_rects(pidx, len(zeta))
        else:
            rects = np.tile(np.array([0, Hc - 1, 0, Wc - 1], np.int64), (len(zeta), 1))
        drawn = 0
        if per_plane is None:  # all kept planes, a group of planes per kernel launch (Fig. 4-15, step 2)
            drawn = splat_planes(beams, cand, box, np.asarray(zeta)[keep], K, rects[keep], pidx, keep, lm.depth,
                                 lm.normal, out)
        for i in (keep if per_plane is not None else ()):
            target = np.zeros(box.size)
            drawn += splat_plane(beams, cand, box, zeta[i], K, rects[i], pidx, int(i), lm.depth, lm.normal, target)
            per_plane.append((int(i), float(zeta[i]), target))
        if extra is not None:
            extra["zeta"] = np.asarray(zeta, dtype=np.float64)
            extra["used"] = np.asarray(keep, dtype=np.int64)
        st["planes_used"] = int(len(keep))
        st["triangles_drawn"] = drawn
    elif variant == "volumetric":
        st.update(volumetric_caustics(beams, cand, box, ctx["receivers"], r, pair.sel, pair.setup, n, K, out,
                                      placement, culling != "bounds"))
        st["planes_used"] = n
    else:
        if culling != "bounds":  # the per-ray search needs beams that reach the box
            cand = cull_beams(beams, box, -box.h / 2.0, box.h / 2.0)
        st.update(per_ray_caustics(beams, cand, lm, box, K, out))
        st["planes_used"] = 0
    timings["caustics"] = timings.get("caustics", 0.0) + (time.perf_counter() - tic) * 1e3
    stats.append(st)
    return out


def _tiny(scene):
    """Warm-up overrides (:attr:`~refraction_ref.graph.Method.tiny`): a coarse water mesh, small maps, few pixels."""
    over = {"camera.width": 8, "camera.height": 8, "caustics.map_size": 8, "exact.water_samples": 16}
    if scene.data.get("water") is not None:  # else the render refuses the scene, naming what is missing
        over["water.resolution"] = 4
    return over


# --------------------------------------------------------------------- stages
def _st_water(ctx):
    from .knobs import STEEP_SLOPE, max_slope

    check_water_scene(ctx.scene)
    w = water_pass(ctx.scene)
    n = int(ctx.scene.data["water"]["resolution"])
    ctx.note(f"{n}x{n} quads, {len(w['mesh'].faces)} beams per light, {len(ctx.scene.data['lights'])} light(s)")
    slope = max_slope(ctx.scene.data["water"])
    if slope > STEEP_SLOPE:
        ctx.note(f"warning: steep waves (slope up to {slope:.2f} > {STEEP_SLOPE}): beams of neighbouring quads "
                 "cross before the receivers and the flat-water refracted axis no longer bounds them; the level "
                 "map's planes and boxes assume gentle waves (§4.2.1)")
    return w


def _st_planes(ctx):
    from .knobs import check_water_depth

    pl = planes_pass(ctx.scene)
    check_water_depth(ctx.scene.data["water"], pl["receivers"].vertices)
    ctx.stats["triangles"] = int(len(pl["receivers"].tris))
    out = dict(pl)
    for r, row in enumerate(pl["boxes"]):
        for l, box in enumerate(row):
            out[f"box_{r}_{l}"] = np.array([box.center, box.U, box.V, box.W, [box.w, box.h, box.d]])
    ctx.note(f"one reference box per (receiver, light), {ctx.scene.data['caustics']['map_size']}^2 maps")
    return out


def _st_level_map(ctx):
    shadows = bool(ctx.scene.data["caustics"]["shadows"])
    pl = ctx.buf["planes"]
    pairs = level_map_pass(pl["receivers"], pl["boxes"], shadows)
    out = {"pairs": pairs}
    for r, row in enumerate(pairs):
        for l, pr in enumerate(row):
            out[f"position_{r}_{l}"] = pr.lm.depth
            out[f"diffuse_{r}_{l}"] = pr.lm.diffuse
            out[f"normal_{r}_{l}"] = pr.lm.normal
    ctx.note(f"orthographic maps, {'receivers shadow each other' if shadows else 'each receiver alone'}")
    return out


def _st_caustics(ctx):
    d = ctx.scene.data
    p = d["levelmap"]
    variant = p["variant"]
    ctx_ = {"vols": ctx.buf["water"]["vols"], "K": ctx.buf["water"]["K"], "pairs": ctx.buf["level_map"]["pairs"],
            "receivers": ctx.buf["planes"]["receivers"], "placement": d["caustics"]["placement"]}
    stats, sub = [], {}
    maps, extras = [], {}
    for r in range(len(ctx_["pairs"])):
        row = []
        for l in range(len(ctx_["vols"])):
            ex = extras[(r, l)] = {}
            row.append(_caustics_pair(ctx_, r, l, p, variant, sub, stats, extra=ex))
        maps.append(row)
    if "smart_slicing" in sub:
        ctx.timings["smart_slicing"] = sub["smart_slicing"]
    ctx.stats["levelmap_stats"] = stats
    ctx.stats["planes_used_per_receiver"] = [[s["planes_used"] for s in stats if s["receiver"] == r]
                                             for r in range(len(maps))]
    smart = bool(p["smart_slicing"]) and variant == "levelmap"
    ctx.note({"levelmap": "intersection triangles on every plane, depth-tested against the position map"
              + (f"; smart slicing over {p['depth_levels']} depth levels ({p['smart_spacing']})" if smart
                 else "; smart slicing off")
              + f"; {ctx_['placement']} plane placement, culling {p['culling']}",
              "volumetric": "one slice image per sample plane (Iwasaki et al.), composited front to back",
              "per_ray": "each beam drawn once where its rays hit (§6.3); planes replaced by a per-ray search"}[variant])
    out = {"maps": maps}
    for r, row in enumerate(maps):
        for l, m in enumerate(row):
            out[f"caustic_map_{r}_{l}"] = m
            out[f"planes_{r}_{l}"] = extras[(r, l)].get("zeta")
            out[f"planes_used_{r}_{l}"] = extras[(r, l)].get("used")
    return out


def _st_plane_maps(ctx):
    """Each used plane's own contribution to the caustics map (eq. 4-18), for inspection."""
    d = ctx.scene.data
    p = d["levelmap"]
    ctx_ = {"vols": ctx.buf["water"]["vols"], "K": ctx.buf["water"]["K"], "pairs": ctx.buf["level_map"]["pairs"],
            "receivers": ctx.buf["planes"]["receivers"], "placement": d["caustics"]["placement"]}
    R, L = len(ctx_["pairs"]), len(ctx_["vols"])
    out = {f"{k}_{r}_{l}": None for r in range(R) for l in range(L) for k in ("plane_maps", "plane_index")}
    for r in range(R):
        for l in range(L):
            planes = []
            _caustics_pair(ctx_, r, l, p, p["variant"], {}, [], per_plane=planes)
            if planes:
                out[f"plane_maps_{r}_{l}"] = np.stack([m for _, _, m in planes]).astype(np.float32)
                out[f"plane_index_{r}_{l}"] = np.array([i for i, _, _ in planes], np.int64)
    ctx.note("one map per used plane (their sum is the pair's caustics map up to rounding)"
             if p["variant"] == "levelmap" else f"the {p['variant']} variant has no per-plane maps")
    return out


def _st_casting(ctx):
    pairs = ctx.buf["level_map"]["pairs"]
    maps = ctx.buf["caustics"]["maps"]
    L = len(ctx.scene.data["lights"])
    out = {}
    for r, row in enumerate(maps):
        total = row[0].copy()
        for l in range(1, L):
            cast_between(row[l], pairs[r][l].box, pairs[r][l].lm, pairs[r][0].box, pairs[r][0].lm, total)
        total = np.nan_to_num(total, nan=0.0, posinf=0.0, neginf=0.0)
        out[f"caustic_map_{r}"] = total.astype(np.float32)
        out[f"caustic_frame_{r}"] = frame_of(pairs[r][0].box)
    ctx.note(f"{L - 1} more light(s) cast into the first light's frame (eq. 4-20)" if L > 1 else
             "one light: its map is the caustics map")
    return out


def shade_stage(ctx, casting):
    """The camera's view of the pool (eq. 4-19): through the water (``image``) and directly (``image_direct``).

    ``image`` is the view through the wavy surface (:mod:`.view`): the level
    map refracts the eye rays at its water mesh (``casting == "casting"``, the
    ``water`` stage's mesh), the exact reference (``casting == "trace"``) at
    the analytic surface. ``image_direct`` is the receivers seen without the
    water (the level map's ``image`` before contract_version 4).
    """
    from .view import direct_view, view_through_water

    p = ctx.scene.data["caustics"]
    pairs = ctx.buf["level_map"]["pairs"]
    pl = ctx.buf["planes"]
    R = len(pairs)
    cam = Camera.from_dict(ctx.scene.data["camera"])
    maps = [ctx.buf[casting][f"caustic_map_{r}"] for r in range(R)]
    boxes = [pairs[r][0].box for r in range(R)]
    stacked = np.ascontiguousarray(np.stack(maps), np.float32)
    rays = cam.primary_rays()
    direct, mask_direct = direct_view(cam, pl["receivers"], boxes, stacked, float(p["ambient"]), rays=rays)
    water = pl["water_block"]
    mesh = ctx.buf["water"]["mesh"] if casting == "casting" else None
    v = view_through_water(cam, water, pl["eta"], float(water["absorption"]), pl["receivers"], boxes, stacked,
                           float(p["ambient"]), mesh=mesh, rays=rays)
    st = v["view_status"]
    ctx.note(f"eq. 4-19 with ambient {p['ambient']}; seen through the water's "
             f"{'mesh' if mesh is not None else 'analytic surface'}: {int((st == 1).sum())} pixels through the "
             f"water, {int((st == 3).sum())} direct, {int((st == 2).sum())} lost, {int((st == 4).sum())} TIR")
    out = dict(v)
    out["image_direct"] = direct
    out["object_mask_direct"] = mask_direct
    return out


def shared_stages(scene):
    """``water``, ``planes`` and ``level_map``: the light side the level map and the exact water share."""
    R, L = len(scene.data["receivers"]), len(scene.data["lights"])
    rl = [(r, l) for r in range(R) for l in range(L)]
    return (
        Stage("water", _st_water, reads=("water", "lights", "outside_ior"),
              makes=("water_vertices", "water_normals"), doc="water mesh and illumination volumes (eqs. 2-8, 4-14)"),
        Stage("planes", _st_planes, reads=("receivers", "lights", "water", "outside_ior", "caustics.map_size",
                                           "caustics.placement"),
              makes=tuple(f"box_{r}_{l}" for r, l in rl), doc="reference boxes (eqs. 4-1 to 4-9)"),
        Stage("level_map", _st_level_map, reads=("caustics.shadows",), after=("planes",),
              makes=tuple(f"{k}_{r}_{l}" for r, l in rl for k in ("position", "diffuse", "normal")),
              doc="position and diffuse maps (eqs. 4-10 to 4-13)"),
    )


#: buffers of the ``image`` stage (the exact water reference's ``image`` stage makes the same)
IMAGE_BUFFERS = ("image", "object_mask", "image_direct", "object_mask_direct", "view_status", "water_pos",
                 "water_dir", "receiver_pos", "water_length")

_CAUSTICS_READS = ("levelmap.planes", "levelmap.smart_slicing", "levelmap.depth_levels", "levelmap.variant",
                   "caustics.placement", "levelmap.smart_spacing", "levelmap.culling")


def _stages(scene):
    R, L = len(scene.data["receivers"]), len(scene.data["lights"])
    return shared_stages(scene) + (
        Stage("caustics", _st_caustics,
              reads=_CAUSTICS_READS,
              after=("water", "planes", "level_map"),
              makes=tuple(f"{k}_{r}_{l}" for r in range(R) for l in range(L)
                          for k in ("caustic_map", "planes", "planes_used")),
              doc="smart slicing, intersection test and caustics map per (receiver, light) (§4.4-4.7)"),
        Stage("plane_maps", _st_plane_maps,
              reads=_CAUSTICS_READS,
              after=("water", "planes", "level_map"), diagnostic=True,
              makes=tuple(f"{k}_{r}_{l}" for r in range(R) for l in range(L) for k in ("plane_maps", "plane_index")),
              doc="each used plane's own caustics map (eq. 4-18); only when kept"),
        Stage("casting", _st_casting, reads=("lights",), after=("level_map", "caustics"),
              makes=tuple(f"{k}_{r}" for r in range(R) for k in ("caustic_map", "caustic_frame")),
              doc="lights cast into one map (eq. 4-20)"),
        Stage("image", lambda ctx: shade_stage(ctx, "casting"), reads=("camera", "caustics.ambient"),
              after=("water", "planes", "level_map", "casting"), makes=IMAGE_BUFFERS,
              doc="camera view through the water and directly, shaded with caustics (eq. 4-19)"),
    )


def water_arrays(bufs, maps_stage):
    """The water outputs (``docs/oracle.md``): each receiver's map and frame from ``maps_stage``, the image."""
    arrays = {}
    for r in range(len(bufs["level_map"]["pairs"])):
        for k in ("caustic_map", "caustic_frame"):
            arrays[f"{k}_{r}"] = bufs[maps_stage][f"{k}_{r}"]
    for k in ("image", "object_mask", "image_direct", "object_mask_direct"):
        if k in bufs["image"]:
            arrays[k] = bufs["image"][k]
    return arrays


def _assemble(scene, bufs, stats):
    p = scene.data["levelmap"]
    arrays = water_arrays(bufs, "casting")
    used = stats["planes_used_per_receiver"]
    info = {"planes_requested": int(p["planes"]), "planes_used": int(max(max(u) for u in used)),
            "planes_used_per_receiver": used, "variant": p["variant"],
            "stats": json.loads(json.dumps(stats["levelmap_stats"], default=float)),
            "triangles": stats["triangles"]}
    return arrays, info


METHOD = register_method(Method(
    "levelmap", blocks=("levelmap", "water"), stages=_stages, assemble=_assemble,
    warm=warmer("levelmap"), tiny=_tiny, default_scene=DEFAULT_SCENE_PATH, label="Tipprasert 2006",
    results=("level_map.pairs", "casting", "image"),
    doc="Tipprasert (2006): water caustics by reference planes, position maps and a caustics map"))


def render_levelmap(scene, *, cache=None, keep=None, warm=True, progress=False):
    """Render water caustics with the level-map method (or its baseline / per-ray variant).

    Parameters
    ----------
    scene : Scene
        With a ``water`` block, receivers and lights above the water.
    cache : dict, optional
        Stage cache (:class:`~refraction_ref.session.Session` keeps one).
    keep : str or list, optional
        Stages whose buffers to return as ``stage.<stage>.<buffer>``.
    warm : bool
        Load every kernel first so that ``timings_ms`` exclude JIT time.
    progress : bool
        Show a progress bar on long work.

    Returns
    -------
    arrays : dict
        ``caustic_map_r`` (Hc, Wc) float32 irradiance and ``caustic_frame_r``
        (4, 3) per receiver r (``docs/oracle.md``), ``image`` (H, W, 3)
        float32 and ``object_mask`` (H, W) bool (the pixels showing a receiver).
    info : dict
        ``timings_ms``, ``plan``, ``planes_requested``, ``planes_used`` (the
        most any receiver used), ``planes_used_per_receiver`` (per light),
        ``stats`` per (receiver, light).

    References
    ----------
    Tipprasert (2006), chapter 4; Figs. 4-15 and 4-17.
    """
    check_water_scene(scene)
    return run_graph(METHOD, scene, cache=cache, keep=keep, progress=progress, warm=warm)
