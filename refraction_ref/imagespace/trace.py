"""Image-space ray tracing through the layered depth images (Chaudhari 2008, §3.6-3.8).

Every pixel's primary ray enters the object at layer 0 of its own pixel and
is refracted there (Snell, with the normal of §3.5). Then, for each
following interface, the intersection with the *next* layer is found by the
binary search of Oliveira and Brauwers (2007): between the current point
``S`` and the point ``E`` where the ray reaches the layer's search bound
``Zmax(n)`` (§3.7),

    E = S + (Zmax - S_d) / v_d * v,

each midpoint ``P`` is projected to its texel ``t_P`` and compared with the
layer's depth there: in front of the surface moves ``S`` to ``P``, behind it
moves ``E`` (5 iterations by default). The intersection is the thesis's
``R_n`` (``endpoint='probe'``, the default): the surface point at the last
probe's texel ``t_Pn`` - the point of the line of sight through ``P_n`` at
the layer's depth there ("Surface normal of the point R3 is then calculated
using the texture coordinate t_P3 of the point P3", §3.6); or, with
``endpoint='bracket'``, the midpoint of the final bracket. Its normal is
estimated at ``t_P`` and Snell's law gives the next direction. The depth
images are sampled with bilinear filtering (``filter='bilinear'``, the
hardware filtering of §3.4.2) where the four texels around a position hold
the layer, at the nearest texel elsewhere (``filter='nearest'`` always).
A ray that reaches the pixel's backmost depth (the last layer, or within
``exit_threshold`` slices of ``Zmax`` of §3.3) stops there: early
termination, §3.7. The geometric length travelled
inside gives the Beer-Lambert absorption ``I = I0 exp(-alpha l eta)``
(§3.8), applied by the caller.

Which side of a layer is inside follows the layers' order: the gap between
layers ``2k`` and ``2k + 1`` is inside an object, the others are outside
(exact for closed meshes; for open meshes a pixel may hold an odd number of
layers and the parity is then a guess, as on the GPU).

Beyond the thesis: with ``tir`` enabled, a total internal reflection (and
any ray turned back towards the viewer) is followed by a *backward*
binary search against the preceding layer, bounded by that layer's minimum
depth - the extension the thesis sketches in §4.3 - instead of giving up.
Every way a ray can be lost gets a status code (docs/oracle.md,
:mod:`refraction_ref.status`):

=== ========== =======================================================
0   ``MISSED`` the pixel shows no layer
1   ``EXITED`` left the object (behind the backmost layer, in front of
               layer 0, or outside the object with no further layer on
               its path)
2   ``LIMIT``  stopped at the layer limit (a deeper layer than
               ``layers`` was needed) or at ``max_interfaces`` events
3   ``TIR``    trapped by total internal reflection (``tir`` disabled,
               or the event limit reached while reflecting)
4   ``LOST``   the search could not resolve an intersection while
               inside the object (a ray parallel to the image plane,
               turned towards the viewer without ``tir``, leaving the
               screen, or converging where the layer is absent)
=== ========== =======================================================

With ``record=K`` the first ``K`` events of every path are kept
(``path_pos``, ``path_dir``): one row per application of Snell's law, so
that a port can be compared with this reference interface by interface,
not only at the exit.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..camera import primary_dir, project_point, unproject_pixel
from ..optics import refract3
from ..schedule import coprime_stride, strided
from ..status import EXITED, LIMIT, LOST, MISSED, TIR
from .normals import ViewGrid, layer_depth, normal_filtered, sample_depth

__all__ = ["trace_layers", "exit_thresholds", "ImagespaceLayers", "ImagespaceOptics", "ImagespaceRays",
           "ImagespaceFrame", "ImagespaceOutputs"]

_PARALLEL_EPS = 1e-9  # |dd/dt| below this: the ray is parallel to the image plane


@nb.njit(cache=True, inline="always")
def _screen(x, y, z, W, H, sx, sy, ortho=False):
    """Screen position (row, col) of a view-space point, pixel units; (-1, -1) when off screen or behind the eye."""
    if -z <= 0.0:
        return -1.0, -1.0
    col, row, d = project_point(x, y, z, W, H, sx, sy, ortho)
    if not (col >= 0.0 and col < W and row >= 0.0 and row < H):
        return -1.0, -1.0
    return row, col


@nb.njit(cache=True, inline="always")
def _behind(ldi, n, x, y, z, forward, lut, grid, filter):
    """Has the point crossed layer n (beyond it in the direction of travel)?"""
    r, c = _screen(x, y, z, grid.W, grid.H, grid.sx, grid.sy, grid.ortho)
    if r < 0.0:
        return False
    ls = sample_depth(ldi, n, r, c, lut, filter)
    if not math.isfinite(ls):
        return False
    if forward:
        return -z >= ls
    return -z <= ls


@nb.njit(cache=True, inline="always")
def _store(out, i, j, x, y, z, frame, m, t, point):
    """Write a view-space vector to out[i, j], rotated (and, for a point, moved) by the frame."""
    if frame:
        for c in range(3):
            out[i, j, c] = x * m[0, c] + y * m[1, c] + z * m[2, c] + (t[c] if point else 0.0)
    else:
        out[i, j, 0] = x
        out[i, j, 1] = y
        out[i, j, 2] = z


class ImagespaceLayers(NamedTuple):
    """The layered depth images and what the search reads beside them (§3.3-3.7): :func:`trace_layers`' input.

    The on-the-fly peeling inputs (``lut``) travel beside it, not in it: a
    parallel loop's outlined body takes a tuple argument's fields one level
    deep, and ``lut`` is itself a tuple.

    Attributes
    ----------
    ldi : (L, H, W) float32 (or float64)
        Layer depths (``+inf`` where absent).
    total : (H, W) int
        Layers per pixel before the layer limit (the last one is the backmost).
    zback : (H, W) float64
        Backmost depth per pixel (Zmax of the min/max pass).
    thr : (H, W) float64
        Early-termination threshold in depth units (:func:`exit_thresholds`).
    bounds_hi, bounds_lo : (L,) float64
        Forward and backward search bounds per layer
        (:func:`~refraction_ref.imagespace.search_bounds.search_bounds`).
    """

    ldi: np.ndarray
    total: np.ndarray
    zback: np.ndarray
    thr: np.ndarray
    bounds_hi: np.ndarray
    bounds_lo: np.ndarray


class ImagespaceOptics(NamedTuple):
    """The indices of refraction a trace refracts with: the objects' and their surroundings'."""

    ior: float
    outside_ior: float


class ImagespaceRays(NamedTuple):
    """The rays a trace casts: the image's own primary rays (``own``), or the given directions ``dirs``."""

    dirs: np.ndarray  # (Hi, Wi, 3) view-space unit directions; (1, 1, 3) unused when own
    own: bool


class ImagespaceFrame(NamedTuple):
    """Frame the outputs are written in: ``world`` applies ``x @ rot + t``."""

    world: bool
    rot: np.ndarray  # (3, 3)
    t: np.ndarray  # (3,)


class ImagespaceOutputs(NamedTuple):
    """Arrays the kernel fills (see :func:`trace_layers`, Returns)."""

    exit_pos: np.ndarray
    exit_dir: np.ndarray
    last_dir: np.ndarray
    interfaces: np.ndarray
    path_length: np.ndarray
    status: np.ndarray
    path_pos: np.ndarray  # (H, W, K, 3); (1, 1, 1, 3) unused when record is 0
    path_dir: np.ndarray


@nb.njit(cache=True, inline="always")
def _bisect(ldi, t, p, e, forward, lut, grid, filter, iterations):
    """The binary search between S = p and E = e (Oliveira & Brauwers 2007; Chaudhari 2008, §3.6).

    Returns the final bracket ``(a, b)`` (fractions of the way from S to E),
    the last probe ``m`` (1, E itself, when there are no iterations) and
    whether any probe crossed layer ``t``.
    """
    px, py, pz = p
    ex, ey, ez = e
    a = 0.0
    b = 1.0
    m = 1.0  # the last probe (E itself when there are no iterations)
    found = False
    for _ in range(iterations):
        m = 0.5 * (a + b)
        if _behind(ldi, t, px + m * (ex - px), py + m * (ey - py), pz + m * (ez - pz),
                   forward, lut, grid, filter):
            b = m
            found = True
        else:
            a = m
    return a, b, m, found


@nb.njit(cache=True, inline="always")
def _probe_hit(ldi, t, p, e, m, lut, grid, filter):
    """``endpoint='probe'`` (§3.6): the surface point R_n of layer ``t`` at the last probe's texel.

    The point of the line of sight through the last probe P_n (at ``m``
    between S = p and E = e) at the layer's depth there, whichever side of
    the layer P_n was. Returns ``(ok, qx, qy, qz, rq, cq)``: ``ok`` False
    where that texel lacks the layer; ``(rq, cq)`` is the probe's screen
    position.
    """
    px, py, pz = p
    ex, ey, ez = e
    W, H, sx, sy, ortho = grid.W, grid.H, grid.sx, grid.sy, grid.ortho
    qx, qy, qz = px + m * (ex - px), py + m * (ey - py), pz + m * (ez - pz)
    rq, cq = _screen(qx, qy, qz, W, H, sx, sy, ortho)
    dq = sample_depth(ldi, t, rq, cq, lut, filter) if rq >= 0.0 else np.inf
    if not math.isfinite(dq):
        return False, qx, qy, qz, rq, cq
    qx, qy, qz = unproject_pixel(cq, rq, dq, W, H, sx, sy, ortho)
    return True, qx, qy, qz, rq, cq


@nb.njit(cache=True, inline="always")
def _bracket_hit(ldi, t, p, e, ab, found, forward, lut, grid, filter):
    """``endpoint='bracket'``: the midpoint of the final bracket ``ab = (a, b)``, with two fallbacks.

    ``E`` is tested when no probe crossed the layer; the bracket's far end
    replaces a midpoint whose texel lacks the layer. Returns
    ``(ok, qx, qy, qz, rq, cq)``, ``ok`` False when not even ``E`` crossed
    layer ``t``.
    """
    px, py, pz = p
    ex, ey, ez = e
    a, b = ab
    W, H, sx, sy, ortho = grid.W, grid.H, grid.sx, grid.sy, grid.ortho
    if not found:
        found = _behind(ldi, t, ex, ey, ez, forward, lut, grid, filter)
    if not found:
        return False, 0.0, 0.0, 0.0, -1.0, -1.0
    m = 0.5 * (a + b)
    qx, qy, qz = px + m * (ex - px), py + m * (ey - py), pz + m * (ez - pz)
    rq, cq = _screen(qx, qy, qz, W, H, sx, sy, ortho)
    if rq < 0.0 or not math.isfinite(layer_depth(ldi, t, np.int64(rq), np.int64(cq), lut)):
        # the midpoint fell where the layer is absent: use the bracket's far end
        qx, qy, qz = px + b * (ex - px), py + b * (ey - py), pz + b * (ez - pz)
        rq, cq = _screen(qx, qy, qz, W, H, sx, sy, ortho)
    return True, qx, qy, qz, rq, cq


@nb.njit(cache=True, inline="always")
def _first_layer(ldi, i, j, image, grid, lut, filter):
    """Layer 0 where pixel (i, j)'s primary ray meets it: ``(depth, row, col)`` of the grid position.

    On a grid of the image's size the pixel's own texel; on another grid
    (``imagespace.grid``) the layer sampled at the pixel centre's grid
    position.
    """
    if ldi.shape[0] == 0:
        return np.inf, i + 0.5, j + 0.5
    if image.W == grid.W and image.H == grid.H:
        return layer_depth(ldi, np.int64(0), i, j, lut), i + 0.5, j + 0.5  # int64: one signature
    rg = (i + 0.5) * grid.H / image.H
    cg = (j + 0.5) * grid.W / image.W
    return sample_depth(ldi, np.int64(0), rg, cg, lut, filter), rg, cg


@nb.njit(cache=True, parallel=True)
def _trace_kernel(layers, lut, rays, image, grid, knobs, optics, frame, out):
    Hi = image.H
    step = coprime_stride(Hi)
    for r in nb.prange(Hi):
        # rows spread over the threads (see ..schedule); a row is an ordinary call, not inlined into the
        # parallel loop: Numba's parfor passes on the inlined search and normals took minutes to compile
        _trace_row(layers, lut, rays, image, grid, knobs, optics, frame, out, strided(r, step, Hi))


# _nrt=False: the row allocates nothing, and the kernel's caller holds every array it reads. With reference
# counting, each array taken out of a tuple or sliced in the search's inner loops is an atomic incref/decref
# pair (the parallel loop's outlined body gets arrays without them): the row ran 4x slower.
@nb.njit(cache=True, _nrt=False)
def _trace_row(layers, lut, rays, image, grid, knobs, optics, frame, out, i):
    """Trace the primary rays of image row ``i`` (see :func:`trace_layers`); the helpers inline here."""
    # the named tuples unpacked by name (a reordered field cannot swap two arguments)
    ldi, total, zback, thr = layers.ldi, layers.total, layers.zback, layers.thr
    bhi, blo = layers.bounds_hi, layers.bounds_lo
    # the rays are the image's pixels; the layers, projections and normals are the grid's
    Wi, Hi, isx, isy = image.W, image.H, image.sx, image.sy
    ortho = grid.ortho
    dirs, own_dirs = rays.dirs, rays.own
    ior, outside_ior = optics.ior, optics.outside_ior
    iterations, normals, delta, tir = knobs.iterations, knobs.normals, knobs.delta, knobs.tir
    max_interfaces, layer_limit, rec = knobs.max_interfaces, knobs.layer_limit, knobs.record
    endpoint, filter = knobs.endpoint, knobs.filter
    world, rot, t0 = frame.world, frame.rot, frame.t
    exit_pos, exit_dir, last_dir, status = out.exit_pos, out.exit_dir, out.last_dir, out.status
    interfaces, path_pos, path_dir = out.interfaces, out.path_pos, out.path_dir
    L = ldi.shape[0]
    for j0 in range(Wi):
        j = np.int64(j0)
        if own_dirs:
            vx, vy, vz = primary_dir(i, j, Wi, Hi, isx, isy, ortho)
        else:
            vx = dirs[i, j, 0]
            vy = dirs[i, j, 1]
            vz = dirs[i, j, 2]
        d0, r0, c0 = _first_layer(ldi, i, j, image, grid, lut, filter)
        if not math.isfinite(d0):
            status[i, j] = MISSED
            interfaces[i, j] = 0
            out.path_length[i, j] = 0.0
            _store(last_dir, i, j, vx, vy, vz, world, rot, t0, False)
            _store(exit_dir, i, j, vx, vy, vz, world, rot, t0, False)
            _store(exit_pos, i, j, np.nan, np.nan, np.nan, False, rot, t0, True)
            for e in range(rec):
                _store(path_pos[i], j, e, np.nan, np.nan, np.nan, False, rot, t0, True)
                _store(path_dir[i], j, e, np.nan, np.nan, np.nan, False, rot, t0, False)
            continue
        if ortho:  # parallel rays from the window plane z = 0
            qx, qy, qz = unproject_pixel(j + 0.5, i + 0.5, d0, Wi, Hi, isx, isy, True)
        else:
            s = d0 / (-vz)
            # the pending hit: layer t at texel (ti, tj), point q, reached from gap g
            qx, qy, qz = vx * s, vy * s, vz * s
        px, py, pz = qx, qy, qz
        t = np.int64(0)  # not a literal 0: callees compile for int64 only
        ti, tj = np.int64(math.floor(r0)), np.int64(math.floor(c0))  # the grid texel of the hit
        rq, cq = r0, c0  # grid position of the pending hit (the normal is read there)
        g = -1
        forward = True
        events = 0
        nint = 0
        path_length = 0.0
        st = LOST
        last_tir = False
        while True:
            # ---- interface at layer t: advance, refract (§3.6) --------------
            if g % 2 == 0:
                path_length += math.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
            px, py, pz = qx, qy, qz
            g2 = t if forward else t - 1
            n1 = ior if g % 2 == 0 else outside_ior
            n2 = ior if g2 % 2 == 0 else outside_ior
            # nearest: the texel's own normal (at its centre); bilinear: filtered reads at the hit's
            # texture coordinate
            rn, cn = (ti + 0.5, tj + 0.5) if filter == 0 else (rq, cq)
            nx, ny, nz = normal_filtered(ldi, t, rn, cn, lut, normals, delta, grid, filter)
            wx, wy, wz, is_tir = refract3(vx, vy, vz, nx, ny, nz, n1 / n2)
            if events < rec:  # event `events`: where, and the direction Snell gave
                _store(path_pos[i], j, events, px, py, pz, world, rot, t0, True)
                _store(path_dir[i], j, events, wx, wy, wz, world, rot, t0, False)
            events += 1
            last_tir = is_tir
            if is_tir and not tir:
                st = TIR
                break
            vx, vy, vz = wx, wy, wz
            if not is_tir:
                g = g2
                nint += 1
                if g == -1:  # back out through the front layer
                    st = EXITED
                    break
                if forward and (t >= total[ti, tj] - 1
                                or zback[ti, tj] - layer_depth(ldi, t, ti, tj, lut) <= thr[ti, tj]):
                    st = EXITED  # early termination at the backmost depth (§3.7)
                    break
            if events >= max_interfaces:
                st = TIR if last_tir else LIMIT
                break
            # ---- next search: which layer, which bound (§3.7) ---------------
            dd = -vz  # rate of change of depth along the ray
            outside = g % 2 != 0
            if dd > _PARALLEL_EPS:
                forward = True
                t = g + 1
                if t >= layer_limit:
                    st = LIMIT
                    break
                zb = bhi[t] if t < L else -np.inf
            elif dd < -_PARALLEL_EPS and tir:
                forward = False
                t = g
                zb = blo[t]
            else:
                st = EXITED if outside and dd < 0.0 else LOST
                break
            depth_p = -pz
            if not math.isfinite(zb) or (forward and zb <= depth_p) or (not forward and zb >= depth_p):
                st = EXITED if outside else LOST  # no layer ahead: escaped, or lost inside
                break
            k = (zb - depth_p) / dd
            ex, ey, ez = px + k * vx, py + k * vy, pz + k * vz
            # ---- binary search between S = p and E (Oliveira & Brauwers 2007)
            a, b, m, found = _bisect(ldi, t, (px, py, pz), (ex, ey, ez), forward, lut, grid, filter,
                                     iterations)
            if endpoint == 0:
                # §3.6: the last probe P_n's texel t_Pn and the surface point R_n there
                ok, qx, qy, qz, rq, cq = _probe_hit(ldi, t, (px, py, pz), (ex, ey, ez), m, lut, grid, filter)
                if not ok:
                    st = EXITED if outside else LOST  # the last probe's texel lacks the layer
                    break
                ti, tj = np.int64(math.floor(rq)), np.int64(math.floor(cq))
                continue
            ok, qx, qy, qz, rq, cq = _bracket_hit(ldi, t, (px, py, pz), (ex, ey, ez), (a, b), found, forward,
                                                  lut, grid, filter)
            if not ok:
                st = EXITED if outside else LOST
                break
            ti, tj = np.int64(rq), np.int64(cq)
        status[i, j] = st
        interfaces[i, j] = nint
        out.path_length[i, j] = path_length
        _store(last_dir, i, j, vx, vy, vz, world, rot, t0, False)
        if st == EXITED:
            _store(exit_pos, i, j, px, py, pz, world, rot, t0, True)
            _store(exit_dir, i, j, vx, vy, vz, world, rot, t0, False)
        else:
            _store(exit_pos, i, j, np.nan, np.nan, np.nan, False, rot, t0, True)
            _store(exit_dir, i, j, np.nan, np.nan, np.nan, False, rot, t0, False)
        for e in range(min(events, rec), rec):  # rows past the path's last event
            _store(path_pos[i], j, e, np.nan, np.nan, np.nan, False, rot, t0, True)
            _store(path_dir[i], j, e, np.nan, np.nan, np.nan, False, rot, t0, False)


@nb.njit(cache=True, parallel=True)
def _threshold_kernel(zlo, zhi, scale, out):
    for i in nb.prange(zlo.shape[0]):
        for j in range(zlo.shape[1]):
            t = (zhi[i, j] - zlo[i, j]) * scale
            out[i, j] = t if math.isfinite(t) else 0.0


def exit_thresholds(zlo, zhi, slices, exit_threshold=1.0):
    """Early-termination thresholds (H, W): ``exit_threshold`` slices of each pixel's grid.

    A ray closer than this to the pixel's backmost depth stops there
    (§3.7). One slice spans ``(zhi - zlo) / (S - 1)`` (§3.3); the threshold
    is 0 where the pixel has no fragment.

    Parameters
    ----------
    zlo, zhi : (H, W) array_like of float
        Frontmost and backmost depth per pixel (the min/max pass; ``inf``
        where the pixel has no fragment).
    slices : int
        Slices ``S`` of each pixel's depth grid (>= 2).
    exit_threshold : float
        Threshold in slices.

    Returns
    -------
    (H, W) float64 ndarray
        Threshold in depth units, 0 where it is not finite.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §3.3 (the depth slices) and §3.7
       (early termination near the backmost surface).
    """
    zlo = np.ascontiguousarray(zlo, dtype=np.float64)
    zhi = np.ascontiguousarray(zhi, dtype=np.float64)
    out = np.empty(zlo.shape)
    _threshold_kernel(zlo, zhi, float(exit_threshold) / (int(slices) - 1), out)
    return out


def trace_layers(layers, camera, knobs, optics, *, dirs_view=None, lut=None, world=False, image=None):
    """Trace every pixel's ray through the layered depth images.

    Parameters
    ----------
    layers : ImagespaceLayers
        The layers (``ldi``, ``total``), the backmost depth ``zback``, the
        early-termination thresholds ``thr`` and the search bounds per layer.
    camera : Camera
        The view of the layers: the eye's, or a light's (perspective for a
        point light, orthographic for a directional light: every ray then
        starts on the window plane and travels along ``-z``).
    knobs : TraceKnobs
        The ``imagespace`` knobs of the trace
        (:func:`~refraction_ref.imagespace.knobs.trace_knobs`): binary-search
        ``iterations`` per interface; the ``normals`` rule and its ``delta``;
        ``tir`` (follow total internal reflection with backward searches);
        ``max_interfaces`` events (refractions plus reflections) per ray; the
        ``layer_limit`` (a search for a layer at or beyond it stops the ray
        with status ``LIMIT``); ``record``: keep the first ``record`` events
        of every path in ``path_pos`` and ``path_dir`` (0 records nothing and
        adds no keys); the ``endpoint`` of a search, ``probe`` (the thesis,
        §3.6: at the texel of the last probe ``P_n``, the midpoint tested by
        the last iteration or ``E`` with 0 iterations, on the layer's surface
        there: the point of the line of sight through ``P_n`` at the layer's
        sampled depth, whichever side of the layer ``P_n`` was; the search
        fails only where that texel lacks the layer) or ``bracket`` (the
        midpoint of the final bracket, an untested point, after testing ``E``
        when no probe crossed the layer, and moved to the bracket's far end
        when the midpoint's texel lacks the layer); the ``filter`` of the
        depth reads (search tests, hit depth, normal reads), ``bilinear``
        (the thesis's hardware filtering, §3.4.2) over the four texels around
        the position when all four hold the layer, the nearest texel where
        any of them lacks it, or ``nearest``: the texel under the position,
        normals at its centre.
    optics : ImagespaceOptics
        Object and surrounding indices.
    dirs_view : (Hi, Wi, 3) float64, optional
        Unit primary ray directions in view space, one per image pixel;
        None for the image's own primary rays (computed per pixel in the
        kernel).
    lut : tuple, optional
        On-the-fly peeling inputs (see :func:`~refraction_ref.imagespace.normals.layer_depth`).
    world : bool, default False
        Return ``exit_pos``, ``exit_dir``, ``last_dir`` (and ``path_pos``,
        ``path_dir``) in world space (the camera's frame applied as they
        are written) instead of view space.
    image : Camera, optional
        The image casting one ray per pixel (``imagespace.grid``; default ``camera``): ``camera``'s
        view, its own pixel count. Positions project to ``camera``'s grid; a primary ray's first
        hit is layer 0 sampled at its pixel centre's grid position.

    Returns
    -------
    dict
        Per image pixel (H, W: ``image``'s size):
        ``exit_pos``, ``exit_dir`` (NaN unless status ``EXITED``),
        ``last_dir`` (H, W, 3) in view space (world space with ``world``),
        ``interfaces`` (H, W) int16, ``path_length`` (H, W) float64,
        ``status`` (H, W) int8 (:mod:`refraction_ref.status`). A missed
        pixel's ``exit_dir`` and ``last_dir`` are its primary ray.

        With ``knobs.record = K > 0`` also ``path_pos`` and ``path_dir``
        (H, W, K, 3) float64, in the frame of ``exit_pos``. Row ``k`` is
        the ``k``-th event of the pixel's path, one per application of
        Snell's law: row 0 is the point where the primary ray meets layer
        0 of its own pixel, each later row the point the binary search
        found on the next layer (forward, or backward after a reflection
        with ``tir``). ``path_dir[..., k, :]`` is the unit direction
        :func:`~refraction_ref.optics.refract3` gives there: the refracted
        ray, or the mirror direction under total internal reflection. With
        ``tir`` disabled the reflection that stops the ray (status ``TIR``)
        is still recorded as its last row, its mirror direction unfollowed
        (``last_dir`` keeps the incident one). Rows past the path's events
        (all rows of a missed pixel; those after the event that ended the
        path) are NaN. For an exited ray with at most ``K`` events the last
        row is ``exit_pos`` and ``exit_dir``, bit for bit.

    References
    ----------
    Chaudhari (2008), §3.6 (binary search at each interface), §3.7 (search
    bounds, early termination), §3.8 (path length for absorption);
    Oliveira and Brauwers (2007).
    """
    from .normals import no_lut

    record = knobs.record
    Hg, Wg = layers.total.shape
    image = camera if image is None else image
    H, W = image.shape
    shape = (H, W, record, 3) if record else (1, 1, 1, 3)
    out = ImagespaceOutputs(exit_pos=np.empty((H, W, 3)), exit_dir=np.empty((H, W, 3)),
                            last_dir=np.empty((H, W, 3)), interfaces=np.empty((H, W), np.int16),
                            path_length=np.empty((H, W)), status=np.empty((H, W), np.int8),
                            path_pos=np.empty(shape), path_dir=np.empty(shape))
    Wc, Hc, sx, sy = camera.kernel_args()
    if (Hc, Wc) != (Hg, Wg):
        raise ValueError(f"trace_layers: the layers are {(Hg, Wg)}, the camera is {(Hc, Wc)}")
    if dirs_view is not None and np.shape(dirs_view)[:2] != (H, W):
        raise ValueError(f"trace_layers: the ray directions are {np.shape(dirs_view)[:2]}, the image {(H, W)}")
    own = dirs_view is None
    dirs = np.zeros((1, 1, 3)) if own else np.ascontiguousarray(dirs_view, dtype=np.float64)
    if world:
        m = np.ascontiguousarray(camera.basis, dtype=np.float64)
        t = np.ascontiguousarray(camera.eye, dtype=np.float64)
    else:
        m, t = np.eye(3), np.zeros(3)
    layers = ImagespaceLayers(np.ascontiguousarray(layers.ldi), np.ascontiguousarray(layers.total, dtype=np.int32),
                              np.ascontiguousarray(layers.zback, dtype=np.float64),
                              np.ascontiguousarray(layers.thr, dtype=np.float64),
                              np.ascontiguousarray(layers.bounds_hi, dtype=np.float64),
                              np.ascontiguousarray(layers.bounds_lo, dtype=np.float64))
    grid = ViewGrid(Wc, Hc, sx, sy, bool(camera.ortho))
    view = ViewGrid(*image.kernel_args(), bool(camera.ortho))
    _trace_kernel(layers, no_lut(None) if lut is None else lut, ImagespaceRays(dirs, own), view, grid, knobs,
                  ImagespaceOptics(float(optics.ior), float(optics.outside_ior)),
                  ImagespaceFrame(bool(world), m, t), out)
    res = {"exit_pos": out.exit_pos, "exit_dir": out.exit_dir, "last_dir": out.last_dir,
           "interfaces": out.interfaces, "path_length": out.path_length, "status": out.status}
    if record:
        res["path_pos"] = out.path_pos
        res["path_dir"] = out.path_dir
    return res
