"""The mesh normals of the exact reference: vertex normals, crease normals and edge angles, on every thread.

The exact reference's ``geometry`` stage refracts with shading normals derived
from the triangles alone (``exact.normals``, docs/oracle.md, Conventions):
area-weighted vertex normals (Max 1999) or per-corner crease normals, smooth
across edges below ``exact.crease_deg`` and sharp across the others (Hoppe et
al. 1994). :func:`mesh_normals` computes them, and the angles of the mesh's
edges for the plan note, in kernels that each write only their own rows and
sum in the order of the serial functions of :mod:`refraction_ref.meshes`, so
the arrays are bit-identical to theirs whatever the thread count.

References
----------
.. [1] N. Max, "Weights for Computing Vertex Normals from Facet Normals",
   *Journal of Graphics Tools* 4(2), 1-6, 1999 (area weights).
.. [2] H. Hoppe et al., "Piecewise Smooth Surface Reconstruction",
   *Proc. SIGGRAPH 94*, 295-302, 1994 (crease edges).
.. [3] docs/oracle.md, Conventions (vertex and shading normals).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..kernels import dot3
from ..meshes import CREASE_MARGIN, face_corner_normals

__all__ = ["area_weighted_vertex_normals", "MeshNormals", "mesh_normals"]


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


@nb.njit(cache=True, inline="always")
def _put_unit(out, r, x, y, z):
    # row r of out = (x, y, z) / its length (np.linalg.norm's operations), zeros for a zero vector;
    # returns the length
    n = math.sqrt(x * x + y * y + z * z)
    if n > 0.0:
        out[r, 0] = x / n
        out[r, 1] = y / n
        out[r, 2] = z / n
    else:
        out[r, 0] = 0.0
        out[r, 1] = 0.0
        out[r, 2] = 0.0
    return n


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
        ln[k] = _put_unit(un, k, nx, ny, nz)


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
        _put_unit(out, v, sx, sy, sz)


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
                # NumPy's einsum('ij,ij->i') order (kernels.dot3); the product commutes
                dots[base + out] = dot3(un[g1, 0], un[g1, 1], un[g1, 2], un[other, 0], un[other, 1], un[other, 2])
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
