"""The final pass: receivers lit directly (with a shadow test) and by the caustics (Chaudhari 2008, §4.1).

A receiver point ``p`` with face normal ``n`` (turned towards the ray that
sees it) and albedo ``rho`` has the colour

.. math:: c = \\rho \\Big(\\sum_l L_l \\big(\\max(0, -n \\cdot \\omega_l)\\, f_l(p)\\, V_l(p)
              + E_{c,l}(p)\\big)\\Big)

with ``L_l`` the light's radiance (RGB), ``omega_l`` the direction its
rays travel, ``f_l = 1`` (directional) or ``1 / r^2`` (point), ``V_l`` the
visibility of the light past the refractive objects (the shadow test) and
``E_c`` the caustic irradiance looked up (bilinearly) in the receiver's
caustic map (``caustic_rgb_r``, which already holds ``L_l``). There is no
ambient term: light that passed through an object reaches the receiver
only as caustics, so at IOR 1 the caustics exactly replace the shadow.

Shadow tests: the image-space method reads the light's min-depth image
(the first pass of §3.3 in the light's view doubles as a shadow map); the
exact reference casts a ray to the light through the real triangles.

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §4.1.
.. [2] L. Williams, "Casting Curved Shadows on Curved Surfaces", SIGGRAPH
   1978 (shadow maps).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..embree import HIT_CHUNK, chunk_length, commit, run_chunks, soup_scene
from ..lights import light_direction_at
from .receivers import map_position, occluded

__all__ = ["sample_bilinear", "shade_points", "shadow_map_visibility", "shadow_map_margin", "shadow_map_test",
           "ShadowMaps", "shade_rows", "shade_rows_applies", "exact_visibility", "take_rows"]


@nb.njit(cache=True, inline="always")
def _bilinear_texels(col, row, Wc, Hc):
    """The four texels and weights of a bilinear look-up at map position ``(col, row)``.

    Texel centres at +0.5; positions clamped to the map and NaN read as its
    first texel (:func:`sample_bilinear`'s rules): ``(i0, j0, i1, j1, fx, fy)``.
    """
    x = min(max(col - 0.5, 0.0), Wc - 1.0)
    y = min(max(row - 0.5, 0.0), Hc - 1.0)
    if math.isnan(col):
        x = 0.0
    if math.isnan(row):
        y = 0.0
    j0 = min(np.int64(math.floor(x)), Wc - 1)
    i0 = min(np.int64(math.floor(y)), Hc - 1)
    return i0, j0, min(i0 + 1, Hc - 1), min(j0 + 1, Wc - 1), x - j0, y - i0


@nb.njit(cache=True, parallel=True)
def _add_bilinear_kernel(E, col, row, sel, out):
    # out[sel[k]] += the bilinear look-up of E at (col[k], row[k]): sample_bilinear's
    # operations in its order, one point per iteration
    Hc, Wc, C = E.shape
    for k0 in nb.prange(col.shape[0]):
        k = np.int64(k0)
        i0, j0, i1, j1, fx, fy = _bilinear_texels(col[k], row[k], Wc, Hc)
        q = sel[k]
        for c in range(C):
            out[q, c] += ((1 - fy) * ((1 - fx) * E[i0, j0, c] + fx * E[i0, j1, c])
                          + fy * ((1 - fx) * E[i1, j0, c] + fx * E[i1, j1, c]))


@nb.njit(cache=True, inline="always")
def _einsum_dot(ax, ay, az, bx, by, bz):
    """``np.einsum('ij,ij->i')``'s sum of one row, in its order (see ``exact._dot3``)."""
    return (ax * bx + az * bz) + ay * by


@nb.njit(cache=True, parallel=True)
def _facing_normals_kernel(normals, faces, ray_dirs, n):
    # n = normals[faces], negated where it faces along the ray (NumPy's einsum > 0)
    for k0 in nb.prange(faces.shape[0]):
        k = np.int64(k0)
        f = faces[k]
        x, y, z = normals[f, 0], normals[f, 1], normals[f, 2]
        if _einsum_dot(x, y, z, ray_dirs[k, 0], ray_dirs[k, 1], ray_dirs[k, 2]) > 0:
            x, y, z = -x, -y, -z
        n[k, 0] = x
        n[k, 1] = y
        n[k, 2] = z


@nb.njit(cache=True, parallel=True)
def _cosine_kernel(n, L, cos):
    # cos = np.maximum(0, -einsum(n, L)) (NaN stays NaN, as np.maximum keeps it)
    for k0 in nb.prange(n.shape[0]):
        k = np.int64(k0)
        c = -_einsum_dot(n[k, 0], n[k, 1], n[k, 2], L[k, 0], L[k, 1], L[k, 2])
        cos[k] = c if (c > 0.0 or c != c) else 0.0


@nb.njit(cache=True, parallel=True)
def _count_positive(a):
    # (a > 0).sum(): an integer sum, the same in any order
    n = 0
    for k0 in nb.prange(a.shape[0]):
        if a[np.int64(k0)] > 0:
            n += 1
    return n


@nb.njit(cache=True, parallel=True)
def _take_kernel(a, idx, out):
    # out = a[idx] (1-D)
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        out[k] = a[idx[k]]


@nb.njit(cache=True, parallel=True)
def _add_direct_kernel(radiance, cos, fall, v, light_sum):
    # light_sum += radiance[None, :] * (cos * fall * v)[:, None], term for term
    for k0 in nb.prange(cos.shape[0]):
        k = np.int64(k0)
        w = cos[k] * fall[k] * v[k]
        for c in range(3):
            light_sum[k, c] += radiance[c] * w


@nb.njit(cache=True, parallel=True)
def _albedo_kernel(albedo, owner, light_sum, out):
    # out = albedo[owner] * light_sum
    for k0 in nb.prange(owner.shape[0]):
        k = np.int64(k0)
        for c in range(3):
            out[k, c] = albedo[owner[k], c] * light_sum[k, c]


@nb.njit(cache=True, parallel=True)
def _take_rows_kernel(a, idx, out):
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        for c in range(a.shape[1]):
            out[k, c] = a[idx[k], c]


def take_rows(a, idx):
    """``a[idx]`` of an (N, C) float64 array, on every thread.

    Parameters
    ----------
    a : (N, C) array_like
    idx : (M,) array_like of int
        Rows to take, in order.

    Returns
    -------
    (M, C) float64

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    a = np.ascontiguousarray(a, dtype=np.float64)
    out = np.empty((len(idx), a.shape[1]))
    if len(idx):
        _take_rows_kernel(a, np.ascontiguousarray(idx, dtype=np.int64), out)
    return out


def sample_bilinear(E, col, row):
    """Bilinear look-up of a map (Hc, Wc, C) at continuous texel positions, clamped at the border.

    Parameters
    ----------
    E : (Hc, Wc, C) array_like
        A caustic map.
    col, row : (M,) array_like
        Continuous positions (texel centres at ``+0.5``).

    Returns
    -------
    (M, C) float64

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    Hc, Wc = E.shape[:2]
    x = np.clip(np.asarray(col, dtype=np.float64) - 0.5, 0.0, Wc - 1.0)
    y = np.clip(np.asarray(row, dtype=np.float64) - 0.5, 0.0, Hc - 1.0)
    x = np.nan_to_num(x)
    y = np.nan_to_num(y)
    j0 = np.minimum(np.floor(x).astype(np.int64), Wc - 1)
    i0 = np.minimum(np.floor(y).astype(np.int64), Hc - 1)
    j1 = np.minimum(j0 + 1, Wc - 1)
    i1 = np.minimum(i0 + 1, Hc - 1)
    fx = (x - j0)[:, None]
    fy = (y - i0)[:, None]
    return ((1 - fy) * ((1 - fx) * E[i0, j0] + fx * E[i0, j1])
            + fy * ((1 - fx) * E[i1, j0] + fx * E[i1, j1]))


class _LightView(NamedTuple):
    """The light camera's projection (Camera.to_screen) and the depth bias of the shadow test."""

    sx: float
    sy: float
    ortho: bool
    width: float
    height: float
    bias: float


@nb.njit(cache=True, inline="always")
def _screen_of(x, y, z, view):
    """Camera.to_screen of view-space point (x, y, z) in its operations' order: (col, row, depth along the view)."""
    d = -z
    s = 1.0 if view.ortho else d
    col = (x / (s * view.sx) * 0.5 + 0.5) * view.width
    row = (0.5 - y / (s * view.sy) * 0.5) * view.height
    return col, row, d


@nb.njit(cache=True, inline="always")
def _light_screen(pv, k, view):
    """Camera.to_screen of view-space point k in its operations' order: (col, row, depth along the view)."""
    return _screen_of(pv[k, 0], pv[k, 1], pv[k, 2], view)


@nb.njit(cache=True, inline="always")
def _to_view(x, y, z, m, t, c):
    """Column ``c`` of :func:`~refraction_ref.vec3.affine`'s ``p @ m + t`` (Camera.world_to_view), in its order."""
    return x * m[0, c] + y * m[1, c] + z * m[2, c] + t[c]


def _world_to_view_args(lcam):
    """``(m, t)`` of ``Camera.world_to_view``'s affine map, computed as it computes them."""
    b = lcam.basis
    return (np.ascontiguousarray(b.T, dtype=np.float64),
            np.ascontiguousarray(-np.asarray(lcam.eye, dtype=np.float64) @ b.T, dtype=np.float64))


def _light_view(lcam, bias):
    return _LightView(float(lcam.sx), float(lcam.sy), bool(lcam.ortho), float(lcam.width), float(lcam.height),
                      float(bias))


@nb.njit(cache=True, inline="always")
def _margin_at(col, row, d, zmin, bias):
    """``dl - (zmin + bias)`` at screen position (col, row), ``-inf`` where no depth is compared.

    Outside the light's window (which covers the objects) or over a texel no object covers nothing is
    compared: lit. For finite values ``d - (z + bias) > 0`` exactly when ``d > z + bias`` (IEEE
    subtraction is 0 only for equal operands), so the shadow test is this margin's sign.
    """
    H, W = zmin.shape
    if not (math.isfinite(col) and math.isfinite(row) and col >= 0 and col < W and row >= 0 and row < H
            and d > 0):
        return -np.inf
    i = min(max(np.int64(math.floor(row)), 0), H - 1)
    j = min(max(np.int64(math.floor(col)), 0), W - 1)
    z = zmin[i, j]
    if not math.isfinite(z):
        return -np.inf
    return d - (z + bias)


@nb.njit(cache=True, parallel=True)
def _shadow_map_kernel(pv, zmin, view, out):
    # the depth test per point: shadowed where the margin is positive
    for k0 in nb.prange(pv.shape[0]):
        k = np.int64(k0)
        col, row, d = _light_screen(pv, k, view)
        out[k] = 0.0 if _margin_at(col, row, d, zmin, view.bias) > 0 else 1.0


def shadow_map_visibility(lcam, zmin, points, bias):
    """Visibility of a light at world points from its min-depth image (1 lit, 0 shadowed).

    Points outside the light's window are lit (the window covers the objects).

    Parameters
    ----------
    lcam : Camera
        The light's camera.
    zmin : (N, N) float64
        The objects' nearest depth from the light (the photon pass's min/max).
    points : (M, 3) array_like
        World points.
    bias : float
        Depth offset against self-shadowing.

    Returns
    -------
    (M,) float64

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return np.ones(0)
    pv = lcam.world_to_view(p)
    out = np.empty(len(p))
    _shadow_map_kernel(pv, np.ascontiguousarray(zmin, dtype=np.float64),
                       _LightView(float(lcam.sx), float(lcam.sy), bool(lcam.ortho), float(lcam.width),
                                  float(lcam.height), float(bias)), out)
    return out


def shadow_map_margin(lcam, zmin, points, bias, tie=0.0):
    """How far each point lies behind its shadow-map depth plus the bias: ``dl - (zmin + bias)``.

    The shadow test of :func:`shadow_map_visibility` shadows a point where this is > 0. Points outside
    the light's window, behind it, or over a texel no object covers get ``-inf`` (lit, no depth compared).
    With ``tie > 0``, a point whose verdict changes when its texel position moves by ``tie`` texel along
    either axis (it lies that close to a texel edge across which the test decides otherwise) gets 0.

    Parameters
    ----------
    lcam : Camera
    zmin : (N, N) float64
    points : (M, 3) array_like
    bias : float
    tie : float
        Texels.

    Returns
    -------
    (M,) float64

    References
    ----------
    .. [1] L. Williams, "Casting Curved Shadows on Curved Surfaces", SIGGRAPH 1978.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros(0)
    pv = lcam.world_to_view(p)
    out = np.empty(len(p))
    # per point on every thread: the NumPy expressions of the test, element by element
    _shadow_margin_kernel(pv, np.ascontiguousarray(zmin, dtype=np.float64), _light_view(lcam, bias), float(tie),
                          out)
    return out


@nb.njit(cache=True, inline="always")
def _tie_probes(col, row, d, zmin, bias, tie, m):
    """``m`` set to 0 where the verdict of the shadow test changes when the point moves ``tie`` texel
    along either axis: four probes in their order, each compared with the margin as the probes
    before left it (:func:`shadow_map_margin`); ``m`` unchanged when ``tie <= 0``."""
    if tie > 0:
        for q in range(4):
            dc = tie if q == 0 else (-tie if q == 1 else 0.0)
            dr = tie if q == 2 else (-tie if q == 3 else 0.0)
            if (_margin_at(col + dc, row + dr, d, zmin, bias) > 0) != (m > 0):
                m = 0.0
    return m


@nb.njit(cache=True, parallel=True)
def _shadow_margin_kernel(pv, zmin, view, tie, out):
    # shadow_map_margin per point: the light's screen position, the margin, and the
    # four tie probes in their order (each compared with the margin as the probes before left it)
    bias = view.bias
    for k0 in nb.prange(pv.shape[0]):
        k = np.int64(k0)
        col, row, d = _light_screen(pv, k, view)
        out[k] = _tie_probes(col, row, d, zmin, bias, tie, _margin_at(col, row, d, zmin, bias))


@nb.njit(cache=True, parallel=True)
def _shadow_test_kernel(p, m, t, zmin, view, tie, idx, code, margin):
    # per point: Camera.world_to_view (affine's order), then _shadow_map_kernel's verdict and
    # _shadow_margin_kernel's margin and tie probes, written to the point's own row idx[k]
    bias = view.bias
    for k0 in nb.prange(p.shape[0]):
        k = np.int64(k0)
        x, y, z = p[k, 0], p[k, 1], p[k, 2]
        col, row, d = _screen_of(_to_view(x, y, z, m, t, 0), _to_view(x, y, z, m, t, 1),
                                 _to_view(x, y, z, m, t, 2), view)
        mg = _margin_at(col, row, d, zmin, bias)
        q = idx[k]
        code[q] = 2 if mg > 0 else 1
        margin[q] = np.float32(_tie_probes(col, row, d, zmin, bias, tie, mg))


def shadow_map_test(lcam, zmin, points, bias, tie, idx, code, margin):
    """The shadow test's verdict and margin at world points, written to rows ``idx`` of two buffers.

    ``code[idx] = np.where(shadow_map_visibility(...) > 0, 1, 2)`` and
    ``margin[idx] = shadow_map_margin(..., tie)`` (cast to the buffer's float32), in one pass over
    the points on every thread: each point's light-view position is computed once for both.

    Parameters
    ----------
    lcam : Camera
    zmin : (N, N) float64
    points : (M, 3) array_like
    bias : float
    tie : float
        Texels (:func:`shadow_map_margin`).
    idx : (M,) array_like of int
        Distinct rows of ``code`` and ``margin``.
    code : (K,) uint8
        1 lit, 2 in shadow, written at ``idx``.
    margin : (K,) float32
        Written at ``idx``.

    References
    ----------
    .. [1] L. Williams, "Casting Curved Shadows on Curved Surfaces", SIGGRAPH 1978.
    """
    p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return
    m, t = _world_to_view_args(lcam)
    _shadow_test_kernel(p, m, t, np.ascontiguousarray(zmin, dtype=np.float64), _light_view(lcam, bias),
                        float(tie), np.ascontiguousarray(idx, dtype=np.int64), code, margin)


class ShadowMaps:
    """Visibility of each light from its min-depth image: ``vis(l, points, normals)`` (normals unused).

    A callable like any ``visibility`` argument of :func:`shade_points`, which recognises it and
    tests the shadow inside its per-point kernel instead of calling it.

    Parameters
    ----------
    shadow : list of (lcam, zmin, bias) or None
        Per light its camera, nearest depth image and bias; None casts no shadow.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """

    def __init__(self, shadow):
        self.shadow = list(shadow)

    def __call__(self, l, points, normals):
        if self.shadow[l] is None:
            return np.ones(len(points))
        lcam, zmin, bias = self.shadow[l]
        return shadow_map_visibility(lcam, zmin, points, bias)


@nb.njit(cache=True, parallel=True)
def _shadow_rays_kernel(p, n, tl, s, o, d):
    # exact_visibility's rays towards a directional light: side = +-1 as n . to_light >= 0
    # (einsum's order), o = p + s (to_light + side n), d = to_light
    tx, ty, tz = tl[0], tl[1], tl[2]
    for k0 in nb.prange(p.shape[0]):
        k = np.int64(k0)
        side = 1.0 if _einsum_dot(n[k, 0], n[k, 1], n[k, 2], tx, ty, tz) >= 0 else -1.0
        o[k, 0] = p[k, 0] + s * (tx + side * n[k, 0])
        o[k, 1] = p[k, 1] + s * (ty + side * n[k, 1])
        o[k, 2] = p[k, 2] + s * (tz + side * n[k, 2])
        d[k, 0] = tx
        d[k, 1] = ty
        d[k, 2] = tz


def exact_visibility(obj_tris, light, points, normals, chunk=None, scene=None, scale=None):
    """Visibility of a light at world points past the refractive triangles (Embree shadow rays).

    The points are tested in fixed chunks (``chunk`` points, default
    :func:`~refraction_ref.embree.chunk_length` of their number: eight or more
    equal chunks) on ``numba.get_num_threads()`` threads
    (:func:`refraction_ref.embree.run_chunks`), each chunk from its points to
    its rays' hits; every ray is tested on its own, so the result does not
    depend on the chunks or the threads.

    Parameters
    ----------
    obj_tris : (T, 3, 3) float64 or IndexedTriangles
        The refractive triangles.
    light : dict
    points, normals : (M, 3) array_like
    chunk : int, optional
    scene : embreex scene, optional
        An Embree scene of the same triangles in the same order (the exact
        tracer's cached ``embree.mesh_scene(vertices, faces)``, which saves
        building a soup of the objects' triangles every render); default the
        cached soup of ``obj_tris``.
    scale : float, optional
        ``max(|obj_tris|.max(), 1)``, the scale of the push off the surface,
        when known.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0 or len(obj_tris) == 0:
        return np.ones(len(p))
    if scale is None:
        scale = max(obj_tris.abs_max() if hasattr(obj_tris, "abs_max") else float(np.abs(obj_tris).max()), 1.0)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    pos = np.asarray(light["position"], dtype=np.float64) if light["type"] == "point" else None
    scene = commit(soup_scene(np.asarray(obj_tris)) if scene is None else scene)  # built before the threads query it
    if pos is None and chunk is None:
        # a directional light: every ray's origin and direction by one parallel kernel (the
        # NumPy expressions below, operation for operation), then the chunked Embree hits
        L, _ = light_direction_at(light, p[:1])
        tl = -np.asarray(L, dtype=np.float64)[0]
        o = np.empty((len(p), 3))
        d = np.empty((len(p), 3))
        _shadow_rays_kernel(p, n, tl, 1e-6 * scale, o, d)
        return (~occluded(obj_tris, o, d, None, scene)).astype(np.float64)
    hit = np.empty(len(p), dtype=bool)

    def one(a, b):
        # every step is row by row: a chunk's rows are those the whole array would have
        L, _ = light_direction_at(light, p[a:b])
        to_light = -np.asarray(L)
        side = np.where(np.einsum("ij,ij->i", n[a:b], to_light) >= 0, 1.0, -1.0)[:, None]
        o = p[a:b] + 1e-6 * scale * (to_light + side * n[a:b])
        tmax = None if pos is None else np.linalg.norm(pos - o, axis=1)
        hit[a:b] = occluded(obj_tris, o, to_light, tmax, scene)

    run_chunks(one, len(p), chunk_length(len(p), HIT_CHUNK) if chunk is None else int(chunk))
    return (~hit).astype(np.float64)


class _ShadeReceivers(NamedTuple):
    """The receivers as :func:`_shade_kernel` reads them."""

    normals: np.ndarray  # (T, 3) unit face normals
    owner: np.ndarray  # (T,) int64 receiver of each triangle
    albedo: np.ndarray  # (R, 3)
    frames: np.ndarray  # (R, 4, 3) centre, U, W, (w, d, 0): map_position's frame per receiver
    size: np.ndarray  # (R, 2) float64 (Hc, Wc) of each receiver's box
    maps: np.ndarray  # (R, Hc, Wc, 3) caustic irradiance (one shape for all)


class _ShadeLights(NamedTuple):
    """The lights and their shadow maps as :func:`_shade_kernel` reads them."""

    L: np.ndarray  # (nl, ML, 3) direction of travel; ML = 1: the same at every point
    fall: np.ndarray  # (nl, ML)
    radiance: np.ndarray  # (nl, 3)
    shadowed: np.ndarray  # (nl,) bool: the light has a shadow map
    m: np.ndarray  # (nl, 3, 3) world_to_view's matrix of the light's camera
    t: np.ndarray  # (nl, 3) and its offset
    views: np.ndarray  # (nl, 6) sx, sy, ortho, width, height, bias (_LightView)
    zmin: np.ndarray  # (nl, N, N) nearest depth from the light (one shape for all)


def _fusable(rs, lights, maps_rgb, visibility):
    """Whether :func:`_shade_kernel` applies: a :class:`ShadowMaps` visibility, directional or point
    lights, one caustic map per receiver, maps and shadow maps of one shape each."""
    if not isinstance(visibility, ShadowMaps) or len(visibility.shadow) < len(lights) or not len(maps_rgb):
        return False
    if any(lt["type"] not in ("directional", "point") for lt in lights) or len(rs.boxes) != len(maps_rgb):
        return False
    zshapes = {np.shape(sh[1]) for sh in visibility.shadow[:len(lights)] if sh is not None}
    return len({np.shape(E) for E in maps_rgb}) == 1 and len(zshapes) <= 1


def _fused_args(rs, lights, maps_rgb, P, visibility):
    """:func:`_shade_kernel`'s inputs, or None where it does not apply (:func:`_fusable`)."""
    if not _fusable(rs, lights, maps_rgb, visibility):
        return None
    nl, nr, M = len(lights), len(rs.boxes), len(P)
    zshapes = {np.shape(sh[1]) for sh in visibility.shadow[:nl] if sh is not None}
    maps = (np.ascontiguousarray(maps_rgb[0], dtype=np.float64)[None] if nr == 1
            else np.ascontiguousarray(np.stack(maps_rgb), dtype=np.float64))
    frames = np.empty((nr, 4, 3))
    size = np.empty((nr, 2))
    for r, box in enumerate(rs.boxes):  # as map_position packs them
        frames[r] = np.array([box.center, box.U, box.W, [box.w, box.d, 0.0]], dtype=np.float64)
        size[r] = [float(box.size[0]), float(box.size[1])]
    rcv = _ShadeReceivers(np.ascontiguousarray(rs.normals, dtype=np.float64),
                          np.ascontiguousarray(rs.owner, dtype=np.int64),
                          np.ascontiguousarray(rs.albedo, dtype=np.float64), frames, size, maps)
    ML = M if any(lt["type"] == "point" for lt in lights) else 1
    L = np.empty((nl, ML, 3))
    fall = np.empty((nl, ML))
    radiance = np.empty((nl, 3))
    shadowed = np.zeros(nl, np.bool_)
    m = np.zeros((nl, 3, 3))
    t = np.zeros((nl, 3))
    view = np.zeros((nl, 6))
    zs = zshapes.pop() if zshapes else (1, 1)
    zmin = None
    for l, lt in enumerate(lights):
        Ll, fl = light_direction_at(lt, P[:ML])  # directional: the same row at every point
        L[l], fall[l] = Ll, fl
        radiance[l] = np.asarray(lt["radiance"], dtype=np.float64)
        sh = visibility.shadow[l]
        if sh is not None:
            lcam, z, bias = sh
            shadowed[l] = True
            m[l], t[l] = _world_to_view_args(lcam)
            view[l] = [float(lcam.sx), float(lcam.sy), 1.0 if lcam.ortho else 0.0, float(lcam.width),
                       float(lcam.height), float(bias)]
            if nl == 1:
                zmin = np.ascontiguousarray(z, dtype=np.float64)[None]
    if zmin is None:
        zmin = np.full((nl,) + tuple(zs), np.inf)
        for l in range(nl):
            if shadowed[l]:
                zmin[l] = visibility.shadow[l][1]
    return rcv, _ShadeLights(L, fall, radiance, shadowed, m, t, view, zmin)


@nb.njit(cache=True, inline="always")
def _shade_one(px, py, pz, f, dx, dy, dz, j, normals, owner, albedo, frames, size, maps, L, fall, radiance, shadowed,
               mat, off, views, zmin, code, margin, tie, dest):
    """One point's colour, shade_points' kernels' operations in their order: the facing normal, per light
    the cosine, the shadow test where the point faces the light (0 elsewhere) and the direct term added
    to a sum that starts at 0, then the caustic map's bilinear look-up added, times the albedo. ``j``:
    the point's row of the per-point light arrays (0 when they hold one row). With ``dest >= 0`` the
    point's shadow buffers too, from the same test (:func:`_shadow_test_kernel`'s verdict and margin,
    whether or not the point faces the light; 1 and -inf for a light without a shadow map), at
    ``code[l, dest]``, ``margin[l, dest]``."""
    nl = radiance.shape[0]
    Hc, Wc = maps.shape[1], maps.shape[2]
    nx, ny, nz = normals[f, 0], normals[f, 1], normals[f, 2]
    if _einsum_dot(nx, ny, nz, dx, dy, dz) > 0:
        nx, ny, nz = -nx, -ny, -nz
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for l in range(nl):
        c = -_einsum_dot(nx, ny, nz, L[l, j, 0], L[l, j, 1], L[l, j, 2])
        cos = c if (c > 0.0 or c != c) else 0.0
        v = 1.0 if cos > 0 else 0.0
        if shadowed[l] and (cos > 0 or dest >= 0):
            view = _LightView(views[l, 0], views[l, 1], views[l, 2] != 0.0, views[l, 3], views[l, 4], views[l, 5])
            m = mat[l]
            tt = off[l]
            zl = zmin[l]
            col, row, d = _screen_of(_to_view(px, py, pz, m, tt, 0), _to_view(px, py, pz, m, tt, 1),
                                     _to_view(px, py, pz, m, tt, 2), view)
            mg = _margin_at(col, row, d, zl, view.bias)
            if cos > 0:
                v = 0.0 if mg > 0 else 1.0
            if dest >= 0:
                code[l, dest] = 2 if mg > 0 else 1
                margin[l, dest] = np.float32(_tie_probes(col, row, d, zl, view.bias, tie, mg))
        elif dest >= 0:
            code[l, dest] = 1
            margin[l, dest] = np.float32(-np.inf)
        w = cos * fall[l, j] * v
        s0 += radiance[l, 0] * w
        s1 += radiance[l, 1] * w
        s2 += radiance[l, 2] * w
    r = owner[f]
    # map_position's col and row, then sample_bilinear's look-up
    qx = px - frames[r, 0, 0]
    qy = py - frames[r, 0, 1]
    qz = pz - frames[r, 0, 2]
    cc = ((qx * frames[r, 1, 0] + qy * frames[r, 1, 1] + qz * frames[r, 1, 2]) / frames[r, 3, 0] + 0.5) * size[r, 1]
    rr = ((qx * frames[r, 2, 0] + qy * frames[r, 2, 1] + qz * frames[r, 2, 2]) / frames[r, 3, 1] + 0.5) * size[r, 0]
    i0, j0, i1, j1, fx, fy = _bilinear_texels(cc, rr, Wc, Hc)
    E = maps[r]
    s0 += ((1 - fy) * ((1 - fx) * E[i0, j0, 0] + fx * E[i0, j1, 0])
           + fy * ((1 - fx) * E[i1, j0, 0] + fx * E[i1, j1, 0]))
    s1 += ((1 - fy) * ((1 - fx) * E[i0, j0, 1] + fx * E[i0, j1, 1])
           + fy * ((1 - fx) * E[i1, j0, 1] + fx * E[i1, j1, 1]))
    s2 += ((1 - fy) * ((1 - fx) * E[i0, j0, 2] + fx * E[i0, j1, 2])
           + fy * ((1 - fx) * E[i1, j0, 2] + fx * E[i1, j1, 2]))
    return albedo[r, 0] * s0, albedo[r, 1] * s1, albedo[r, 2] * s2


@nb.njit(cache=True, parallel=True)
def _shade_kernel(P, faces, dirs, rcv, lts, out):
    # shade_points per point (_shade_one)
    normals, owner, albedo, frames, size, maps = rcv.normals, rcv.owner, rcv.albedo, rcv.frames, rcv.size, rcv.maps
    L, fall, radiance, shadowed = lts.L, lts.fall, lts.radiance, lts.shadowed
    mat, off, views, zmin = lts.m, lts.t, lts.views, lts.zmin
    ML = L.shape[1]
    code = np.zeros((0, 0), np.uint8)
    margin = np.zeros((0, 0), np.float32)
    for k0 in nb.prange(P.shape[0]):
        k = np.int64(k0)
        j = k if ML > 1 else np.int64(0)
        c0, c1, c2 = _shade_one(P[k, 0], P[k, 1], P[k, 2], faces[k], dirs[k, 0], dirs[k, 1], dirs[k, 2], j, normals,
                                owner, albedo, frames, size, maps, L, fall, radiance, shadowed, mat, off, views, zmin,
                                code, margin, 0.0, np.int64(-1))
        out[k, 0] = c0
        out[k, 1] = c1
        out[k, 2] = c2


class _ShadeRows(NamedTuple):
    """Where :func:`_shade_rows_kernel` reads its points and writes their colours."""

    P: np.ndarray  # (N, 3) the rays' hit points
    face: np.ndarray  # (N,) their receiver triangles
    d: np.ndarray  # (N, 3) the rays' directions
    hi: np.ndarray  # (nh,) the rows of the rays that hit a receiver
    Pd: np.ndarray  # (nd, 3) points seen directly
    fd: np.ndarray  # (nd,)
    dd: np.ndarray  # (nd, 3)
    out: np.ndarray  # (N, 3) the rays' colours, written at rows hi
    out_d: np.ndarray  # (nd, 3) the direct points' colours
    dest: np.ndarray  # (nd,) int64 the direct points' columns of code and margin (empty: none written)
    code: np.ndarray  # (nl, K) uint8 out: shadow verdict (1 lit, 2 in shadow) per light
    margin: np.ndarray  # (nl, K) float32 out: shadow_map_margin per light
    tie: float  # texels (shadow_map_margin)


@nb.njit(cache=True, parallel=True)
def _shade_rows_kernel(rows, rcv, lts):
    # shade_points of the rows P[hi], then of the direct points, each colour written to its own row
    # (out[hi], out_d): what gathering the rows into one array, shading it and scattering the colours
    # back gave, without the gathered copies; directional lights only (their arrays hold one row)
    P, face, d, hi, Pd, fd, dd, out, out_d = rows.P, rows.face, rows.d, rows.hi, rows.Pd, rows.fd, rows.dd, \
        rows.out, rows.out_d
    dest, code, margin, tie = rows.dest, rows.code, rows.margin, rows.tie
    bufs = dest.shape[0] > 0
    normals, owner, albedo, frames, size, maps = rcv.normals, rcv.owner, rcv.albedo, rcv.frames, rcv.size, rcv.maps
    L, fall, radiance, shadowed = lts.L, lts.fall, lts.radiance, lts.shadowed
    mat, off, views, zmin = lts.m, lts.t, lts.views, lts.zmin
    nh = hi.shape[0]
    j = np.int64(0)
    for k0 in nb.prange(nh + Pd.shape[0]):
        k = np.int64(k0)
        if k < nh:
            q = hi[k]
            c0, c1, c2 = _shade_one(P[q, 0], P[q, 1], P[q, 2], face[q], d[q, 0], d[q, 1], d[q, 2], j, normals, owner,
                                    albedo, frames, size, maps, L, fall, radiance, shadowed, mat, off, views, zmin,
                                    code, margin, tie, np.int64(-1))
            out[q, 0] = c0
            out[q, 1] = c1
            out[q, 2] = c2
        else:
            q = k - nh
            c0, c1, c2 = _shade_one(Pd[q, 0], Pd[q, 1], Pd[q, 2], fd[q], dd[q, 0], dd[q, 1], dd[q, 2], j, normals,
                                    owner, albedo, frames, size, maps, L, fall, radiance, shadowed, mat, off, views,
                                    zmin, code, margin, tie, dest[q] if bufs else np.int64(-1))
            out_d[q, 0] = c0
            out_d[q, 1] = c1
            out_d[q, 2] = c2


def shade_rows_applies(rs, lights, maps_rgb, visibility):
    """Whether :func:`shade_rows` shades in place (a :class:`ShadowMaps` visibility, directional lights
    only, caustic maps and shadow maps of one shape each).

    Parameters
    ----------
    rs : ReceiverSet
    lights : list of dict
    maps_rgb : list of (Hc, Wc, 3) arrays
    visibility : callable

    Returns
    -------
    bool

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    return (bool(lights) and all(lt["type"] == "directional" for lt in lights)
            and _fusable(rs, lights, maps_rgb, visibility))


def shade_rows(rs, lights, maps_rgb, P, face, d, hi, direct, visibility, out, shadow_buffers=None):
    """``out[hi] = c[:nh]`` and ``c[nh:]`` of ``c = shade_points`` over the rows ``hi`` of ``(P, face, d)``
    followed by the ``direct`` points, without gathering the rows: one kernel on every thread.

    For a :class:`ShadowMaps` visibility and directional lights only (else None: gather and call
    :func:`shade_points`).

    Parameters
    ----------
    rs : ReceiverSet
    lights : list of dict
    maps_rgb : list of (Hc, Wc, 3) arrays
    P, d : (N, 3) float64
        Points and ray directions.
    face : (N,) int64
    hi : (nh,) int64
        Distinct rows to shade.
    direct : (points, faces, ray directions)
        ``nd`` more points, shaded after the rows.
    visibility : ShadowMaps
    out : (N, 3) float64
        Written at rows ``hi``.
    shadow_buffers : (dest, code, margin, tie), optional
        Also the direct points' shadow buffers from the same shadow test: per light ``l``,
        ``code[l, dest]`` (uint8: 1 lit, 2 in shadow, as :func:`shadow_map_test`) and
        ``margin[l, dest]`` (float32: :func:`shadow_map_margin` with ``tie``), whether or not a point
        faces the light; 1 and -inf for a light without a shadow map.

    Returns
    -------
    (nd, 3) float64 or None
        The direct points' colours; None where the kernel does not apply (``out`` and the buffers
        untouched; :func:`shade_rows_applies`).

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    if not shade_rows_applies(rs, lights, maps_rgb, visibility):
        return None
    fused = _fused_args(rs, lights, maps_rgb, np.zeros((1, 3)), visibility)
    Pd = np.ascontiguousarray(direct[0], dtype=np.float64).reshape(-1, 3)
    out_d = np.empty((len(Pd), 3))
    if shadow_buffers is None or not len(Pd):
        dest, code, margin, tie = np.zeros(0, np.int64), np.zeros((0, 0), np.uint8), np.zeros((0, 0), np.float32), 0.0
    else:
        dest, code, margin, tie = shadow_buffers
        dest = np.ascontiguousarray(dest, dtype=np.int64)
        if len(dest) != len(Pd) or code.shape[0] != len(lights) or margin.shape[0] != len(lights):
            raise ValueError("shade_rows: shadow_buffers need one column per direct point and one row per light")
    _shade_rows_kernel(_ShadeRows(np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3),
                                  np.ascontiguousarray(face, dtype=np.int64).reshape(-1),
                                  np.ascontiguousarray(d, dtype=np.float64).reshape(-1, 3),
                                  np.ascontiguousarray(hi, dtype=np.int64),
                                  Pd, np.ascontiguousarray(direct[1], dtype=np.int64).reshape(-1),
                                  np.ascontiguousarray(direct[2], dtype=np.float64).reshape(-1, 3), out, out_d,
                                  dest, code, margin, float(tie)),
                       fused[0], fused[1])
    return out_d


def shade_points(rs, lights, maps_rgb, points, faces, ray_dirs, visibility):
    """Colour of receiver points (see the module docstring).

    Parameters
    ----------
    rs : ReceiverSet
    lights : list of dict
    maps_rgb : list of (Hc, Wc, 3) arrays
        Caustic irradiance per receiver, radiance included.
    points : (M, 3) float64
        World points on the receivers.
    faces : (M,) int64
        Receiver triangle of each point.
    ray_dirs : (M, 3) float64
        Direction of the ray that sees each point (the normal is turned to face it).
    visibility : callable
        ``visibility(l, points, normals) -> (M,)`` in [0, 1] for light ``l``.

    Returns
    -------
    (M, 3) float64

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    M = len(P)
    if M == 0:
        return np.zeros((M, 3))
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1)
    fused = _fused_args(rs, lights, maps_rgb, P, visibility)
    if fused is not None:  # shadow maps: every point's colour in one kernel, no per-point temporaries
        out = np.empty((M, 3))
        _shade_kernel(np.ascontiguousarray(P), faces, np.ascontiguousarray(ray_dirs, dtype=np.float64).reshape(-1, 3),
                      fused[0], fused[1], out)
        return out
    out = np.zeros((M, 3))
    n = np.empty((M, 3))
    _facing_normals_kernel(rs.normals, faces, np.ascontiguousarray(ray_dirs, dtype=np.float64).reshape(-1, 3), n)
    owner = np.empty(M, np.int64)
    _take_kernel(np.ascontiguousarray(rs.owner, dtype=np.int64), faces, owner)  # rs.owner[faces]
    light_sum = np.zeros((M, 3))
    cos = np.empty(M)
    for l, lt in enumerate(lights):
        L, fall = light_direction_at(lt, P)
        _cosine_kernel(n, L, cos)
        lit = None if _count_positive(cos) == M else np.flatnonzero(cos > 0)
        if lit is None:  # every point faces the light: v = visibility(l, P, n), no scatter
            v = np.ascontiguousarray(visibility(l, P, n), dtype=np.float64).reshape(M)
        else:
            v = np.zeros(M)
            if len(lit):  # v[lit] = visibility(l, P[lit], n[lit]), the rows gathered on every thread
                v[lit] = visibility(l, take_rows(P, lit), take_rows(n, lit))
        _add_direct_kernel(np.asarray(lt["radiance"], dtype=np.float64), cos, fall, v, light_sum)
    for r in range(len(rs.boxes)):
        sel = np.flatnonzero(owner == r)
        if len(sel):
            col, row = map_position(rs, r, P if len(sel) == M else take_rows(P, sel))
            # light_sum[sel] += sample_bilinear(maps_rgb[r], col, row), on every thread
            _add_bilinear_kernel(np.ascontiguousarray(maps_rgb[r], dtype=np.float64),
                                 np.ascontiguousarray(col, dtype=np.float64),
                                 np.ascontiguousarray(row, dtype=np.float64), sel, light_sum)
    _albedo_kernel(rs.albedo, owner, light_sum, out)
    return out
