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

Shadow tests (:mod:`~refraction_ref.caustics.shadow`): the image-space
method reads the light's min-depth image (the first pass of §3.3 in the
light's view doubles as a shadow map); the exact reference casts a ray to
the light through the real triangles. :func:`shade_rays` colours world
rays: the receiver each meets (:func:`~refraction_ref.caustics.receivers.receiver_hits`),
shaded, else the environment.

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

from ..environment import environment_lookup
from ..kernels import copy_rows, dot3, put_rows, take_rows, take_values
from ..lights import light_direction_at
from .receivers import map_position, receiver_hits
from .shadow import LightView, ShadowMaps, screen_of, shadow_margin_at, tie_probes, to_view, view_affine

__all__ = ["sample_bilinear", "add_bilinear", "shade_points", "shade_points_fuses", "ReceiverLighting", "shade_rows",
           "shade_rows_applies", "shade_rays"]


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
def add_bilinear(E, col, row, sel, out):
    """``out[sel[k]] +=`` the bilinear look-up of map ``E`` at ``(col[k], row[k])``, on every thread.

    :func:`sample_bilinear`'s operations in its order, one point per iteration (a kernel).

    Parameters
    ----------
    E : (Hc, Wc, C) float64
        A caustic map.
    col, row : (M,) float64
        Continuous positions (texel centres at ``+0.5``).
    sel : (M,) int64
        Distinct rows of ``out``.
    out : (N, C) float64
        Added to in place.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    Hc, Wc, C = E.shape
    for k0 in nb.prange(col.shape[0]):
        k = np.int64(k0)
        i0, j0, i1, j1, fx, fy = _bilinear_texels(col[k], row[k], Wc, Hc)
        q = sel[k]
        for c in range(C):
            out[q, c] += ((1 - fy) * ((1 - fx) * E[i0, j0, c] + fx * E[i0, j1, c])
                          + fy * ((1 - fx) * E[i1, j0, c] + fx * E[i1, j1, c]))


@nb.njit(cache=True, parallel=True)
def _facing_normals_kernel(normals, faces, ray_dirs, n):
    # n = normals[faces], negated where it faces along the ray (NumPy's einsum > 0)
    for k0 in nb.prange(faces.shape[0]):
        k = np.int64(k0)
        f = faces[k]
        x, y, z = normals[f, 0], normals[f, 1], normals[f, 2]
        if dot3(x, y, z, ray_dirs[k, 0], ray_dirs[k, 1], ray_dirs[k, 2]) > 0:
            x, y, z = -x, -y, -z
        n[k, 0] = x
        n[k, 1] = y
        n[k, 2] = z


@nb.njit(cache=True, parallel=True)
def _cosine_kernel(n, L, cos):
    # cos = np.maximum(0, -einsum(n, L)) (NaN stays NaN, as np.maximum keeps it)
    for k0 in nb.prange(n.shape[0]):
        k = np.int64(k0)
        c = -dot3(n[k, 0], n[k, 1], n[k, 2], L[k, 0], L[k, 1], L[k, 2])
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
    views: np.ndarray  # (nl, 6) sx, sy, ortho, width, height, bias (LightView)
    zmin: np.ndarray  # (nl, N, N) nearest depth from the light (one shape for all)


def shade_points_fuses(rs, lights, maps_rgb, visibility):
    """Whether :func:`shade_points` colours every point in one kernel, the shadow test inside it.

    It does for a :class:`~refraction_ref.caustics.shadow.ShadowMaps` visibility, directional or
    point lights, one caustic map per receiver, maps and shadow maps of one shape each.

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
    if not isinstance(visibility, ShadowMaps) or len(visibility.shadow) < len(lights) or not len(maps_rgb):
        return False
    if any(lt["type"] not in ("directional", "point") for lt in lights) or len(rs.boxes) != len(maps_rgb):
        return False
    zshapes = {np.shape(sh[1]) for sh in visibility.shadow[:len(lights)] if sh is not None}
    return len({np.shape(E) for E in maps_rgb}) == 1 and len(zshapes) <= 1


def _fused_args(rs, lights, maps_rgb, P, visibility):
    """:func:`_shade_kernel`'s inputs, or None where it does not apply (:func:`shade_points_fuses`)."""
    if not shade_points_fuses(rs, lights, maps_rgb, visibility):
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
            m[l], t[l] = view_affine(lcam)
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
def _shade_one(P, face, D, q, rcv, lts, code, margin, tie, dest):
    """The colour of point ``q`` (``P[q]`` on triangle ``face[q]``, seen along ``D[q]``): the module
    docstring's equation, with :func:`shade_points`' kernels' operations in their order.

    The facing normal; per light the cosine, the shadow test where the point faces the light (0
    elsewhere) and the direct term added to a sum that starts at 0; then the caustic map's bilinear
    look-up added; times the albedo. The per-point light arrays are read at row ``q`` when they hold
    one row per point, else at row 0. With ``dest >= 0`` the point's shadow buffers too, from the same
    test (:func:`~refraction_ref.caustics.shadow.shadow_map_test`'s verdict and margin, whether or not
    the point faces the light; 1 and -inf for a light without a shadow map), at ``code[l, dest]``,
    ``margin[l, dest]`` (arrays of their own: Numba drops stores into a tuple's arrays inside
    ``prange``, numba#7135).

    Parameters
    ----------
    P, D : (N, 3) float64
        Points and the directions of the rays that see them.
    face : (N,) int64
        Receiver triangle of each point.
    q : int
        The point.
    rcv : _ShadeReceivers
    lts : _ShadeLights
    code : (nl, K) uint8
    margin : (nl, K) float32
    tie : float
        Texels (:func:`~refraction_ref.caustics.shadow.shadow_map_margin`).
    dest : int
        Column of ``code`` and ``margin``, -1 for none.

    Returns
    -------
    tuple of float
        The colour (r, g, b).

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    normals, owner, albedo, frames, size, maps = rcv.normals, rcv.owner, rcv.albedo, rcv.frames, rcv.size, rcv.maps
    L, fall, radiance, shadowed = lts.L, lts.fall, lts.radiance, lts.shadowed
    mat, off, views, zmin = lts.m, lts.t, lts.views, lts.zmin
    j = q if L.shape[1] > 1 else np.int64(0)
    px, py, pz = P[q, 0], P[q, 1], P[q, 2]
    f = face[q]
    nl = radiance.shape[0]
    Hc, Wc = maps.shape[1], maps.shape[2]
    nx, ny, nz = normals[f, 0], normals[f, 1], normals[f, 2]
    if dot3(nx, ny, nz, D[q, 0], D[q, 1], D[q, 2]) > 0:
        nx, ny, nz = -nx, -ny, -nz
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for l in range(nl):
        c = -dot3(nx, ny, nz, L[l, j, 0], L[l, j, 1], L[l, j, 2])
        cos = c if (c > 0.0 or c != c) else 0.0
        v = 1.0 if cos > 0 else 0.0
        if shadowed[l] and (cos > 0 or dest >= 0):
            view = LightView(views[l, 0], views[l, 1], views[l, 2] != 0.0, views[l, 3], views[l, 4], views[l, 5])
            m = mat[l]
            tt = off[l]
            zl = zmin[l]
            col, row, d = screen_of(to_view(px, py, pz, m, tt, 0), to_view(px, py, pz, m, tt, 1),
                                     to_view(px, py, pz, m, tt, 2), view)
            mg = shadow_margin_at(col, row, d, zl, view.bias)
            if cos > 0:
                v = 0.0 if mg > 0 else 1.0
            if dest >= 0:
                code[l, dest] = 2 if mg > 0 else 1
                margin[l, dest] = np.float32(tie_probes(col, row, d, zl, view.bias, tie, mg))
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
    code = np.zeros((0, 0), np.uint8)
    margin = np.zeros((0, 0), np.float32)
    for k0 in nb.prange(P.shape[0]):
        k = np.int64(k0)
        c0, c1, c2 = _shade_one(P, faces, dirs, k, rcv, lts, code, margin, 0.0, np.int64(-1))
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
    nh = hi.shape[0]
    for k0 in nb.prange(nh + Pd.shape[0]):
        k = np.int64(k0)
        if k < nh:
            q = hi[k]
            c0, c1, c2 = _shade_one(P, face, d, q, rcv, lts, code, margin, tie, np.int64(-1))
            out[q, 0] = c0
            out[q, 1] = c1
            out[q, 2] = c2
        else:
            q = k - nh
            c0, c1, c2 = _shade_one(Pd, fd, dd, q, rcv, lts, code, margin, tie, dest[q] if bufs else np.int64(-1))
            out_d[q, 0] = c0
            out_d[q, 1] = c1
            out_d[q, 2] = c2


def shade_rows_applies(rs, lights, maps_rgb, visibility):
    """Whether :func:`shade_rows` shades in place (a :class:`ShadowMaps` visibility, directional lights
    only, caustic maps and shadow maps of one shape each).

    Parameters
    ----------
    rs, lights, maps_rgb, visibility
        As for :func:`shade_points_fuses`.

    Returns
    -------
    bool

    References
    ----------
    Chaudhari 2008, §4.1.
    """
    return (bool(lights) and all(lt["type"] == "directional" for lt in lights)
            and shade_points_fuses(rs, lights, maps_rgb, visibility))


class ReceiverLighting(NamedTuple):
    """What the final pass (§4.1) lights receiver points with.

    Attributes
    ----------
    rs : ReceiverSet
        The receivers.
    lights : list of dict
        The scene's lights.
    maps_rgb : list of (Hc, Wc, 3) arrays
        Caustic irradiance per receiver, radiance included (:func:`~refraction_ref.caustics.pipeline.collect_maps`).
    visibility : callable
        ``visibility(l, points, normals) -> (M,)`` in [0, 1] for light ``l`` (a
        :class:`~refraction_ref.caustics.shadow.ShadowMaps` is tested inside the shading kernels).
    """

    rs: object
    lights: list
    maps_rgb: list
    visibility: object


def shade_rows(lighting, P, face, d, hi, direct, out, shadow_buffers=None):
    """``out[hi] = c[:nh]`` and ``c[nh:]`` of ``c = shade_points`` over the rows ``hi`` of ``(P, face, d)``
    followed by the ``direct`` points, without gathering the rows: one kernel on every thread.

    For a :class:`ShadowMaps` visibility and directional lights only (else None: gather and call
    :func:`shade_points`).

    Parameters
    ----------
    lighting : ReceiverLighting
        Its ``visibility`` a :class:`~refraction_ref.caustics.shadow.ShadowMaps`.
    P, d : (N, 3) float64
        Points and ray directions.
    face : (N,) int64
    hi : (nh,) int64
        Distinct rows to shade.
    direct : (points, faces, ray directions)
        ``nd`` more points, shaded after the rows.
    out : (N, 3) float64
        Written at rows ``hi``.
    shadow_buffers : (dest, code, margin, tie), optional
        Also the direct points' shadow buffers from the same shadow test: per light ``l``,
        ``code[l, dest]`` (uint8: 1 lit, 2 in shadow, as :func:`~.shadow.shadow_map_test`) and
        ``margin[l, dest]`` (float32: :func:`~.shadow.shadow_map_margin` with ``tie``), whether or not a point
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
    rs, lights, maps_rgb, visibility = lighting
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
    take_values(np.ascontiguousarray(rs.owner, dtype=np.int64), faces, owner)  # rs.owner[faces]
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
            add_bilinear(np.ascontiguousarray(maps_rgb[r], dtype=np.float64),
                                 np.ascontiguousarray(col, dtype=np.float64),
                                 np.ascontiguousarray(row, dtype=np.float64), sel, light_sum)
    _albedo_kernel(rs.albedo, owner, light_sum, out)
    return out


def shade_rays(scene, lighting, hits, o, d, direct=None, shadow_buffers=None, view=None):
    """Colour seen along world rays: the receiver they meet (shaded), else the environment.

    Parameters
    ----------
    scene : Scene
        Its environment colours the rays that meet no receiver.
    lighting : ReceiverLighting
        The receivers, lights, caustic maps and visibility.
    hits : ReceiverHitMode
        How the rays meet the receivers (:func:`~refraction_ref.caustics.receivers.receiver_hits`).
    o, d : (N, 3) float64
        World rays.
    direct : (points, faces, ray directions), optional
        Receiver points seen directly, shaded in the same call (every point's
        colour is its own).
    shadow_buffers : (dest, code, margin, tie), optional
        Filled for the direct points where :func:`shade_rows` shades them
        (:func:`shade_rows_applies`), else untouched.
    view : (origins, dirs), optional
        The rays in the camera's view space (:func:`~refraction_ref.caustics.receivers.receiver_hits`).

    Returns
    -------
    (N, 3) float64
        The rays' colours; with ``direct``, ``(rays' colours, theirs)``.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    rs = lighting.rs
    env = scene.data["environment"]
    out = np.zeros((len(o), 3))
    d = np.ascontiguousarray(d, dtype=np.float64).reshape(-1, 3)
    if len(o):
        P, face = receiver_hits(rs, o, d, hits.mode, hits.cam, hits.eyebuf, view)
    else:
        P, face = np.zeros((0, 3)), np.zeros(0, np.int64)
    hi = np.flatnonzero(face >= 0)
    mi = np.flatnonzero(face < 0)
    nh = len(hi)
    if direct is not None:  # shadow maps, directional lights: shaded in place, no gathered rows
        cd = shade_rows(lighting, P, face, d, hi, direct, out, shadow_buffers)
        if cd is not None:
            if len(mi):
                put_rows(out, mi, environment_lookup(env, take_rows(d, mi), scene.base_dir))
            return out, cd
    # the hit rays' points, faces and directions, then the direct points: gathered and copied
    # into one set of rows on every thread (np.concatenate of the boolean selections, row for row)
    nd = 0 if direct is None else len(direct[0])
    pts, fcs, drs = np.empty((nh + nd, 3)), np.empty(nh + nd, np.int64), np.empty((nh + nd, 3))
    _gather_rows_kernel(P, face, d, hi, pts, fcs, drs)
    if nd:
        copy_rows(np.ascontiguousarray(direct[0], dtype=np.float64).reshape(-1, 3), pts, nh)
        copy_rows(np.ascontiguousarray(direct[1], dtype=np.int64).reshape(-1, 1), fcs.reshape(-1, 1), nh)
        copy_rows(np.ascontiguousarray(direct[2], dtype=np.float64).reshape(-1, 3), drs, nh)
    c = shade_points(rs, lighting.lights, lighting.maps_rgb, pts, fcs, drs, lighting.visibility)
    if nh:
        put_rows(out, hi, c[:nh])
    if len(mi):
        put_rows(out, mi, environment_lookup(env, take_rows(d, mi), scene.base_dir))
    return out if direct is None else (out, c[nh:])


@nb.njit(cache=True, parallel=True)
def _gather_rows_kernel(P, face, d, idx, pts, fcs, drs):
    # rows idx of P, face, d into the first rows of pts, fcs, drs
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        i = idx[k]
        fcs[k] = face[i]
        for c in range(3):
            pts[k, c] = P[i, c]
            drs[k, c] = d[i, c]
