"""The level-map water-caustics pipeline (Tipprasert 2006, ch. 4), pass by pass.

=====================  ===============================================  ===========
stage (``timings_ms``)  pass                                             section
=====================  ===============================================  ===========
``water``               water mesh, refraction at vertices (eq. 2-8),    §2.6, §4.3
                        illumination volumes (eq. 4-14)
``planes``              reference boxes and slicing (eqs. 4-1 to 4-9)    §4.2.1
``level_map``           position and diffuse maps (eqs. 4-10 to 4-13)    §4.2.2
``caustics``            per (receiver, light): smart slicing             §4.7.2,
                        (``levelmap.smart_slicing``, eqs. 4-21, 4-22),   §4.4, §4.5
                        intersection test (eq. 4-15) and caustics map
                        (eq. 4-18); or the slice-image baseline          §5.2.1
                        (:mod:`.slice_image_baseline`); or the per-ray   §6.3
                        variant (:mod:`.per_ray`)
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
from typing import NamedTuple

import numpy as np

from ..camera import Camera
from ..caustics.receivers import receiver_soup
from ..graph import Method, Stage, method_renderer, register_method, run_stages
from ..scene import load_scene
from ..validation import SceneError
from ..warm import warmer
from .casting import cast_between
from .caustics_map import PlaneSet, ReceiverTexels, beams_in_map, cull_beams, splat_plane, splat_planes
from .illumination import illumination_volumes
from .intersection import plane_index_map, plane_rects
from .knobs import levelmap_knobs
from .maps import LevelMapPair, level_map
from .per_ray import per_ray_caustics
from .planes import CENTRED, frame_of, plane_lattice, receiver_origin, reference_box, refracted_axis
from .slice_image_baseline import slice_image_caustics
from .smart_slicing import respaced_planes, smart_planes
from .water import water_mesh

__all__ = ["render_levelmap", "default_scene", "receivers_of", "prepare", "DEFAULT_SCENE_PATH", "METHOD",
           "water_pass", "planes_pass", "level_map_pass", "check_water_scene", "shared_stages", "shade_stage",
           "water_arrays", "IMAGE_BUFFERS", "PairCaustics", "pair_caustics"]

DEFAULT_SCENE_PATH = os.path.join(os.path.dirname(os.path.dirname(__file__)), "data", "levelmap_default.json")


def default_scene(overrides=None):
    """The default level-map scene: the teapot on a pool floor under a wavy surface in sunlight.

    Parameters
    ----------
    overrides : dict, optional
        Dotted keys over the scene file (``{"levelmap.planes": 12}``).

    Returns
    -------
    Scene
    """
    return load_scene(DEFAULT_SCENE_PATH, overrides)


def receivers_of(scene):
    """All receiver triangles of a scene (:class:`~refraction_ref.caustics.receivers.Receivers`).

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    Receivers
    """
    return receiver_soup(scene, "levelmap")


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


def prepare(scene, timings=None, plan=None):
    """Water beams per light, and box, raster set-up and level map per (receiver, light).

    The ``water``, ``planes`` and ``level_map`` stages (:func:`shared_stages`),
    run by :func:`~refraction_ref.graph.run_stages` with the render's timings
    and plan rows (tests, benchmarks, tables).

    Parameters
    ----------
    scene : Scene
        With a ``water`` block and lights.
    timings : dict, optional
        Gets each stage's time (ms), as ``timings_ms``.
    plan : list, optional
        Gets each stage's plan row.

    Returns
    -------
    dict
        ``mesh``, ``vols`` (per light), ``receivers``, ``pairs[r][l]``
        (:class:`~.maps.LevelMapPair`), ``eta``, ``K``, ``placement``
        (``caustics.placement``).

    References
    ----------
    Tipprasert (2006), §4.2 and §4.3: :func:`water_pass`, :func:`planes_pass`,
    :func:`level_map_pass`.
    """
    check_water_scene(scene)
    bufs = run_stages(shared_stages(scene), {}, scene, timings, plan)
    water, planes = bufs["water"], bufs["planes"]
    return {"mesh": water["mesh"], "vols": water["vols"], "receivers": planes["receivers"],
            "pairs": bufs["level_map"]["pairs"], "eta": water["eta"], "K": water["K"],
            "placement": scene.data["caustics"]["placement"]}


def water_pass(scene):
    """The water mesh and each light's illumination volumes.

    Parameters
    ----------
    scene : Scene
        Its ``water`` block, ``outside_ior`` and ``lights``.

    Returns
    -------
    dict
        ``mesh``, ``vols`` (per light), ``eta`` (``outside_ior / water.ior``),
        ``K`` (``water.absorption``), ``water_vertices``, ``water_normals``.

    References
    ----------
    Tipprasert (2006), §4.3, eqs. 2-8, 4-14.
    """
    water = scene.data["water"]
    eta = float(scene.data["outside_ior"]) / float(water["ior"])
    mesh = water_mesh(water)
    vols = [illumination_volumes(light, mesh, eta) for light in scene.data["lights"]]
    return {"mesh": mesh, "vols": vols, "eta": eta, "K": float(water["absorption"]),
            "water_vertices": mesh.vertices, "water_normals": mesh.normals}


def planes_pass(scene):
    """Receivers and one reference box per (receiver, light).

    With ``caustics.placement = "component"`` or ``"thesis"`` each box is
    centred on the receiver's origin (eqs. 4-2, 4-3), and a point light's axis
    aims at that origin (Fig. 4-7); with ``"tight"`` on the tight box's centre.

    Parameters
    ----------
    scene : Scene
        Its ``receivers``, ``lights``, ``water`` block, ``outside_ior`` and
        ``caustics`` knobs (``placement``, ``map_size``).

    Returns
    -------
    dict
        ``receivers``, ``boxes[r][l]``, ``water_block``, ``eta``.

    References
    ----------
    Tipprasert (2006), §4.2.1, eqs. 4-1 to 4-9, Figs. 4-5, 4-7.
    """
    water = scene.data["water"]
    caustics = scene.data["caustics"]
    placement = caustics["placement"]
    eta = float(scene.data["outside_ior"]) / float(water["ior"])
    receivers = receivers_of(scene)
    boxes = []
    for r, vertices in enumerate(receivers.vertices):
        if placement in CENTRED:
            centre = receiver_origin(scene.data["receivers"][r])
        else:
            centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2.0
        boxes.append([reference_box(vertices, refracted_axis(light, water, eta, centre), int(caustics["map_size"]),
                                    placement, centre)
                      for light in scene.data["lights"]])
    return {"receivers": receivers, "boxes": boxes, "water_block": water, "eta": eta}


def level_map_pass(receivers, boxes, shadows):
    """Position and diffuse maps per (receiver, light).

    Parameters
    ----------
    receivers : Receivers
    boxes : list of list of Box
        ``boxes[r][l]`` (:func:`planes_pass`).
    shadows : bool
        ``caustics.shadows``: draw every receiver into each map.

    Returns
    -------
    list of list of LevelMapPair
        ``pairs[r][l]``.

    References
    ----------
    Tipprasert (2006), §4.2.2, eqs. 4-10 to 4-13.
    """
    pairs = []
    for r in range(len(receivers.vertices)):
        row = []
        for box in boxes[r]:
            lm, sel, setup = level_map(receivers, r, box, shadows)
            row.append(LevelMapPair(box, sel, setup, lm, r))
        pairs.append(row)
    return pairs


class PairCaustics(NamedTuple):
    """One (receiver, light) pair's caustics map and what its passes report.

    Attributes
    ----------
    map : (Hc, Wc) float64
        The caustics map in the pair's box.
    stats : dict
        The pair's ``stats`` row (``docs/oracle.md``).
    zeta, used : ndarray or None
        The level map's plane depths and the indices of the planes drawn
        (None for the other variants).
    smart_ms : float or None
        Time of the plane set-up (smart slicing), ms; None for the other variants.
    """

    map: np.ndarray
    stats: dict
    zeta: np.ndarray | None
    used: np.ndarray | None
    smart_ms: float | None


def _candidate_beams(beams, box, cull):
    """Beams that may light the box: §6.1's bounding-volume test, or every beam with flux."""
    if cull:
        return cull_beams(beams, box, -box.h / 2.0, box.h / 2.0)
    return np.flatnonzero(beams.flux > 0).astype(np.int64)


def _reference_planes(pair, lattice, knobs):
    """The planes drawn: depths, the plane index map (eq. 4-15), the indices kept and smart slicing's info."""
    lm, box, n = pair.lm, pair.box, knobs.planes
    if knobs.smart_slicing and knobs.respace:
        zeta, pidx, info = respaced_planes(lm, box, n, knobs.depth_levels, knobs.placement)
        return zeta, pidx, np.arange(len(zeta)), info
    pidx = plane_index_map(lm, box, n, knobs.placement)
    if knobs.smart_slicing:
        keep, info = smart_planes(lm, box, n, knobs.depth_levels, knobs.placement, pidx)
        return lattice.zeta, pidx, keep, info
    return lattice.zeta, pidx, np.arange(n), None


def _level_map_caustics(beams, cand, pair, knobs, stats, out, per_plane):
    """The level map's planes (smart slicing, §4.7.2) drawn into ``out`` (or one map per plane into ``per_plane``)."""
    box, lm = pair.box, pair.lm
    Hc, Wc = box.size
    lattice = plane_lattice(box, knobs.planes, knobs.placement)
    stats["eps"] = lattice.s / 2.0
    tic = time.perf_counter()
    zeta, pidx, keep, smart = _reference_planes(pair, lattice, knobs)
    if smart is not None:
        stats["smart"] = {"sub_boxes": smart["sub_boxes"], "empty_levels": smart["empty_levels"]}
    smart_ms = (time.perf_counter() - tic) * 1e3
    if knobs.cull:
        rects = plane_rects(pidx, len(zeta))
    else:
        rects = np.tile(np.array([0, Hc - 1, 0, Wc - 1], np.int64), (len(zeta), 1))
    texels = ReceiverTexels(pidx, lm.depth, lm.normal)
    drawn = 0
    if per_plane is None:  # all kept planes, a group of planes per kernel launch (Fig. 4-15, step 2)
        drawn = splat_planes(beams, cand, box, PlaneSet(np.asarray(zeta)[keep], keep, rects[keep]), texels, knobs.K,
                             out)
    for i in (keep if per_plane is not None else ()):
        target = np.zeros(box.size)
        drawn += splat_plane(beams, cand, box, PlaneSet(zeta[i], int(i), rects[i]), texels, knobs.K, target)
        per_plane.append((int(i), float(zeta[i]), target))
    stats["planes_used"] = int(len(keep))
    stats["triangles_drawn"] = drawn
    return np.asarray(zeta, dtype=np.float64), np.asarray(keep, dtype=np.int64), smart_ms


def pair_caustics(prep, r, l, knobs, per_plane=None):
    """The caustics map of one (receiver, light) pair, by the scene's variant.

    ``levelmap.culling = "none"`` (the thesis's cost, Figs. 4-15, 5-7): every
    beam's intersection triangle is drawn over the whole map on every plane
    drawn, each fragment depth-tested; ``"bounds"`` (§6.1's bounding-volume
    test): beams that cannot reach the box are culled and each plane is
    scissored to the texels it accepts. The maps are identical; only the
    work differs.

    Parameters
    ----------
    prep : dict
        ``vols`` (per light), ``pairs[r][l]`` and ``receivers``
        (:func:`prepare`'s result, or the stages' buffers).
    r, l : int
        The receiver and the light.
    knobs : LevelMapKnobs
        :func:`~refraction_ref.levelmap.knobs.levelmap_knobs`.
    per_plane : list, optional
        With the level map, each used plane's own map is appended as
        ``(index, zeta, map)`` instead of being summed (the ``plane_maps``
        inspection stage).

    Returns
    -------
    PairCaustics

    References
    ----------
    Tipprasert (2006), §4.4 to §4.7.2 (eqs. 4-15 to 4-18, 4-21, 4-22), §5.2.1
    (the slice-image baseline), §6.1, §6.3 (the per-ray variant).
    """
    pair = prep["pairs"][r][l]
    box = pair.box
    out = np.zeros(box.size)
    beams = beams_in_map(prep["vols"][l], box)
    cand = _candidate_beams(beams, box, knobs.cull)
    stats = {"receiver": r, "light": l, "candidate_beams": int(len(cand)), "box": [box.w, box.h, box.d]}
    zeta = used = smart_ms = None
    if knobs.variant == "levelmap":
        zeta, used, smart_ms = _level_map_caustics(beams, cand, pair, knobs, stats, out, per_plane)
    elif knobs.variant == "volumetric":  # the thesis's slice-image baseline (the scene value's name)
        stats.update(slice_image_caustics(beams, cand, pair, prep["receivers"], knobs, out))
        stats["planes_used"] = knobs.planes
    else:
        if not knobs.cull:  # the per-ray search needs beams that reach the box
            cand = _candidate_beams(beams, box, True)
        stats.update(per_ray_caustics(beams, cand, pair.lm, box, knobs.K, out))
        stats["planes_used"] = 0
    return PairCaustics(out, stats, zeta, used, smart_ms)


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
    water = water_pass(ctx.scene)
    n = int(ctx.scene.data["water"]["resolution"])
    ctx.note(f"{n}x{n} quads, {len(water['mesh'].faces)} beams per light, {len(ctx.scene.data['lights'])} light(s)")
    slope = max_slope(ctx.scene.data["water"])
    if slope > STEEP_SLOPE:
        ctx.note(f"warning: steep waves (slope up to {slope:.2f} > {STEEP_SLOPE}): beams of neighbouring quads "
                 "cross before the receivers and the flat-water refracted axis no longer bounds them; the level "
                 "map's planes and boxes assume gentle waves (§4.2.1)")
    return water


def _st_planes(ctx):
    from .knobs import check_water_depth

    planes = planes_pass(ctx.scene)
    check_water_depth(ctx.scene.data["water"], planes["receivers"].vertices)
    ctx.stats["triangles"] = int(len(planes["receivers"].tris))
    out = dict(planes)
    for r, row in enumerate(planes["boxes"]):
        for l, box in enumerate(row):
            out[f"box_{r}_{l}"] = np.array([box.center, box.U, box.V, box.W, [box.w, box.h, box.d]])
    ctx.note(f"one reference box per (receiver, light), {ctx.scene.data['caustics']['map_size']}^2 maps")
    return out


def _st_level_map(ctx):
    shadows = bool(ctx.scene.data["caustics"]["shadows"])
    planes = ctx.buf["planes"]
    pairs = level_map_pass(planes["receivers"], planes["boxes"], shadows)
    out = {"pairs": pairs}
    for r, row in enumerate(pairs):
        for l, pair in enumerate(row):
            out[f"position_{r}_{l}"] = pair.lm.depth
            out[f"diffuse_{r}_{l}"] = pair.lm.diffuse
            out[f"normal_{r}_{l}"] = pair.lm.normal
    ctx.note(f"orthographic maps, {'receivers shadow each other' if shadows else 'each receiver alone'}")
    return out


def _pair_inputs(ctx):
    """What :func:`pair_caustics` reads of the upstream stages, and the scene's :class:`LevelMapKnobs`."""
    d = ctx.scene.data
    prep = {"vols": ctx.buf["water"]["vols"], "pairs": ctx.buf["level_map"]["pairs"],
            "receivers": ctx.buf["planes"]["receivers"]}
    return prep, levelmap_knobs(d["levelmap"], d["caustics"]["placement"], ctx.buf["water"]["K"])


def _st_caustics(ctx):
    prep, knobs = _pair_inputs(ctx)
    n_receivers, n_lights = len(prep["pairs"]), len(prep["vols"])
    done = [[pair_caustics(prep, r, l, knobs) for l in range(n_lights)] for r in range(n_receivers)]
    smart_ms = [pc.smart_ms for row in done for pc in row if pc.smart_ms is not None]
    if smart_ms:
        ctx.timings["smart_slicing"] = sum(smart_ms, 0.0)
    stats = [pc.stats for row in done for pc in row]
    ctx.stats["levelmap_stats"] = stats
    ctx.stats["planes_used_per_receiver"] = [[pc.stats["planes_used"] for pc in row] for row in done]
    block = ctx.scene.data["levelmap"]
    smart = knobs.smart_slicing and knobs.variant == "levelmap"
    ctx.note({"levelmap": "intersection triangles on every plane, depth-tested against the position map"
              + (f"; smart slicing over {block['depth_levels']} depth levels ({block['smart_spacing']})" if smart
                 else "; smart slicing off")
              + f"; {knobs.placement} plane placement, culling {block['culling']}",
              "volumetric": "one slice image per sample plane (Iwasaki et al.), composited front to back",
              "per_ray": "each beam drawn once where its rays hit (§6.3); planes replaced by a per-ray search"
              }[knobs.variant])
    out = {"maps": [[pc.map for pc in row] for row in done]}
    for r, row in enumerate(done):
        for l, pc in enumerate(row):
            out[f"caustic_map_{r}_{l}"] = pc.map
            out[f"planes_{r}_{l}"] = pc.zeta
            out[f"planes_used_{r}_{l}"] = pc.used
    return out


def _st_plane_maps(ctx):
    """Each used plane's own contribution to the caustics map (eq. 4-18), for inspection."""
    prep, knobs = _pair_inputs(ctx)
    n_receivers, n_lights = len(prep["pairs"]), len(prep["vols"])
    out = {f"{k}_{r}_{l}": None for r in range(n_receivers) for l in range(n_lights)
           for k in ("plane_maps", "plane_index")}
    for r in range(n_receivers):
        for l in range(n_lights):
            planes = []
            pair_caustics(prep, r, l, knobs, per_plane=planes)
            if planes:
                out[f"plane_maps_{r}_{l}"] = np.stack([m for _, _, m in planes]).astype(np.float32)
                out[f"plane_index_{r}_{l}"] = np.array([i for i, _, _ in planes], np.int64)
    ctx.note("one map per used plane (their sum is the pair's caustics map up to rounding)"
             if knobs.variant == "levelmap" else f"the {knobs.variant} variant has no per-plane maps")
    return out


def _st_casting(ctx):
    pairs = ctx.buf["level_map"]["pairs"]
    maps = ctx.buf["caustics"]["maps"]
    n_lights = len(ctx.scene.data["lights"])
    out = {}
    for r, row in enumerate(maps):
        total = row[0].copy()
        first = pairs[r][0]
        for l in range(1, n_lights):
            cast_between(row[l], pairs[r][l].box, pairs[r][l].lm, first.box, first.lm, total)
        total = np.nan_to_num(total, nan=0.0, posinf=0.0, neginf=0.0)
        out[f"caustic_map_{r}"] = total.astype(np.float32)
        out[f"caustic_frame_{r}"] = frame_of(first.box)
    ctx.note(f"{n_lights - 1} more light(s) cast into the first light's frame (eq. 4-20)" if n_lights > 1 else
             "one light: its map is the caustics map")
    return out


def shade_stage(ctx, casting):
    """The camera's view of the pool (eq. 4-19): through the water (``image``) and directly (``image_direct``).

    ``image`` is the view through the wavy surface (:mod:`.view`): the level
    map refracts the eye rays at its water mesh (``casting == "casting"``, the
    ``water`` stage's mesh), the exact reference (``casting == "trace"``) at
    the analytic surface. ``image_direct`` is the receivers seen without the
    water.

    Parameters
    ----------
    ctx : Context
        The ``image`` stage's context: ``camera`` and ``caustics.ambient``,
        the ``water``, ``planes``, ``level_map`` and ``casting`` stages' buffers.
    casting : str
        The stage whose ``caustic_map_r`` to show.

    Returns
    -------
    dict
        :data:`IMAGE_BUFFERS`.

    References
    ----------
    Tipprasert (2006), §4.6, eq. 4-19; §2.6, eq. 2-8; eq. 4-17.
    """
    from .view import CausticMaps, direct_view, view_through_water

    ambient = ctx.scene.data["caustics"]["ambient"]
    pairs = ctx.buf["level_map"]["pairs"]
    planes = ctx.buf["planes"]
    n_receivers = len(pairs)
    cam = Camera.from_dict(ctx.scene.data["camera"])
    maps = [ctx.buf[casting][f"caustic_map_{r}"] for r in range(n_receivers)]
    boxes = [pairs[r][0].box for r in range(n_receivers)]
    look = CausticMaps(boxes, np.ascontiguousarray(np.stack(maps), np.float32), float(ambient))
    rays = cam.primary_rays()
    direct, mask_direct = direct_view(cam, planes["receivers"], look, rays=rays)
    mesh = ctx.buf["water"]["mesh"] if casting == "casting" else None
    view = view_through_water(cam, planes["water_block"], planes["eta"], planes["receivers"], look, mesh=mesh,
                              rays=rays)
    status = view["view_status"]
    ctx.note(f"eq. 4-19 with ambient {ambient}; seen through the water's "
             f"{'mesh' if mesh is not None else 'analytic surface'}: {int((status == 1).sum())} pixels through the "
             f"water, {int((status == 3).sum())} direct, {int((status == 2).sum())} lost, "
             f"{int((status == 4).sum())} TIR")
    out = dict(view)
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
    block = scene.data["levelmap"]
    arrays = water_arrays(bufs, "casting")
    used = stats["planes_used_per_receiver"]
    info = {"planes_requested": int(block["planes"]), "planes_used": int(max(max(u) for u in used)),
            "planes_used_per_receiver": used, "variant": block["variant"],
            "stats": json.loads(json.dumps(stats["levelmap_stats"], default=float)),
            "triangles": stats["triangles"]}
    return arrays, info


METHOD = register_method(Method(
    "levelmap", blocks=("levelmap", "water"), stages=_stages, assemble=_assemble, check=check_water_scene,
    warm=warmer("levelmap"), tiny=_tiny, default_scene=DEFAULT_SCENE_PATH, label="Tipprasert 2006",
    results=("level_map.pairs", "casting", "image"),
    doc="Tipprasert (2006): water caustics by reference planes, position maps and a caustics map"))

render_levelmap = method_renderer(
    METHOD, "render_levelmap",
    "Render water caustics with the level-map method (Tipprasert 2006, ch. 4), its slice-image baseline or "
    "per-ray variant.")
