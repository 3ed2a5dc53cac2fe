"""The shadow test of the final pass: a light's visibility at receiver points (Chaudhari 2008, §4.1).

The image-space method reads the light's min-depth image: the first pass of
§3.3 in the light's view doubles as a shadow map (Williams 1978). A point
is in shadow where its depth along the light's view exceeds the map's
nearest depth plus a bias (:func:`shadowshadow_margin_at`); outside the light's
window (which covers the objects) or over a texel no object covers it is
lit (:func:`shadow_map_visibility`, :func:`shadow_map_margin`,
:func:`shadow_map_test`, :class:`ShadowMaps`). The exact reference casts a
ray to the light through the real triangles (:func:`exact_visibility`).

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.3, §4.1.
.. [2] L. Williams, "Casting Curved Shadows on Curved Surfaces", SIGGRAPH
   1978 (shadow maps).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..embree import HIT_CHUNK, chunk_length, commit, run_chunks, soup_scene
from ..kernels import dot3
from ..lights import light_direction_at
from .exact_hits import occluded

__all__ = ["LightView", "light_view", "view_affine", "screen_of", "to_view", "shadow_margin_at", "tie_probes",
           "shadow_map_visibility", "shadow_map_margin", "shadow_map_test", "ShadowMaps", "exact_visibility"]


class LightView(NamedTuple):
    """The light camera's projection (``Camera.to_screen``) and the depth bias of the shadow-map test."""

    sx: float
    sy: float
    ortho: bool
    width: float
    height: float
    bias: float


@nb.njit(cache=True, inline="always")
def screen_of(x, y, z, view):
    """``Camera.to_screen`` of a view-space point, in its operations' order (a kernel helper).

    Parameters
    ----------
    x, y, z : float
        The point in the camera's view space.
    view : LightView

    Returns
    -------
    col, row, d : float
        Continuous screen position and depth along the view (``-z``).

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §3.6 (texture coordinates of a point).
    """
    d = -z
    s = 1.0 if view.ortho else d
    col = (x / (s * view.sx) * 0.5 + 0.5) * view.width
    row = (0.5 - y / (s * view.sy) * 0.5) * view.height
    return col, row, d


@nb.njit(cache=True, inline="always")
def _light_screen(pv, k, view):
    """Camera.to_screen of view-space point k in its operations' order: (col, row, depth along the view)."""
    return screen_of(pv[k, 0], pv[k, 1], pv[k, 2], view)


@nb.njit(cache=True, inline="always")
def to_view(x, y, z, m, t, c):
    """Column ``c`` of :func:`~refraction_ref.vec3.affine`'s ``p @ m + t`` (``Camera.world_to_view``), in its order.

    Parameters
    ----------
    x, y, z : float
        A world point.
    m : (3, 3) float64
    t : (3,) float64
        :func:`view_affine`.
    c : int
        The view-space coordinate.

    Returns
    -------
    float

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §3.6 (texture coordinates of a point).
    """
    return x * m[0, c] + y * m[1, c] + z * m[2, c] + t[c]


def view_affine(lcam):
    """``(m, t)`` of ``Camera.world_to_view``'s affine map ``p @ m + t``, computed as it computes them.

    Parameters
    ----------
    lcam : Camera

    Returns
    -------
    m : (3, 3) float64
        ``basis.T``.
    t : (3,) float64
        ``-eye @ basis.T``.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §3.6 (texture coordinates of a point).
    """
    b = lcam.basis
    return (np.ascontiguousarray(b.T, dtype=np.float64),
            np.ascontiguousarray(-np.asarray(lcam.eye, dtype=np.float64) @ b.T, dtype=np.float64))


def light_view(lcam, bias):
    """A light camera's :class:`LightView` with the shadow test's depth bias.

    Parameters
    ----------
    lcam : Camera
    bias : float

    Returns
    -------
    LightView

    References
    ----------
    Williams 1978 (the light's depth image and the shadow test's bias).
    """
    return LightView(float(lcam.sx), float(lcam.sy), bool(lcam.ortho), float(lcam.width), float(lcam.height),
                     float(bias))


@nb.njit(cache=True, inline="always")
def shadow_margin_at(col, row, d, zmin, bias):
    """``dl - (zmin + bias)`` at screen position (col, row), ``-inf`` where no depth is compared.

    Outside the light's window (which covers the objects) or over a texel no object covers nothing is
    compared: lit. For finite values ``d - (z + bias) > 0`` exactly when ``d > z + bias`` (IEEE
    subtraction is 0 only for equal operands), so the shadow test is this margin's sign.

    Parameters
    ----------
    col, row : float
        The point's position in the light's image.
    d : float
        Its depth along the light's view.
    zmin : (N, N) float64
        The objects' nearest depth from the light.
    bias : float

    Returns
    -------
    float

    References
    ----------
    .. [1] L. Williams, "Casting Curved Shadows on Curved Surfaces", SIGGRAPH 1978.
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
        out[k] = 0.0 if shadow_margin_at(col, row, d, zmin, view.bias) > 0 else 1.0


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
    _shadow_map_kernel(pv, np.ascontiguousarray(zmin, dtype=np.float64), light_view(lcam, bias), out)
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
    _shadow_margin_kernel(pv, np.ascontiguousarray(zmin, dtype=np.float64), light_view(lcam, bias), float(tie),
                          out)
    return out


@nb.njit(cache=True, inline="always")
def tie_probes(col, row, d, zmin, bias, tie, m):
    """``m`` set to 0 where the verdict of the shadow test changes when the point moves ``tie`` texel
    along either axis: four probes in their order, each compared with the margin as the probes
    before left it (:func:`shadow_map_margin`); ``m`` unchanged when ``tie <= 0``.

    Parameters
    ----------
    col, row, d, zmin, bias
        As for :func:`shadow_margin_at`.
    tie : float
        Texels.
    m : float
        The point's margin.

    Returns
    -------
    float

    References
    ----------
    Williams 1978 (the shadow test, probed around the point).
    """
    if tie > 0:
        for q in range(4):
            dc = tie if q == 0 else (-tie if q == 1 else 0.0)
            dr = tie if q == 2 else (-tie if q == 3 else 0.0)
            if (shadow_margin_at(col + dc, row + dr, d, zmin, bias) > 0) != (m > 0):
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
        out[k] = tie_probes(col, row, d, zmin, bias, tie, shadow_margin_at(col, row, d, zmin, bias))


@nb.njit(cache=True, parallel=True)
def _shadow_test_kernel(p, m, t, zmin, view, tie, idx, code, margin):
    # per point: Camera.world_to_view (affine's order), then _shadow_map_kernel's verdict and
    # _shadow_margin_kernel's margin and tie probes, written to the point's own row idx[k]
    bias = view.bias
    for k0 in nb.prange(p.shape[0]):
        k = np.int64(k0)
        x, y, z = p[k, 0], p[k, 1], p[k, 2]
        col, row, d = screen_of(to_view(x, y, z, m, t, 0), to_view(x, y, z, m, t, 1),
                                 to_view(x, y, z, m, t, 2), view)
        mg = shadow_margin_at(col, row, d, zmin, bias)
        q = idx[k]
        code[q] = 2 if mg > 0 else 1
        margin[q] = np.float32(tie_probes(col, row, d, zmin, bias, tie, mg))


def shadow_map_test(lcam, zmin, points, bias, tie, idx, code, margin):
    """The shadow test's verdict and margin at world points, written to rows ``idx`` of two buffers.

    ``code[idx] = np.where(shadow_map_visibility(...) > 0, 1, 2)`` and
    ``margin[idx] = shadow_map_margin(..., tie)`` (cast to the buffer's float32), in one pass over
    the points on every thread: each point's light-view position is computed once for both.

    Parameters
    ----------
    lcam, zmin, points, bias, tie
        As for :func:`shadow_map_margin`.
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
    m, t = view_affine(lcam)
    _shadow_test_kernel(p, m, t, np.ascontiguousarray(zmin, dtype=np.float64), light_view(lcam, bias),
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
        side = 1.0 if dot3(n[k, 0], n[k, 1], n[k, 2], tx, ty, tz) >= 0 else -1.0
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

