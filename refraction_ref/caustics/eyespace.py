"""Eye-space intersection of photon rays with the receivers (Chaudhari 2008, §4.1; Krüger et al. 2006).

The ``receiver_hit = 'eyespace'`` pass: photon rays marched in the camera's
depth image of the receivers (:func:`~refraction_ref.caustics.receivers.eye_buffers`).

The thesis follows Krüger et al. (2006): the exiting photon becomes a
line primitive in the camera's image, and the first fragment of the
line that falls behind the receivers' depth image is its hit. Here the
ray is clipped to the camera's frustum, sampled once per pixel along
its screen-space projection (``ceil(L) + 1`` steps for ``L`` pixels
along the major axis, uniform on screen, perspective-correct along the
ray), compared at each sample with the depth image of the receivers
(rasterized from the camera with the shared rasterizer, nearest depth
and triangle) at the nearest texel, and the crossing is refined by
linear interpolation of the depth gap between the last sample in front
and the first behind (the first behind itself when the sample before
it saw no receiver); the hit's triangle is that of the texel where the
crossing was detected. The hit lies on the ray, near but not exactly
on the receiver (docs/oracle.md, "Porting rules: image-space",
``receiver_hit``). A sample that lands
behind by more than the ray's depth step plus 1 % of the depth is taken
as passing behind an occluder, not a hit, and the march goes on.
Photons that leave the frustum, or never cross, are lost (the method's
known limitation: it only sees what the camera sees).

The march steps over runs of samples that cannot hit with two levels of
tiles of the depth image's nearest depth (:data:`TILE_COARSE`,
:data:`TILE_FINE`): the hits are those of testing every sample.

References
----------
.. [1] J. Krüger, K. Bürger, R. Westermann, "Interactive Screen-Space
   Accurate Photon Tracing on GPUs", EGSR 2006.
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §4.1.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..camera import project_point

__all__ = ["march_eyespace", "clip_interval", "tile_min", "TILE_COARSE", "TILE_FINE"]


@nb.njit(cache=True, inline="always")
def clip_interval(a0, a1, t0, t1):
    """Clip the ray interval ``[t0, t1]`` to where the linear function ``a0 + a1 t <= 0`` (one frustum plane).

    Parameters
    ----------
    a0, a1 : float
        The plane's signed distance at ``t = 0`` and its rate along the ray.
    t0, t1 : float
        The interval so far.

    Returns
    -------
    t0, t1 : float
        The clipped interval (empty, ``t1 < t0``, where none of it is inside).

    References
    ----------
    .. [1] J. Krüger, K. Bürger, R. Westermann, "Interactive Screen-Space
       Accurate Photon Tracing on GPUs", EGSR 2006 (the ray clipped to the view frustum).
    """
    if a1 == 0.0:
        if a0 > 0.0:
            return 1.0, 0.0
        return t0, t1
    tc = -a0 / a1
    if a1 > 0.0:
        return t0, min(t1, tc)
    return max(t0, tc), t1


class _MarchRays(NamedTuple):
    """The march's rays, in the camera's view space."""

    O: np.ndarray  # (N, 3) origins
    D: np.ndarray  # (N, 3) directions


class _MarchView(NamedTuple):
    """The camera the march's depth image was rendered with: image grid, projection, depth range."""

    W: int
    H: int
    sx: float
    sy: float
    ortho: bool
    near: float
    far: float


class _MarchSettings(NamedTuple):
    """Settings of the march."""

    rel_thick: float  # surface thickness as a fraction of its depth
    max_samples: int  # samples per ray at most


class _MarchHits(NamedTuple):
    """What the march finds, per ray."""

    t: np.ndarray  # (N,) ray parameter of the hit, NaN where none
    pix: np.ndarray  # (N, 2) int64 pixel (row, column), -1 where none


#: sides (pixels) of the two levels of tiles whose nearest receiver depth lets the march
#: step over samples that cannot hit (see :func:`_march_kernel`); the coarse a multiple of the fine
TILE_COARSE = 32
TILE_FINE = 8


@nb.njit(cache=True, parallel=True)
def _tile_min_kernel(depth, T, out):
    # out[a, b]: the nearest finite depth of tile (a, b) of T x T pixels, +inf where none
    # (min is exact: the same whatever the order)
    H, W = depth.shape
    for a0 in nb.prange(out.shape[0]):
        a = np.int64(a0)
        for b in range(out.shape[1]):
            out[a, b] = np.inf
        for i in range(a * T, min(a * T + T, H)):
            for j in range(W):
                v = depth[i, j]
                if math.isfinite(v) and v < out[a, j // T]:
                    out[a, j // T] = v


def tile_min(depth, T):
    """The nearest finite depth of each ``T`` x ``T`` tile of a depth image (``+inf`` where none).

    Parameters
    ----------
    depth : (H, W) float64
    T : int
        Tile side in pixels (the last row and column of tiles may be partial).

    Returns
    -------
    (ceil(H / T), ceil(W / T)) float64

    References
    ----------
    .. [1] J. Krüger, K. Bürger, R. Westermann, "Interactive Screen-Space
       Accurate Photon Tracing on GPUs", EGSR 2006.
    """
    d = np.ascontiguousarray(depth, dtype=np.float64)
    out = np.empty((-(-d.shape[0] // T), -(-d.shape[1] // T)))
    _tile_min_kernel(d, np.int64(T), out)
    return out


@nb.njit(cache=True, parallel=True)
def _coarsen_min(fine, r, out):
    # out[a, b] = min of fine[r a : r a + r, r b : r b + r] (exact in any order)
    for a0 in nb.prange(out.shape[0]):
        a = np.int64(a0)
        for b in range(out.shape[1]):
            v = np.inf
            for i in range(a * r, min(a * r + r, fine.shape[0])):
                for j in range(b * r, min(b * r + r, fine.shape[1])):
                    v = min(v, fine[i, j])
            out[a, b] = v


class _ClippedRay(NamedTuple):
    """One ray of the march, clipped to the frustum and sampled ``n + 1`` times on screen."""

    ox: float  # origin (view space)
    oy: float
    oz: float
    dx: float  # direction
    dy: float
    dz: float
    t0: float  # the clipped interval
    t1: float
    dA: float  # depth at t0 and at t1
    dB: float
    n: int  # samples 0 .. n
    persp: bool  # perspective-correct samples (1/depth linear on screen)


@nb.njit(cache=True, inline="always")
def _march_sample(m, ray, view):
    """Sample ``m`` of ``ray.n`` of a clipped ray: its parameter ``t`` and (col, row, depth) on screen.

    Uniform on screen: perspective-correct along the ray (``1/depth`` linear in ``u = m / n``),
    or uniform in ``t`` for an orthographic view.

    References
    ----------
    .. [1] J. Krüger, K. Bürger, R. Westermann, "Interactive Screen-Space
       Accurate Photon Tracing on GPUs", EGSR 2006 (the photon's line in the image).
    """
    u = m / ray.n
    if ray.persp:  # perspective-correct: 1/depth is linear in screen space
        s = (u / ray.dB) / ((1.0 - u) / ray.dA + u / ray.dB)
    else:
        s = u
    t = ray.t0 + s * (ray.t1 - ray.t0)
    col, row, rd = project_point(ray.ox + t * ray.dx, ray.oy + t * ray.dy, ray.oz + t * ray.dz, view.W, view.H,
                                 view.sx, view.sy, view.ortho)
    return t, col, row, rd


#: how far inside a tile (pixels) the samples of a run stepped over must lie on the line
#: through the end points: far above the rounding of their screen positions (~1e-10 px),
#: far below a pixel
_TILE_MARGIN = 1e-6


class _ScreenLine(NamedTuple):
    """A clipped ray's samples on screen: sample ``m`` at ``(c0, r0) + m (stepc, stepr)``, ``m = 0 .. n``."""

    c0: float
    r0: float
    stepc: float
    stepr: float
    inv_c: float  # 1 / stepc, 0 for none
    inv_r: float  # 1 / stepr, 0 for none
    n: int


@nb.njit(cache=True, inline="always")
def _run_in_tile(T, m, line, W, H):
    """The tile (a, b) of ``T`` pixels (a literal: the divisions are shifts) holding sample
    ``m`` of ``line`` (``_TILE_MARGIN`` inside) and the last sample ``mb <= n`` of the run from
    ``m`` still in it; ``mb = -1`` when sample ``m`` is not inside a tile."""
    stepc, stepr, inv_c, inv_r = line.stepc, line.stepr, line.inv_c, line.inv_r
    col = line.c0 + m * stepc
    row = line.r0 + m * stepr
    if not (col >= 0.0 and col < W and row >= 0.0 and row < H):
        return 0, 0, np.int64(-1)
    a = np.int64(math.floor(row)) // T
    b = np.int64(math.floor(col)) // T
    x0 = b * T + _TILE_MARGIN
    x1 = min(b * T + T, W) - _TILE_MARGIN
    y0 = a * T + _TILE_MARGIN
    y1 = min(a * T + T, H) - _TILE_MARGIN
    if not (col >= x0 and col <= x1 and row >= y0 and row <= y1):
        return a, b, np.int64(-1)
    k = 1e18
    if stepc > 0.0:
        k = min(k, (x1 - col) * inv_c)
    elif stepc < 0.0:
        k = min(k, (x0 - col) * inv_c)
    if stepr > 0.0:
        k = min(k, (y1 - row) * inv_r)
    elif stepr < 0.0:
        k = min(k, (y0 - row) * inv_r)
    return a, b, min(m + np.int64(k), line.n)


@nb.njit(cache=True, inline="always")
def _nearer(m, me, persp, inv_n, ia, ib, dA, dB, slack, lim):
    """Whether the ray's depth at samples ``m .. me`` is below ``lim`` (less ``slack``): from its
    end depths, 1/depth linear in the sample for perspective-correct samples (``ia``, ``ib``
    the end points' 1/depth), the depth itself for orthographic ones; the extremes at the ends."""
    if persp:
        w = min(ia + (m * inv_n) * (ib - ia), ia + (me * inv_n) * (ib - ia))
        return w > 0.0 and w * (lim - slack) > 1.0
    return max(dA + (m * inv_n) * (dB - dA), dA + (me * inv_n) * (dB - dA)) + slack < lim


@nb.njit(cache=True, parallel=True)
def _march_kernel(rays, depth, view, settings, tiles, hits):
    # the named tuples unpacked by name, outside the prange loop (inside it, Numba
    # drops stores into arrays taken from a tuple: numba#7135)
    O, D = rays.O, rays.D
    W, H, sx, sy, ortho, near, far = view.W, view.H, view.sx, view.sy, view.ortho, view.near, view.far
    rel_thick, max_samples = settings.rel_thick, settings.max_samples
    t_hit, pix = hits.t, hits.pix
    tc, tf = tiles.coarse, tiles.fine
    for k0 in nb.prange(O.shape[0]):
        k = np.int64(k0)
        t_hit[k] = np.nan
        pix[k, 0] = -1
        pix[k, 1] = -1
        ox, oy, oz = O[k, 0], O[k, 1], O[k, 2]
        dx, dy, dz = D[k, 0], D[k, 1], D[k, 2]
        if not (math.isfinite(ox) and math.isfinite(dx)):
            continue
        # clip the ray to the view frustum: each bound is linear in t
        t0 = 0.0
        t1 = 1e30
        t0, t1 = clip_interval(near + oz, dz, t0, t1)      # depth >= near
        t0, t1 = clip_interval(-oz - far, -dz, t0, t1)     # depth <= far
        if ortho:
            t0, t1 = clip_interval(ox - sx, dx, t0, t1)
            t0, t1 = clip_interval(-ox - sx, -dx, t0, t1)
            t0, t1 = clip_interval(oy - sy, dy, t0, t1)
            t0, t1 = clip_interval(-oy - sy, -dy, t0, t1)
        else:  # |x| <= sx d, |y| <= sy d with d = -z
            t0, t1 = clip_interval(ox + sx * oz, dx + sx * dz, t0, t1)
            t0, t1 = clip_interval(-ox + sx * oz, -dx + sx * dz, t0, t1)
            t0, t1 = clip_interval(oy + sy * oz, dy + sy * dz, t0, t1)
            t0, t1 = clip_interval(-oy + sy * oz, -dy + sy * dz, t0, t1)
        if not (t1 > t0) or t1 >= 1e29:
            continue
        # screen-space end points: one sample per pixel along the projected line
        c0, r0, dA = project_point(ox + t0 * dx, oy + t0 * dy, oz + t0 * dz, W, H, sx, sy, ortho)
        c1, r1, dB = project_point(ox + t1 * dx, oy + t1 * dy, oz + t1 * dz, W, H, sx, sy, ortho)
        n = np.int64(math.ceil(max(abs(c1 - c0), abs(r1 - r0)))) + 1
        n = min(max(n, 2), max_samples)
        persp = not (ortho or not (dA > 0.0 and dB > 0.0))
        ray = _ClippedRay(ox, oy, oz, dx, dy, dz, t0, t1, dA, dB, n, persp)
        # Tiles: whether sample m hits depends on it and on sample m - 1 alone, and it can hit
        # only where the ray is at or behind the receiver under it. With samples uniform on
        # screen (orthographic, or perspective-correct: then on screen sample m lies at
        # (c0, r0) + m (c1 - c0, r1 - r0) / n and 1/depth is linear in m), a run of samples
        # inside one tile whose ray depth at both ends is nearer than the tile's nearest
        # receiver holds no hit: it is stepped over, and the sample before the next one tested
        # is evaluated as the state that one compares with. The hits are those of testing
        # every sample.
        tiled = ortho or persp
        stepc = (c1 - c0) / n
        stepr = (r1 - r0) / n
        line = _ScreenLine(c0, r0, stepc, stepr, 1.0 / stepc if stepc != 0.0 else 0.0,
                           1.0 / stepr if stepr != 0.0 else 0.0, n)
        inv_n = 1.0 / n
        ia = 1.0 / dA if dA != 0.0 else 0.0
        ib = 1.0 / dB if dB != 0.0 else 0.0
        # the bounds' own rounding, and that of a sample's depth -(oz + t dz), are ~1e-15 of these
        slack = 1e-9 * (abs(oz) + abs(t0 * dz) + abs(t1 * dz) + abs(dA) + abs(dB))
        prev_gap = -np.inf
        prev_t = t0
        prev_rd = dA
        m = np.int64(0)
        stale = False  # prev_* are not sample m - 1's (a run was stepped over)
        hit = False
        while m <= n and not hit:
            mb = m  # test samples m .. mb one by one
            if tiled:
                a, b, me = _run_in_tile(TILE_COARSE, m, line, W, H)
                if me >= m and _nearer(m, me, persp, inv_n, ia, ib, dA, dB, slack, tc[a, b]):
                    m = me + 1
                    stale = True
                    continue
                a, b, me = _run_in_tile(TILE_FINE, m, line, W, H)
                if me >= m:
                    if _nearer(m, me, persp, inv_n, ia, ib, dA, dB, slack, tf[a, b]):
                        m = me + 1
                        stale = True
                        continue
                    mb = me  # the rest of this fine tile, tested sample by sample
            if stale:
                t, col, row, rd = _march_sample(m - 1, ray, view)
                i = min(max(np.int64(math.floor(row)), 0), H - 1)
                j = min(max(np.int64(math.floor(col)), 0), W - 1)
                sd = depth[i, j]
                prev_gap = rd - sd if math.isfinite(sd) else -np.inf
                prev_t = t
                prev_rd = rd
                stale = False
            for q in range(m, mb + 1):
                t, col, row, rd = _march_sample(q, ray, view)
                i = min(max(np.int64(math.floor(row)), 0), H - 1)
                j = min(max(np.int64(math.floor(col)), 0), W - 1)
                sd = depth[i, j]
                gap = rd - sd if math.isfinite(sd) else -np.inf
                if gap >= 0.0 and prev_gap < 0.0:
                    if gap <= abs(rd - prev_rd) + rel_thick * sd:
                        f = 1.0
                        if math.isfinite(prev_gap):
                            f = -prev_gap / (gap - prev_gap)
                        t_hit[k] = prev_t + f * (t - prev_t)
                        pix[k, 0] = i
                        pix[k, 1] = j
                        hit = True
                        break
                prev_gap = gap
                prev_t = t
                prev_rd = rd
            m = mb + 1


class _DepthTiles(NamedTuple):
    """The depth image's nearest depth per tile, two levels (:func:`tile_min`)."""

    coarse: np.ndarray  # TILE_COARSE pixels a side
    fine: np.ndarray  # TILE_FINE pixels a side


def march_eyespace(origins_view, dirs_view, depth, cam, rel_thick=0.01, max_samples=1 << 16):
    """Krüger-style screen-space march of rays against a depth image.

    Parameters
    ----------
    origins_view, dirs_view : (N, 3) array_like
        Rays in the camera's view space.
    depth : (H, W) float64
        The receivers' depth image (:func:`eye_buffers`).
    cam : Camera
    rel_thick : float
        Surface thickness as a fraction of its depth (beyond it a sample
        behind the surface is taken as passing behind it).
    max_samples : int
        Samples per ray at most.

    Returns
    -------
    t : (N,) float64
        Ray parameter of the hit, NaN where none.
    pix : (N, 2) int64
        Pixel (row, column) of the hit, ``-1`` where none.

    References
    ----------
    Chaudhari 2008, §4.1 (photons to their receivers); Krüger et al. 2006 (the screen-space march).
    """
    O = np.ascontiguousarray(origins_view, dtype=np.float64).reshape(-1, 3)
    D = np.ascontiguousarray(dirs_view, dtype=np.float64).reshape(-1, 3)
    t = np.empty(len(O))
    pix = np.empty((len(O), 2), np.int64)
    if len(O):
        W, H, sx, sy = cam.kernel_args()
        # marches differ in length by orders of magnitude (a ray crossing the image against one
        # that leaves at once): rays go to the threads in small chunks as they free up
        dep = np.ascontiguousarray(depth, dtype=np.float64)
        fine = tile_min(dep, TILE_FINE)
        coarse = np.empty((-(-dep.shape[0] // TILE_COARSE), -(-dep.shape[1] // TILE_COARSE)))
        _coarsen_min(fine, TILE_COARSE // TILE_FINE, coarse)
        with nb.parallel_chunksize(64):
            _march_kernel(_MarchRays(O, D), dep,
                          _MarchView(W, H, sx, sy, bool(cam.ortho), float(cam.near), float(cam.far)),
                          _MarchSettings(float(rel_thick), int(max_samples)), _DepthTiles(coarse, fine),
                          _MarchHits(t, pix))
    return t, pix

