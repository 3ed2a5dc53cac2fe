"""The image-space multiple-refraction pipeline (Chaudhari 2008, ch. 3) as a registered stage graph.

======================  ===========================================  =========
stage (``timings_ms``)  pass                                          section
======================  ===========================================  =========
``geometry``            the objects' triangles in world space          §3.2
``minmax``              min / max depth, per-pixel local bounds       §3.3
``voxelize``            bitmask voxelization (or the float A-buffer)  §3.3
``peel``                layered depth images                          §3.4
``reduce``              search bounds per layer                       §3.7
``normals``             per-layer normal maps (only when kept: the    §3.5
                        trace computes its normals on the fly)
``trace``               binary search + Snell at every interface      §3.6-3.7
``shade``               environment look-up, Beer-Lambert absorption  §3.8
``rays``                the primary rays (the output keys)            §3.2
======================  ===========================================  =========

With lights and receivers the caustic stages of §4.1 follow
(:func:`refraction_ref.imagespace.caustics.imagespace_caustic_stages`).
The same passes in a light's view make the photon pass (:func:`layered_trace`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..camera import Camera
from ..environment import environment_lookup
from ..graph import Method, Stage, method_renderer, register_method, run_stages
from ..meshes import eye_inside, scene_geometry
from ..optics import beer_lambert
from ..raster import raster_setup
from ..validation import SceneError
from ..warm import warmer
from .depth_bounds import depth_bounds, global_bounds
from .grid import at_pixels, grid_camera
from .knobs import TRACE_KNOBS, TraceKnobs, check_memory, trace_knobs
from .normals import layer_normals
from .peel import POPCOUNT8, SELECT8, depth_complexity, peel_layers
from .search_bounds import search_bounds
from .trace import ImagespaceLayers, ImagespaceOptics, exit_thresholds, trace_layers
from .voxelize import collect_depths, slice_bounds, voxelize_bitmask

__all__ = ["render_imagespace", "check_materials", "layered_trace", "METHOD", "TRACE_KNOBS", "VIEW_STAGES",
           "pass_minmax", "pass_voxelize", "pass_peel", "pass_reduce", "pass_trace",
           "MinMax", "Voxels", "Layers", "Bounds", "TraceKnobs", "trace_knobs", "ImagespaceOptics"]

#: the knobs each pass reads (the eye's stages and the light's photon pass declare the same; the trace's,
#: :data:`TRACE_KNOBS`, are :func:`~refraction_ref.imagespace.knobs.trace_knobs`' own)
MINMAX_KNOBS = ("depth",)
VOXELIZE_KNOBS = ("depth", "slices", "slicing", "blend", "layers")
PEEL_KNOBS = ("depth", "layers", "peeling", "slices", "peel_all")
REDUCE_KNOBS = ("bounds", "mip_size", "bound_margin")


def check_materials(geom):
    """The bitmask cannot tell objects apart: all must share ior and absorption (§4.1).

    Parameters
    ----------
    geom : Geometry
        The objects' triangles and materials (:func:`~refraction_ref.meshes.scene_geometry`).

    Returns
    -------
    ior : float
        The objects' index (1 without objects).
    absorption : (3,) float64
        Their absorption coefficients.

    Raises
    ------
    SceneError
        When the objects' materials differ.
    """
    if len(geom.ior) == 0:
        return 1.0, np.zeros(3)
    if np.ptp(geom.ior) > 0 or np.ptp(geom.absorption, axis=0).max() > 0:
        raise SceneError("imagespace: objects have different materials "
                         f"(ior {geom.ior.tolist()}); the occupancy bitmask cannot tell objects apart "
                         "(Chaudhari 2008, §4.1). Give all objects the same material, or use --method exact")
    return float(geom.ior[0]), geom.absorption[0]


# --------------------------------------------------------------------- passes (any view)
class MinMax(NamedTuple):
    """What the min/max pass makes (:func:`pass_minmax`).

    Attributes
    ----------
    tri_view : object
        The view's triangle set-up (:func:`~refraction_ref.raster.raster_setup`), or None.
    zmin, zmax : (H, W) float64
        Per-pixel nearest and farthest depth (``+inf`` / ``-inf`` where no object).
    frags : object
        The fragments, kept for the bitmask pass, or None.
    gmin, gmax : float
        The global depth range of the objects.
    """

    tri_view: object
    zmin: np.ndarray
    zmax: np.ndarray
    frags: object
    gmin: float
    gmax: float


class Voxels(NamedTuple):
    """What the voxelization pass makes (:func:`pass_voxelize`).

    Attributes
    ----------
    bits : (H, W, S/32) uint32 or None
        Occupancy words (bit k of word w is slice 32 w + k, slice 0 nearest); None for ``depth='float'``.
    zlo, zhi : (H, W) float64
        The depth range the slices span.
    ldi : (L, H, W) or None
        ``depth='float'``: the A-buffer's exact depths, sorted into layers.
    total : (H, W) int or None
        ``depth='float'``: fragments per pixel.
    """

    bits: object
    zlo: np.ndarray
    zhi: np.ndarray
    ldi: object
    total: object


class Layers(NamedTuple):
    """What the peeling pass makes (:func:`pass_peel`).

    Attributes
    ----------
    ldi : (L, H, W) float32
        Layer depths (``+inf`` where a pixel has fewer layers).
    total : (H, W) int32
        Layers per pixel (set bits of the bitmask).
    lut : tuple or None
        On-the-fly peeling inputs (§3.4.1), or None when the layers were peeled.
    ran : bool
        Whether a peeling pass ran.
    why : str
        What was done, for the plan.
    """

    ldi: np.ndarray
    total: np.ndarray
    lut: object
    ran: bool
    why: str


class Bounds(NamedTuple):
    """What the reduction pass makes (:func:`pass_reduce`).

    Attributes
    ----------
    bounds_hi, bounds_lo : (L,) float64
        Forward and backward search bounds per layer.
    why : str
        What was done, for the plan.
    """

    bounds_hi: np.ndarray
    bounds_lo: np.ndarray
    why: str


def from_buffers(cls, buf):
    """The named tuple ``cls`` of a stage's buffer dict (its other keys ignored).

    Parameters
    ----------
    cls : type
        :class:`MinMax`, :class:`Voxels`, :class:`Layers` or :class:`Bounds`.
    buf : dict
        A stage's buffers (``ctx.buf[stage]``), made by ``cls._asdict()`` and more.

    Returns
    -------
    cls
    """
    return cls(**{k: buf[k] for k in cls._fields})


def pass_minmax(geom, cam, p):
    """Per-pixel Zmin/Zmax of the objects in a view, and their global range (§3.3).

    Parameters
    ----------
    geom : Geometry
        The objects' triangles (:func:`~refraction_ref.meshes.scene_geometry`).
    cam : Camera
        The view.
    p : dict
        The ``imagespace`` knobs (reads :data:`MINMAX_KNOBS`).

    Returns
    -------
    MinMax

    References
    ----------
    Chaudhari (2008), §3.3.
    """
    tri_view = raster_setup(cam.world_to_view(geom.vertices), cam, faces=geom.faces)
    found = depth_bounds(tri_view, cam, keep_fragments=p["depth"] == "bitmask")
    zmin, zmax, frags = found if len(found) == 3 else (*found, None)
    gmin, gmax = global_bounds(zmin, zmax)
    return MinMax(tri_view, zmin, zmax, frags, gmin, gmax)


def pass_voxelize(minmax, cam, p):
    """Bitmask voxelization (§3.3), or, for ``depth='float'``, the A-buffer of exact depths.

    Parameters
    ----------
    minmax : MinMax
        The min/max pass of this view.
    cam : Camera
        The view.
    p : dict
        The ``imagespace`` knobs (reads :data:`VOXELIZE_KNOBS`).

    Returns
    -------
    Voxels
        ``bits`` and the depth range ``zlo``, ``zhi`` the slices span; for
        ``depth='float'`` no ``bits`` but the A-buffer's ``ldi`` and ``total``
        (``zlo``, ``zhi`` then the per-pixel Zmin/Zmax).

    References
    ----------
    Chaudhari (2008), §3.3 (bitmask voxelization, Eisemann and Décoret 2006).
    """
    if p["depth"] == "bitmask":
        zlo, zhi = slice_bounds(minmax.zmin, minmax.zmax, p["slicing"])
        src = minmax.tri_view if minmax.frags is None else minmax.frags
        bits = voxelize_bitmask(src, cam, zlo, zhi, int(p["slices"]), p["blend"])
        return Voxels(bits, zlo, zhi, None, None)
    ldi, total = collect_depths(minmax.tri_view, cam, int(p["layers"]))
    Lr = int(min(int(p["layers"]), total.max(initial=0)))
    # the grid the early-termination threshold counts in
    return Voxels(None, minmax.zmin, minmax.zmax, np.ascontiguousarray(ldi[:Lr]), total)


def pass_peel(voxels, shape, p):
    """Layered depth images from the bitmask (§3.4.2), or the on-the-fly tables of §3.4.1.

    Parameters
    ----------
    voxels : Voxels
        The voxelization pass of this view (only ``bits``, ``zlo``, ``zhi``
        are read for the bitmask; ``ldi``, ``total`` for ``depth='float'``).
    shape : (H, W)
        The view's size.
    p : dict
        The ``imagespace`` knobs (reads :data:`PEEL_KNOBS`).

    Returns
    -------
    Layers

    References
    ----------
    Chaudhari (2008), §3.4.1 (on-the-fly peeling), §3.4.2 (layered depth images).
    """
    H, W = shape
    L = int(p["layers"])
    peel_all = bool(p["peel_all"])
    if voxels.bits is None:
        ldi = voxels.ldi
        why = "the A-buffer is already sorted into layers"
        if peel_all and ldi.shape[0] < L:  # the thesis's fixed layer count: pad with absent layers
            ldi = np.concatenate([ldi, np.full((L - ldi.shape[0], H, W), np.inf, ldi.dtype)])
            why += f"; padded to all {L} layers (peel_all)"
        return Layers(ldi, voxels.total, None, False, why)
    S = int(p["slices"])
    total = depth_complexity(voxels.bits)
    if p["peeling"] == "separate":
        ldi, total = peel_layers(voxels.bits, voxels.zlo, voxels.zhi, S, L, total, peel_all=peel_all)
        why = (f"all {L} layers peeled (peel_all, §3.4.2): the scene's depth complexity is "
               f"{int(total.max(initial=0))}" if peel_all else
               f"{ldi.shape[0]} layers peeled: the scene's depth complexity is "
               f"{int(total.max(initial=0))}, the limit {L} (§3.4.2)")
        return Layers(ldi, total, None, True, why)
    Lr = L if peel_all else int(min(L, total.max(initial=0)))
    ldi = np.broadcast_to(np.float32(np.inf), (Lr, H, W))
    lut = (True, voxels.bits, np.ascontiguousarray(voxels.zlo), np.ascontiguousarray(voxels.zhi), S, POPCOUNT8,
           SELECT8)
    return Layers(ldi, total, lut, False, "on-the-fly peeling with 8-bit look-up tables during the trace (§3.4.1)")


def pass_reduce(minmax, layers, p):
    """Search bounds per layer (§3.7).

    Parameters
    ----------
    minmax : MinMax
        The min/max pass of this view (only ``gmin``, ``gmax`` are read).
    layers : Layers
        The peeling pass of this view (only ``ldi``, ``lut`` are read).
    p : dict
        The ``imagespace`` knobs (reads :data:`REDUCE_KNOBS`).

    Returns
    -------
    Bounds

    References
    ----------
    Chaudhari (2008), §3.7 (the MIP max-reduction of each layer).
    """
    L = layers.ldi.shape[0]
    if layers.lut is not None:
        # no LDI to reduce: the exact global bound serves every layer
        return Bounds(np.full(L, minmax.gmax), np.full(L, minmax.gmin),
                      "on-the-fly peeling has no LDI: the global Zmax bounds every layer")
    margin = float(p["bound_margin"]) * (minmax.gmax - minmax.gmin) if np.isfinite(minmax.gmax) else 0.0
    bhi, blo = search_bounds(layers.ldi, p["bounds"], int(p["mip_size"]), margin)
    why = (f"max-reduction of the {p['mip_size']}x{p['mip_size']} MIP level + margin {margin:.3g} (§3.7)"
           if p["bounds"] == "mip" else "exact per-layer maxima")
    return Bounds(bhi, blo, why)


def pass_trace(minmax, voxels, layers, bounds, cam, knobs, optics, image=None):
    """Every pixel's ray through the layers (§3.6-3.7), world space (:func:`trace_layers`).

    Parameters
    ----------
    minmax : MinMax
        The min/max pass (``zmax``: the backmost depth of early termination).
    voxels : Voxels
        The voxelization pass (``zlo``, ``zhi``: the grid the exit threshold counts slices in).
    layers : Layers
        The layers (``ldi``, ``total``, ``lut``).
    bounds : Bounds
        The search bounds per layer.
    cam : Camera
        The view.
    knobs : TraceKnobs
        The trace's knobs (:func:`~refraction_ref.imagespace.knobs.trace_knobs`; ``record``: events kept
        per path, ``path_pos``, ``path_dir``).
    optics : ImagespaceOptics or (ior, outside_ior)
        Object and surrounding indices.
    image : Camera, optional
        The image casting one ray per pixel when the grid (``cam``) has another size
        (``imagespace.grid``); default ``cam``.

    Returns
    -------
    dict
        :func:`~refraction_ref.imagespace.trace.trace_layers`'s output, world space, per image pixel.

    References
    ----------
    Chaudhari (2008), §3.6 (binary search, Snell at every interface), §3.7 (search bounds, early
    termination), §3.8 (path length); Oliveira and Brauwers (2007).
    """
    thr = exit_thresholds(voxels.zlo, voxels.zhi, knobs.slices, knobs.exit_threshold)
    stack = ImagespaceLayers(layers.ldi, layers.total, minmax.zmax, thr, bounds.bounds_hi, bounds.bounds_lo)
    return trace_layers(stack, cam, knobs, ImagespaceOptics(*optics), lut=layers.lut, world=True, image=image)


# --------------------------------------------------------------------- the passes in any view
def _view_minmax(ctx):
    view = ctx.buf["input"]
    ctx.note("per-pixel Zmin/Zmax (§3.3)")
    return pass_minmax(view["geom"], view["cam"], view["p"])._asdict()


def _view_voxelize(ctx):
    view = ctx.buf["input"]
    p = view["p"]
    voxels = pass_voxelize(from_buffers(MinMax, ctx.buf["minmax"]), view["cam"], p)
    ctx.note("float depth: exact fragment depths (A-buffer)" if voxels.bits is None
             else f"{p['slices']} slices, {p['slicing']} bounds, {p['blend']} blending")
    return voxels._asdict()


def _view_peel(ctx):
    view = ctx.buf["input"]
    layers = pass_peel(from_buffers(Voxels, ctx.buf["voxelize"]), view["cam"].shape, view["p"])
    ctx.ran = layers.ran
    ctx.note(layers.why)
    return layers._asdict()


def _view_reduce(ctx):
    layers = from_buffers(Layers, ctx.buf["peel"])
    bounds = pass_reduce(from_buffers(MinMax, ctx.buf["minmax"]), layers, ctx.buf["input"]["p"])
    ctx.ran = layers.lut is None  # on-the-fly peeling has no LDI to reduce
    ctx.note(bounds.why)
    return bounds._asdict()


def _view_trace(ctx):
    view = ctx.buf["input"]
    b = ctx.buf
    trace = pass_trace(from_buffers(MinMax, b["minmax"]), from_buffers(Voxels, b["voxelize"]),
                       from_buffers(Layers, b["peel"]), from_buffers(Bounds, b["reduce"]), view["cam"],
                       trace_knobs(view["p"]), view["optics"])  # a light's photons keep no paths (record 0)
    ctx.note(f"{view['p']['iterations']} binary-search iterations")
    return {"trace": trace}


#: the passes of chapter 3 in one view, on the buffers ``geom``, ``cam``, ``p`` (the ``imagespace`` knobs) and
#: ``optics`` (:func:`layered_trace`; :func:`refraction_ref.graph.run_stages` runs them)
VIEW_STAGES = (
    Stage("minmax", _view_minmax, after=("input",), makes=MinMax._fields, doc="per-pixel Zmin/Zmax (§3.3)"),
    Stage("voxelize", _view_voxelize, after=("input", "minmax"), makes=Voxels._fields,
          doc="bitmask voxelization (§3.3)"),
    Stage("peel", _view_peel, after=("input", "voxelize"), makes=Layers._fields, doc="layered depth images (§3.4)"),
    Stage("reduce", _view_reduce, after=("input", "minmax", "peel"), makes=Bounds._fields,
          doc="search bounds per layer (§3.7)"),
    Stage("trace", _view_trace, after=("input", "minmax", "voxelize", "peel", "reduce"), makes=("trace",),
          doc="binary search + Snell at every interface (§3.6-3.7)"),
)


def layered_trace(geom, cam, p, ior, outside, timings, plan):
    """Min/max, voxelization, peeling, reduction and trace in one view (§3.3-3.7).

    The passes of chapter 3 for any view of the refractive objects: the
    eye's (perspective), or a light's (perspective for a point light,
    orthographic for a directional one: the photon pass of §4.1, which
    traces one photon per texel with the very same kernels). They run as
    :data:`VIEW_STAGES` through :func:`refraction_ref.graph.run_stages`.

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

    References
    ----------
    Chaudhari (2008), §3.3-3.7 (the passes), §4.1 (the photon pass in a light's view).
    """
    view = {"geom": geom, "cam": cam, "p": p, "optics": ImagespaceOptics(ior, outside)}
    bufs = run_stages(VIEW_STAGES, view, timings=timings, plan=plan)
    layers = bufs["peel"]
    total = layers["total"]
    n_over = int(np.count_nonzero(total > int(p["layers"])))
    return {"trace": bufs["trace"]["trace"], "total": total, "ldi": layers["ldi"], "zmin": bufs["minmax"]["zmin"],
            "zmax": bufs["minmax"]["zmax"], "pixels_over_layer_limit": n_over}


# --------------------------------------------------------------------- the eye's stages
def _k(*names):
    return tuple(f"imagespace.{n}" for n in names)


def _st_geometry(ctx):
    sc = ctx.scene
    geom = scene_geometry(sc)
    ior, absorption = check_materials(geom)
    for k, nb_ in enumerate(geom.boundary_edges):
        if nb_:
            ctx.note(f"object {k} is open ({int(nb_)} boundary edges): pixels can see an odd number of layers, "
                     "and inside/outside then follows layer parity")
    for k, nd in enumerate(geom.degenerate):
        if nd:
            ctx.note(f"object {k} has {int(nd)} zero-area triangles; they produce no fragments")
    ctx.stats["triangles"] = int(len(geom.faces))
    return {"geom": geom, "ior": ior, "absorption": absorption, "outside_ior": float(sc.data["outside_ior"])}


def _st_minmax(ctx):
    g = ctx.buf["geometry"]
    cam = Camera.from_dict(ctx.scene.data["camera"])
    if eye_inside(g["geom"], cam.eye):
        raise SceneError("imagespace: the camera is inside a refractive object; the image-space method "
                         "needs the viewer outside (its first layer is the front face). Move camera.eye "
                         "outside the objects")
    p = ctx.scene.data["imagespace"]
    gcam = grid_camera(cam, p["grid"])  # the grid's passes: the image's view, the grid's pixel count
    minmax = pass_minmax(g["geom"], gcam, p)
    ctx.note("per-pixel Zmin/Zmax (§3.3)" if gcam is cam else
             f"per-texel Zmin/Zmax of a {gcam.width}x{gcam.height} grid (§3.3; imagespace.grid)")
    return dict(minmax._asdict(), cam=gcam, image_cam=cam)


def _st_voxelize(ctx):
    p = ctx.scene.data["imagespace"]
    minmax = ctx.buf["minmax"]
    voxels = pass_voxelize(from_buffers(MinMax, minmax), minmax["cam"], p)
    ctx.note("float depth: exact fragment depths kept per pixel (A-buffer), no bitmask" if voxels.bits is None
             else f"{p['slices']} slices, {p['slicing']} bounds, {p['blend']} blending (§3.3)")
    return voxels._asdict()


def _st_peel(ctx):
    p = ctx.scene.data["imagespace"]
    layers = pass_peel(from_buffers(Voxels, ctx.buf["voxelize"]), ctx.buf["minmax"]["cam"].shape, p)
    ctx.note(layers.why)
    total = layers.total
    ctx.stats.update({"layers_used": int(layers.ldi.shape[0]),
                      "pixels_over_layer_limit": int(np.count_nonzero(total > int(p["layers"]))),
                      "depth_complexity_max": int(total.max(initial=0))})
    return dict(layers._asdict(), depth_complexity=total.astype(np.int16))


def _st_reduce(ctx):
    bounds = pass_reduce(from_buffers(MinMax, ctx.buf["minmax"]), from_buffers(Layers, ctx.buf["peel"]),
                         ctx.scene.data["imagespace"])
    ctx.note(bounds.why)
    return bounds._asdict()


def _st_normals(ctx):
    """Per-layer normal maps, as the trace's normal rule gives them at pixel centres (§3.5)."""
    p = ctx.scene.data["imagespace"]
    cam = ctx.buf["minmax"]["cam"]
    layers = ctx.buf["peel"]
    ldi = layers["ldi"]
    if layers["lut"] is not None:  # on-the-fly peeling: materialise the layers to show their normals
        voxels = ctx.buf["voxelize"]
        ldi, _ = peel_layers(voxels["bits"], voxels["zlo"], voxels["zhi"], int(p["slices"]), int(p["layers"]),
                             peel_all=bool(p["peel_all"]))
    out = np.full(ldi.shape + (3,), np.nan)
    for k in range(ldi.shape[0]):
        out[k] = layer_normals(ldi[k], cam, p["normals"], int(p["delta"]))
    ctx.note(f"{p['normals']} normals (delta {p['delta']}) of {ldi.shape[0]} layers, view space, for inspection")
    return {"normals": out}


def _st_trace(ctx):
    p = ctx.scene.data["imagespace"]
    g = ctx.buf["geometry"]
    b = ctx.buf
    trace = pass_trace(from_buffers(MinMax, b["minmax"]), from_buffers(Voxels, b["voxelize"]),
                       from_buffers(Layers, b["peel"]), from_buffers(Bounds, b["reduce"]), b["minmax"]["cam"],
                       trace_knobs(p, int(p["record"])), ImagespaceOptics(g["ior"], g["outside_ior"]),
                       image=b["minmax"]["image_cam"])
    ctx.note(f"{p['iterations']} binary-search iterations per interface ending at the "
             + ("last probe's texel (§3.6)" if p["endpoint"] == "probe" else "final bracket's midpoint")
             + f", {p['filter']} depth sampling, {p['normals']} normals"
             + (", total internal reflection followed" if p["tir"] else ""))
    out = dict(trace)
    out.setdefault("path_pos", None)
    out.setdefault("path_dir", None)
    return out


def _st_rays(ctx):
    origin, rdir = Camera.from_dict(ctx.scene.data["camera"]).primary_rays()
    return {"ray_origin": origin, "ray_dir": rdir}


def _st_shade(ctx):
    g = ctx.buf["geometry"]
    trace = ctx.buf["trace"]
    sc = ctx.scene
    image = environment_lookup(sc.data["environment"], trace["last_dir"], sc.base_dir)
    if np.any(g["absorption"] > 0):
        trans = beer_lambert(g["absorption"], trace["path_length"], g["ior"])
        image = (image * trans).astype(np.float32)
        ctx.note("environment look-up; I = I0 exp(-alpha l eta) (§3.8)")
    else:
        ctx.note("environment look-up; absorption is zero")
    return {"image": image}


def eye_stages():
    """The eye's stages of chapter 3 (without caustics).

    ``rays`` comes first: the pass a port writes first, and the first that ``check`` judges (the
    golden suite's stage order is this graph's: :func:`refraction_ref.golden.build.stage_order`).
    """
    return (
        Stage("rays", _st_rays, reads=("camera",), makes=("ray_origin", "ray_dir"),
              doc="every pixel's primary ray, world space (the output keys ray_origin, ray_dir)"),
        Stage("geometry", _st_geometry, reads=("objects", "outside_ior"), makes=("geom", "ior", "absorption"),
              doc="the objects' triangles, one material (§3.2, §4.1)"),
        Stage("minmax", _st_minmax, reads=("camera",) + _k(*MINMAX_KNOBS, "grid"), after=("geometry",),
              makes=("zmin", "zmax"), doc="per-pixel Zmin/Zmax (§3.3)"),
        Stage("voxelize", _st_voxelize, reads=("camera",) + _k(*VOXELIZE_KNOBS, "grid"), after=("minmax",),
              makes=("bits", "zlo", "zhi"), doc="bitmask voxelization (§3.3)"),
        Stage("peel", _st_peel, reads=_k(*PEEL_KNOBS), after=("minmax", "voxelize"),
              makes=("ldi", "depth_complexity"), doc="layered depth images (§3.4)"),
        Stage("reduce", _st_reduce, reads=_k(*REDUCE_KNOBS), after=("minmax", "peel"),
              makes=("bounds_hi", "bounds_lo"), doc="search bounds per layer (§3.7)"),
        Stage("normals", _st_normals, reads=_k("normals", "delta", "slices", "layers", "peel_all"),
              after=("minmax", "voxelize", "peel"), makes=("normals",), diagnostic=True,
              doc="per-layer normal maps, view space (§3.5); only when kept"),
        Stage("trace", _st_trace, reads=_k(*TRACE_KNOBS, "record", "grid"),
              after=("geometry", "minmax", "voxelize", "peel", "reduce"),
              makes=("exit_pos", "exit_dir", "last_dir", "interfaces", "path_length", "status", "path_pos",
                     "path_dir"), doc="binary search + Snell at every interface (§3.6-3.7)"),
        Stage("shade", _st_shade, reads=("environment",), after=("geometry", "trace"), makes=("image",),
              doc="environment look-up, Beer-Lambert absorption (§3.8)"),
    )


def _stages(scene):
    from ..caustics.pipeline import has_caustics
    from .caustics import imagespace_caustic_stages

    st = eye_stages()
    knobs = MINMAX_KNOBS + VOXELIZE_KNOBS + PEEL_KNOBS + REDUCE_KNOBS + TRACE_KNOBS
    return st + (imagespace_caustic_stages(scene, layered_trace, knobs) if has_caustics(scene) else ())


def _skipped(scene):
    from ..caustics.pipeline import has_caustics, skip_reason

    return [] if has_caustics(scene) else [{"stage": "caustics", "ran": False, "why": skip_reason(scene)}]


def _assemble(scene, bufs, stats):
    trace = bufs["trace"]
    arrays = {
        "ray_origin": bufs["rays"]["ray_origin"],
        "ray_dir": bufs["rays"]["ray_dir"],
        "hit": trace["status"] != 0,
        "exit_pos": trace["exit_pos"],
        "exit_dir": trace["exit_dir"],
        "interfaces": trace["interfaces"],
        "path_length": trace["path_length"],
        "status": trace["status"],
        "image": bufs["shade"]["image"],
        # per image pixel: the grid texel under its centre (imagespace.grid)
        "depth_complexity": at_pixels(bufs["peel"]["depth_complexity"], bufs["rays"]["ray_dir"].shape[:2]),
    }
    info = {k: stats[k] for k in ("layers_used", "pixels_over_layer_limit", "depth_complexity_max", "triangles")}
    if "caustic_final" in bufs:
        from ..caustics.pipeline import caustic_arrays

        c_arrays, info["caustics"] = caustic_arrays(scene, "imagespace", bufs, stats)
        from ..caustics.pipeline import merge_caustics

        merge_caustics(arrays, c_arrays)
    return arrays, info


def _tiny(scene):
    """Warm-up overrides (:attr:`~refraction_ref.graph.Method.tiny`): a few pixels and photons, same kernels."""
    return {"camera.width": 16, "camera.height": 16, "imagespace.photons": 8, "caustics.map_size": 8,
            "imagespace.grid": None}  # a grid of the tiny image's size: the same kernels


METHOD = register_method(Method(
    "imagespace", blocks=("imagespace",), stages=_stages, assemble=_assemble, skipped=_skipped,
    warm=warmer("imagespace"), tiny=_tiny, label="Chaudhari 2008",
    results=("rays", "trace", "shade", "peel.depth_complexity", "receivers.rs", "gather", "caustic_final"),
    check=check_memory,
    doc="Chaudhari (2008): bitmask voxelization, peeled LDIs, gradient normals, 5-step binary search"))


render_imagespace = method_renderer(
    METHOD, "render_imagespace",
    "Render a scene with the image-space method (Chaudhari 2008, ch. 3): :data:`METHOD`'s stage graph.")
