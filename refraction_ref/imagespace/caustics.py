"""The image-space method's caustic stages (Chaudhari 2008, §4.1): its photon trace and final pass.

==========================  =====================================================  ===========
stage (``timings_ms``)      pass                                                   section
==========================  =====================================================  ===========
``receivers``               receiver triangles and their caustic-map frames         §4.1
``receiver_depth``          the receivers' depth image from the camera              §4.1
``photon_trace``            per light: its camera, then min/max, voxelization,      §3.3-3.8
                            peeling, reduction (``photon_trace.minmax`` ...) and
                            one photon per texel through every layer
``receiver_hit``            eye-space march (Krüger 2006) or Embree                 §4.1
``splat``                   bilinear splat of irradiance into each receiver's map   §2.3.2
``gather``                  Gaussian gathering in a window (Wyman & Davis 2006)     §2.3.2
``caustic_final``           receivers lit directly (shadow test) and by caustics;   §4.1
                            the object with single-surface and multi-layer passes
==========================  =====================================================  ===========

``photon_trace`` and ``caustic_final`` are this method's own; the other
stages are the caustics service's (:mod:`refraction_ref.caustics.pipeline`),
shared with the volumetric method and the exact reference. The knobs:
``imagespace.photons`` and ``imagespace.receiver_hit`` here, the maps' size
and gathering window in the ``caustics`` block (``caustics.map_size``,
``caustics.gather``). Outputs: see :mod:`refraction_ref.caustics.pipeline`.

Threads: the final pass's kernels write only their own rows (each pixel
class's flat indices from per-image-row counts and offsets; the rays, the
shading and the two images row by row), so the bits do not depend on the
number of threads. With the OpenMP layer each thread gets one contiguous
block of a kernel's iterations, so a kernel whose rows differ in cost
interleaves them (:func:`final_rays_kernel`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..camera import _pixel_xy, primary_dir
from ..caustics.light import texel_flux
from ..caustics.pipeline import (camera_array, gather_names, gather_stage, per_light_names, photon_buffer_names,
                                 receiver_hit_stage, receiver_stages, splat_stage)
from ..caustics.receivers import ReceiverHitMode
from ..caustics.shade import ReceiverLighting, shade_rays, shade_rows_applies
from ..caustics.shadow import ShadowMaps, shadow_map_test, view_affine
from ..kernels import put_rows, take_rows, take_values
from ..environment import environment_lookup
from ..graph import Stage
from ..lights import light_camera
from ..optics import beer_lambert, refract3
from ..status import EXITED
from .grid import at_pixels
from .normals import NORMAL_METHODS, ViewGrid, no_lut, normal_at

__all__ = ["imagespace_caustic_stages"]


@nb.njit(cache=True, parallel=True)
def put32_kernel(idx, vals, a32, b32):
    """``a32[idx] = b32[idx] = vals.astype(np.float32)``, row by row on every thread.

    Parameters
    ----------
    idx : (M,) int64
    vals : (M, 3) float64
    a32, b32 : (N, 3) float32
        Written in place.

    References
    ----------
    .. [1] Chaudhari 2008, §4.1 (the caustic pass's final image: the receivers seen through the object)
    """
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        q = idx[k]
        for c in range(3):
            a32[q, c] = np.float32(vals[k, c])
            b32[q, c] = np.float32(vals[k, c])


class ObjectRows(NamedTuple):
    """The object's pixels and the rows :func:`object_pixels_kernel` reads their colours from."""

    oi: np.ndarray  # (no,) the object's pixels (flat, ascending)
    orow: np.ndarray  # (no,) each one's row in c (exited) or env_stuck (stuck): _Pixels.orow
    st: np.ndarray  # (H W,) trace status: 1 exited (its exit ray's colour), else stuck
    c: np.ndarray  # (n_full + no, 3) the exit rays' colours (exit pixels ascending), then the single-surface rays'
    n_full: int
    env_stuck: np.ndarray  # (nstuck, 3) the environment along the stuck pixels' last directions (ascending)
    trans: np.ndarray  # (no, 3) transmittance per object pixel
    f32: np.ndarray  # (H W, 3) out: image_caustics
    s32: np.ndarray  # (H W, 3) out: image_caustics_single


@nb.njit(cache=True, parallel=True)
def object_pixels_kernel(rows):
    """The object pixels' colours: ``full[p]`` = (exit: ``c[its exit row]``, else ``env_stuck[its stuck row]``)
    ``* trans[k]`` and ``single[p] = c[n_full + k]``, cast to float32, for the k-th object pixel ``p = oi[k]``.

    Parameters
    ----------
    rows : ObjectRows
        The pixels, their rows and the outputs ``f32``, ``s32`` (written).

    References
    ----------
    .. [1] Chaudhari 2008, §4.1 (the caustic pass's final image: the receivers seen through the object)
    """
    oi, orow, st, c, n_full, env_stuck, trans, f32, s32 = rows.oi, rows.orow, rows.st, rows.c, rows.n_full, \
        rows.env_stuck, rows.trans, rows.f32, rows.s32
    for k0 in nb.prange(oi.shape[0]):
        k = np.int64(k0)
        p = oi[k]
        r = orow[k]
        if st[p] == 1:
            for q in range(3):
                f32[p, q] = np.float32(c[r, q] * trans[k, q])
        else:
            for q in range(3):
                f32[p, q] = np.float32(env_stuck[r, q] * trans[k, q])
        for q in range(3):
            s32[p, q] = np.float32(c[n_full + k, q])


class _Pixels(NamedTuple):
    """The final pass's pixel classes (:func:`_classify_kernel`): flat indices, ascending."""

    ri: np.ndarray  # receivers seen directly
    bi: np.ndarray  # the environment (neither a receiver in front nor the object)
    oi: np.ndarray  # the object
    orow: np.ndarray  # per object pixel (as oi) its index in xi (exited) or si (stuck)
    xi: np.ndarray  # the object, its trace exited (status 1)
    si: np.ndarray  # the object, its trace stuck (status not 1)


@nb.njit(cache=True, inline="always")
def _pixel_class(zf, rd, s):
    """0 receiver seen directly, 1 environment, 2 object exited, 3 object stuck: the NumPy masks
    ``obj = isfinite(zfront)``, ``rec = isfinite(rdepth) & (rdepth < where(obj, zfront, inf))``,
    ``obj &= ~rec`` and ``status == 1``, at one pixel."""
    o = math.isfinite(zf)
    if math.isfinite(rd) and rd < (zf if o else np.inf):
        return 0
    if not o:
        return 1
    return 2 if s == 1 else 3


@nb.njit(cache=True, parallel=True)
def _class_count_kernel(zfront, rdepth, st, ldi, cnt):
    # cnt[i + 1, c]: pixels of class c in image row i; ldi = where(isfinite(zfront), zfront, inf)
    H, W = zfront.shape
    for i0 in nb.prange(H):
        i = np.int64(i0)
        for c in range(4):
            cnt[i + 1, c] = 0
        for j in range(W):
            zf = zfront[i, j]
            ldi[i, j] = zf if math.isfinite(zf) else np.inf
            cnt[i + 1, _pixel_class(zf, rdepth[i, j], st[i, j])] += 1


@nb.njit(cache=True, parallel=True)
def _class_fill_kernel(zfront, rdepth, st, first, rows):
    # each image row writes its pixels' flat indices from the row's first slot of each class
    # (first[i, c]: the pixels of class c in the rows above), so each list is ascending
    ri, bi, oi, orow, xi, si = rows.ri, rows.bi, rows.oi, rows.orow, rows.xi, rows.si
    H, W = zfront.shape
    for i0 in nb.prange(H):
        i = np.int64(i0)
        a0, a1, a2, a3 = first[i, 0], first[i, 1], first[i, 2], first[i, 3]
        ao = a2 + a3
        for j in range(W):
            c = _pixel_class(zfront[i, j], rdepth[i, j], st[i, j])
            p = i * W + j
            if c == 0:
                ri[a0] = p
                a0 += 1
            elif c == 1:
                bi[a1] = p
                a1 += 1
            else:
                oi[ao] = p
                if c == 2:
                    orow[ao] = a2
                    xi[a2] = p
                    a2 += 1
                else:
                    orow[ao] = a3
                    si[a3] = p
                    a3 += 1
                ao += 1


def classify_pixels(zfront, rdepth, st):
    """``(_Pixels, ldi)``: the flat indices of each class of :func:`_pixel_class`, ascending (as
    ``np.flatnonzero`` of the NumPy masks), and the front depth with +inf where none (1, H, W), by
    two passes over the image rows on every thread.

    Parameters
    ----------
    zfront : (H, W) float
        The object's front depth (+inf where none).
    rdepth : (H, W) float
        The receivers' depth.
    st : (H, W) int
        The trace's status codes.

    References
    ----------
    .. [1] Chaudhari 2008, §4.1 (the caustic pass's final image: the receivers seen through the object)
    """
    zf = np.ascontiguousarray(zfront, dtype=np.float64)
    rd = np.ascontiguousarray(rdepth, dtype=np.float64)
    st = np.ascontiguousarray(st)
    H = zf.shape[0]
    ldi = np.empty((1,) + zf.shape)
    cnt = np.zeros((H + 1, 4), np.int64)
    _class_count_kernel(zf, rd, st, ldi[0], cnt)
    first = np.cumsum(cnt, axis=0)  # integers: exact
    n = first[H]
    rows = _Pixels(np.empty(n[0], np.int64), np.empty(n[1], np.int64), np.empty(n[2] + n[3], np.int64),
                   np.empty(n[2] + n[3], np.int64), np.empty(n[2], np.int64), np.empty(n[3], np.int64))
    _class_fill_kernel(zf, rd, st, first, rows)
    return rows, ldi


class EyeView(NamedTuple):
    """The eye camera's scalars, for :func:`direct_rays_kernel`."""

    W: int
    H: int
    sx: float
    sy: float
    ortho: bool


class DirectGeometry(NamedTuple):
    """What :func:`direct_rays_kernel` reads."""

    basis: np.ndarray  # (3, 3) Camera.basis
    eye: np.ndarray  # (3,)
    fwd: np.ndarray  # (3,) -basis[2]
    rdepth: np.ndarray  # (H W,) the receivers' depth image
    rtri: np.ndarray  # (H W,) the receiver triangle seen at each pixel


class DirectOut(NamedTuple):
    """What :func:`direct_rays_kernel` writes."""

    Pd: np.ndarray  # (nr, 3) points seen directly
    fd: np.ndarray  # (nr,) int64 their triangles
    dd: np.ndarray  # (nr, 3) the primary rays' directions there
    db: np.ndarray  # (nb, 3) the primary rays' directions at the environment pixels


@nb.njit(cache=True, inline="always")
def _pixel_dir(p, W, H, sx, sy, ortho, rot):
    """Row and column of flat pixel ``p`` and its primary direction turned by ``rot`` (``x rot[0] + y rot[1] +
    z rot[2]``, :meth:`Camera.primary_rays`' order)."""
    i = p // W
    j = p - i * W
    x, y, z = primary_dir(i, j, W, H, sx, sy, ortho)
    d0 = x * rot[0, 0] + y * rot[1, 0] + z * rot[2, 0]
    d1 = x * rot[0, 1] + y * rot[1, 1] + z * rot[2, 1]
    d2 = x * rot[0, 2] + y * rot[1, 2] + z * rot[2, 2]
    return i, j, d0, d1, d2


@nb.njit(cache=True, parallel=True)
def direct_rays_kernel(view, geo, rows, out):
    """Per receiver pixel seen directly (``rows.ri``): the primary ray's origin and direction
    (:meth:`Camera.primary_rays`' operations), the receiver point at its depth and the triangle under
    it; per environment pixel (``rows.bi``): the direction.

    Parameters
    ----------
    view : EyeView
    geo : DirectGeometry
    rows : tuple
        ``ri``, ``bi``: the receiver and environment pixels (flat).
    out : DirectOut
        Written.

    References
    ----------
    .. [1] Chaudhari 2008, §4.1 (the caustic pass's final image: the receivers seen through the object)
    """
    W, H, sx, sy, ortho = view.W, view.H, view.sx, view.sy, view.ortho
    basis, eye, fwd, rdepth, rtri = geo.basis, geo.eye, geo.fwd, geo.rdepth, geo.rtri
    ri, bi = rows.ri, rows.bi
    Pd, fd, dd, db = out.Pd, out.fd, out.dd, out.db
    nr = ri.shape[0]
    for k0 in nb.prange(nr + bi.shape[0]):
        k = np.int64(k0)
        p = ri[k] if k < nr else bi[k - nr]
        i, j, d0, d1, d2 = _pixel_dir(p, W, H, sx, sy, ortho, basis)
        if k >= nr:
            q = k - nr
            db[q, 0] = d0
            db[q, 1] = d1
            db[q, 2] = d2
            continue
        if ortho:
            xw, yw = _pixel_xy(i, j, W, H, sx, sy)
            o0 = eye[0] + xw * basis[0, 0] + yw * basis[1, 0]
            o1 = eye[1] + xw * basis[0, 1] + yw * basis[1, 1]
            o2 = eye[2] + xw * basis[0, 2] + yw * basis[1, 2]
        else:
            o0, o1, o2 = eye[0], eye[1], eye[2]
        sc = rdepth[p] / (d0 * fwd[0] + d1 * fwd[1] + d2 * fwd[2])
        Pd[k, 0] = o0 + d0 * sc
        Pd[k, 1] = o1 + d1 * sc
        Pd[k, 2] = o2 + d2 * sc
        fd[k] = rtri[p]
        dd[k, 0] = d0
        dd[k, 1] = d1
        dd[k, 2] = d2


class FrontView(NamedTuple):
    """The eye camera's scalars and the front surface's normal rule, for :func:`final_rays_kernel`."""

    W: int
    H: int
    sx: float
    sy: float
    ortho: bool
    eta: float  # outside / ior at the front surface
    normals: int  # NORMAL_METHODS code of imagespace.normals
    delta: int


class FinalRays(NamedTuple):
    """Inputs and outputs of :func:`final_rays_kernel`."""

    xi: np.ndarray  # (nx,) exit pixels (flat)
    exit_pos: np.ndarray  # (H W, 3) world
    exit_dir: np.ndarray  # (H W, 3) world
    oi: np.ndarray  # (no,) the object's pixels (flat)
    ldi: np.ndarray  # (1, H, W) the front depth, +inf where none (layer_normals' input)
    zfront: np.ndarray  # (H W,) the front depth as _final_imagespace reads it
    eye3: np.ndarray  # (3, 3) identity: primary_rays_view's basis
    basis: np.ndarray  # (3, 3) Camera.basis (view_to_world's matrix)
    eye: np.ndarray  # (3,) Camera.eye (view_to_world's offset)
    zero3: np.ndarray  # (3,) dir_view_to_world's (and dir_world_to_view's) offset
    m: np.ndarray  # (3, 3) world_to_view's matrix (basis.T)
    t: np.ndarray  # (3,) world_to_view's offset (-eye @ basis.T)
    O: np.ndarray  # (nx + no, 3) out: the rays' world origins
    D: np.ndarray  # (nx + no, 3) out: their world directions
    Ov: np.ndarray  # (nx + no, 3) out: Camera.world_to_view(O)
    Dv: np.ndarray  # (nx + no, 3) out: Camera.dir_world_to_view(D)


@nb.njit(cache=True, inline="always")
def _to_view_rows(O, D, k, m, t, zero3, Ov, Dv):
    """Row ``k`` of Camera.world_to_view(O) and dir_world_to_view(D) (vec3.affine's order)."""
    x, y, z = O[k, 0], O[k, 1], O[k, 2]
    a, b, c = D[k, 0], D[k, 1], D[k, 2]
    for q in range(3):
        Ov[k, q] = x * m[0, q] + y * m[1, q] + z * m[2, q] + t[q]
        Dv[k, q] = a * m[0, q] + b * m[1, q] + c * m[2, q] + zero3[q]


@nb.njit(cache=True, inline="always")
def _front_ray(p, ldi, lut, zfront, e3, view):
    """The thesis's single-surface ray at object pixel ``p`` in view space: its front point and
    direction, with the bits of the public functions' operations in their order: primary_rays_view's
    direction (rotated by the identity ``e3``), layer_normals' normal (NaN where the layer is absent),
    refract, then the refracted direction (the primary one where it is not finite) and the pixel
    centre's point at depth ``zfront``. ``view`` is the eye's :class:`FrontView`."""
    W, H, sx, sy, ortho = view.W, view.H, view.sx, view.sy, view.ortho
    ii, jj, dvx, dvy, dvz = _pixel_dir(p, W, H, sx, sy, ortho, e3)
    nxx, nyy, nzz = np.nan, np.nan, np.nan
    if math.isfinite(ldi[0, ii, jj]):
        nxx, nyy, nzz = normal_at(ldi, 0, ii, jj, lut, view.normals, view.delta, ViewGrid(W, H, sx, sy, ortho))
    tx, ty, tz, _ = refract3(dvx, dvy, dvz, nxx, nyy, nzz, view.eta)
    if not (math.isfinite(tx) and math.isfinite(ty) and math.isfinite(tz)):
        tx, ty, tz = dvx, dvy, dvz
    px, py = _pixel_xy(ii, jj, W, H, sx, sy)
    dfront = zfront[p]
    if not ortho:
        px = px * dfront
        py = py * dfront
    return px, py, -dfront, tx, ty, tz


@nb.njit(cache=True, parallel=True)
def final_rays_kernel(view, lut, rays):
    """The final pass's rays: rows ``0 .. nx-1`` the exit rays (``exit_pos``, ``exit_dir`` at ``xi``),
    rows ``nx ..`` the thesis's single-surface rays at the object's pixels, in world space
    (:meth:`Camera.view_to_world`'s order) and in view space.

    Parameters
    ----------
    view : FrontView
    lut : array
        The peeling look-up table (empty without one).
    rays : FinalRays
        Inputs and outputs (``O``, ``D``, ``Ov``, ``Dv`` written).

    References
    ----------
    .. [1] Chaudhari 2008, §4.1 (the caustic pass's final image: the receivers seen through the object)
    """
    xi, exit_pos, exit_dir, oi, ldi, zfront = rays.xi, rays.exit_pos, rays.exit_dir, rays.oi, rays.ldi, rays.zfront
    e3, basis, eye, zero3, O, D = rays.eye3, rays.basis, rays.eye, rays.zero3, rays.O, rays.D
    m, tv, Ov, Dv = rays.m, rays.t, rays.Ov, rays.Dv
    nx = xi.shape[0]
    no = oi.shape[0]
    # iteration k makes exit row k and front row nx + k: OpenMP hands each thread one contiguous
    # block of iterations, which so holds as many cheap copies as refracted rays
    for k0 in nb.prange(max(nx, no)):
        k = np.int64(k0)
        if k < nx:
            q = xi[k]
            for c in range(3):
                O[k, c] = exit_pos[q, c]
                D[k, c] = exit_dir[q, c]
            _to_view_rows(O, D, k, m, tv, zero3, Ov, Dv)
        if k < no:
            px, py, pz, tx, ty, tz = _front_ray(oi[k], ldi, lut, zfront, e3, view)
            r = nx + k
            for c in range(3):
                O[r, c] = px * basis[0, c] + py * basis[1, c] + pz * basis[2, c] + eye[c]
                D[r, c] = tx * basis[0, c] + ty * basis[1, c] + tz * basis[2, c] + zero3[c]
            _to_view_rows(O, D, r, m, tv, zero3, Ov, Dv)


def _st_photon_trace(ctx, layered_trace):
    """Per light: its camera, the passes of ch. 3 in its view, one photon per texel (§4.1)."""
    d = ctx.scene.data
    p = d["imagespace"]
    g = ctx.buf["geometry"]
    geom, ior, outside, absorption = g["geom"], g["ior"], g["outside_ior"], g["absorption"]
    out = {"lights": [], **dict.fromkeys(photon_buffer_names(len(d["lights"]), True))}
    for l, light in enumerate(d["lights"]):
        lcam = light_camera(light, geom.vertices, int(p["photons"])) if len(geom.faces) else None
        if lcam is None:
            out["lights"].append(None)
            continue
        timings = {}
        view = layered_trace(geom, lcam, p, ior, outside, timings, [])
        for k, v in timings.items():
            ctx.timings[k] = ctx.timings.get(k, 0.0) + v
        trace = view["trace"]
        st = trace["status"].ravel()
        N = lcam.width
        cols = np.tile(np.arange(N) + 0.5, N)
        rows = np.repeat(np.arange(N) + 0.5, N)
        flux0 = texel_flux(lcam, cols, rows)
        ex = np.flatnonzero(st == EXITED)
        trans = beer_lambert(absorption, trace["path_length"].ravel()[ex], ior)
        o = trace["exit_pos"].reshape(-1, 3)[ex]  # world space (layered_trace)
        dd = trace["exit_dir"].reshape(-1, 3)[ex]
        bias = 1e-3 * (lcam.far - lcam.near) + 2.0 * 2.0 * lcam.sy / N
        out["lights"].append({"cam": lcam, "status": st, "flux0": flux0, "ex": ex, "trans": trans, "o": o, "d": dd,
                              "shadow": (lcam, view["zmin"], bias)})
        out[f"camera_{l}"] = camera_array(lcam)
        out[f"ldi_{l}"] = view["ldi"] if 0 not in view["ldi"].strides else None
        out[f"exit_pos_{l}"] = o
        out[f"exit_dir_{l}"] = dd
    ctx.note(f"{p['photons']}x{p['photons']} photons per light through all layers (§4.1)")
    return out


def _st_final(ctx):
    """Receivers lit directly (shadow map) and by the caustics, seen through the object (§4.1)."""
    d = ctx.scene.data
    p = d["imagespace"]
    b = ctx.buf
    g = b["geometry"]
    rs = b["receivers"]["rs"]
    rd = b["receiver_depth"]
    shadow = [None if L is None else L["shadow"] for L in b["photon_trace"]["lights"]]
    vis = ShadowMaps(shadow)  # shade_points tests these shadow maps inside its per-point kernel

    # the eye's front depth per image pixel (the grid texel under it when imagespace.grid differs)
    eye = {"trace": b["trace"], "zmin": at_pixels(b["minmax"]["zmin"], rd["cam"].shape), "cam": rd["cam"],
           "depth": rd["eyebuf"]}
    img, img1, shadow_bufs = _final_imagespace(ctx.scene, rs, eye, b["gather"]["rgb_maps"], vis, g, p)
    ctx.note("receivers lit directly (shadow map) and by the caustics; the object's multi-layer and "
             "single-surface (the thesis's) final passes")
    return {"image_caustics": img, "image_caustics_single": img1, **shadow_bufs}


#: texels: a receiver point this close to a light texel's edge, across which the shadow test decides
#: otherwise, is a tie (``shadow_margin_l`` 0): moving a receiver point by the ``receiver_depth`` tolerance
#: (1e-5 of its depth, ~3e-5 on the golden cases) moves it ~5e-3 of a light texel (2 sy / N = 6.4e-3)
SHADOW_TIE = 5e-3


def _shadow_buffers(shape, ri, P, shadow):
    """``shadow_l`` and ``shadow_margin_l``: light l's shadow test at every receiver pixel seen directly.

    The points are the final pass's (``eye + ray_dir depth / (ray_dir . f)``), tested whether or not they
    face the light, so that a shadow map read one texel off shows in a buffer of its own and not only in
    the few image pixels it darkens. ``shadow_l`` (H, W) uint8: 0 no receiver seen directly, 1 lit, 2 in
    shadow; ``shadow_margin_l`` (H, W) float32: ``dl - (zmin + bias)`` where the test compared depths,
    ``-inf`` where it did not (outside the light's window, or no object in the texel), 0 at a texel-edge
    tie (:data:`SHADOW_TIE`), NaN off the receiver pixels: ``check``'s ambiguity mask for ``shadow_l`` is
    where it lies near 0. ``ri`` are the flat indices of those pixels and ``P`` their points, as the final
    pass computed them (:func:`_final_imagespace`).

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    .. [2] L. Williams, "Casting Curved Shadows on Curved Surfaces", SIGGRAPH 1978.
    """
    H, W = shape
    out = {}
    for l, sh in enumerate(shadow):
        code = np.zeros(H * W, np.uint8)
        margin = np.full(H * W, np.nan, np.float32)
        if sh is None:  # no light camera (no objects): nothing casts a shadow
            code[ri], margin[ri] = 1, -np.inf
        else:
            lcam, zmin, bias = sh
            # code[ri] = np.where(shadow_map_visibility(...) > 0, 1, 2), margin[ri] = shadow_map_margin(...):
            # one kernel, each point's light-view position computed once for both
            shadow_map_test(lcam, zmin, P, bias, SHADOW_TIE, ri, code, margin)
        out[f"shadow_{l}"] = code.reshape(H, W)
        out[f"shadow_margin_{l}"] = margin.reshape(H, W)
    return out


def imagespace_caustic_stages(scene, layered_trace, trace_knobs):
    """The caustic stages the image-space method adds for a scene with lights and receivers (§4.1).

    The photon trace runs the method's own passes of chapter 3 in each
    light's view (``layered_trace``, given by the caller so that this module
    needs no import of :mod:`refraction_ref.imagespace.pipeline`); the
    receivers, receiver hits, splat and gathering are the caustics service's
    generic stages (:mod:`refraction_ref.caustics.pipeline`).

    Parameters
    ----------
    scene : Scene
        A loaded scene with at least one light and one receiver
        (:func:`refraction_ref.caustics.pipeline.has_caustics`).
    layered_trace : callable
        ``layered_trace(geom, cam, p, ior, outside_ior, timings, plan) -> dict``:
        min/max, voxelization, peeling, reduction and the multi-layer trace
        from a camera (:func:`refraction_ref.imagespace.pipeline.layered_trace`).
    trace_knobs : tuple of str
        The ``imagespace`` knobs ``layered_trace`` reads, in order (the photon
        trace declares them, after ``photons``, in its ``Stage.reads``).

    Returns
    -------
    tuple of Stage
        ``receivers``, ``receiver_depth``, ``photon_trace``, ``receiver_hit``,
        ``splat``, ``gather``, ``caustic_final``, in execution order.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1 (caustics), §3.3-3.8 (the
       passes in the light's view).
    .. [2] C. Wyman, S. Davis, "Interactive Image-Space Techniques for
       Approximating Caustics", I3D 2006 (the Gaussian gathering).
    """
    nl, nr = len(scene.data["lights"]), len(scene.data["receivers"])
    eyespace = scene.data["imagespace"]["receiver_hit"] == "eyespace"
    knobs = tuple(dict.fromkeys(("photons",) + tuple(trace_knobs)))
    return receiver_stages(nr) + (
        Stage("photon_trace", lambda ctx: _st_photon_trace(ctx, layered_trace),
              reads=("lights",) + tuple(f"imagespace.{k}" for k in knobs), after=("geometry",),
              makes=photon_buffer_names(nl, True),
              doc="per light: its camera, the passes of ch. 3 in its view, one photon per texel (§4.1)"),
        Stage("receiver_hit", lambda ctx: receiver_hit_stage(ctx, eyespace),
              reads=("imagespace.receiver_hit",),
              after=("receivers", "photon_trace") + (("receiver_depth",) if eyespace else ()),
              makes=per_light_names("hit_pos", nl) + per_light_names("hit_face", nl),
              doc="where exiting photons meet the receivers (§4.1)"),
        Stage("splat", lambda ctx: splat_stage(ctx, False), reads=("caustics.map_size",),
              after=("receivers", "photon_trace", "receiver_hit"), makes=per_light_names("splat", nr),
              doc="bilinear splat of each photon's irradiance (§2.3.2)"),
        Stage("gather", lambda ctx: gather_stage(ctx, True), reads=("caustics.gather", "lights"),
              after=("receivers", "splat"), makes=gather_names(nr),
              doc="Gaussian gathering (Wyman & Davis 2006)"),
        Stage("caustic_final", _st_final,
              reads=("environment", "lights", "imagespace.normals", "imagespace.delta",
                     "imagespace.receiver_hit"),
              after=("geometry", "minmax", "trace", "receivers", "receiver_depth", "photon_trace", "gather"),
              makes=("image_caustics", "image_caustics_single") + per_light_names("shadow", nl)
              + per_light_names("shadow_margin", nl),
              doc="receivers lit directly and by caustics, seen through the object (§4.1)"),
    )


def _final_imagespace(scene, rs, eye, rgb_maps, vis, material, p):
    """The final pass (§4.1): ``image_caustics`` (multi-layer), ``image_caustics_single`` (the thesis's), and
    the shadow buffers ``shadow_l``, ``shadow_margin_l`` of :func:`_shadow_buffers` (``vis``: a
    :class:`~refraction_ref.caustics.shade.ShadowMaps`), filled by the shading kernel from its own
    shadow test where it shades in place, else by :func:`_shadow_buffers`.

    ``eye``: the eye's ``trace``, its front depth ``zmin`` per image pixel, its camera ``cam`` and the
    receivers' depth image ``depth`` (``(rdepth, rtri)``); ``material``: the objects' ``ior``,
    ``outside_ior`` and ``absorption`` (the ``geometry`` stage's buffers); ``p``: the ``imagespace`` knobs
    (``normals``, ``delta``, ``receiver_hit``)."""
    cam, eyebuf, mode = eye["cam"], eye["depth"], p["receiver_hit"]
    ior, outside, absorption = material["ior"], material["outside_ior"], material["absorption"]
    H, W = cam.shape
    trace = eye["trace"]
    zfront = eye["zmin"]
    rdepth, rtri = eyebuf
    env = scene.data["environment"]
    st = trace["status"]
    # the pixel classes (receiver seen directly, environment, object exited or stuck) as flat
    # indices, ascending, and the front depth for the normals, on every thread
    px, ldi = classify_pixels(zfront, rdepth, st)
    ri, bi, oi, xi = px.ri, px.bi, px.oi, px.xi
    # receivers seen directly: shaded with the object's rays below (one call): each one's primary
    # ray, its point origin + dir (rdepth / dir . fwd) and triangle; the environment pixels'
    # directions; by one kernel on every thread (not the whole image's rays)
    Wk, Hk, sx, sy = cam.kernel_args()
    direct = (np.empty((len(ri), 3)), np.empty(len(ri), np.int64), np.empty((len(ri), 3)))
    dirs_bg = np.empty((len(bi), 3))
    if len(ri) + len(bi):
        direct_rays_kernel(EyeView(Wk, Hk, float(sx), float(sy), bool(cam.ortho)),
                            DirectGeometry(np.ascontiguousarray(cam.basis, dtype=np.float64),
                                            np.ascontiguousarray(cam.eye, dtype=np.float64),
                                            np.ascontiguousarray(-cam.basis[2], dtype=np.float64),
                                            np.ascontiguousarray(rdepth, dtype=np.float64).reshape(-1),
                                            np.ascontiguousarray(rtri).reshape(-1)),
                            px, DirectOut(*direct, dirs_bg))
    env_bg = environment_lookup(env, dirs_bg, scene.base_dir) if len(bi) else np.zeros((0, 3))
    # the shadow buffers at the receiver pixels seen directly: written by the shading kernel from the
    # shadow test it makes there anyway, where it shades in place; else tested on their own after
    nl = len(vis.shadow)
    if shade_rows_applies(rs, scene.data["lights"], rgb_maps, vis):
        code = np.zeros((nl, H * W), np.uint8)
        margin = np.full((nl, H * W), np.nan, np.float32)
        bufs = (ri, code, margin, SHADOW_TIE)
        shadow_out = {}
        for l in range(nl):
            shadow_out[f"shadow_{l}"] = code[l].reshape(H, W)
            shadow_out[f"shadow_margin_{l}"] = margin[l].reshape(H, W)
    else:
        bufs = None
    if not len(oi):
        base = np.zeros((H, W, 3))
        put_rows(base.reshape(-1, 3), bi, env_bg)
        _, cd = shade_rays(scene, ReceiverLighting(rs, scene.data["lights"], rgb_maps, vis),
                           ReceiverHitMode(mode, cam, eyebuf), np.zeros((0, 3)), np.zeros((0, 3)), direct, bufs)
        put_rows(base.reshape(-1, 3), ri, cd)
        if bufs is None:
            shadow_out = _shadow_buffers(cam.shape, ri, direct[0], vis.shadow)
        return base.astype(np.float32), base.astype(np.float32), shadow_out
    # the multi-layer pass: exit rays on to the receivers, else the environment (§3.6-3.8)
    path_length = np.empty(len(oi))  # trace["path_length"] at the object's pixels
    take_values(np.ascontiguousarray(trace["path_length"], dtype=np.float64).reshape(-1), oi, path_length)
    trans = beer_lambert(absorption, path_length, ior)  # per pixel: only the object's
    # both passes' rays in one march and one shading: each ray's colour is its own, and one call
    # instead of two halves the serial work around the kernels. The exit rays (world space,
    # layered_trace), then the thesis's final pass: refraction at the front surface only, its
    # normal, refraction and front point per object pixel (not the whole image's normals and
    # directions), both written into the rays' rows by one kernel on every thread
    n_full = len(xi)
    O, D = np.empty((n_full + len(oi), 3)), np.empty((n_full + len(oi), 3))
    Ov, Dv = np.empty_like(O), np.empty_like(D)
    m, t = view_affine(cam)
    final_rays_kernel(FrontView(Wk, Hk, float(sx), float(sy), bool(cam.ortho), float(outside / ior),
                                  NORMAL_METHODS[p["normals"]], int(p["delta"])), no_lut(zfront.shape),
                       FinalRays(xi, np.ascontiguousarray(trace["exit_pos"], dtype=np.float64).reshape(-1, 3),
                                  np.ascontiguousarray(trace["exit_dir"], dtype=np.float64).reshape(-1, 3), oi, ldi,
                                  np.ascontiguousarray(zfront, dtype=np.float64).reshape(-1), np.eye(3),
                                  np.ascontiguousarray(cam.basis, dtype=np.float64),
                                  np.ascontiguousarray(cam.eye, dtype=np.float64), np.zeros(3), m, t, O, D, Ov,
                                  Dv))
    c, cd = shade_rays(scene, ReceiverLighting(rs, scene.data["lights"], rgb_maps, vis),
                       ReceiverHitMode(mode, cam, eyebuf), O, D, direct, bufs, (Ov, Dv))
    if bufs is None:
        shadow_out = _shadow_buffers(cam.shape, ri, direct[0], vis.shadow)
    # the two images in float32, each pixel written once from its own rows on every thread (the bits of
    # composing them in float64 and casting to float32): receivers seen directly
    # (cd) and the environment (env_bg) in both; the object's pixels: the exit ray's colour or,
    # stuck, the environment along the last direction, times the transmittance (full), and the
    # single-surface ray's colour (single)
    si = px.si
    env_stuck = (environment_lookup(env, take_rows(trace["last_dir"].reshape(-1, 3), si), scene.base_dir) if len(si)
                 else np.zeros((0, 3)))
    f32 = np.empty((H, W, 3), np.float32)
    s32 = np.empty((H, W, 3), np.float32)
    f32f, s32f = f32.reshape(-1, 3), s32.reshape(-1, 3)
    put32_kernel(np.ascontiguousarray(ri, dtype=np.int64), np.ascontiguousarray(cd, dtype=np.float64), f32f, s32f)
    put32_kernel(np.ascontiguousarray(bi, dtype=np.int64), np.ascontiguousarray(env_bg, dtype=np.float64), f32f,
                  s32f)
    object_pixels_kernel(ObjectRows(oi, px.orow, np.ascontiguousarray(st).reshape(-1), np.ascontiguousarray(c),
                                      n_full, np.ascontiguousarray(env_stuck, dtype=np.float64),
                                      np.ascontiguousarray(trans, dtype=np.float64), f32f, s32f))
    return f32, s32, shadow_out
