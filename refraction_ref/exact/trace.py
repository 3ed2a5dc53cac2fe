"""Exact multi-interface Snell tracer through the actual triangles (:func:`trace_exact`).

This is the ground-truth oracle for the image-space approximations of
Chaudhari (2008): every ray is intersected with the real triangle mesh
(Embree for the search, float64 Möller–Trumbore for the hit itself) and
refracted by Snell's law at *every* interface it crosses, with total internal
reflection, until it leaves the scene or the bounce limit is reached.

Snell's law, total internal reflection and Beer–Lambert absorption are *not*
implemented here; they come from :mod:`refraction_ref.optics` so that the
oracle and the approximations share one implementation of each law.

Deterministic: identical inputs give bit-identical outputs whatever the
thread count (Embree's BVH build and traversal are deterministic, its
queries run on fixed chunks of rays, and all float64 work is per ray, in
Numba kernels that write only their ray's rows). Each bounce splits the rays
still travelling into fixed chunks that ``numba.get_num_threads()`` threads
take in turn (:func:`refraction_ref.embree.run_chunks`); a chunk is queried
with Embree (embreex releases the GIL while tracing) and then bounced by a
Numba kernel that releases the GIL too (:mod:`refraction_ref.exact.bounce`).
The shading normals come from :mod:`refraction_ref.exact.normals`.

The exact reference is described in docs/oracle.md ("Per-pixel keys", the
``exact`` block and "Caustics on receivers").

References
----------
.. [1] T. Whitted, "An Improved Illumination Model for Shaded Display",
   *Communications of the ACM* 23(6), 343–349, 1980 (recursive ray tracing
   with refraction at every interface).
.. [2] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
   ed., §8.2 (Snell's law, total internal reflection).
.. [3] T. Möller, B. Trumbore, "Fast, Minimum Storage Ray/Triangle
   Intersection", *Journal of Graphics Tools* 2(1), 21–28, 1997.
.. [4] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008 (the image-space method this module is
   the reference for; absorption model of §3.8).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from .. import optics
from ..embree import HIT_CHUNK, chunk_length, mesh_scene, run_chunks
from ..meshes import bounds
from ..status import EXITED, LIMIT, LOST, MISSED, TIR
from .bounce import (ACTIVE, ExactFaces, ExactHits, ExactOutputs, ExactRayState, ExactSettings, bounce_rows,
                     face_rows, init_rows, query_rows)
from .knobs import EXACT_DEFAULTS
from .normals import MeshNormals, area_weighted_vertex_normals, mesh_normals

__all__ = [
    "trace_exact",
    "ExactMesh",
    "area_weighted_vertex_normals",
    "MeshNormals",
    "mesh_normals",
    "STATUS_MISSED",
    "STATUS_EXITED",
    "STATUS_BOUNCE_LIMIT",
    "STATUS_BOUNCE_LIMIT_TIR",
    "STATUS_LOST",
]

# the tracer's status codes under this module's names (:mod:`refraction_ref.status`)
STATUS_MISSED = MISSED
STATUS_EXITED = EXITED
STATUS_BOUNCE_LIMIT = LIMIT
STATUS_BOUNCE_LIMIT_TIR = TIR
STATUS_LOST = LOST


class ExactMesh(NamedTuple):
    """The triangles and media :func:`trace_exact` refracts through.

    Attributes
    ----------
    vertices : (V, 3) array_like of float
        World-space vertex positions (float64 is used throughout).
    faces : (F, 3) array_like of int
        Outward-wound triangles of all objects.
    face_object : (F,) array_like of int
        Object index in ``[0, K)`` of each face.
    object_ior : (K,) array_like of float
        Index of refraction of each object, > 0.
    object_absorption : (K, 3) array_like of float
        Absorption coefficient per colour channel of each object, >= 0.
    normals : (V, 3) or (F, 3, 3) array_like of float, optional
        Shading normals, per vertex or per corner (row ``[f, k]`` belongs to
        vertex ``faces[f, k]``, e.g. the crease normals of :func:`mesh_normals`,
        which let a vertex on a sharp edge carry one normal per side); the
        ``geometry`` stage's ``normals`` buffer. Default: area-weighted vertex
        normals (:func:`area_weighted_vertex_normals`). Only used when
        ``smooth``. A zero normal (interpolated) means "use the face normal".
    smooth : bool, default True
        Refract with barycentrically interpolated shading normals (``True``)
        or with the face normals (``False``). The shading normal is flipped
        to the geometric normal's side when they disagree; if it would send
        the ray to the wrong side of the triangle the face normal is used for
        that event instead (keeps the media consistent with the geometry).
    outside_ior : float, default 1.0
        Index of the surrounding medium.
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_object: np.ndarray
    object_ior: np.ndarray
    object_absorption: np.ndarray
    normals: np.ndarray | None = None
    smooth: bool = True
    outside_ior: float = 1.0

    @classmethod
    def of(cls, geom, normals=None, smooth=True, outside_ior=1.0):
        """The :class:`ExactMesh` of a scene's merged objects (:func:`refraction_ref.meshes.scene_geometry`).

        Parameters
        ----------
        geom : Geometry
        normals, smooth, outside_ior
            As the attributes (the ``geometry`` stage's ``normals`` and ``smooth`` buffers).

        Returns
        -------
        ExactMesh
        """
        return cls(geom.vertices, geom.faces, geom.face_object, geom.ior, geom.absorption, normals, bool(smooth),
                   float(outside_ior))


@nb.njit(cache=True, parallel=True)
def _max_unit_error(d):
    # max | |d_k| - 1 | over the rays, on every thread (a check: any order of the max is the same)
    e = 0.0
    for k in nb.prange(d.shape[0]):
        x, y, z = d[k, 0], d[k, 1], d[k, 2]
        e = max(e, abs(math.sqrt(x * x + y * y + z * z) - 1.0))
    return e



def _checked_mesh(mesh):
    """``mesh``'s arrays as the kernels take them, after checking them: shapes, finiteness, ranges.

    These are :func:`trace_exact`'s public arguments, which any caller may give; a scene's
    geometry meets them by construction (its objects and materials are checked when the
    scene is loaded), so on the ``exact`` method's path they are cheap checks of arrays, not a
    second validation of knobs.
    """
    v = np.asarray(mesh.vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("vertices contain non-finite values (NaN or inf)")
    f = np.asarray(mesh.faces)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {f.shape}")
    if f.shape[0] == 0:
        raise ValueError("faces is empty")
    if not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be integers, got dtype {f.dtype}")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"faces index out of range [0, {len(v)})")
    f = f.astype(np.int64)
    fo = np.asarray(mesh.face_object)
    if fo.shape != (len(f),):
        raise ValueError(f"face_object must have shape ({len(f)},), got {fo.shape}")
    if not np.issubdtype(fo.dtype, np.integer):
        raise ValueError(f"face_object must be integers, got dtype {fo.dtype}")
    ior = np.asarray(mesh.object_ior, dtype=np.float64)
    if ior.ndim != 1 or len(ior) == 0:
        raise ValueError(f"object_ior must have shape (K,), got {ior.shape}")
    k = len(ior)
    if fo.min() < 0 or fo.max() >= k:
        raise ValueError(f"face_object values must lie in [0, {k}) (K = len(object_ior))")
    fo = fo.astype(np.int64)
    if not np.all(np.isfinite(ior)) or np.any(ior <= 0):
        raise ValueError("object_ior must be finite and > 0")
    absorption = np.asarray(mesh.object_absorption, dtype=np.float64)
    if absorption.shape != (k, 3):
        raise ValueError(f"object_absorption must have shape ({k}, 3), got {absorption.shape}")
    if not np.all(np.isfinite(absorption)) or np.any(absorption < 0):
        raise ValueError("object_absorption must be finite and >= 0")
    outside_ior = mesh.outside_ior
    if not (np.isfinite(outside_ior) and outside_ior > 0):
        raise ValueError(f"outside_ior must be finite and > 0, got {outside_ior}")
    normals = None
    if mesh.normals is not None:
        normals = np.asarray(mesh.normals, dtype=np.float64)
        if normals.shape != v.shape and normals.shape != (len(f), 3, 3):
            raise ValueError(f"normals must have shape {v.shape} (per vertex) or {(len(f), 3, 3)} "
                             f"(per corner), got {normals.shape}")
        if not np.all(np.isfinite(normals)):
            raise ValueError("normals contain non-finite values")
    return ExactMesh(v, f, fo, ior, absorption, normals, bool(mesh.smooth), float(outside_ior))


def _checked_rays(origins, dirs):
    """``origins`` and ``dirs`` as float64 arrays, after checking them (shapes, finite, unit directions)."""
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(dirs, dtype=np.float64)
    if o.ndim != 2 or o.shape[1] != 3:
        raise ValueError(f"origins must have shape (N, 3), got {o.shape}")
    if d.shape != o.shape:
        raise ValueError(f"dirs must have the shape of origins {o.shape}, got {d.shape}")
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))):
        raise ValueError("origins and dirs must be finite")
    if len(d) and _max_unit_error(np.ascontiguousarray(d)) > 1e-6:
        raise ValueError("dirs must be unit vectors (|d| - 1 > 1e-6)")
    return o, d


def _checked_settings(mesh, max_bounces, record, epsilon, chunk_size):
    """:class:`~refraction_ref.exact.bounce.ExactSettings` of a checked mesh and trace_exact's counts.

    ``max_bounces`` and ``record`` are checked as public arguments (the scene's ``exact`` block
    checked its own, tighter); 32767 is the int16 counts' limit.
    """
    if int(max_bounces) != max_bounces or not (0 <= max_bounces <= np.iinfo(np.int16).max):
        raise ValueError(f"max_bounces must be an integer in [0, 32767], got {max_bounces}")
    chunk_size = int(chunk_size)
    if chunk_size < 1:
        raise ValueError("chunk_size must be >= 1")
    epsilon = _epsilon(mesh.vertices, epsilon)
    if int(record) != record or record < 0:
        raise ValueError(f"record must be an integer >= 0, got {record!r}")
    per_corner = mesh.normals is not None and mesh.normals.ndim == 3
    return ExactSettings(int(max_bounces), int(record), epsilon, mesh.smooth, bool(per_corner), mesh.outside_ior,
                         chunk_size)


def trace_exact(mesh, origins, dirs, *, max_bounces=EXACT_DEFAULTS["max_bounces"], record=EXACT_DEFAULTS["record"],
                epsilon=None, chunk_size=HIT_CHUNK, progress=False) -> dict:
    """Trace rays through a triangle scene, refracting at every interface.

    Each ray is intersected with the real triangles: Embree (float32) finds
    the nearest triangle, then the hit distance and barycentrics are
    recomputed in float64 with Möller–Trumbore [3]_ on that triangle. At each
    hit the ray is refracted with :func:`refraction_ref.optics.refract`
    (Snell's law [1]_ [2]_; no Fresnel split: the whole ray is transmitted);
    under total internal reflection (TIR) it takes the mirror direction and
    stays in the same medium. This is the exact reference for the image-space
    method of Chaudhari (2008) [4]_ (docs/oracle.md, "Per-pixel keys").

    Inside/outside is decided by the geometric facing of the hit triangle
    (outward, counter-clockwise winding is assumed): ``dot(d, Ng) < 0``
    means the ray enters object ``face_object[f]`` (index goes from the
    current medium to ``object_ior[k]``); ``> 0`` means it leaves (index goes
    to ``outside_ior``). Rays start in the outside medium; objects are
    assumed not to be nested. Deterministic whatever the thread count (see
    the module's docstring).

    Parameters
    ----------
    mesh : ExactMesh
        The triangles, their objects' media and the shading normals
        (:meth:`ExactMesh.of` a scene's geometry).
    origins, dirs : (N, 3) array_like of float
        Ray origins (outside every object) and unit directions.
    max_bounces : int, default 64
        Maximum number of surface events (refractions + TIR reflections),
        ``exact.max_bounces``. After that many events one more intersection
        query decides whether the ray exits (status 1) or is stopped (status 2 / 3).
    record : int, default 0
        Keep the first ``record`` events of every path in ``path_pos`` and
        ``path_dir`` (``exact.record``); 0 records nothing (and adds no keys).
    epsilon : float, optional
        Origin offset of the float32 Embree query against self-intersection
        (along the new direction and the face normal, to the side the ray
        leaves to). Default ``1e-5 * scale``, ``scale`` the larger of the
        bounding-box diagonal and the largest absolute coordinate. Distances
        and hit points are recomputed in float64 from the un-offset point.
    chunk_size : int, default 8192
        Rays per Embree call and per chunk of a bounce, on up to
        ``numba.get_num_threads()`` threads; results depend on neither.
    progress : bool, default False
        Show a tqdm progress bar over bounces.

    Returns
    -------
    dict of ndarray, N rows each
        ``hit`` (bool): the first ray hit a triangle. ``status`` (int8,
        :mod:`refraction_ref.status`): 0 ``MISSED``, 1 ``EXITED``, 2 ``LIMIT``
        (stopped at the bounce limit), 3 ``TIR`` (the same, TIR as last
        event), 4 ``LOST`` (non-finite direction; should not happen).
        ``exit_pos`` (N, 3): where the ray left (NaN unless status 1).
        ``exit_dir`` (N, 3): the direction after the last event (status 1),
        ``dirs`` (status 0), NaN otherwise. ``last_dir`` (N, 3): the direction
        at the end (the one before the failure for status 4). ``hit_pos``
        (N, 3), ``first_face`` (N,) int64: first hit point (NaN on miss) and
        face (-1). ``first_normal``, ``first_dir`` (N, 3): the shading normal
        used at the first hit (on the geometric normal's side) and the
        direction after it (NaN on miss). ``interfaces`` (int16): refractions
        (TIR not counted). ``bounces`` (int16): surface events.
        ``path_length``: length travelled inside objects. ``transmittance``
        (N, 3): the product over segments inside object ``k`` of
        ``exp(-absorption_k * length * ior_k)``
        (:func:`refraction_ref.optics.beer_lambert`). ``leaked`` (bool): the
        ray escaped while inside an object (an open or badly wound mesh;
        status still 1). With ``record=K > 0``: ``path_pos``, ``path_dir``
        (N, K, 3), row ``k`` the ``k``-th event's float64 point and the
        direction after it (row 0: ``hit_pos``, ``first_dir``); a lost event
        keeps its point with a NaN direction; rows past the path's events are
        NaN; for an exited ray with at most ``K`` events the last row is
        ``exit_pos`` and ``exit_dir``, bit for bit.

    Raises
    ------
    ValueError
        On malformed input: wrong shapes, non-finite vertices, ``ior <= 0``,
        negative absorption, face indices out of range, non-unit directions.

    References
    ----------
    .. [1] T. Whitted, "An Improved Illumination Model for Shaded Display",
       Commun. ACM 23(6), 1980.
    .. [2] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*,
       3rd ed., §8.2.
    .. [3] T. Möller, B. Trumbore, "Fast, Minimum Storage Ray/Triangle
       Intersection", J. Graphics Tools 2(1), 1997.
    .. [4] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §3.6-3.8 (the quantities
       reproduced; docs/oracle.md, "The exact reference").
    """
    mesh = _checked_mesh(mesh)
    o, d = _checked_rays(origins, dirs)
    settings = _checked_settings(mesh, max_bounces, record, epsilon, chunk_size)
    if mesh.smooth and mesh.normals is None:
        mesh = mesh._replace(normals=area_weighted_vertex_normals(mesh.vertices, mesh.faces))
    tables = _face_tables(mesh, settings)
    rays, outputs = _allocate(d, settings.record)
    _run_bounces(mesh, o, settings, tables, rays, outputs, progress)
    assert not np.any(rays.status == ACTIVE)
    res = {"hit": rays.status != MISSED, "status": rays.status}
    res.update({k: getattr(outputs, k) for k in ("exit_pos", "exit_dir", "last_dir", "hit_pos", "first_face",
                                                 "first_normal", "first_dir")})
    res.update({"interfaces": rays.interfaces, "bounces": rays.bounces, "path_length": rays.path_length,
                "transmittance": outputs.transmittance, "leaked": outputs.leaked})
    if settings.record:
        res["path_pos"] = outputs.path_pos
        res["path_dir"] = outputs.path_dir
    return res


def _epsilon(v, epsilon):
    """The query offset: ``epsilon``, or ``1e-5`` of the scene's scale (:func:`trace_exact`)."""
    if epsilon is None:
        lo, hi = bounds(v)  # v.min(axis=0), v.max(axis=0) in one pass (NumPy's is ~50x slower on (N, 3))
        scale = max(float(np.linalg.norm(hi - lo)), float(np.abs(v).max()), 1e-30)
        epsilon = 1e-5 * scale
    epsilon = float(epsilon)
    if not (np.isfinite(epsilon) and epsilon >= 0):
        raise ValueError("epsilon must be finite and >= 0")
    return epsilon


def _face_tables(mesh, settings):
    """The per-face tables of the bounces (:class:`~refraction_ref.exact.bounce.ExactFaces`), on every thread."""
    v, f = mesh.vertices, mesh.faces
    nf = len(f)
    v0_all, e1_all, e2_all, ng_all = np.empty((nf, 3)), np.empty((nf, 3)), np.empty((nf, 3)), np.empty((nf, 3))
    run_chunks(lambda a, b: face_rows(a, b, v, f, v0_all, e1_all, e2_all, ng_all), nf, chunk_length(nf, 1 << 15))
    # shading normals: per vertex (V, 3) or per corner (F, 3, 3); the other is a dummy
    vn = mesh.normals
    vn_v = np.ascontiguousarray(vn) if settings.smooth and not settings.per_corner else np.zeros((1, 3))
    vn_c = np.ascontiguousarray(vn) if settings.smooth and settings.per_corner else np.zeros((1, 3, 3))
    # index of refraction of each medium; the outside medium is the last entry
    med_ior = np.append(mesh.object_ior, settings.outside_ior)
    return ExactFaces(v0_all, e1_all, e2_all, ng_all, f, vn_v, vn_c, mesh.face_object, mesh.object_ior, med_ior)


def _allocate(d, record):
    """The per-ray arrays, unfilled: the first bounce's chunks fill them
    (:func:`~refraction_ref.exact.bounce.init_rows`)."""
    n = len(d)
    v3 = lambda: np.empty((n, 3))  # noqa: E731
    rays = ExactRayState(d, v3(), v3(), v3(), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int8),
                         np.empty(n, dtype=bool), np.empty(n, dtype=np.int16), np.empty(n, dtype=np.int16),
                         np.empty(n))
    if record:
        path_pos = np.empty((n, record, 3))
        path_dir = np.empty((n, record, 3))
    else:  # never written (bounce < record is never true)
        path_pos = path_dir = np.empty((1, 1, 3))
    outputs = ExactOutputs(v3(), v3(), v3(), v3(), np.empty(n, dtype=np.int64), v3(), v3(), np.empty(n, dtype=bool),
                           path_pos, path_dir, v3())
    return rays, outputs


def _run_bounces(mesh, o, settings, tables, st, out, progress):
    """Every bounce: the rays still travelling, in fixed chunks of ``chunk_size`` on the thread pool.

    A chunk is queried with Embree (embreex releases the GIL while tracing), bounced by
    :func:`~refraction_ref.exact.bounce.bounce_rows` (no GIL either), then its Beer-Lambert factors
    multiplied in (Chaudhari 2008, §3.8).
    """
    n = len(o)
    ab = mesh.object_absorption
    scene = mesh_scene(mesh.vertices, mesh.faces) if n else None
    # per-bounce work arrays, rows [0, len(active)) used
    org32 = np.empty((n, 3), np.float32)
    dir32 = np.empty((n, 3), np.float32)
    prim = np.empty(n, np.int32)
    tfar = np.empty(n, np.float32)
    bu = np.empty(n, np.float32)
    bv = np.empty(n, np.float32)
    seg = np.empty(n)
    seg_obj = np.empty(n, np.int64)
    absorbing = bool(np.any(ab > 0))  # else exp(-0) = 1 leaves the transmittance as it is
    ior, trans = tables.ior, out.transmittance

    bar = None
    if progress:
        from tqdm.auto import tqdm  # deferred: only for a progress bar

        bar = tqdm(total=settings.max_bounces + 1, desc="trace_exact", unit="bounce")
    active = np.arange(n, dtype=np.int64)
    for bounce in range(settings.max_bounces + 1):
        if bounce:
            active = active[st.status[active] == ACTIVE]
        m = len(active)
        if bar is not None:
            bar.set_postfix(active=m)
        if m == 0:
            break
        hits = ExactHits(active, prim, tfar, bu, bv, seg, seg_obj)

        def chunk(a, b, bounce=bounce, active=active, hits=hits):
            # rows [a, b) of the active rays: float32 queries, Embree, the float64 bounce
            if bounce == 0:  # active is 0..n-1: rows [a, b) are rays [a, b)
                init_rows(a, b, o, st, out)
            query_rows(a, b, active, st.pos, st.dirn, st.side, settings.epsilon, bounce == 0, org32, dir32)
            res = scene.run(org32[a:b], dir32[a:b], output=1)
            prim[a:b] = res["primID"]
            tfar[a:b] = res["tfar"]
            bu[a:b] = res["u"]
            bv[a:b] = res["v"]
            bounce_rows(a, b, bounce, settings, tables, hits, st, out)
            if absorbing:  # Beer-Lambert with NumPy's exp, the one of optics.beer_lambert
                k = seg_obj[a:b]
                sel = np.flatnonzero(k >= 0)
                if len(sel):
                    k = k[sel]
                    trans[active[a:b][sel]] *= optics.beer_lambert(ab[k], seg[a:b][sel], ior[k])

        run_chunks(chunk, m, chunk_length(m, settings.chunk_size))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
