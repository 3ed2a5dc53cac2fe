"""Exact intersection of rays with triangles: Embree's hits and shadow rays (Chaudhari 2008, §4.1).

The ``receiver_hit = 'exact'`` pass: Embree on the receivers' triangles, the
oracle's ground truth for this step, its distances recomputed in float64
(:func:`hit_exact`); the same hits answer the exact shadow test's any-hit
queries (:func:`occluded`). The rays are traced in fixed chunks on the
shared thread pool (:func:`refraction_ref.embree.run_chunks`): each ray's
hit is computed on its own, so the result does not depend on the chunks or
the threads.

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §4.1.
.. [2] T. Möller, B. Trumbore, "Fast, Minimum Storage Ray-Triangle
   Intersection", Journal of Graphics Tools 2(1), 1997.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..embree import HIT_CHUNK, chunk_length, commit, run_chunks, soup_scene
from ..kernels import dot3

__all__ = ["IndexedTriangles", "hit_exact", "occluded"]


@nb.njit(cache=True, parallel=True)
def _abs_max_kernel(vertices, faces):
    # max |vertices[faces]| (max is exact: the same whatever the order)
    m = 0.0
    for f0 in nb.prange(faces.shape[0]):
        f = np.int64(f0)
        for k in range(3):
            for c in range(3):
                m = max(m, abs(vertices[faces[f, k], c]))
    return m


class IndexedTriangles:
    """The triangles ``vertices[faces]`` without building them: what :func:`hit_exact` and
    :func:`~refraction_ref.caustics.shade.exact_visibility` read of them.

    ``tris[f, k]`` (``f`` indices, ``k`` a corner) is ``vertices[faces[f, k]]``, the values
    ``vertices[faces][f, k]`` holds; ``len`` is the number of faces; ``np.asarray`` builds
    the (F, 3, 3) array.
    """

    def __init__(self, vertices, faces):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.shape = (len(self.faces), 3, 3)

    def __len__(self):
        return len(self.faces)

    def __getitem__(self, key):
        f, k = key
        return self.vertices[self.faces[f, k]]

    def __array__(self, dtype=None, copy=None):
        a = self.vertices[self.faces]
        return a if dtype is None else a.astype(dtype)

    def abs_max(self):
        """``np.abs(vertices[faces]).max()`` on every thread (0 without faces)."""
        return float(_abs_max_kernel(self.vertices, self.faces)) if len(self.faces) else 0.0


def hit_exact(tris, origins, dirs, scene=None):
    """Nearest hit of world rays with triangles (Embree), t recomputed in float64.

    The rays are traced in fixed chunks of :data:`~refraction_ref.embree.HIT_CHUNK`
    on ``numba.get_num_threads()`` threads (:func:`~refraction_ref.embree.run_chunks`):
    each ray's hit is computed on its own, so the result does not depend on the
    chunks or the threads.

    Parameters
    ----------
    tris : (T, 3, 3) float64 or IndexedTriangles
    origins, dirs : (N, 3) float64
    scene : embreex scene, optional
        An Embree scene whose primitive ``k`` is ``tris[k]`` (e.g. the indexed mesh
        ``embree.mesh_scene(vertices, faces)`` with ``tris = vertices[faces]``);
        default the cached soup of ``tris``.

    Returns
    -------
    t : (N,) float64
        Distance along the ray, NaN on a miss.
    face : (N,) int64
        Triangle index, ``-1`` on a miss.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    o = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = len(o)
    if n == 0 or len(tris) == 0:
        return np.full(n, np.nan), np.full(n, -1, np.int64)
    t = np.empty(n)  # rows set to NaN / -1 by their chunk (_finite_rows32), then the hits
    face = np.empty(n, np.int64)
    scene = commit(soup_scene(np.asarray(tris)) if scene is None else scene)  # built before the threads query it

    VF = _indexed(tris)

    def one(a, b):
        # rays [a, b): the finite ones are traced; their float32 copies for Embree are made
        # by a nogil kernel (no NumPy under the GIL), in the chunk's thread
        m = b - a
        ii = np.empty(m, np.int64)
        o32 = np.empty((m, 3), np.float32)
        d32 = np.empty((m, 3), np.float32)
        cnt = _finite_rows32(o, d, a, b, ii, o32, d32, t, face)
        if cnt == 0:
            return
        res = scene.run(o32[:cnt], d32[:cnt], output=1)
        _mt_kernel(VF[0], VF[1], o, d, ii[:cnt], np.asarray(res["primID"]), np.asarray(res["tfar"]), t, face)

    run_chunks(one, n, chunk_length(n, HIT_CHUNK))
    return t, face


@nb.njit(cache=True, nogil=True)
def _finite_rows32(o, d, a, b, ii, o32, d32, t, face):
    # rays [a, b): t NaN and face -1 (no hit yet); those whose origin and direction are finite,
    # in order: their indices and float32 copies (NumPy's casts: round to nearest); returns how many
    cnt = 0
    for i in range(a, b):
        t[i] = np.nan
        face[i] = -1
        ok = True
        for c in range(3):
            if not (math.isfinite(o[i, c]) and math.isfinite(d[i, c])):
                ok = False
        if ok:
            ii[cnt] = i
            for c in range(3):
                o32[cnt, c] = np.float32(o[i, c])
                d32[cnt, c] = np.float32(d[i, c])
            cnt += 1
    return cnt


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _mt_kernel(V, F, o, d, ii, prim, tfar, t, face):
    """The float64 Möller-Trumbore distance ``t = (e2 . q) / (e1 . p)`` on the triangle Embree found.

    For rays ``ii``: ``p = d x e2``, ``q = (o - a) x e1`` (``np.cross``; the dot products in
    ``einsum('ij,ij->i')``'s order, :func:`~refraction_ref.kernels.dot3`), Embree's own
    ``tfar`` where that is not finite and positive; compiled nogil, so the chunks' threads
    run it at once.

    References
    ----------
    .. [1] T. Möller, B. Trumbore, "Fast, Minimum Storage Ray-Triangle
       Intersection", Journal of Graphics Tools 2(1), 1997.
    """
    for m in range(ii.shape[0]):
        f = np.int64(prim[m])
        if f < 0:
            continue
        i = ii[m]
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        e1x, e1y, e1z = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
        e2x, e2y, e2z = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        px = dy * e2z - dz * e2y
        py = dz * e2x - dx * e2z
        pz = dx * e2y - dy * e2x
        det = dot3(e1x, e1y, e1z, px, py, pz)
        tx, ty, tz = o[i, 0] - V[a, 0], o[i, 1] - V[a, 1], o[i, 2] - V[a, 2]
        qx = ty * e1z - tz * e1y
        qy = tz * e1x - tx * e1z
        qz = tx * e1y - ty * e1x
        tt = dot3(e2x, e2y, e2z, qx, qy, qz) / det
        if not (math.isfinite(tt) and tt > 0):
            tt = np.float64(tfar[m])
        t[i] = tt
        face[i] = f


def _indexed(tris):
    """(V, F) with ``tris[f, k] == V[F[f, k]]``: an IndexedTriangles' arrays, or a soup's corners."""
    if isinstance(tris, IndexedTriangles):
        return tris.vertices, tris.faces
    V = np.ascontiguousarray(tris, dtype=np.float64).reshape(-1, 3)
    return V, np.arange(len(V), dtype=np.int64).reshape(-1, 3)


def occluded(tris, origins, dirs, tmax=None, scene=None):
    """Does a ray meet any of the triangles (before ``tmax``)? Embree any-hit test.

    Parameters
    ----------
    tris : (T, 3, 3) float64 or IndexedTriangles
    origins, dirs : (N, 3) float64
        World rays.
    tmax : (N,) float64, optional
        Farthest distance tested per ray; default unbounded.
    scene : embreex scene, optional
        As for :func:`hit_exact`.

    Returns
    -------
    (N,) bool
        True where the ray is blocked.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    if len(o) == 0 or len(tris) == 0:
        return np.zeros(len(o), bool)
    t, _ = hit_exact(tris, o, dirs, scene)
    hit = np.isfinite(t)
    if tmax is not None:
        hit &= t < np.asarray(tmax)
    return hit
