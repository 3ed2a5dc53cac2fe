"""One bounce of the exact tracer: float64 Möller-Trumbore on Embree's triangle, Snell or TIR, bookkeeping.

The kernels :func:`refraction_ref.exact.trace.trace_exact` runs on each chunk
of the rays still travelling (:func:`refraction_ref.embree.run_chunks`):
:func:`face_rows` (the per-face tables, once), :func:`init_rows` (the
per-ray arrays, on the first bounce), :func:`query_rows` (the float32 Embree
queries) and :func:`bounce_rows` (the float64 hit, the shading normal,
Snell's law or total internal reflection, the path's bookkeeping). Each writes
only the rows of its own rays, serially and without the GIL, so any split of
the rows over threads gives the same bits. They take their arrays as small
named tuples (:class:`ExactRayState`, :class:`ExactOutputs`,
:class:`ExactFaces`, :class:`ExactHits`, :class:`ExactSettings`).

Dot products are summed as NumPy's ``einsum('ij,ij->i')`` sums them
(:func:`refraction_ref.kernels.dot3`) and every other operation is the
vectorised NumPy form's, in its order (``tests/exact/test_exact_parallel.py``
keeps that form as the reference), so the results are bit-identical to it.

References
----------
.. [1] T. Möller, B. Trumbore, "Fast, Minimum Storage Ray/Triangle
   Intersection", *Journal of Graphics Tools* 2(1), 21–28, 1997.
.. [2] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
   ed., §8.2 (Snell's law, total internal reflection), §3.6.2 (shading normals).
.. [3] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.8 (path length inside an object, for
   Beer-Lambert).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from .. import optics
from ..kernels import dot3, unit3
from ..status import EXITED, LIMIT, LOST, MISSED, TIR

__all__ = ["OUTSIDE", "ACTIVE", "ExactRayState", "ExactOutputs", "ExactFaces", "ExactSettings", "ExactHits",
           "face_rows", "init_rows", "query_rows", "bounce_rows"]

#: medium index of the surrounding medium
OUTSIDE = -1
#: status of a ray still being traced (never in the tracer's result)
ACTIVE = -1

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
def face_rows(lo, hi, v, faces, v0, e1, e2, ng):
    """Faces ``[lo, hi)``: first vertex, edges ``v1 - v0``, ``v2 - v0`` and the unit geometric
    normal ``e1 x e2 / |e1 x e2|`` (NaN for a face of zero area), as ``np.cross`` and
    ``np.linalg.norm`` compute them.

    References
    ----------
    .. [1] Möller and Trumbore 1997, "Fast, minimum storage ray-triangle intersection" (the edges and normal
        its test reads); docs/oracle.md, "`exact` block".
    """
    for k in range(lo, hi):
        a, b, c = faces[k, 0], faces[k, 1], faces[k, 2]
        for j in range(3):
            v0[k, j] = v[a, j]
            e1[k, j] = v[b, j] - v[a, j]
            e2[k, j] = v[c, j] - v[a, j]
        nx = e1[k, 1] * e2[k, 2] - e1[k, 2] * e2[k, 1]
        ny = e1[k, 2] * e2[k, 0] - e1[k, 0] * e2[k, 2]
        nz = e1[k, 0] * e2[k, 1] - e1[k, 1] * e2[k, 0]
        ng[k, 0], ng[k, 1], ng[k, 2] = unit3(nx, ny, nz)


class ExactRayState(NamedTuple):
    """The tracer's per-ray state, N rows each; the first bounce's chunks fill it (:func:`init_rows`)."""

    dir0: np.ndarray  # (N, 3) the rays' given directions (read only)
    pos: np.ndarray  # (N, 3) the last surface point (the origin before the first hit)
    dirn: np.ndarray  # (N, 3) the direction after the last event
    side: np.ndarray  # (N, 3) unit face normal on the side the ray leaves to
    medium: np.ndarray  # (N,) int64 object the ray travels in, OUTSIDE
    status: np.ndarray  # (N,) int8, ACTIVE while traced
    last_tir: np.ndarray  # (N,) bool, the last event was a total internal reflection
    interfaces: np.ndarray  # (N,) int16
    bounces: np.ndarray  # (N,) int16
    path_length: np.ndarray  # (N,) float64


class ExactOutputs(NamedTuple):
    """The tracer's outputs besides :class:`ExactRayState`: the keys of
    :func:`~refraction_ref.exact.trace.trace_exact`'s dict."""

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


class ExactFaces(NamedTuple):
    """Per face: first vertex, edges, unit geometric normal (:func:`face_rows`); the shading
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


class ExactSettings(NamedTuple):
    """The scalars of a trace (:func:`~refraction_ref.exact.trace.trace_exact`'s arguments)."""

    max_bounces: int  # exact.max_bounces
    record: int  # exact.record
    epsilon: float  # the query offset, world units
    smooth: bool  # refract with the interpolated shading normals
    per_corner: bool  # the shading normals are per corner (F, 3, 3), else per vertex
    outside_ior: float
    chunk_size: int  # rays per Embree call and per chunk of a bounce


class ExactHits(NamedTuple):
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
def init_rows(lo, hi, origins, st, out):
    """Rays ``[lo, hi)``: the tracer's per-ray arrays before the first bounce (filled by the
    first bounce's chunks, in parallel, rather than by NumPy up front).

    References
    ----------
    .. [1] docs/oracle.md, Outputs (the exact reference's per-pixel keys before the first event).
    """
    o = origins
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
        medium[i] = OUTSIDE
        status[i] = ACTIVE
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
def query_rows(lo, hi, active, pos, dirn, side, eps, first, org32, dir32):
    """Rows ``[lo, hi)``: the float32 Embree queries of the rays ``active[m]``, their origins
    pushed off the surface along the new direction and the face normal (``pos + eps (dir + side)``)
    after the first bounce.

    References
    ----------
    .. [1] docs/oracle.md, "`exact` block" (Embree's float32 queries, offset by `epsilon` from the last hit).
    """
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
    det = dot3(e1x, e1y, e1z, pvx, pvy, pvz)
    inv = 1.0 / det
    tx = px - v0[fi, 0]
    ty = py - v0[fi, 1]
    tz = pz - v0[fi, 2]
    u = dot3(tx, ty, tz, pvx, pvy, pvz) * inv
    qx = ty * e1z - tz * e1y
    qy = tz * e1x - tx * e1z
    qz = tx * e1y - ty * e1x
    w2 = dot3(dx, dy, dz, qx, qy, qz) * inv
    t = dot3(e2x, e2y, e2z, qx, qy, qz) * inv
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
        t = dot3(hx - px, hy - py, hz - pz, dx, dy, dz)
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
    nsx, nsy, nsz = unit3(nsx, nsy, nsz)
    if not (math.isfinite(nsx) and math.isfinite(nsy) and math.isfinite(nsz)):
        nsx, nsy, nsz = ngx, ngy, ngz
    if dot3(nsx, nsy, nsz, ngx, ngy, ngz) < 0.0:
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
        sn = _sign(dot3(ndx, ndy, ndz, ngx, ngy, ngz))
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
def bounce_rows(lo, hi, bounce, settings, tables, hits, st, out):
    """One bounce of the rays ``hits.active[m]``, rows ``m`` in ``[lo, hi)``, given Embree's hits
    in those rows.

    float64 Möller-Trumbore on Embree's triangle (:func:`_hit_distance`), Snell / TIR
    (:func:`_refract_event`) with the interpolated shading normal (:func:`_shading_normal`),
    and the bookkeeping of the tracer's per-ray arrays. Writes only the rows of its own rays,
    so any split of the rows over threads gives the same result. Serial and without the GIL:
    one chunk of a thread pool (:func:`refraction_ref.embree.run_chunks`).

    The dot products are summed as NumPy's ``einsum('ij,ij->i')`` sums them
    (:func:`refraction_ref.kernels.dot3`) and every other operation is the
    vectorised NumPy form's, in its order (module docstring).

    References
    ----------
    .. [1] Möller and Trumbore (1997) (the hit); Pharr, Jakob, Humphreys, *PBR*
       3rd ed., §8.2 (Snell, TIR); Chaudhari (2008), §3.8 (path length inside).
    """
    max_bounces, record, eps = settings.max_bounces, settings.record, settings.epsilon
    smooth, per_corner, outside_ior = settings.smooth, settings.per_corner, settings.outside_ior
    ng_all, fo, ior, med_ior = tables.ng, tables.face_object, tables.ior, tables.med_ior
    v0_all, e1_all, e2_all, faces = tables.v0, tables.e1, tables.e2, tables.faces
    vn_v, vn_c = tables.vn_v, tables.vn_c
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
                leaked[i] = medium[i] != OUTSIDE
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
        if med != OUTSIDE:
            path_length[i] += t
            seg[m] = t
            seg_obj[m] = med

        # --- normals, Snell (optics.refract3) ----------------------------------
        ngx, ngy, ngz = ng_all[fi, 0], ng_all[fi, 1], ng_all[fi, 2]
        cos_g = dot3(dx, dy, dz, ngx, ngy, ngz)
        entering = cos_g < 0.0
        if smooth:
            nsx, nsy, nsz = _shading_normal(vn_c, vn_v, faces, fi, u, w2, (ngx, ngy, ngz), per_corner)
        else:
            nsx, nsy, nsz = ngx, ngy, ngz
        obj = fo[fi]
        n1 = med_ior[n_out] if med == OUTSIDE else med_ior[med]
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
            medium[i] = obj if entering else OUTSIDE
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
        sgn = 1.0 if dot3(ndx, ndy, ndz, ngx, ngy, ngz) >= 0.0 else -1.0
        side[i, 0] = ngx * sgn
        side[i, 1] = ngy * sgn
        side[i, 2] = ngz * sgn
        if lost:
            status[i] = LOST
