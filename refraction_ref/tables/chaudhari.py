"""Chaudhari (2008), chapter 4, measured with this package: Tables 4.1 and 4.2 and the error against the view.

Reusable by any caller (``benchmarks/thesis_tables.py`` and
``benchmarks/error_vs_view.py`` print and save what these functions return):

* :data:`THESIS_4_1`, :data:`THESIS_4_2`: the thesis's numbers (NVIDIA 8800 GTX).
* :data:`VIEWS` (14 listed views) and :func:`highest_complexity_view`: "we report the
  frame rates for the view comprising of the highest depth complexity possible for
  each scene" (§4.2) - the view with the largest per-pixel depth complexity
  (fragments per pixel, from the rasterizer's ``count`` blend) over the list.
* :func:`table_4_1`: frames per second at 32 / 16 layers and 256 / 512 texels a
  side, in the thesis mode (``imagespace.peel_all``: every one of the ``layers``
  is peeled, as the thesis's one pass writes all 32 channels of its 8 render
  targets, §3.4.2) and in ours (never more layers than the depth complexity).
* :func:`table_4_2`: time per stage, with the photon-generation row: the thesis
  "generates photons by rasterizing the geometry one more time" (§4.2); our
  trace starts each ray from layer 0 of the LDI instead, so that pass is timed
  apart (:func:`photon_generation_ms`: the objects' triangles set up and
  rasterized once more in the view) and reported beside the pipeline.
* :func:`error_vs_view`: the exit-direction error against the exact Embree
  reference over a ring of views (:data:`RING`), per IOR and per option
  (:data:`ERROR_OPTIONS`): median and p90 over the pixels where both exit, the
  fraction of hit pixels that exit, and the fraction within 5 degrees.
* :func:`defaults_before_after`: the seed defaults against the former ones on
  the default bunny (against the exact reference) and the sphere (against the
  closed form).

Timing is the caller's: every table takes ``time_fn(scene) -> dict`` with
``pipeline_ms`` (sum of the per-frame stages), ``total_ms``, ``stages_ms`` and
``result`` (the benchmarks pass ``benchmarks/common.time_render``, which also
guards against other load); :func:`time_pipeline` is a plain default.
"""

from __future__ import annotations

import copy
import math
import statistics
import time
from typing import NamedTuple

import numpy as np

__all__ = ["THESIS_4_1", "THESIS_4_1_ALL", "COLS_4_1", "THESIS_4_2", "SCENES_4_2", "THESIS_SCENE_TEXT",
           "STAGE_OF", "View", "VIEWS", "RING", "Model", "ERROR_OPTIONS", "FORMER_DEFAULTS", "eye_of",
           "with_view", "scene_of", "view_complexities", "highest_complexity_view", "time_pipeline", "pipeline_ms",
           "photon_generation_ms", "photon_generation_pass", "cell_scene", "time_cells", "table_4_1", "table_4_2", "exit_error", "error_vs_view",
           "summarize_error", "defaults_before_after", "PIPELINE_STAGES"]

# --------------------------------------------------------------------------- the thesis's numbers
#: Table 4.1, all rows: model -> (triangles, {(layers, texels a side): FPS}) (NVIDIA 8800 GTX)
THESIS_4_1_ALL = {
    "Holes": (4000, {(32, 256): 23, (32, 512): 16, (16, 256): 67, (16, 512): 30}),
    "Dwarf": (5270, {(32, 256): 54, (32, 512): 42, (16, 256): 80, (16, 512): 74}),
    "Bunny-lowpoly": (15000, {(32, 256): 106, (32, 512): 57, (16, 256): 114, (16, 512): 71}),
    "Sunflower": (18094, {(32, 256): 54, (32, 512): 43, (16, 256): 88, (16, 512): 80}),
    "Armadillo-lowpoly": (30000, {(32, 256): 59, (32, 512): 37, (16, 256): 95, (16, 512): 58}),
    "Bunny and Bunny": (30000, {(32, 256): 48, (32, 512): 25, (16, 256): 90, (16, 512): 41}),
    "Dragon-lowpoly": (39741, {(32, 256): 34, (32, 512): 23, (16, 256): 71, (16, 512): 43}),
    "Armadillo and bunny": (45000, {(32, 256): 54, (32, 512): 38, (16, 256): 89, (16, 512): 56}),
    "Ganesh": (51624, {(32, 256): 43, (32, 512): 28, (16, 256): 82, (16, 512): 51}),
    "Buddha": (67234, {(32, 256): 53, (32, 512): 28, (16, 256): 83, (16, 512): 52}),
    "Bunny I": (69451, {(32, 256): 87, (32, 512): 36, (16, 256): 99, (16, 512): 60}),
    "Maxplanck": (98260, {(32, 256): 66, (32, 512): 39, (16, 256): 112, (16, 512): 65}),
    "Bunny II": (144000, {(32, 256): 54, (32, 512): 30, (16, 256): 88, (16, 512): 62}),
    "Igea": (268686, {(32, 256): 53, (32, 512): 31, (16, 256): 77, (16, 512): 47}),
    "Armadillo": (345944, {(32, 256): 43, (32, 512): 28, (16, 256): 56, (16, 512): 41}),
    "Dragon": (871391, {(32, 256): 31, (32, 512): 21, (16, 256): 43, (16, 512): 29}),
}
#: the rows we have meshes for
THESIS_4_1 = {k: THESIS_4_1_ALL[k] for k in ("Bunny-lowpoly", "Bunny and Bunny", "Bunny I", "Igea")}
COLS_4_1 = ((32, 256), (32, 512), (16, 256), (16, 512))

#: Table 4.2 (ms): stage -> {texels a side: (I-A, I-B, II-A, II-B)}
THESIS_4_2 = {
    "Min-Max Depths": {256: (2.085, 0.365, 2.086, 0.369), 512: (2.101, 0.428, 2.112, 0.404)},
    "Voxelization": {256: (2.235, 0.652, 2.176, 0.622), 512: (3.807, 1.358, 3.076, 1.312)},
    "Depth Layer Peeling": {256: (1.032, 1.044, 0.918, 0.907), 512: (2.968, 2.955, 2.705, 2.698)},
    "Parallel Reduction": {256: (0.573, 0.58, 0.574, 0.564), 512: (1.294, 1.266, 1.323, 1.306)},
    "Photon Generation": {256: (2.403, 0.608, 2.411, 0.613), 512: (2.428, 0.617, 2.431, 0.641)},
    "Photon Tracing": {256: (4.938, 4.889, 3.22, 2.99), 512: (8.665, 7.774, 5.691, 4.981)},
}
#: our stage of each thesis row (Photon Generation: timed apart, :func:`photon_generation_ms`)
STAGE_OF = {"Min-Max Depths": "minmax", "Voxelization": "voxelize", "Depth Layer Peeling": "peel",
            "Parallel Reduction": "reduce", "Photon Generation": None, "Photon Tracing": "trace"}
SCENES_4_2 = ("I-A", "I-B", "II-A", "II-B")
THESIS_SCENE_TEXT = {"I-A": "two bunnies, 288,092 tris (2 x 144k Bunny II)", "I-B": "two bunnies, 30,000 tris",
                     "II-A": "one bunny (caption: 288,092)", "II-B": "one bunny (caption: 30,000)"}
#: the per-frame stages of the image-space pipeline (``geometry`` and ``rays`` are scene set-up)
PIPELINE_STAGES = ("minmax", "voxelize", "peel", "reduce", "trace", "shade")


# --------------------------------------------------------------------------- views
class View(NamedTuple):
    """A camera direction around the scene's target."""

    name: str
    azimuth: float  # degrees about +y; 0: eye on +z (the default front view), 90: eye on +x
    elevation: float  # degrees above the xz plane


def _view(a, e):
    return View(f"az{int(a):03d}_el{int(e):+03d}", float(a), float(e))


#: the listed views of Table 4.1: a ring of 8 at the target's height, 4 from 45 degrees above,
#: 2 from 45 degrees below
VIEWS = tuple([_view(a, 0) for a in range(0, 360, 45)] + [_view(a, 45) for a in (0, 90, 180, 270)]
              + [_view(a, -45) for a in (45, 225)])
#: the ring of the error-against-view table: 8 views, every 45 degrees around the vertical axis
RING = tuple(_view(a, 0) for a in range(0, 360, 45))


class Model(NamedTuple):
    """A table row's objects and how far the camera stands from them."""

    objects: list  # scene ``objects`` entries
    distance: float = 2.6  # eye to target (the default scene's)
    note: str = ""


def eye_of(view, distance, target=(0.0, 0.0, 0.0)):
    """World position of the eye ``distance`` from ``target`` in direction ``view``.

    Parameters
    ----------
    view : View
        Azimuth and elevation, degrees.
    distance : float
        Eye to target, scene units.
    target : (3,) sequence of float
        The point looked at.

    Returns
    -------
    list of 3 float
    """
    a, e = math.radians(view.azimuth), math.radians(view.elevation)
    d = np.array([math.sin(a) * math.cos(e), math.sin(e), math.cos(a) * math.cos(e)])
    return (np.asarray(target, dtype=np.float64) + distance * d).tolist()


def with_view(scene, view, distance, res, fov_y=30.0, target=(0.0, 0.0, 0.0), imagespace=None):
    """A copy of a scene dict seen from ``view`` at ``res`` x ``res``; ``imagespace`` knobs merged in.

    Parameters
    ----------
    scene : dict
        A scene dict (not modified).
    view : View
        Camera direction.
    distance : float
        Eye to target, scene units.
    res : int
        Image width and height in pixels.
    fov_y : float
        Vertical field of view, degrees.
    target : (3,) sequence of float
        The point looked at.
    imagespace : dict, optional
        ``imagespace`` knobs merged over the scene's.

    Returns
    -------
    dict
        The new scene dict, ``up`` +y.
    """
    d = copy.deepcopy(scene)
    cam = dict(d.get("camera") or {})
    cam.update({"eye": eye_of(view, distance, target), "target": list(map(float, target)), "up": [0.0, 1.0, 0.0],
                "fov_y": float(fov_y), "width": int(res), "height": int(res)})
    d["camera"] = cam
    if imagespace:
        d["imagespace"] = dict(d.get("imagespace") or {}, **imagespace)
    return d


def scene_of(model):
    """A table row's scene dict: its objects (copied), no receivers; the camera is the view's (:func:`with_view`).

    Parameters
    ----------
    model : Model
        The row's objects and camera distance.

    Returns
    -------
    dict
    """
    return {"objects": copy.deepcopy(model.objects), "receivers": []}


def view_complexities(scene, views=VIEWS, distance=2.6, res=256, fov_y=30.0):
    """Per view: the largest and mean depth complexity (fragments per pixel) of the objects.

    The objects are set up once; each view rasterizes them with the ``count``
    blend (every fragment, no culling: the true depth complexity, before any
    bitmask merges fragments of one slice).

    Parameters
    ----------
    scene : dict
        Scene dict whose objects are measured.
    views : sequence of View
        Camera directions (default :data:`VIEWS`, the listed views of Table 4.1).
    distance : float
        Eye to target (the origin), scene units.
    res : int
        Image side in pixels.
    fov_y : float
        Vertical field of view, degrees.

    Returns
    -------
    list of dict
        ``view``, ``azimuth``, ``elevation``, ``dc_max``, ``dc_mean`` (over
        covered pixels), ``covered`` (pixels), in the order of ``views``.
    """
    from ..camera import Camera
    from ..meshes import scene_geometry
    from ..raster import raster_setup, rasterize
    from ..scene import load_scene

    sc = load_scene(with_view(scene, views[0], distance, res, fov_y))
    geom = scene_geometry(sc)
    c = sc.data["camera"]
    out = []
    for v in views:
        cam = Camera(eye_of(v, distance), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), float(fov_y), int(res), int(res),
                     c["near"], c["far"])
        n = rasterize(raster_setup(cam.world_to_view(geom.vertices), cam, faces=geom.faces), cam, "count",
                      clip=True)
        cov = n > 0
        out.append({"view": v.name, "azimuth": v.azimuth, "elevation": v.elevation, "dc_max": int(n.max(initial=0)),
                    "dc_mean": float(n[cov].mean()) if cov.any() else 0.0, "covered": int(cov.sum())})
    return out


def highest_complexity_view(scene, views=VIEWS, distance=2.6, res=256, fov_y=30.0):
    """The view of highest depth complexity: the largest per-pixel count, ties to the larger mean.

    Parameters
    ----------
    scene, views, distance, res, fov_y
        As :func:`view_complexities`.

    Returns
    -------
    (View, list of dict)
        The view, and :func:`view_complexities`'s rows.
    """
    rows = view_complexities(scene, views, distance, res, fov_y)
    best = max(range(len(views)), key=lambda k: (rows[k]["dc_max"], rows[k]["dc_mean"], -k))
    return views[best], rows


# --------------------------------------------------------------------------- timing
def pipeline_ms(result):
    """Sum of the per-frame stages' ``timings_ms`` (min/max pass to finished image).

    Parameters
    ----------
    result : Result
        An image-space render (its ``meta['timings_ms']``).

    Returns
    -------
    float
        Milliseconds over :data:`PIPELINE_STAGES`.
    """
    t = result.meta["timings_ms"]
    return float(sum(t.get(k, 0.0) for k in PIPELINE_STAGES))


def time_pipeline(scene, repeats=9, warmup=2):
    """A plain timer: ``warmup`` renders, then the medians of ``repeats`` (``time_fn`` for the tables).

    Parameters
    ----------
    scene : Scene or dict
        The scene to render.
    repeats : int
        Timed renders (at least 1).
    warmup : int
        Untimed renders first.

    Returns
    -------
    dict
        ``pipeline_ms``, ``total_ms`` (medians), ``stages_ms`` (median per
        stage), ``samples`` (every ``pipeline_ms``), ``result`` (the last
        render), ``other_load`` (0: not measured).
    """
    from ..render import render

    for _ in range(max(0, int(warmup))):
        render(scene)
    sums, totals, per, res = [], [], {}, None
    for _ in range(max(1, int(repeats))):
        res = render(scene)
        sums.append(pipeline_ms(res))
        totals.append(float(res.meta["total_ms"]))
        for k, v in res.meta["timings_ms"].items():
            per.setdefault(k, []).append(float(v))
    return {"pipeline_ms": statistics.median(sums), "total_ms": statistics.median(totals),
            "stages_ms": {k: statistics.median(v) for k, v in per.items()}, "samples": sums, "result": res,
            "other_load": 0.0}


def photon_generation_pass(scene):
    """A callable running the thesis's photon-generation pass once (see :func:`photon_generation_ms`).

    Parameters
    ----------
    scene : Scene or dict
        The scene (objects and camera).

    Returns
    -------
    callable
        ``once()`` rasterizes the objects' triangles with the ``min`` blend and
        returns the (H, W) nearest depths.
    """
    from ..camera import Camera
    from ..meshes import scene_geometry
    from ..raster import raster_setup, rasterize
    from ..scene import load_scene

    sc = load_scene(scene)
    geom = scene_geometry(sc)
    cam = Camera.from_dict(sc.data["camera"])

    def once():
        rs = raster_setup(cam.world_to_view(geom.vertices), cam, faces=geom.faces)
        return rasterize(rs, cam, "min", clip=True)

    return once


def cell_scene(model, view, res, layers, mode):
    """The loaded scene of one table cell: ``model`` from ``view`` on a ``res``^2 grid, ``layers``, ``mode``.

    Parameters
    ----------
    model : Model
        The table row's objects and camera distance.
    view : View
        Camera direction.
    res : int
        Voxel grid side (``imagespace.grid``); the image is the thesis's
        :data:`VIEWPORT` (512x512) whatever the grid (§4.1-4.2).
    layers : int
        ``imagespace.layers``.
    mode : str
        ``'thesis'`` peels all layers (``imagespace.peel_all``), else only the
        depth complexity.

    Returns
    -------
    Scene
    """
    return _scene_for(model, view, res, layers, mode)


def photon_generation_ms(scene, repeats=9, warmup=2):
    """The thesis's photon generation, "rasterizing the geometry one more time" (§4.2), timed apart.

    The objects' world triangles (already placed: scene set-up, as the
    thesis's vertex buffers) are transformed into the view, set up and
    rasterized with the ``min`` blend (the nearest surface per pixel: where
    each eye photon starts). Median ms over ``repeats`` after ``warmup``.

    Parameters
    ----------
    scene : Scene or dict
        The scene (objects and camera).
    repeats : int
        Timed runs.
    warmup : int
        Untimed runs first (at least 1).

    Returns
    -------
    float
        Median milliseconds.
    """
    once = photon_generation_pass(scene)
    for _ in range(max(1, int(warmup))):
        once()
    ts = []
    for _ in range(max(1, int(repeats))):
        t0 = time.perf_counter()
        once()
        ts.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(ts)


# --------------------------------------------------------------------------- Tables 4.1 and 4.2
#: the thesis's viewport (§4.1-4.2): every cell renders 512x512 pixels; a cell's ``res`` is the voxel grid's
#: x-y size (``imagespace.grid``, the bitmask and layer textures: 256 or 512)
VIEWPORT = 512


def _scene_for(model, view, res, layers, mode):
    from ..scene import load_scene

    return load_scene(with_view(scene_of(model), view, model.distance, VIEWPORT,
                                imagespace={"layers": int(layers), "peel_all": mode == "thesis",
                                            "grid": [int(res), int(res)]}))


def _cells(model, view, keys, time_fn, time_many, cache, log):
    """Time the cells ``keys`` ((res, layers, mode) tuples) of one model, all together when ``time_many``."""
    todo = [k for k in keys if (id(model), view.name) + k not in cache]
    if todo:
        scenes = [_scene_for(model, view, res, L, mode) for res, L, mode in todo]
        ts = time_many(scenes) if time_many is not None else [time_fn(sc) for sc in scenes]
        for (res, L, mode), scene, t in zip(todo, scenes, ts):
            m = t["result"].meta
            st = np.asarray(t["result"]["status"])
            cell = {"traced_pixels": int(np.count_nonzero(st != 0)),
                    "interfaces": int(np.asarray(t["result"]["interfaces"], np.int64).sum()),"pipeline_ms": float(t["pipeline_ms"]), "total_ms": float(t.get("total_ms", float("nan"))),
                    "stages_ms": dict(t.get("stages_ms", {})), "fps": 1000.0 / float(t["pipeline_ms"]),
                    "dc_max_bitmask": m.get("depth_complexity_max"), "layers_used": m.get("layers_used"),
                    "pixels_over_layer_limit": m.get("pixels_over_layer_limit"), "triangles": m.get("triangles"),
                    "other_load": float(t.get("other_load", 0.0)), "scene": scene,
                    "samples": [float(x) for x in t.get("samples", ())]}  # pipeline ms per round, in round order
            cache[(id(model), view.name, res, L, mode)] = cell
            if log:
                log(f"  {view.name} {res}x{res}x256 grid {L:2d} layers {mode:6s}: {cell['pipeline_ms']:7.1f} ms "
                    f"({cell['fps']:5.1f} FPS), bitmask depth complexity {cell['dc_max_bitmask']}, "
                    f"{cell['layers_used']} layers peeled, other load {100 * cell['other_load']:.0f}%")
    return {k: cache[(id(model), view.name) + k] for k in keys}


def time_cells(model, view, keys, time_many, cache=None, log=None):
    """Time the cells ``keys`` ((res, layers, mode) tuples) of ``model`` seen from ``view``, interleaved.

    Parameters
    ----------
    model, view
        As :func:`cell_scene`.
    keys : iterable of (int, int, str)
        ``(res, layers, mode)`` cells.
    time_many : callable
        Takes a list of scenes and returns one timing dict per scene (the keys
        of :func:`time_pipeline`).
    cache : dict, optional
        Cells timed before, reused and added to.
    log : callable, optional
        Receives one progress line per cell.

    Returns
    -------
    dict
        ``(res, layers, mode)`` -> cell dict (``pipeline_ms``, ``stages_ms``, ``fps``, ``traced_pixels``
        (pixels whose status is not ``MISSED``), ``interfaces`` (summed over the image), ``triangles``,
        ``scene``, ...).
    """
    return _cells(model, view, list(keys), None, time_many, {} if cache is None else cache, log)


def table_4_1(models, time_fn=None, cols=COLS_4_1, modes=("thesis", "ours"), views=VIEWS, cache=None, log=print,
              time_many=None):
    """Table 4.1 in each model's view of highest depth complexity.

    Parameters
    ----------
    models : dict
        Row name (a key of :data:`THESIS_4_1_ALL`) -> :class:`Model`.
    time_fn : callable
        ``time_fn(scene) -> dict`` (see the module docstring), one cell at a time.
    time_many : callable, optional
        ``time_many(scenes) -> list of dict``: all cells of a model timed
        together (their renders interleaved, so that a slow spell of the
        machine weighs on every cell alike and the 16-vs-32 ratios hold);
        used instead of ``time_fn`` when given.
    cols : sequence of (layers, res)
    modes : sequence of {'thesis', 'ours'}
        ``thesis``: ``peel_all`` (every one of ``layers`` peeled); ``ours``:
        never more layers than the depth complexity.
    cache : dict, optional
        Shared with :func:`table_4_2` so that a cell is timed once.

    Returns
    -------
    list of dict
        One per model: ``model``, ``view`` (:class:`View`), ``views`` (the
        depth complexity of every listed view), ``thesis_triangles``,
        ``cells`` {(layers, res, mode): cell dict} and ``thesis_fps``.
    """
    cache = {} if cache is None else cache
    rows = []
    for name, model in models.items():
        view, vrows = highest_complexity_view(scene_of(model), views, model.distance)
        best = next(r for r in vrows if r["view"] == view.name)
        if log:
            log(f"{name}: view of highest depth complexity {view.name} (max {best['dc_max']} fragments per pixel, "
                f"mean {best['dc_mean']:.2f}; front view az000_el+00: max {vrows[0]['dc_max']})")
        keys = [(res, L, mode) for mode in modes for L, res in cols]
        got = _cells(model, view, keys, time_fn, time_many, cache, log)
        cells = {(L, res, mode): got[(res, L, mode)] for res, L, mode in keys}
        tris, fps = THESIS_4_1_ALL.get(name, (None, {}))
        rows.append({"model": name, "note": model.note, "view": view, "views": vrows, "thesis_triangles": tris,
                     "thesis_fps": fps, "cells": cells})
    return rows


def table_4_2(models, time_many, scenes=None, resolutions=(256, 512), views=VIEWS, cache=None, photon_fn=None,
              log=print):
    """Table 4.2: ms per stage for I-A, I-B, II-A, II-B at 256x256x256 and 512x512x256, 32 layers, thesis mode.

    Parameters
    ----------
    models : dict
        Row name -> :class:`Model`; ``scenes`` maps each of
        :data:`SCENES_4_2` to one of them (default: I-A ``"I-A"``, I-B
        ``"Bunny and Bunny"``, II-A ``"II-A"``, II-B ``"II-B"``). All four
        are filmed from one view: the I-A model's view of highest depth
        complexity over ``views`` (or each scene's own where I-A is missing),
        so that one bunny and two are compared in one framing, as the thesis's
        Table 4.2 compares one scene with one and two bunnies.
    time_many : callable
        ``time_many(scenes) -> list of dict``: the cells of a scene timed together (as for :func:`table_4_1`).
    scenes : dict, optional
        See ``models``.
    resolutions : sequence of int
        Voxel grids (texels a side).
    views : sequence of View
        The listed views.
    cache : dict, optional
        Shared with :func:`table_4_1` (cells it timed are reused).
    photon_fn : callable, optional
        ``photon_fn(scene) -> ms`` for the photon-generation row (default
        :func:`photon_generation_ms`).
    log : callable, optional
        Receives one progress line per cell.

    Returns
    -------
    dict
        ``(scene, res)`` -> ``{"stages_ms", "pipeline_ms", "photon_generation_ms", "view", "model",
        "triangles"}``; ``None`` for a scene whose model is missing.
    """
    scenes = scenes or {"I-A": "I-A", "I-B": "Bunny and Bunny", "II-A": "II-A", "II-B": "II-B"}
    cache = {} if cache is None else cache
    photon_fn = photon_fn or photon_generation_ms
    out = {}
    ia = models.get(scenes.get("I-A"))
    if ia is not None:
        views = (highest_complexity_view(scene_of(ia), views, ia.distance)[0],)
    for sc in SCENES_4_2:
        name = scenes.get(sc)
        model = models.get(name)
        if model is None:
            for res in resolutions:
                out[(sc, res)] = None
            continue
        view, _ = highest_complexity_view(scene_of(model), views, model.distance)
        got = _cells(model, view, [(res, 32, "thesis") for res in resolutions], None, time_many, cache, log)
        for res in resolutions:
            cell = got[(res, 32, "thesis")]
            pg = photon_fn(cell["scene"])
            if log:
                log(f"  {sc} ({name}) {res}: photon generation (one more rasterization) {pg:.2f} ms")
            out[(sc, res)] = {"stages_ms": cell["stages_ms"], "pipeline_ms": cell["pipeline_ms"],
                              "photon_generation_ms": pg, "view": view.name, "model": name,
                              "triangles": cell["triangles"], "other_load": cell["other_load"],
                              "traced_pixels": cell["traced_pixels"], "interfaces": cell["interfaces"],
                              "distance": model.distance}
    return out


# --------------------------------------------------------------------------- error against the view
#: the options whose effect the error table shows, as imagespace knob overrides
FORMER_DEFAULTS = {"blend": "or", "endpoint": "bracket", "filter": "nearest"}
ERROR_OPTIONS = (
    ("seed defaults", {}),
    ("tir", {"tir": True}),
    ("depth=float", {"depth": "float"}),
    ("normals=mesh3x3", {"normals": "mesh3x3"}),
    ("normals=cross", {"normals": "cross"}),
    ("iterations=10", {"iterations": 10}),
    ("blend=or", {"blend": "or"}),
    ("endpoint=bracket", {"endpoint": "bracket"}),
    ("filter=nearest", {"filter": "nearest"}),
    ("former defaults", dict(FORMER_DEFAULTS)),
    ("tir+float+cross", {"tir": True, "depth": "float", "normals": "cross"}),
)


def exit_error(a, b):
    """One run against the exact reference, over the pixels the reference hits.

    Parameters
    ----------
    a : mapping
        Image-space arrays (``status``, ``exit_dir`` (H, W, 3)).
    b : mapping
        Reference arrays (``hit`` (H, W) bool, ``status``, ``exit_dir``).

    Returns
    -------
    dict
        ``hit`` (pixels), ``median``, ``p90`` (degrees, over pixels where both
        exit), ``exit`` (fraction of hit pixels whose image-space ray exits),
        ``within5`` (fraction of hit pixels that exit in both within 5 degrees),
        ``tir``, ``lost``, ``limit`` (image-space status 3, 4, 2 fractions),
        ``exact_exit`` (the reference's exit fraction), ``errors`` (the
        per-pixel errors, for pooling).
    """
    from ..compare import angular_error_deg

    hit = np.asarray(b["hit"], bool)
    n = int(hit.sum())
    both = hit & (a["status"] == 1) & (b["status"] == 1)
    err = angular_error_deg(a["exit_dir"][both], b["exit_dir"][both])
    st = a["status"][hit]
    frac = (lambda x: float(np.count_nonzero(x)) / n) if n else (lambda x: float("nan"))
    return {"hit": n, "median": float(np.median(err)) if err.size else float("nan"),
            "p90": float(np.percentile(err, 90)) if err.size else float("nan"), "exit": frac(st == 1),
            "within5": float(np.count_nonzero(err < 5.0)) / n if n else float("nan"), "tir": frac(st == 3),
            "lost": frac(st == 4), "limit": frac(st == 2), "exact_exit": frac(b["status"][hit] == 1),
            "errors": err}


def error_vs_view(models, iors=(1.2, 1.33, 1.5), ring=RING, options=ERROR_OPTIONS, res=512, log=print):
    """Exit-direction error against the exact reference, per model, IOR, view and option.

    One :class:`~refraction_ref.session.Session` per model and IOR: a view
    change re-runs the camera's stages, an option only the stages that read
    it. The exact reference is rendered once per view.

    Parameters
    ----------
    models : dict
        Name -> :class:`Model`.
    iors : sequence of float
        Indices of refraction given to every object.
    ring : sequence of View
        Camera directions (default :data:`RING`).
    options : sequence of (str, dict)
        Label and ``imagespace`` knob overrides (default :data:`ERROR_OPTIONS`).
    res : int
        Image side in pixels.
    log : callable or None
        Receives one progress line per view.

    Returns
    -------
    list of dict
        ``model``, ``ior``, ``view``, ``azimuth``, ``elevation``, ``option``
        and :func:`exit_error`'s keys (``errors`` included, for pooling).
    """
    from ..scene import load_scene
    from ..session import Session

    rows = []
    for name, model in models.items():
        for ior in iors:
            objs = copy.deepcopy(model.objects)
            for o in objs:
                o.setdefault("material", {})
                o["material"] = dict(o["material"], ior=float(ior))
            session = None
            for v in ring:
                d = with_view({"objects": objs, "receivers": []}, v, model.distance, res)
                if session is None:
                    session = Session(d)
                else:
                    session.update({"camera.eye": d["camera"]["eye"]})
                base = session.scene
                t0 = time.perf_counter()
                ex = session.render("exact")
                for label, ov in options:
                    session.scene = load_scene(base, {f"imagespace.{k}": val for k, val in ov.items()}) if ov else base
                    r = session.render("imagespace")
                    e = exit_error(r.arrays, ex.arrays)
                    rows.append({"model": name, "ior": float(ior), "view": v.name, "azimuth": v.azimuth,
                                 "elevation": v.elevation, "option": label, **e})
                session.scene = base
                if log:
                    e0 = next(r_ for r_ in rows[::-1] if r_["option"] == options[0][0] and r_["view"] == v.name)
                    log(f"  {name} ior {ior} {v.name}: {options[0][0]}: median {e0['median']:.2f} p90 "
                        f"{e0['p90']:.2f} deg, exit {100 * e0['exit']:.1f}% (TIR {100 * e0['tir']:.1f}%, exact "
                        f"exits {100 * e0['exact_exit']:.1f}%), within 5 deg {100 * e0['within5']:.1f}% "
                        f"[{time.perf_counter() - t0:.1f} s]")
    return rows


def summarize_error(rows, by=("model", "ior", "option")):
    """Pool the ring: per group, the median and p90 of every pixel's error and the hit-weighted fractions.

    Parameters
    ----------
    rows : list of dict
        :func:`error_vs_view`'s rows.
    by : tuple of str
        Keys that form a group.

    Returns
    -------
    list of dict
        The group keys, ``views``, ``hit``, pooled ``median`` and ``p90``
        (degrees), hit-weighted ``exit``, ``within5``, ``tir``, ``lost``,
        ``exact_exit``, and the range over views of ``exit`` and ``p90``.
    """
    groups = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in by), []).append(r)
    out = []
    for key, rs in groups.items():
        err = np.concatenate([r["errors"] for r in rs]) if rs else np.zeros(0)
        n = sum(r["hit"] for r in rs)
        w = lambda k: sum(r[k] * r["hit"] for r in rs) / n if n else float("nan")  # noqa: E731
        out.append({**dict(zip(by, key)), "views": len(rs), "hit": n,
                    "median": float(np.median(err)) if err.size else float("nan"),
                    "p90": float(np.percentile(err, 90)) if err.size else float("nan"),
                    "exit": w("exit"), "within5": w("within5"), "tir": w("tir"), "lost": w("lost"),
                    "exact_exit": w("exact_exit"),
                    "exit_min": min(r["exit"] for r in rs), "exit_max": max(r["exit"] for r in rs),
                    "p90_min": min(r["p90"] for r in rs), "p90_max": max(r["p90"] for r in rs)})
    return out


def defaults_before_after(res=512, log=print):
    """The seed defaults against the former ones (and each change alone).

    The default bunny (front view, IOR 1.2) against the exact reference, and
    the sphere (``mesh: sphere``, fit 1, IOR 1.5, eye at distance 3) against
    the closed form (:func:`~refraction_ref.analytic.sphere_refraction`).

    Parameters
    ----------
    res : int
        Image side in pixels.
    log : callable or None
        Receives one line per row.

    Returns
    -------
    list of dict
        ``scene``, ``option`` and :func:`exit_error`'s statistics.
    """
    from ..analytic import sphere_refraction
    from ..render import render

    opts = (("former defaults", dict(FORMER_DEFAULTS)),
            ("blend=add only", {"endpoint": "bracket", "filter": "nearest"}),
            ("endpoint=probe only", {"blend": "or", "filter": "nearest"}),
            ("filter=bilinear only", {"blend": "or", "endpoint": "bracket"}), ("seed defaults", {}))
    rows = []
    bunny = {"camera": {"width": res, "height": res}, "receivers": []}
    ex = render(bunny, method="exact")
    for label, ov in opts:
        r = render(bunny, overrides={f"imagespace.{k}": v for k, v in ov.items()})
        rows.append({"scene": "bunny (IOR 1.2) vs exact", "option": label, **exit_error(r.arrays, ex.arrays)})
    sphere = {"camera": {"width": res, "height": res, "eye": [0.0, 0.0, 3.0]},
              "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.5}}], "receivers": []}
    for label, ov in opts:
        r = render(sphere, overrides={f"imagespace.{k}": v for k, v in ov.items()})
        an = sphere_refraction(r["ray_origin"].reshape(-1, 3), r["ray_dir"].reshape(-1, 3), (0.0, 0.0, 0.0), 0.5,
                               1.5)
        sh = r["status"].shape
        ref = {"hit": an["hit"].reshape(sh), "status": np.where(an["hit"].reshape(sh), 1, 0),
               "exit_dir": an["exit_dir"].reshape(sh + (3,))}
        rows.append({"scene": "sphere (IOR 1.5) vs closed form", "option": label, **exit_error(r.arrays, ref)})
    if log:
        for r in rows:
            log(f"  {r['scene']:32s} {r['option']:22s} median {r['median']:.3f} p90 {r['p90']:.3f} deg, "
                f"exit {100 * r['exit']:.1f}%, within 5 deg {100 * r['within5']:.1f}%")
    return rows
