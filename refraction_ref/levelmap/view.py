"""The view through the water: what a camera above the pool sees (Tipprasert 2006, ch. 5 images).

Every eye ray (the primary rays of ``docs/oracle.md``) that meets the wavy
water surface is refracted there by Snell's law (eq. 2-8, from
``outside_ior`` into ``water.ior``), travels on through the water to the
first receiver it meets and shows that receiver with its caustics (eq. 4-19:
``albedo (I_c + ambient)``, ``I_c`` the nearest texel of the receiver's
caustics map), attenuated by the water's absorption over the eye path,
``exp(-K d)`` (eq. 4-17, ``d`` the distance from the surface to the
receiver). An eye ray that misses the water rectangle sees the receivers
directly (no water on its way); one that meets no receiver is black.

* Level map (``--method levelmap``): the water **mesh** the beams were built
  from (``water.resolution``), its vertex normals interpolated across each
  triangle (Phong) as a GPU would shade it.
* Exact reference (``--method exact`` on a water scene): the **analytic**
  height field, met exactly (a Lipschitz march that cannot step over the first
  root, then a guarded Newton step) and refracted with its analytic normal.

The mesh is met by a walk over its grid cells along the ray (float64
Moller-Trumbore on each cell's two triangles); both find the receivers with
Embree's first hit and recompute the hit in float64 on the triangle found, so the view is exact up to float64 rounding
and the same whatever the thread count (every ray is independent).

Status of each pixel (``stage.image.view_status``), the ``VIEW_*`` codes of
:mod:`refraction_ref.status` (not the per-pixel ``status`` of the other methods:
the same integers mean other things there):

====  =================  ==============================================================
code  name               meaning
====  =================  ==============================================================
0     ``VIEW_MISSED``    no water and no receiver along the ray: black
1     ``VIEW_THROUGH``   refracted by the water onto a receiver (the thesis's view)
2     ``VIEW_LOST``      refracted by the water, then met no receiver: black
3     ``VIEW_DIRECT``    missed the water rectangle, met a receiver directly
4     ``VIEW_TIR``       total internal reflection at the water (only when
                         ``outside_ior > water.ior``): black, not followed
====  =================  ==============================================================

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §2.6 (eqs. 2-7, 2-8), §4.6 (eq. 4-19), eq. 4-17,
   Figs. 5-13 and the appendix's images (the pool seen through its surface).
"""

from __future__ import annotations

import hashlib
import math
import threading
from typing import NamedTuple

import numba as nb
import numpy as np

from ..embree import nearest_hits, soup_scene
from ..optics import refract3
from ..status import VIEW_DIRECT, VIEW_LOST, VIEW_MISSED, VIEW_STATUS, VIEW_THROUGH, VIEW_TIR

__all__ = ["VIEW_STATUS", "CausticMaps", "shade_point", "view_through_water", "direct_view", "water_surface_hits_mesh", "water_surface_hits_analytic"]


class _Waves(NamedTuple):
    """The analytic height field: ``h = height + sum a sin(k (dx x + dz z) + phase)`` on the water rectangle."""

    a: np.ndarray
    k: np.ndarray
    dx: np.ndarray
    dz: np.ndarray
    phase: np.ndarray
    height: float
    half_x: float
    half_z: float
    slope: float  # sum a k: a Lipschitz bound of |grad h|


class _Rays(NamedTuple):
    """Rays and the buffers the surface kernels fill."""

    O: np.ndarray  # (N, 3)
    D: np.ndarray  # (N, 3) unit
    prim: np.ndarray  # unused (kept empty)
    P: np.ndarray  # (N, 3) out: where the ray meets the water, NaN where not
    T: np.ndarray  # (N, 3) out: refracted direction
    status: np.ndarray  # (N,) int8 out: VIEW_THROUGH (so far), VIEW_DIRECT or VIEW_TIR


class _Look(NamedTuple):
    """What the shading reads: each receiver's albedo, map frame and caustics map (eq. 4-19)."""

    albedo: np.ndarray  # (R, 3)
    centre: np.ndarray  # (R, 3) box centres
    U: np.ndarray  # (R, 3)
    W: np.ndarray  # (R, 3)
    ext: np.ndarray  # (R, 2) w, d
    maps: np.ndarray  # (R, Hc, Wc) float32
    ambient: float
    K: float


class _WaterGrid(NamedTuple):
    """The water mesh as the regular height-field grid :func:`~.water.water_mesh` builds."""

    vertices: np.ndarray  # ((n + 1)^2, 3), vertex (i, j) at i (n + 1) + j: z = zs[i], x = xs[j]
    normals: np.ndarray  # ((n + 1)^2, 3) unit vertex normals
    n: int
    x0: float
    z0: float
    cx: float  # cell size along x
    cz: float
    ylo: float  # lowest and highest vertex
    yhi: float


@nb.njit(cache=True, inline="always")
def _tri_hit(V, a, b, c, ox, oy, oz, dx, dy, dz):
    """Moller-Trumbore in float64 on vertices a, b, c: (t, u, v), t = inf on a miss (edges inclusive)."""
    e1x = V[b, 0] - V[a, 0]
    e1y = V[b, 1] - V[a, 1]
    e1z = V[b, 2] - V[a, 2]
    e2x = V[c, 0] - V[a, 0]
    e2y = V[c, 1] - V[a, 1]
    e2z = V[c, 2] - V[a, 2]
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return np.inf, 0.0, 0.0
    inv = 1.0 / det
    tx = ox - V[a, 0]
    ty = oy - V[a, 1]
    tz = oz - V[a, 2]
    u = (tx * px + ty * py + tz * pz) * inv
    qx = ty * e1z - tz * e1y
    qy = tz * e1x - tx * e1z
    qz = tx * e1y - ty * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    tol = 1e-12
    if u < -tol or v < -tol or u + v > 1.0 + tol:
        return np.inf, 0.0, 0.0
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    if t < 0.0:
        return np.inf, 0.0, 0.0
    return t, u, v


@nb.njit(cache=True, parallel=True)
def _mesh_surface(grid, rays, eta):
    """First hit of each ray on the water mesh (a walk over the grid's cells along the ray, float64),
    the vertex normals interpolated there (Phong), Snell (eq. 2-8)."""
    V = grid.vertices
    NV = grid.normals
    n = grid.n
    x0 = grid.x0
    z0 = grid.z0
    cx = grid.cx
    cz = grid.cz
    ylo = grid.ylo
    yhi = grid.yhi
    O = rays.O
    D = rays.D
    P = rays.P
    T = rays.T
    status = rays.status
    for q in nb.prange(O.shape[0]):
        status[q] = VIEW_DIRECT
        for c in range(3):
            P[q, c] = np.nan
            T[q, c] = np.nan
        ox, oy, oz = O[q, 0], O[q, 1], O[q, 2]
        dx, dy, dz = D[q, 0], D[q, 1], D[q, 2]
        if not (dy < 0.0):
            continue
        ta = max((yhi - oy) / dy, 0.0)
        tb = (ylo - oy) / dy
        # clip [ta, tb] to the grid's rectangle in x and z
        for ax in range(2):
            o_ = ox if ax == 0 else oz
            d_ = dx if ax == 0 else dz
            lo = x0 if ax == 0 else z0
            hi = lo + n * (cx if ax == 0 else cz)
            if d_ == 0.0:
                if o_ < lo or o_ > hi:
                    ta = np.inf
            else:
                t0 = (lo - o_) / d_
                t1 = (hi - o_) / d_
                ta = max(ta, min(t0, t1))
                tb = min(tb, max(t0, t1))
        if not (ta <= tb):
            continue
        # cells from where the ray enters the slab to where it leaves it (2D DDA in x, z)
        xe = ox + ta * dx
        ze = oz + ta * dz
        j = min(max(np.int64(math.floor((xe - x0) / cx)), 0), n - 1)
        i = min(max(np.int64(math.floor((ze - z0) / cz)), 0), n - 1)
        sj = 1 if dx > 0.0 else -1
        si = 1 if dz > 0.0 else -1
        tnx = np.inf
        tnz = np.inf
        if dx != 0.0:
            tnx = (x0 + (j + (1 if dx > 0.0 else 0)) * cx - ox) / dx
        if dz != 0.0:
            tnz = (z0 + (i + (1 if dz > 0.0 else 0)) * cz - oz) / dz
        dtx = cx / abs(dx) if dx != 0.0 else np.inf
        dtz = cz / abs(dz) if dz != 0.0 else np.inf
        best = np.inf
        bu = 0.0
        bv = 0.0
        ba = 0
        bb = 0
        bc = 0
        for _ in range(4 * n + 4):
            v00 = i * (n + 1) + j
            v10 = v00 + n + 1
            v01 = v00 + 1
            v11 = v10 + 1
            t, u, v = _tri_hit(V, v00, v10, v01, ox, oy, oz, dx, dy, dz)
            if t < best:
                best, bu, bv, ba, bb, bc = t, u, v, v00, v10, v01
            t, u, v = _tri_hit(V, v10, v11, v01, ox, oy, oz, dx, dy, dz)
            if t < best:
                best, bu, bv, ba, bb, bc = t, u, v, v10, v11, v01
            if best < np.inf:
                break
            if min(tnx, tnz) > tb:
                break
            if tnx < tnz:
                j += sj
                tnx += dtx
                if j < 0 or j >= n:
                    break
            else:
                i += si
                tnz += dtz
                if i < 0 or i >= n:
                    break
        if best == np.inf:
            continue
        u = min(max(bu, 0.0), 1.0)
        v = min(max(bv, 0.0), 1.0 - u)
        w = 1.0 - u - v
        P[q, 0] = ox + best * dx
        P[q, 1] = oy + best * dy
        P[q, 2] = oz + best * dz
        nx = w * NV[ba, 0] + u * NV[bb, 0] + v * NV[bc, 0]
        ny = w * NV[ba, 1] + u * NV[bb, 1] + v * NV[bc, 1]
        nz = w * NV[ba, 2] + u * NV[bb, 2] + v * NV[bc, 2]
        s = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
        tx, ty, tz, tir = refract3(dx, dy, dz, nx * s, ny * s, nz * s, eta)
        T[q, 0] = tx
        T[q, 1] = ty
        T[q, 2] = tz
        status[q] = VIEW_TIR if tir else VIEW_THROUGH


@nb.njit(cache=True, inline="always")
def _height(wv_a, wv_k, wv_dx, wv_dz, wv_ph, height, x, z):
    h = height
    for m in range(wv_a.shape[0]):
        h += wv_a[m] * math.sin(wv_k[m] * (wv_dx[m] * x + wv_dz[m] * z) + wv_ph[m])
    return h


@nb.njit(cache=True, parallel=True)
def _analytic_surface(waves, rays, eta):
    """First root of ``y(t) - h(x(t), z(t))`` per ray, analytic normal, Snell (eq. 2-8)."""
    a = waves.a
    k = waves.k
    wdx = waves.dx
    wdz = waves.dz
    ph = waves.phase
    height = waves.height
    hx_ = waves.half_x
    hz_ = waves.half_z
    S = waves.slope
    O = rays.O
    D = rays.D
    P = rays.P
    T = rays.T
    status = rays.status
    amp = 0.0
    for m in range(a.shape[0]):
        amp += abs(a[m])
    for q in nb.prange(O.shape[0]):
        ox, oy, oz = O[q, 0], O[q, 1], O[q, 2]
        dx, dy, dz = D[q, 0], D[q, 1], D[q, 2]
        status[q] = VIEW_DIRECT
        for c in range(3):
            P[q, c] = np.nan
            T[q, c] = np.nan
        if not (dy < 0.0):
            continue
        t0 = max((height + amp - oy) / dy, 0.0)
        t1 = (height - amp - oy) / dy
        L = -dy + S * math.sqrt(dx * dx + dz * dz)  # |d f / d t| <= L
        t = t0
        for _ in range(100000):  # never steps over a root: f decreases by at most L per unit t
            f = oy + t * dy - _height(a, k, wdx, wdz, ph, height, ox + t * dx, oz + t * dz)
            if f <= 1e-14 * (1.0 + abs(height) + amp):
                break
            t += f / L
            if t >= t1:
                t = t1
                break
        # one guarded Newton step from the upper side of the root
        x = ox + t * dx
        z = oz + t * dz
        f = oy + t * dy - _height(a, k, wdx, wdz, ph, height, x, z)
        gx = 0.0
        gz = 0.0
        for m in range(a.shape[0]):
            c = a[m] * k[m] * math.cos(k[m] * (wdx[m] * x + wdz[m] * z) + ph[m])
            gx += c * wdx[m]
            gz += c * wdz[m]
        fp = dy - gx * dx - gz * dz
        if fp < 0.0 and f > 0.0:
            tn = t - f / fp
            xn = ox + tn * dx
            zn = oz + tn * dz
            fn = oy + tn * dy - _height(a, k, wdx, wdz, ph, height, xn, zn)
            if tn >= t and tn <= t1 and abs(fn) < f:
                t, x, z = tn, xn, zn
                gx = 0.0
                gz = 0.0
                for m in range(a.shape[0]):
                    c = a[m] * k[m] * math.cos(k[m] * (wdx[m] * x + wdz[m] * z) + ph[m])
                    gx += c * wdx[m]
                    gz += c * wdz[m]
        if abs(x) > hx_ or abs(z) > hz_:
            continue  # outside the water rectangle: a direct ray
        P[q, 0] = x
        P[q, 1] = _height(a, k, wdx, wdz, ph, height, x, z)
        P[q, 2] = z
        s = 1.0 / math.sqrt(gx * gx + 1.0 + gz * gz)
        tx, ty, tz, tir = refract3(dx, dy, dz, -gx * s, s, -gz * s, eta)
        T[q, 0] = tx
        T[q, 1] = ty
        T[q, 2] = tz
        status[q] = VIEW_TIR if tir else VIEW_THROUGH


@nb.njit(cache=True, parallel=True)
def _second_rays(idx, O, D, P, T, status, O2, D2):
    """float32 rays to the receivers: from the water along T (status 1), from the eye along D (status 3)."""
    for k in nb.prange(idx.shape[0]):
        q = idx[k]
        through = status[q] == VIEW_THROUGH
        for c in range(3):
            O2[k, c] = np.float32(P[q, c] if through else O[q, c])
            D2[k, c] = np.float32(T[q, c] if through else D[q, c])


class _Hits(NamedTuple):
    """Rays, their water hits and the receiver triangles Embree found; the kernel fills the last three."""

    O: np.ndarray
    D: np.ndarray
    P: np.ndarray  # (N, 3) water points: set to NaN where the ray did not reach the water
    T: np.ndarray  # (N, 3) refracted directions: NaN unless status 1 or 2
    prim: np.ndarray  # (N,) receiver triangle, -1 for none
    status: np.ndarray  # (N,) int8, updated: 1 -> 2 and 3 -> 0 where no receiver is met
    tris: np.ndarray
    owner: np.ndarray
    Q: np.ndarray  # out (N, 3): receiver point, NaN where none
    length: np.ndarray  # out (N,): distance in water (0 direct, NaN none)
    rid: np.ndarray  # out (N,): receiver, -1 where none


@nb.njit(cache=True, parallel=True)
def _receiver_points(h, look, img):
    """Float64 hit of each ray on the plane of the receiver triangle Embree found; final status per ray;
    the pixel's colour (eq. 4-19 times exp(-K d), eq. 4-17)."""
    O = h.O
    D = h.D
    P = h.P
    T = h.T
    prim = h.prim
    status = h.status
    tris = h.tris
    owner = h.owner
    Q = h.Q
    length = h.length
    rid = h.rid
    for q in nb.prange(O.shape[0]):
        f = prim[q]
        st = status[q]
        through = st == VIEW_THROUGH
        if f < 0:
            if st == VIEW_THROUGH:
                status[q] = VIEW_LOST
            elif st == VIEW_DIRECT:
                status[q] = VIEW_MISSED
            st = status[q]
            Q[q, 0] = np.nan
            Q[q, 1] = np.nan
            Q[q, 2] = np.nan
            length[q] = np.nan
            rid[q] = -1
        else:
            ox = P[q, 0] if through else O[q, 0]
            oy = P[q, 1] if through else O[q, 1]
            oz = P[q, 2] if through else O[q, 2]
            dx = T[q, 0] if through else D[q, 0]
            dy = T[q, 1] if through else D[q, 1]
            dz = T[q, 2] if through else D[q, 2]
            e1x = tris[f, 1, 0] - tris[f, 0, 0]
            e1y = tris[f, 1, 1] - tris[f, 0, 1]
            e1z = tris[f, 1, 2] - tris[f, 0, 2]
            e2x = tris[f, 2, 0] - tris[f, 0, 0]
            e2y = tris[f, 2, 1] - tris[f, 0, 1]
            e2z = tris[f, 2, 2] - tris[f, 0, 2]
            nx = e1y * e2z - e1z * e2y
            ny = e1z * e2x - e1x * e2z
            nz = e1x * e2y - e1y * e2x
            den = dx * nx + dy * ny + dz * nz
            t = ((tris[f, 0, 0] - ox) * nx + (tris[f, 0, 1] - oy) * ny + (tris[f, 0, 2] - oz) * nz) / den \
                if den != 0.0 else 0.0
            Q[q, 0] = ox + t * dx
            Q[q, 1] = oy + t * dy
            Q[q, 2] = oz + t * dz
            length[q] = t if through else 0.0
            rid[q] = owner[f]
        if st == VIEW_MISSED or st == VIEW_DIRECT:  # never reached the water
            for c in range(3):
                P[q, c] = np.nan
        if not (st == VIEW_THROUGH or st == VIEW_LOST):
            for c in range(3):
                T[q, c] = np.nan
        shade_point(look, rid[q], Q[q, 0], Q[q, 1], Q[q, 2], length[q] if rid[q] >= 0 else 0.0, img, q)


@nb.njit(cache=True, inline="always")
def shade_point(look, r, qx, qy, qz, length, out, q):
    """Eq. 4-19 at one receiver point, nearest texel of its caustics map, times exp(-K d) (eq. 4-17).

    ``I_o = albedo (I_c + ambient)``: ``I_c I_d + I_a`` with the diffuse map's
    ``I_d`` the albedo and ``I_a = ambient * albedo``.

    Parameters
    ----------
    look : _Look
        The receivers' albedo, map frames, caustics maps, ambient and ``K``; only read.
    r : int
        The receiver, < 0 for none (black).
    qx, qy, qz : float
        The point, world space.
    length : float
        Distance travelled in water to it (0 for a direct ray).
    out : (N, 3) float32
        Gets the colour in row ``q``.
    q : int

    References
    ----------
    Tipprasert (2006), §4.6, eq. 4-19; §4.5, eq. 4-17.
    """
    albedo, centre, U, W, ext = look.albedo, look.centre, look.U, look.W, look.ext
    maps, ambient, K = look.maps, look.ambient, look.K
    if r < 0:
        out[q, 0] = 0.0
        out[q, 1] = 0.0
        out[q, 2] = 0.0
        return
    Hc = maps.shape[1]
    Wc = maps.shape[2]
    px = qx - centre[r, 0]
    py = qy - centre[r, 1]
    pz = qz - centre[r, 2]
    col = ((px * U[r, 0] + py * U[r, 1] + pz * U[r, 2]) / ext[r, 0] + 0.5) * Wc
    row = ((px * W[r, 0] + py * W[r, 1] + pz * W[r, 2]) / ext[r, 1] + 0.5) * Hc
    j = min(max(np.int64(math.floor(col)), 0), Wc - 1) if np.isfinite(col) else 0
    i = min(max(np.int64(math.floor(row)), 0), Hc - 1) if np.isfinite(row) else 0
    e = np.float64(maps[r, i, j])
    tr = math.exp(-K * length) if K > 0.0 else 1.0
    for c in range(3):
        out[q, c] = np.float32(albedo[r, c] * (e + ambient) * tr)


class CausticMaps(NamedTuple):
    """Each receiver's caustics map, its frame and eq. 4-19's ambient term: what a view shades with.

    Attributes
    ----------
    boxes : list of Box
        Frame (first light's box) of each receiver's caustics map.
    maps : (R, Hc, Wc) float32 array or list of (Hc, Wc) arrays
        ``caustic_map_r``.
    ambient : float
        ``caustics.ambient``, a fraction of the albedo.
    """

    boxes: list
    maps: object
    ambient: float


def _look(receivers, caustics, K):
    boxes, maps = caustics.boxes, caustics.maps
    R = len(boxes)
    stacked = maps if isinstance(maps, np.ndarray) else np.ascontiguousarray(np.stack(maps[:R]), np.float32)
    return _Look(np.ascontiguousarray(receivers.albedo, np.float64), np.array([b.center for b in boxes]),
                 np.array([b.U for b in boxes]), np.array([b.W for b in boxes]), np.array([[b.w, b.d] for b in boxes]),
                 stacked, float(caustics.ambient), float(K))


@nb.njit(cache=True, parallel=True)
def _direct_shade(eye, D, fwd, depths, look, out):
    """Per pixel: the nearest receiver over the depth images (R, H, W), its point at that view depth, eq. 4-19."""
    R, H, Wd = depths.shape
    for i in nb.prange(H):
        for j in range(Wd):
            b = np.inf
            k = -1
            for r in range(R):
                if depths[r, i, j] < b:
                    b = depths[r, i, j]
                    k = r
            q = i * Wd + j
            if k < 0:
                shade_point(look, -1, 0.0, 0.0, 0.0, 0.0, out, q)
                continue
            t = b / (D[q, 0] * fwd[0] + D[q, 1] * fwd[1] + D[q, 2] * fwd[2])
            shade_point(look, k, eye[0] + D[q, 0] * t, eye[1] + D[q, 1] * t, eye[2] + D[q, 2] * t, 0.0, out, q)


def direct_view(camera, receivers, caustics, rays=None):
    """The receivers seen directly, without the water (eq. 4-19).

    Parameters
    ----------
    camera : Camera
    receivers : Receivers
        The receivers' triangle soup.
    caustics : CausticMaps
        Each receiver's caustics map, its frame and the ambient term.
    rays : (origins, directions), optional
        ``camera.primary_rays()``, when already computed.

    Returns
    -------
    image : (H, W, 3) float32
    mask : (H, W) bool
        Pixels showing a receiver.

    References
    ----------
    Tipprasert (2006), §4.6, eq. 4-19.
    """
    from ..raster import rasterize

    H, W = camera.shape
    depths = np.stack([rasterize(camera.world_to_view(receivers.tris[receivers.owner == r]), camera, "min")
                       for r in range(len(caustics.boxes))])
    _, rd = camera.primary_rays() if rays is None else rays
    D = np.ascontiguousarray(rd.reshape(-1, 3), np.float64)
    img = np.empty((H * W, 3), np.float32)
    _direct_shade(np.asarray(camera.eye, np.float64), D, np.ascontiguousarray(-camera.basis[2], np.float64), depths,
                  _look(receivers, caustics, 0.0), img)
    return img.reshape(H, W, 3), np.isfinite(depths).any(axis=0)


_SCENES = {}  # content digest of a receivers' soup -> (the soup, its Embree scene)
_SCENES_LOCK = threading.Lock()


def receiver_scene(tris):
    """The Embree scene of a receivers' triangle soup, reused while the same triangles come again.

    Keyed by the triangles' content (SHA-1 of their float64 bytes, ~1 ms per MB), not the array
    object: each render rebuilds the soup, but a scene rendered again (a sweep, a benchmark, the
    tables, a camera change) finds its BVH built. Up to four scenes are kept.

    Parameters
    ----------
    tris : (T, 3, 3) array_like
        The receivers' world-space triangles.

    Returns
    -------
    Embree scene
        The scene :func:`~refraction_ref.embree.soup_scene` builds of ``tris``.

    References
    ----------
    Tipprasert (2006), §4.6 (the receivers the eye rays reach after the water).
    """
    t = np.ascontiguousarray(tris, np.float64)
    key = (t.shape, hashlib.sha1(t.view(np.uint8)).hexdigest())
    with _SCENES_LOCK:
        hit = _SCENES.get(key)
    if hit is not None:
        return hit[1]
    scene = soup_scene(t.copy(), cache=False)
    with _SCENES_LOCK:
        if len(_SCENES) >= 4:
            _SCENES.pop(next(iter(_SCENES)))
        _SCENES[key] = (t, scene)
    return scene


def _waves(water):
    ws = water.get("waves") or []
    a = np.array([float(w["amplitude"]) for w in ws], np.float64)
    k = np.array([2.0 * np.pi / float(w["wavelength"]) for w in ws], np.float64)
    d = np.array([np.asarray(w["direction"], np.float64) / np.linalg.norm(w["direction"]) for w in ws],
                 np.float64).reshape(-1, 2)
    ph = np.array([float(w["phase"]) for w in ws], np.float64)
    sx, sz = (float(s) for s in water["size"])
    return _Waves(a, k, np.ascontiguousarray(d[:, 0]), np.ascontiguousarray(d[:, 1]), ph, float(water["height"]),
                  sx / 2.0, sz / 2.0, float(np.sum(np.abs(a) * k)))


def _new_rays(O, D):
    """Rays and empty buffers; the surface kernels write every element (NaN where the ray misses the water)."""
    n = len(O)
    return _Rays(np.ascontiguousarray(O, np.float64), np.ascontiguousarray(D, np.float64), np.empty(0, np.int32),
                 np.empty((n, 3)), np.empty((n, 3)), np.empty(n, np.int8))


def water_surface_hits_mesh(mesh, origins, dirs, eta, water=None):
    """Where rays meet the water mesh, refracted (level map).

    Parameters
    ----------
    mesh : WaterMesh
        The regular grid of :func:`~refraction_ref.levelmap.water.water_mesh`.
    origins, dirs : (N, 3) float64
    eta : float
        ``outside_ior / water.ior``.
    water : dict
        The ``water`` block the mesh was built from (its size and resolution).

    Returns
    -------
    P, T : (N, 3) float64
        Surface point and refracted unit direction (NaN where the ray misses the water).
    status : (N,) int8
        ``VIEW_THROUGH`` (1), ``VIEW_DIRECT`` (3, missed the water) or ``VIEW_TIR`` (4).

    References
    ----------
    Tipprasert (2006), §2.6 (Snell's law, eq. 2-8); ch. 5 (views through the
    water).
    """
    n = int(water["resolution"])
    sx, sz = (float(v) for v in water["size"])
    V = np.ascontiguousarray(mesh.vertices, np.float64)
    grid = _WaterGrid(V, np.ascontiguousarray(mesh.normals, np.float64), n, -sx / 2.0, -sz / 2.0, sx / n, sz / n,
                 float(V[:, 1].min()), float(V[:, 1].max()))
    rays = _new_rays(origins, dirs)
    _mesh_surface(grid, rays, float(eta))
    return rays.P, rays.T, rays.status


def water_surface_hits_analytic(water, origins, dirs, eta):
    """Where rays meet the analytic height field, refracted with its analytic normal (exact reference).

    Same returns as :func:`water_surface_hits_mesh`.

    Parameters
    ----------
    water : dict
        The resolved ``water`` block (height, size, waves).
    origins, dirs : (N, 3) float64
        Ray origins and unit directions, world space.
    eta : float
        ``outside_ior / water.ior``.

    References
    ----------
    Tipprasert (2006), §2.6 (Snell's law, eq. 2-8).
    """
    rays = _new_rays(origins, dirs)
    _analytic_surface(_waves(water), rays, float(eta))
    return rays.P, rays.T, rays.status


def view_through_water(camera, water, eta, receivers, caustics, mesh=None, rays=None):
    """Render the pool as the camera sees it through the water surface.

    Parameters
    ----------
    camera : Camera
    water : dict
        The resolved ``water`` block (its ``absorption`` K attenuates the eye
        path in water, eq. 4-17).
    eta : float
        ``outside_ior / water.ior``.
    receivers : Receivers
    caustics : CausticMaps
        Each receiver's caustics map, its frame and the ambient term.
    mesh : WaterMesh, optional
        Refract at this mesh (level map); the analytic surface when None (exact).
    rays : (origins, directions), optional
        ``camera.primary_rays()``, when already computed.

    Returns
    -------
    dict
        ``image`` (H, W, 3) float32, ``object_mask`` (H, W) bool (status 1 or 3),
        ``view_status`` (H, W) int8, ``water_pos`` and ``water_dir`` (H, W, 3)
        float64 (NaN where the ray did not enter the water), ``receiver_pos``
        (H, W, 3) float64 (NaN where none), ``water_length`` (H, W) float64
        (distance in water, 0 for direct rays, NaN where none).

    References
    ----------
    Tipprasert (2006), §4.6 (eq. 4-19), §4.5 (eq. 4-17, absorption), §2.6
    (eq. 2-8).
    """
    H, W = camera.shape
    ro, rd = camera.primary_rays() if rays is None else rays
    O = np.ascontiguousarray(np.broadcast_to(np.asarray(ro, np.float64), rd.shape).reshape(-1, 3))
    D = np.ascontiguousarray(rd.reshape(-1, 3), np.float64)
    if mesh is not None:
        P, T, status = water_surface_hits_mesh(mesh, O, D, eta, water)
    else:
        P, T, status = water_surface_hits_analytic(water, O, D, eta)
    # the rays that go on to the receivers: refracted ones from the water, direct ones from the eye
    idx = np.flatnonzero((status == VIEW_THROUGH) | (status == VIEW_DIRECT))
    O2 = np.empty((len(idx), 3), np.float32)
    D2 = np.empty((len(idx), 3), np.float32)
    _second_rays(idx, O, D, P, T, status, O2, D2)
    prim = np.full(len(O), -1, np.int64)
    if len(idx):
        p, _, _, _ = nearest_hits(receiver_scene(receivers.tris), O2, D2)
        prim[idx] = p
    Q = np.empty((len(O), 3))
    length = np.empty(len(O))
    rid = np.empty(len(O), np.int64)
    img = np.empty((len(O), 3), np.float32)
    _receiver_points(_Hits(O, D, P, T, prim, status, np.ascontiguousarray(receivers.tris), receivers.owner, Q,
                           length, rid), _look(receivers, caustics, float(water["absorption"])), img)
    ok = (status == VIEW_THROUGH) | (status == VIEW_DIRECT)
    return {"image": img.reshape(H, W, 3), "object_mask": ok.reshape(H, W),
            "view_status": status.reshape(H, W), "water_pos": P.reshape(H, W, 3),
            "water_dir": T.reshape(H, W, 3), "receiver_pos": Q.reshape(H, W, 3),
            "water_length": length.reshape(H, W)}
