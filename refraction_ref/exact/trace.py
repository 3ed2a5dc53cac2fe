"""Exact multi-interface Snell tracer through the actual triangles.

This is the ground-truth oracle for the image-space approximations of
Chaudhari (2008): every ray is intersected with the real triangle mesh
(Embree for the search, float64 Möller–Trumbore for the hit itself) and
refracted by Snell's law at *every* interface it crosses, with total internal
reflection, until it leaves the scene or a bounce limit is reached.

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
Numba kernel that releases the GIL too. The kernels take their arrays as
small named tuples (:class:`_Rays`, :class:`_Outputs`, :class:`_Mesh`,
:class:`_Hits`, :class:`_Settings`).

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
import warnings
from typing import NamedTuple

import numba as nb
import numpy as np

from .. import optics
from ..embree import HIT_CHUNK, chunk_length, mesh_scene, run_chunks
from ..meshes import CREASE_MARGIN, bounds, face_corner_normals
from ..status import EXITED, LIMIT, LOST, MISSED, TIR

__all__ = [
    "trace_exact",
    "area_weighted_vertex_normals",
    "MeshNormals",
    "mesh_normals",
    "STATUS_MISSED",
    "STATUS_EXITED",
    "STATUS_BOUNCE_LIMIT",
    "STATUS_BOUNCE_LIMIT_TIR",
    "STATUS_LOST",
]

# the historical names of this module, aliases of :mod:`refraction_ref.status`
STATUS_MISSED = MISSED
STATUS_EXITED = EXITED
STATUS_BOUNCE_LIMIT = LIMIT
STATUS_BOUNCE_LIMIT_TIR = TIR
STATUS_LOST = LOST

_CHUNK = HIT_CHUNK
_OUTSIDE = -1  # medium index of the surrounding medium
_ACTIVE = -1  # status value of a ray still being traced (internal)


def area_weighted_vertex_normals(vertices, faces):
    """Area-weighted unit vertex normals of a triangle mesh.

    Each vertex normal is the normalised sum of the (unnormalised) face
    normals ``(v1 - v0) x (v2 - v0)`` of the faces that use it, i.e. the sum
    of unit face normals weighted by twice the face area.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Counter-clockwise (outward) triangles.

    Returns
    -------
    (V, 3) ndarray of float64
        Unit normals; all-zero rows for vertices used by no face of non-zero
        area (the tracer then falls back to the face normal).

    References
    ----------
    .. [1] N. Max, "Weights for Computing Vertex Normals from Facet Normals",
       *Journal of Graphics Tools* 4(2), 1-6, 1999 (area weights).
    .. [2] docs/oracle.md, Conventions (vertex and shading normals).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    vn = np.zeros_like(v)
    for c in range(3):
        for j in range(3):
            vn[:, c] += np.bincount(f[:, j], weights=fn[:, c], minlength=len(v))
    norm = np.linalg.norm(vn, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        vn = np.where(norm > 0, vn / np.where(norm > 0, norm, 1.0), 0.0)
    return vn


class _Adjacency(NamedTuple):
    """Faces around each vertex: ``incident[start[v]:start[v + 1]]`` lists the faces that use
    vertex ``v`` in corner order (face index ascending, a face that uses ``v`` twice listed twice),
    the order ``np.argsort(faces.ravel(), kind="stable") // 3`` gives."""

    faces: np.ndarray  # (F, 3) int64
    start: np.ndarray  # (V + 1,) int64
    incident: np.ndarray  # (3 F,) int64


class _FaceNormals(NamedTuple):
    """Per face: the unnormalised normal ``(v1 - v0) x (v2 - v0)``, its length and the unit normal
    (zero for a face of zero area)."""

    fn: np.ndarray  # (F, 3)
    ln: np.ndarray  # (F,)
    un: np.ndarray  # (F, 3)


class MeshNormals(NamedTuple):
    """What the exact reference's ``geometry`` stage derives from the triangles (:func:`mesh_normals`).

    Attributes
    ----------
    vertex : (V, 3) float64
        Area-weighted unit vertex normals, bit for bit those of
        :func:`refraction_ref.meshes.vertex_normals`.
    corner : (F, 3, 3) float64 or None
        Crease normals, bit for bit those of :func:`refraction_ref.meshes.corner_normals`
        (None when not asked for).
    edge_angles : (E,) float64
        The angles of :func:`refraction_ref.meshes.crease_edge_angles`, the same values
        in another order (by the edge's lower vertex).
    """

    vertex: np.ndarray
    corner: np.ndarray | None
    edge_angles: np.ndarray


@nb.njit(cache=True)
def _adjacency_kernel(f, nv, start, incident):
    # a counting sort of the corners by vertex: stable, hence the faces of a vertex in index
    # order, in O(F) where NumPy's stable argsort is O(F log F) on one thread
    fill = np.zeros(nv, np.int64)
    for c in range(f.shape[0] * 3):
        fill[f[c // 3, c % 3]] += 1
    start[0] = 0
    for v in range(nv):
        start[v + 1] = start[v] + fill[v]
        fill[v] = start[v]
    for c in range(f.shape[0] * 3):
        v = f[c // 3, c % 3]
        incident[fill[v]] = c // 3
        fill[v] += 1


@nb.njit(cache=True, parallel=True)
def _face_normals_kernel(v, f, fn, ln, un):
    # np.cross and np.linalg.norm's operations, in their order: the same bits
    for k0 in nb.prange(f.shape[0]):
        k = np.int64(k0)
        a, b, c = f[k, 0], f[k, 1], f[k, 2]
        e1x, e1y, e1z = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
        e2x, e2y, e2z = v[c, 0] - v[a, 0], v[c, 1] - v[a, 1], v[c, 2] - v[a, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        fn[k, 0] = nx
        fn[k, 1] = ny
        fn[k, 2] = nz
        n = math.sqrt(nx * nx + ny * ny + nz * nz)
        ln[k] = n
        if n > 0.0:
            un[k, 0] = nx / n
            un[k, 1] = ny / n
            un[k, 2] = nz / n
        else:
            un[k, 0] = 0.0
            un[k, 1] = 0.0
            un[k, 2] = 0.0


@nb.njit(cache=True, parallel=True)
def _vertex_normals_kernel(adj, fnt, out):
    # a gather per vertex instead of np.add.at's scatter, summing in np.add.at's order (every
    # face with the vertex as corner 0, in face order, then corner 1, then corner 2)
    f = adj.faces
    start = adj.start
    incident = adj.incident
    fn = fnt.fn
    for v0 in nb.prange(start.shape[0] - 1):
        v = np.int64(v0)
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for k in range(3):
            last = -1
            for p in range(start[v], start[v + 1]):
                g = incident[p]
                if g == last:
                    continue
                last = g
                if f[g, k] == v:
                    sx += fn[g, 0]
                    sy += fn[g, 1]
                    sz += fn[g, 2]
        n = math.sqrt(sx * sx + sy * sy + sz * sz)
        if n > 0.0:
            out[v, 0] = sx / n
            out[v, 1] = sy / n
            out[v, 2] = sz / n
        else:
            out[v, 0] = 0.0
            out[v, 1] = 0.0
            out[v, 2] = 0.0


@nb.njit(cache=True, parallel=True)
def _corner_normals_kernel(adj, fnt, cos_t, out):
    # meshes.face_corner_normals with the faces shared among threads: each writes only its faces
    f = adj.faces
    start = adj.start
    incident = adj.incident
    fn = fnt.fn
    un = fnt.un
    for f0 in nb.prange(f.shape[0]):
        face_corner_normals(np.int64(f0), f, fn, un, start, incident, cos_t, out)


@nb.njit(cache=True, parallel=True)
def _edge_dots_kernel(adj, fnt, dots, hi, own):
    # every edge occurrence (a, b), a <= b, is met once at its lower vertex a; an edge that exactly
    # two faces of non-zero area share gets the dot of their unit normals in slot start[a] + j
    # (a face meets at most two such edges at a, a pair takes two: at most deg(a) pairs), NaN elsewhere
    f = adj.faces
    start = adj.start
    incident = adj.incident
    ln = fnt.ln
    un = fnt.un
    for a0 in nb.prange(start.shape[0] - 1):
        a = np.int64(a0)
        base = start[a]
        for j in range(start[a + 1] - start[a]):
            dots[base + j] = np.nan
        # the edges met at a, (other end, face), in the scratch rows [2 start[a], 2 start[a + 1])
        # (at most two per face): no allocation inside the parallel loop
        s0 = 2 * start[a]
        cnt = 0
        last = -1
        for p in range(start[a], start[a + 1]):
            g = incident[p]
            if g == last:
                continue
            last = g
            for e in range(3):
                x = f[g, e]
                y = f[g, (e + 1) % 3]
                if min(x, y) != a:
                    continue
                hi[s0 + cnt] = max(x, y)
                own[s0 + cnt] = g
                cnt += 1
        out = 0
        for i in range(s0, s0 + cnt):
            seen = False
            for i2 in range(s0, i):
                if hi[i2] == hi[i]:
                    seen = True
                    break
            if seen:
                continue
            n = 1
            other = -1
            for i2 in range(i + 1, s0 + cnt):
                if hi[i2] == hi[i]:
                    n += 1
                    other = own[i2]
            if n != 2:
                continue  # boundary (1) or non-manifold (> 2): no angle
            g1 = own[i]
            if ln[g1] > 0.0 and ln[other] > 0.0:
                # NumPy's einsum('ij,ij->i') order (see _dot3); the product commutes
                dots[base + out] = _dot3(un[g1, 0], un[g1, 1], un[g1, 2], un[other, 0], un[other, 1], un[other, 2])
                out += 1


def _adjacency(v, f):
    start = np.empty(len(v) + 1, np.int64)
    incident = np.empty(3 * len(f), np.int64)
    _adjacency_kernel(f, len(v), start, incident)
    return _Adjacency(f, start, incident)


def mesh_normals(vertices, faces, crease_deg=None):
    """Vertex normals, crease normals and edge angles of a mesh on every thread, deterministically.

    The parallel form of :func:`refraction_ref.meshes.vertex_normals`,
    :func:`~refraction_ref.meshes.corner_normals` and
    :func:`~refraction_ref.meshes.crease_edge_angles` (the exact reference's
    ``geometry`` stage): one counting sort of the corners by vertex, then
    kernels over faces or vertices that each write only their own rows and
    sum in the serial functions' order, so the arrays are bit-identical to
    theirs whatever the thread count.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
    faces : (F, 3) array_like of int
        Counter-clockwise (outward) triangles, ``F >= 1``.
    crease_deg : float, optional
        The crease angle of the corner normals, in ``(0, 180]``; None: no corner normals.

    Returns
    -------
    MeshNormals

    References
    ----------
    .. [1] N. Max, "Weights for Computing Vertex Normals from Facet Normals",
       *Journal of Graphics Tools* 4(2), 1-6, 1999.
    .. [2] H. Hoppe et al., "Piecewise Smooth Surface Reconstruction",
       *Proc. SIGGRAPH 94*, 295-302, 1994 (crease edges).
    """
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    fnt = _FaceNormals(np.empty((len(f), 3)), np.empty(len(f)), np.empty((len(f), 3)))
    _face_normals_kernel(v, f, fnt.fn, fnt.ln, fnt.un)
    adj = _adjacency(v, f)
    vn = np.empty_like(v)
    _vertex_normals_kernel(adj, fnt, vn)
    dots = np.empty(3 * len(f))
    _edge_dots_kernel(adj, fnt, dots, np.empty(2 * len(adj.incident), np.int64),
                      np.empty(2 * len(adj.incident), np.int64))
    c = np.clip(dots[~np.isnan(dots)], -1.0, 1.0)
    ang = np.degrees(np.arccos(c))  # NumPy's arccos, the one crease_edge_angles uses
    cn = None
    if crease_deg is not None:
        crease_deg = float(crease_deg)
        if not (0.0 < crease_deg <= 180.0):
            raise ValueError(f"crease_deg must lie in (0, 180], got {crease_deg}")
        cos_t = -np.inf if crease_deg >= 180.0 else float(np.cos(np.radians(crease_deg))) + CREASE_MARGIN
        cn = np.zeros((len(f), 3, 3))
        _corner_normals_kernel(adj, fnt, cos_t, cn)
    return MeshNormals(vn, cn, ang)


@nb.njit(cache=True, parallel=True)
def _max_unit_error(d):
    # max | |d_k| - 1 | over the rays, on every thread (a check: any order of the max is the same)
    e = 0.0
    for k in nb.prange(d.shape[0]):
        x, y, z = d[k, 0], d[k, 1], d[k, 2]
        e = max(e, abs(math.sqrt(x * x + y * y + z * z) - 1.0))
    return e


def _validate(vertices, faces, face_object, object_ior, object_absorption,
              origins, dirs, vertex_normals, outside_ior, max_bounces, normals_name="vertex_normals"):
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("vertices contain non-finite values (NaN or inf)")
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {f.shape}")
    if f.shape[0] == 0:
        raise ValueError("faces is empty")
    if not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be integers, got dtype {f.dtype}")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"faces index out of range [0, {len(v)})")
    f = f.astype(np.int64)
    fo = np.asarray(face_object)
    if fo.shape != (len(f),):
        raise ValueError(f"face_object must have shape ({len(f)},), got {fo.shape}")
    if not np.issubdtype(fo.dtype, np.integer):
        raise ValueError(f"face_object must be integers, got dtype {fo.dtype}")
    ior = np.asarray(object_ior, dtype=np.float64)
    if ior.ndim != 1 or len(ior) == 0:
        raise ValueError(f"object_ior must have shape (K,), got {ior.shape}")
    k = len(ior)
    if fo.min() < 0 or fo.max() >= k:
        raise ValueError(f"face_object values must lie in [0, {k}) (K = len(object_ior))")
    fo = fo.astype(np.int64)
    if not np.all(np.isfinite(ior)) or np.any(ior <= 0):
        raise ValueError("object_ior must be finite and > 0")
    ab = np.asarray(object_absorption, dtype=np.float64)
    if ab.shape != (k, 3):
        raise ValueError(f"object_absorption must have shape ({k}, 3), got {ab.shape}")
    if not np.all(np.isfinite(ab)) or np.any(ab < 0):
        raise ValueError("object_absorption must be finite and >= 0")
    if not (np.isfinite(outside_ior) and outside_ior > 0):
        raise ValueError(f"outside_ior must be finite and > 0, got {outside_ior}")
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
    if vertex_normals is not None:
        vn = np.asarray(vertex_normals, dtype=np.float64)
        if vn.shape != v.shape and vn.shape != (len(f), 3, 3):
            raise ValueError(f"{normals_name} must have shape {v.shape} (per vertex) or {(len(f), 3, 3)} "
                             f"(per corner), got {vn.shape}")
        if not np.all(np.isfinite(vn)):
            raise ValueError(f"{normals_name} contain non-finite values")
    else:
        vn = None
    if int(max_bounces) != max_bounces or not (0 <= max_bounces <= np.iinfo(np.int16).max):
        raise ValueError(f"max_bounces must be an integer in [0, 32767], got {max_bounces}")
    return v, f, fo, ior, ab, o, d, vn


def _unit(a):
    n = np.linalg.norm(a, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return a / n


@nb.njit(cache=True, inline="always")
def _dot3(ax, ay, az, bx, by, bz):
    """``a . b`` summed as ``(ax bx + az bz) + ay by``, the order in which NumPy's
    ``einsum('ij,ij->i')`` sums it (measured, NumPy 2.x on x86-64; the NumPy tracer
    of earlier versions used it), so the results stay bit-identical to that tracer."""
    return (ax * bx + az * bz) + ay * by


@nb.njit(cache=True, inline="always")
def _sign(x):
    """``np.sign``: -1, 0, 1, NaN for NaN."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    if x == 0.0:
        return 0.0
    return x


@nb.njit(cache=True, inline="always")
def _clip01(x):
    """``np.clip(x, 0, 1)`` (NaN stays NaN)."""
    if x < 0.0:
        return 0.0
    if x > 1.0:
        return 1.0
    return x


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _face_rows(lo, hi, v, faces, v0, e1, e2, ng):
    """Faces ``[lo, hi)``: first vertex, edges ``v1 - v0``, ``v2 - v0`` and the unit geometric
    normal ``e1 x e2 / |e1 x e2|`` (NaN for a face of zero area), as ``np.cross`` and
    ``np.linalg.norm`` compute them."""
    for k in range(lo, hi):
        a, b, c = faces[k, 0], faces[k, 1], faces[k, 2]
        for j in range(3):
            v0[k, j] = v[a, j]
            e1[k, j] = v[b, j] - v[a, j]
            e2[k, j] = v[c, j] - v[a, j]
        nx = e1[k, 1] * e2[k, 2] - e1[k, 2] * e2[k, 1]
        ny = e1[k, 2] * e2[k, 0] - e1[k, 0] * e2[k, 2]
        nz = e1[k, 0] * e2[k, 1] - e1[k, 1] * e2[k, 0]
        nrm = math.sqrt(nx * nx + ny * ny + nz * nz)
        ng[k, 0] = nx / nrm
        ng[k, 1] = ny / nrm
        ng[k, 2] = nz / nrm


class _Rays(NamedTuple):
    """The tracer's per-ray state, N rows each; the first bounce's chunks fill it (:func:`_init_rows`)."""

    dir0: np.ndarray  # (N, 3) the rays' given directions (read only)
    pos: np.ndarray  # (N, 3) the last surface point (the origin before the first hit)
    dirn: np.ndarray  # (N, 3) the direction after the last event
    side: np.ndarray  # (N, 3) unit face normal on the side the ray leaves to
    medium: np.ndarray  # (N,) int64 object the ray travels in, _OUTSIDE
    status: np.ndarray  # (N,) int8, _ACTIVE while traced
    last_tir: np.ndarray  # (N,) bool, the last event was a total internal reflection
    interfaces: np.ndarray  # (N,) int16
    bounces: np.ndarray  # (N,) int16
    path_length: np.ndarray  # (N,) float64


class _Outputs(NamedTuple):
    """The tracer's outputs besides :class:`_Rays` (the keys of :func:`trace_exact`'s dict)."""

    exit_pos: np.ndarray  # (N, 3)
    exit_dir: np.ndarray  # (N, 3)
    last_dir: np.ndarray  # (N, 3)
    hit_pos: np.ndarray  # (N, 3)
    first_face: np.ndarray  # (N,) int64
    first_normal: np.ndarray  # (N, 3)
    first_dir: np.ndarray  # (N, 3)
    leaked: np.ndarray  # (N,) bool
    path_pos: np.ndarray  # (N, K, 3), or a (1, 1, 3) dummy when nothing is recorded
    path_dir: np.ndarray  # (N, K, 3), or a (1, 1, 3) dummy
    transmittance: np.ndarray  # (N, 3)


class _Mesh(NamedTuple):
    """Per face: first vertex, edges, unit geometric normal (:func:`_face_rows`); the shading
    normals per vertex ``vn_v`` or per corner ``vn_c`` (the other a dummy); the media."""

    v0: np.ndarray  # (F, 3)
    e1: np.ndarray  # (F, 3)
    e2: np.ndarray  # (F, 3)
    ng: np.ndarray  # (F, 3)
    faces: np.ndarray  # (F, 3) int64
    vn_v: np.ndarray  # (V, 3) or (1, 3)
    vn_c: np.ndarray  # (F, 3, 3) or (1, 3, 3)
    face_object: np.ndarray  # (F,) int64
    ior: np.ndarray  # (K,) the objects' indices
    med_ior: np.ndarray  # (K + 1,) the media's indices, the outside medium last


class _Settings(NamedTuple):
    """The scalars of a trace."""

    max_bounces: int
    record: int
    eps: float
    smooth: bool
    per_corner: bool
    outside_ior: float


class _Hits(NamedTuple):
    """One bounce's rows ``m``: the ray ``active[m]``, Embree's answer (``prim``, ``tfar``,
    barycentrics ``bu``, ``bv``) and the segment just travelled inside an object (``seg``,
    ``seg_obj``; -1: none), for the Beer-Lambert factor."""

    active: np.ndarray  # (M,) int64
    prim: np.ndarray  # int32
    tfar: np.ndarray  # float32
    bu: np.ndarray  # float32
    bv: np.ndarray  # float32
    seg: np.ndarray  # float64
    seg_obj: np.ndarray  # int64


@nb.njit(cache=True, nogil=True)
def _init_rows(lo, hi, o, st, out):
    """Rays ``[lo, hi)``: the tracer's per-ray arrays before the first bounce (filled by the
    first bounce's chunks, in parallel, rather than by NumPy up front)."""
    d = st.dir0
    pos, dirn, side, medium, status = st.pos, st.dirn, st.side, st.medium, st.status
    last_tir, interfaces, bounces, path_length = st.last_tir, st.interfaces, st.bounces, st.path_length
    exit_pos, exit_dir, last_dir, hit_pos = out.exit_pos, out.exit_dir, out.last_dir, out.hit_pos
    first_face, first_normal, first_dir, leaked = out.first_face, out.first_normal, out.first_dir, out.leaked
    path_pos, path_dir, trans = out.path_pos, out.path_dir, out.transmittance
    for i in range(lo, hi):
        for c in range(3):
            pos[i, c] = o[i, c]
            dirn[i, c] = d[i, c]
            last_dir[i, c] = d[i, c]
            side[i, c] = 0.0
            trans[i, c] = 1.0
            exit_pos[i, c] = np.nan
            exit_dir[i, c] = np.nan
            hit_pos[i, c] = np.nan
            first_normal[i, c] = np.nan
            first_dir[i, c] = np.nan
        medium[i] = _OUTSIDE
        status[i] = _ACTIVE
        last_tir[i] = False
        interfaces[i] = 0
        bounces[i] = 0
        path_length[i] = 0.0
        first_face[i] = -1
        leaked[i] = False
        if path_pos.shape[0] == o.shape[0]:  # recording (else a dummy)
            for k in range(path_pos.shape[1]):
                for c in range(3):
                    path_pos[i, k, c] = np.nan
                    path_dir[i, k, c] = np.nan


@nb.njit(cache=True, nogil=True)
def _query_rows(lo, hi, active, pos, dirn, side, eps, first, org32, dir32):
    """Rows ``[lo, hi)``: the float32 Embree queries of the rays ``active[m]``, their origins
    pushed off the surface along the new direction and the face normal (``pos + eps (dir + side)``)
    after the first bounce."""
    for m in range(lo, hi):
        i = active[m]
        for c in range(3):
            dc = dirn[i, c]
            if first:
                org32[m, c] = np.float32(pos[i, c])
            else:
                org32[m, c] = np.float32(pos[i, c] + eps * (dc + side[i, c]))
            dir32[m, c] = np.float32(dc)


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _hit_distance(v0, e1, e2, embree_hit, fi, p, d, s, eps, bounce):
    """float64 Möller-Trumbore on the triangle ``fi`` Embree found (``embree_hit``: its float32
    ``tfar``, ``u``, ``v``): the distance ``t`` from ``p`` along ``d`` and the barycentrics ``u``,
    ``w2``. Parallel or degenerate (``t`` not finite or not positive): Embree's distance from the
    pushed-off origin (``p + eps (d + s)`` after the first bounce) and its barycentrics."""
    px, py, pz = p
    dx, dy, dz = d
    e1x, e1y, e1z = e1[fi, 0], e1[fi, 1], e1[fi, 2]
    e2x, e2y, e2z = e2[fi, 0], e2[fi, 1], e2[fi, 2]
    pvx = dy * e2z - dz * e2y
    pvy = dz * e2x - dx * e2z
    pvz = dx * e2y - dy * e2x
    det = _dot3(e1x, e1y, e1z, pvx, pvy, pvz)
    inv = 1.0 / det
    tx = px - v0[fi, 0]
    ty = py - v0[fi, 1]
    tz = pz - v0[fi, 2]
    u = _dot3(tx, ty, tz, pvx, pvy, pvz) * inv
    qx = ty * e1z - tz * e1y
    qy = tz * e1x - tx * e1z
    qz = tx * e1y - ty * e1x
    w2 = _dot3(dx, dy, dz, qx, qy, qz) * inv
    t = _dot3(e2x, e2y, e2z, qx, qy, qz) * inv
    if not math.isfinite(t) or t <= 0.0:  # parallel / degenerate: trust Embree's distance
        tf = np.float64(embree_hit[0])
        if bounce:
            hx = (px + eps * (dx + s[0])) + tf * dx
            hy = (py + eps * (dy + s[1])) + tf * dy
            hz = (pz + eps * (dz + s[2])) + tf * dz
        else:
            hx = px + tf * dx
            hy = py + tf * dy
            hz = pz + tf * dz
        t = _dot3(hx - px, hy - py, hz - pz, dx, dy, dz)
        u = np.float64(embree_hit[1])  # barycentrics of the Embree point
        w2 = np.float64(embree_hit[2])
    return t, u, w2


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _shading_normal(vn_c, vn_v, faces, fi, u, w2, ng, per_corner):
    """The unit shading normal at barycentrics ``(u, w2)`` of face ``fi``, interpolated from its
    corner (``per_corner``) or vertex normals, on the side of the geometric normal ``ng``; ``ng``
    itself where the interpolation is zero or not finite."""
    ngx, ngy, ngz = ng
    b1 = _clip01(u)
    b2 = _clip01(w2)
    b0 = _clip01(1.0 - u - w2)
    s = b0 + b1 + b2
    if not (s > 0):
        s = 1.0
    if per_corner:  # the same sum, the corner normals of face fi
        nsx = (b0 * vn_c[fi, 0, 0] + b1 * vn_c[fi, 1, 0] + b2 * vn_c[fi, 2, 0]) / s
        nsy = (b0 * vn_c[fi, 0, 1] + b1 * vn_c[fi, 1, 1] + b2 * vn_c[fi, 2, 1]) / s
        nsz = (b0 * vn_c[fi, 0, 2] + b1 * vn_c[fi, 1, 2] + b2 * vn_c[fi, 2, 2]) / s
    else:
        a0, a1, a2 = faces[fi, 0], faces[fi, 1], faces[fi, 2]
        nsx = (b0 * vn_v[a0, 0] + b1 * vn_v[a1, 0] + b2 * vn_v[a2, 0]) / s
        nsy = (b0 * vn_v[a0, 1] + b1 * vn_v[a1, 1] + b2 * vn_v[a2, 1]) / s
        nsz = (b0 * vn_v[a0, 2] + b1 * vn_v[a1, 2] + b2 * vn_v[a2, 2]) / s
    nrm = math.sqrt(nsx * nsx + nsy * nsy + nsz * nsz)
    nsx = nsx / nrm
    nsy = nsy / nrm
    nsz = nsz / nrm
    if not (math.isfinite(nsx) and math.isfinite(nsy) and math.isfinite(nsz)):
        nsx, nsy, nsz = ngx, ngy, ngz
    if _dot3(nsx, nsy, nsz, ngx, ngy, ngz) < 0.0:
        nsx, nsy, nsz = -nsx, -nsy, -nsz
    return nsx, nsy, nsz


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _refract_event(d, ns, ng, cos_g, eta, smooth):
    """Snell / TIR (:func:`refraction_ref.optics.refract3`) of ``d`` at the shading normal ``ns``.

    With shading normals a transmitted ray must keep the sign of ``d . ng`` and a reflected one
    flip it; otherwise the event is redone with the face normal ``ng``. A non-finite result
    keeps ``d`` (``lost``). Returns the new direction, ``tir``, ``lost`` and the normal used.
    """
    dx, dy, dz = d
    nsx, nsy, nsz = ns
    ngx, ngy, ngz = ng
    ndx, ndy, ndz, tir = optics.refract3(dx, dy, dz, nsx, nsy, nsz, eta)
    if smooth:
        # transmitted rays must keep the sign of d.Ng, reflected ones flip it
        sn = _sign(_dot3(ndx, ndy, ndz, ngx, ngy, ngz))
        sg = _sign(cos_g)
        wrong = (sn == sg) if tir else (sn != sg)
        if wrong:
            ndx, ndy, ndz, tir = optics.refract3(dx, dy, dz, ngx, ngy, ngz, eta)
            nsx, nsy, nsz = ngx, ngy, ngz
    lost = not (math.isfinite(ndx) and math.isfinite(ndy) and math.isfinite(ndz))
    if lost:  # keep the previous direction
        ndx, ndy, ndz = dx, dy, dz
    return ndx, ndy, ndz, tir, lost, nsx, nsy, nsz


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _bounce_rows(lo, hi, bounce, cfg, mesh, hits, st, out):
    """One bounce of the rays ``hits.active[m]``, rows ``m`` in ``[lo, hi)``, given Embree's hits
    in those rows.

    float64 Möller-Trumbore on Embree's triangle (:func:`_hit_distance`), Snell / TIR
    (:func:`_refract_event`) with the interpolated shading normal (:func:`_shading_normal`),
    and the bookkeeping of the tracer's per-ray arrays. Writes only the rows of its own rays,
    so any split of the rows over threads gives the same result. Serial and without the GIL:
    one chunk of a thread pool (:func:`refraction_ref.embree.run_chunks`).

    The dot products are summed as NumPy's ``einsum('ij,ij->i')`` sums them
    (:func:`_dot3`) and every other operation is the one of the NumPy tracer
    of earlier versions, in its order, so the results are bit-identical to it.
    """
    max_bounces, record, eps = cfg.max_bounces, cfg.record, cfg.eps
    smooth, per_corner, outside_ior = cfg.smooth, cfg.per_corner, cfg.outside_ior
    ng_all, fo, ior, med_ior = mesh.ng, mesh.face_object, mesh.ior, mesh.med_ior
    v0_all, e1_all, e2_all, faces, vn_v, vn_c = mesh.v0, mesh.e1, mesh.e2, mesh.faces, mesh.vn_v, mesh.vn_c
    active, prim, seg, seg_obj = hits.active, hits.prim, hits.seg, hits.seg_obj
    tfar, bu, bv = hits.tfar, hits.bu, hits.bv
    pos, dirn, side, medium, status = st.pos, st.dirn, st.side, st.medium, st.status
    last_tir, interfaces, bounces, path_length = st.last_tir, st.interfaces, st.bounces, st.path_length
    last_dir, hit_pos, first_face = out.last_dir, out.hit_pos, out.first_face
    first_normal, first_dir = out.first_normal, out.first_dir
    exit_pos, exit_dir, leaked, dir0 = out.exit_pos, out.exit_dir, out.leaked, st.dir0
    path_pos, path_dir = out.path_pos, out.path_dir
    n_out = med_ior.shape[0] - 1  # med_ior's entry of the outside medium
    for m in range(lo, hi):
        i = active[m]
        seg_obj[m] = -1
        seg[m] = 0.0
        px, py, pz = pos[i, 0], pos[i, 1], pos[i, 2]
        dx, dy, dz = dirn[i, 0], dirn[i, 1], dirn[i, 2]
        fi = np.int64(prim[m])
        if fi < 0:  # no further hit
            if bounce == 0:  # missed
                status[i] = MISSED
                for c in range(3):
                    exit_dir[i, c] = dir0[i, c]
            else:  # exited
                status[i] = EXITED
                for c in range(3):
                    exit_pos[i, c] = pos[i, c]
                    exit_dir[i, c] = dirn[i, c]
                leaked[i] = medium[i] != _OUTSIDE
            for c in range(3):
                last_dir[i, c] = dirn[i, c]
            continue
        t, u, w2 = _hit_distance(v0_all, e1_all, e2_all, (tfar[m], bu[m], bv[m]), fi, (px, py, pz),
                                 (dx, dy, dz), (side[i, 0], side[i, 1], side[i, 2]), eps, bounce)
        xx = px + t * dx
        xy = py + t * dy
        xz = pz + t * dz
        if bounce == 0:
            hit_pos[i, 0] = xx
            hit_pos[i, 1] = xy
            hit_pos[i, 2] = xz
            first_face[i] = fi
        if bounce == max_bounces:  # budget spent, and there is a further hit
            status[i] = TIR if last_tir[i] else LIMIT
            for c in range(3):
                last_dir[i, c] = dirn[i, c]
            continue

        # --- path length on the segment just travelled (Beer-Lambert: trace_exact's chunks) --
        med = medium[i]
        if med != _OUTSIDE:
            path_length[i] += t
            seg[m] = t
            seg_obj[m] = med

        # --- normals, Snell (optics.refract3) ----------------------------------
        ngx, ngy, ngz = ng_all[fi, 0], ng_all[fi, 1], ng_all[fi, 2]
        cos_g = _dot3(dx, dy, dz, ngx, ngy, ngz)
        entering = cos_g < 0.0
        if smooth:
            nsx, nsy, nsz = _shading_normal(vn_c, vn_v, faces, fi, u, w2, (ngx, ngy, ngz), per_corner)
        else:
            nsx, nsy, nsz = ngx, ngy, ngz
        obj = fo[fi]
        n1 = med_ior[n_out] if med == _OUTSIDE else med_ior[med]
        n2 = ior[obj] if entering else outside_ior
        eta = n1 / n2
        ndx, ndy, ndz, tir, lost, nsx, nsy, nsz = _refract_event((dx, dy, dz), (nsx, nsy, nsz), (ngx, ngy, ngz),
                                                                 cos_g, eta, smooth)
        if bounce < record:  # every active ray has had `bounce` events: this is row `bounce`
            path_pos[i, bounce, 0] = xx
            path_pos[i, bounce, 1] = xy
            path_pos[i, bounce, 2] = xz
            path_dir[i, bounce, 0] = np.nan if lost else ndx
            path_dir[i, bounce, 1] = np.nan if lost else ndy
            path_dir[i, bounce, 2] = np.nan if lost else ndz

        # --- bookkeeping ----------------------------------------------------
        if bounce == 0:
            first_normal[i, 0] = nsx
            first_normal[i, 1] = nsy
            first_normal[i, 2] = nsz
            first_dir[i, 0] = ndx
            first_dir[i, 1] = ndy
            first_dir[i, 2] = ndz
        crossed = not tir and not lost
        if crossed:
            medium[i] = obj if entering else _OUTSIDE
            interfaces[i] += 1
        bounces[i] += 1
        last_tir[i] = tir
        pos[i, 0] = xx
        pos[i, 1] = xy
        pos[i, 2] = xz
        dirn[i, 0] = ndx
        dirn[i, 1] = ndy
        dirn[i, 2] = ndz
        last_dir[i, 0] = ndx
        last_dir[i, 1] = ndy
        last_dir[i, 2] = ndz
        sgn = 1.0 if _dot3(ndx, ndy, ndz, ngx, ngy, ngz) >= 0.0 else -1.0
        side[i, 0] = ngx * sgn
        side[i, 1] = ngy * sgn
        side[i, 2] = ngz * sgn
        if lost:
            status[i] = LOST


def trace_exact(vertices, faces, face_object, object_ior, object_absorption,
                origins, dirs, *, normals=None, smooth=True,
                outside_ior=1.0, max_bounces=64, progress=False,
                epsilon=None, chunk_size=_CHUNK, record=0, vertex_normals=None) -> dict:
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
    origins, dirs : (N, 3) array_like of float
        Ray origins (outside every object) and unit directions.
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
    max_bounces : int, default 64
        Maximum number of surface events (refractions + TIR reflections).
        After that many events one more intersection query decides whether
        the ray exits (status 1) or is stopped (status 2 / 3).
    progress : bool, default False
        Show a tqdm progress bar over bounces.
    epsilon : float, optional
        Origin offset of the float32 Embree query against self-intersection
        (along the new direction and the face normal, to the side the ray
        leaves to). Default ``1e-5 * scale``, ``scale`` the larger of the
        bounding-box diagonal and the largest absolute coordinate. Distances
        and hit points are recomputed in float64 from the un-offset point.
    chunk_size : int, default 8192
        Rays per Embree call and per chunk of a bounce, on up to
        ``numba.get_num_threads()`` threads; results depend on neither.
    record : int, default 0
        Keep the first ``record`` events of every path in ``path_pos`` and
        ``path_dir``; 0 records nothing (and adds no keys).
    vertex_normals : array_like, optional
        Deprecated: the former name of ``normals`` (a DeprecationWarning).

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
        negative absorption, face indices out of range, non-unit directions,
        both ``normals`` and ``vertex_normals``.

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
    normals, name = _normals_argument(normals, vertex_normals)
    v, f, fo, ior, ab, o, d, vn = _validate(
        vertices, faces, face_object, object_ior, object_absorption,
        origins, dirs, normals, outside_ior, max_bounces, name)
    max_bounces = int(max_bounces)
    chunk_size = int(chunk_size)
    if chunk_size < 1:
        raise ValueError("chunk_size must be >= 1")
    if smooth and vn is None:
        vn = area_weighted_vertex_normals(v, f)
    epsilon = _epsilon(v, epsilon)
    if int(record) != record or record < 0:
        raise ValueError(f"record must be an integer >= 0, got {record!r}")
    record = int(record)
    per_corner = vn is not None and vn.ndim == 3
    cfg = _Settings(max_bounces, record, epsilon, bool(smooth), bool(per_corner), float(outside_ior))
    mesh = _mesh_tables(v, f, fo, ior, vn, cfg)
    st, out = _allocate(d, record)
    _run_bounces(v, f, o, ab, cfg, mesh, st, out, chunk_size, progress)
    assert not np.any(st.status == _ACTIVE)
    res = {"hit": st.status != MISSED, "status": st.status}
    res.update({k: getattr(out, k) for k in ("exit_pos", "exit_dir", "last_dir", "hit_pos", "first_face",
                                             "first_normal", "first_dir")})
    res.update({"interfaces": st.interfaces, "bounces": st.bounces, "path_length": st.path_length,
                "transmittance": out.transmittance, "leaked": out.leaked})
    if record:
        res["path_pos"] = out.path_pos
        res["path_dir"] = out.path_dir
    return res


def _normals_argument(normals, vertex_normals):
    """``normals``, or the deprecated ``vertex_normals`` with a warning; and the name to report."""
    if vertex_normals is None:
        return normals, "normals"
    warnings.warn("trace_exact(vertex_normals=...) is deprecated; pass normals=...", DeprecationWarning,
                  stacklevel=3)
    if normals is not None:
        raise ValueError("give the shading normals as normals or as vertex_normals, not both")
    return vertex_normals, "vertex_normals"


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


def _mesh_tables(v, f, fo, ior, vn, cfg):
    """The per-face tables of the bounces (:class:`_Mesh`), on every thread."""
    nf = len(f)
    v0_all, e1_all, e2_all, ng_all = np.empty((nf, 3)), np.empty((nf, 3)), np.empty((nf, 3)), np.empty((nf, 3))
    run_chunks(lambda a, b: _face_rows(a, b, v, f, v0_all, e1_all, e2_all, ng_all), nf, chunk_length(nf, 1 << 15))
    # shading normals: per vertex (V, 3) or per corner (F, 3, 3); the other is a dummy
    vn_v = np.ascontiguousarray(vn) if cfg.smooth and not cfg.per_corner else np.zeros((1, 3))
    vn_c = np.ascontiguousarray(vn) if cfg.smooth and cfg.per_corner else np.zeros((1, 3, 3))
    # index of refraction of each medium; the outside medium is the last entry
    med_ior = np.append(ior, cfg.outside_ior)
    return _Mesh(v0_all, e1_all, e2_all, ng_all, f, vn_v, vn_c, fo, ior, med_ior)


def _allocate(d, record):
    """The per-ray arrays, unfilled: the first bounce's chunks fill them (:func:`_init_rows`)."""
    n = len(d)
    v3 = lambda: np.empty((n, 3))  # noqa: E731
    st = _Rays(d, v3(), v3(), v3(), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int8),
               np.empty(n, dtype=bool), np.empty(n, dtype=np.int16), np.empty(n, dtype=np.int16), np.empty(n))
    if record:
        path_pos = np.empty((n, record, 3))
        path_dir = np.empty((n, record, 3))
    else:  # never written (bounce < record is never true)
        path_pos = path_dir = np.empty((1, 1, 3))
    out = _Outputs(v3(), v3(), v3(), v3(), np.empty(n, dtype=np.int64), v3(), v3(), np.empty(n, dtype=bool),
                   path_pos, path_dir, v3())
    return st, out


def _run_bounces(v, f, o, ab, cfg, mesh, st, out, chunk_size, progress):
    """Every bounce: the rays still travelling, in fixed chunks of ``chunk_size`` on the thread pool.

    A chunk is queried with Embree (embreex releases the GIL while tracing), bounced by
    :func:`_bounce_rows` (no GIL either), then its Beer-Lambert factors multiplied in.
    """
    n = len(o)
    scene = mesh_scene(v, f) if n else None
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
    ior, trans = mesh.ior, out.transmittance

    bar = None
    if progress:
        from tqdm.auto import tqdm  # deferred: only for a progress bar

        bar = tqdm(total=cfg.max_bounces + 1, desc="trace_exact", unit="bounce")
    active = np.arange(n, dtype=np.int64)
    for bounce in range(cfg.max_bounces + 1):
        if bounce:
            active = active[st.status[active] == _ACTIVE]
        m = len(active)
        if bar is not None:
            bar.set_postfix(active=m)
        if m == 0:
            break
        hits = _Hits(active, prim, tfar, bu, bv, seg, seg_obj)

        def chunk(a, b, bounce=bounce, active=active, hits=hits):
            # rows [a, b) of the active rays: float32 queries, Embree, the float64 bounce
            if bounce == 0:  # active is 0..n-1: rows [a, b) are rays [a, b)
                _init_rows(a, b, o, st, out)
            _query_rows(a, b, active, st.pos, st.dirn, st.side, cfg.eps, bounce == 0, org32, dir32)
            res = scene.run(org32[a:b], dir32[a:b], output=1)
            prim[a:b] = res["primID"]
            tfar[a:b] = res["tfar"]
            bu[a:b] = res["u"]
            bv[a:b] = res["v"]
            _bounce_rows(a, b, bounce, cfg, mesh, hits, st, out)
            if absorbing:  # Beer-Lambert with NumPy's exp, the one of optics.beer_lambert
                k = seg_obj[a:b]
                sel = np.flatnonzero(k >= 0)
                if len(sel):
                    k = k[sel]
                    trans[active[a:b][sel]] *= optics.beer_lambert(ab[k], seg[a:b][sel], ior[k])

        run_chunks(chunk, m, chunk_length(m, chunk_size))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
