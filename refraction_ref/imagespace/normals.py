"""Surface normals from depth images (Chaudhari 2008, §3.5).

All three estimators read one layered depth image ``d`` (view-space depth
per pixel, ``+inf`` where the layer is absent) and return a unit normal in
view space (x right, y up, z towards the viewer). Orientation is not
meaningful: the optics flip a normal to face the incident ray.

``forward`` (eq. 3.1)
    ``g_x = [1, 0, d(i+1, j) - d(i, j)]``, ``g_y = [0, 1, d(i, j+1) - d(i, j)]``,
    ``n = g_x x g_y``: one pixel is taken as one unit of depth, the crude
    estimate the thesis starts from.
``central`` (eq. 3.2)
    Perspective-corrected central differences with step ``delta``: each
    neighbour is unprojected to its view-space point ``p`` with its own
    depth, and ``grad_x d = (d(i+delta) - d(i-delta)) / (p(i+delta)_x -
    p(i-delta)_x)`` (likewise in y).
``cross`` (beyond the thesis)
    The same four reads as ``central``, but the normal is the cross
    product of the full 3D differences ``p(i+delta) - p(i-delta)`` and
    ``p(j+delta) - p(j-delta)``: eq. 3.2 neglects that, in perspective, a
    step along a pixel row also moves the point in y (and vice versa),
    which is what limits its accuracy away from the image centre.
``mesh3x3`` (Fig. 3.4, right)
    The normal of the little mesh formed by the 3x3 neighbourhood's
    view-space points: the sum of the 8 triangle normals around the centre
    (9 texture reads instead of 4).

Where a neighbour is absent (silhouette of the layer) the difference
becomes one-sided; where both are, that gradient component is taken as 0.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..camera import unproject_pixel
from .peel import layer_depth_lut

__all__ = ["NORMAL_METHODS", "normal_at", "layer_normals", "layer_depth", "no_lut"]

NORMAL_METHODS = {"forward": 0, "central": 1, "mesh3x3": 2, "cross": 3}


@nb.njit(cache=True, inline="always")
def layer_depth(ldi, n, i, j, lut):
    """Depth of layer ``n`` at pixel (i, j); ``+inf`` when absent or off screen.

    ``lut`` is ``(use_lut, bits, zlo, zhi, slices, pop8, sel8)``: with
    ``use_lut`` the depth is found on the fly in the bitmask (§3.4.1), else
    it is read from the peeled LDI array ``ldi`` (§3.4.2).
    """
    H = ldi.shape[1]
    W = ldi.shape[2]
    if i < 0 or j < 0 or i >= H or j >= W:
        return np.inf
    if lut[0]:
        return layer_depth_lut(lut[1], i, j, n, lut[2][i, j], lut[3][i, j], lut[4], lut[5], lut[6])
    return ldi[n, i, j]


@nb.njit(cache=True, inline="always")
def _point(ldi, n, i, j, lut, W, H, sx, sy, ortho=False):
    d = layer_depth(ldi, n, i, j, lut)
    return unproject_pixel(j + 0.5, i + 0.5, d, W, H, sx, sy, ortho)


@nb.njit(cache=True, inline="always")
def normal_at(ldi, n, i, j, lut, method, delta, W, H, sx, sy, ortho=False):
    """Unit view-space normal of depth image ``layer`` at pixel (i, j).

    Parameters
    ----------
    ldi : (L, H, W) float64
        Layered depth images.
    n : int
        The layer.
    i, j : int
        Row and column.
    lut : tuple
        On-the-fly peeling inputs (see :func:`layer_depth`).
    method : int
        0 forward (eq. 3.1), 1 central perspective-corrected (eq. 3.2),
        2 3x3 mesh (Fig. 3.4), 3 cross product of central differences.
    delta : int
        Step of the central differences.
    W, H, sx, sy :
        Camera scalars (:meth:`Camera.kernel_args`).
    ortho : bool
        Orthographic view (a directional light's): neighbours unproject
        without the perspective scaling, eq. 3.2 otherwise unchanged.

    Returns
    -------
    nx, ny, nz : float

    References
    ----------
    Chaudhari (2008), §3.5, eqs. 3.1 and 3.2, Fig. 3.4.
    """
    i = np.int64(i)  # a prange index may arrive unsigned; neighbour offsets need signed ints
    j = np.int64(j)
    dc = layer_depth(ldi, n, i, j, lut)
    if not math.isfinite(dc):
        return 0.0, 0.0, 1.0
    if method == 0:
        dr = layer_depth(ldi, n, i, j + 1, lut)
        du = layer_depth(ldi, n, i - 1, j, lut)  # the row above is +y
        gx = dr - dc if math.isfinite(dr) else 0.0
        gy = du - dc if math.isfinite(du) else 0.0
        nx, ny, nz = gx, gy, 1.0
    elif method == 1:
        # horizontal: x of the unprojected neighbours
        jr, jl = j + delta, j - delta
        dr = layer_depth(ldi, n, i, jr, lut)
        dl = layer_depth(ldi, n, i, jl, lut)
        if not math.isfinite(dr):
            jr, dr = j, dc
        if not math.isfinite(dl):
            jl, dl = j, dc
        gx = 0.0
        if jr != jl:
            xr = unproject_pixel(jr + 0.5, i + 0.5, dr, W, H, sx, sy, ortho)[0]
            xl = unproject_pixel(jl + 0.5, i + 0.5, dl, W, H, sx, sy, ortho)[0]
            if xr != xl:
                gx = (dr - dl) / (xr - xl)
        iu, idn = i - delta, i + delta
        du = layer_depth(ldi, n, iu, j, lut)
        dd = layer_depth(ldi, n, idn, j, lut)
        if not math.isfinite(du):
            iu, du = i, dc
        if not math.isfinite(dd):
            idn, dd = i, dc
        gy = 0.0
        if iu != idn:
            yu = unproject_pixel(j + 0.5, iu + 0.5, du, W, H, sx, sy, ortho)[1]
            yd = unproject_pixel(j + 0.5, idn + 0.5, dd, W, H, sx, sy, ortho)[1]
            if yu != yd:
                gy = (du - dd) / (yu - yd)
        # surface z = -d(x, y): normal (dd/dx, dd/dy, 1)
        nx, ny, nz = gx, gy, 1.0
    elif method == 3:
        jr, jl, iu, idn = j + delta, j - delta, i - delta, i + delta
        if not math.isfinite(layer_depth(ldi, n, i, jr, lut)):
            jr = j
        if not math.isfinite(layer_depth(ldi, n, i, jl, lut)):
            jl = j
        if not math.isfinite(layer_depth(ldi, n, iu, j, lut)):
            iu = i
        if not math.isfinite(layer_depth(ldi, n, idn, j, lut)):
            idn = i
        ax, ay, az = _point(ldi, n, i, jr, lut, W, H, sx, sy, ortho)
        bx, by, bz = _point(ldi, n, i, jl, lut, W, H, sx, sy, ortho)
        ux, uy, uz = ax - bx, ay - by, az - bz
        ax, ay, az = _point(ldi, n, iu, j, lut, W, H, sx, sy, ortho)
        bx, by, bz = _point(ldi, n, idn, j, lut, W, H, sx, sy, ortho)
        vx, vy, vz = ax - bx, ay - by, az - bz
        nx = uy * vz - uz * vy
        ny = uz * vx - ux * vz
        nz = ux * vy - uy * vx
        if nx == 0.0 and ny == 0.0 and nz == 0.0:
            nz = 1.0
    else:
        cx, cy, cz = _point(ldi, n, i, j, lut, W, H, sx, sy, ortho)
        nx = 0.0
        ny = 0.0
        nz = 0.0
        # ring of the 8 neighbours, counter-clockwise on screen
        ri = (0, -1, -1, -1, 0, 1, 1, 1)
        rj = (1, 1, 0, -1, -1, -1, 0, 1)
        for k in range(8):
            ai, aj = i + ri[k], j + rj[k]
            bi, bj = i + ri[(k + 1) % 8], j + rj[(k + 1) % 8]
            if not (math.isfinite(layer_depth(ldi, n, ai, aj, lut)) and math.isfinite(layer_depth(ldi, n, bi, bj, lut))):
                continue
            ax, ay, az = _point(ldi, n, ai, aj, lut, W, H, sx, sy, ortho)
            bx, by, bz = _point(ldi, n, bi, bj, lut, W, H, sx, sy, ortho)
            ux, uy, uz = ax - cx, ay - cy, az - cz
            vx, vy, vz = bx - cx, by - cy, bz - cz
            nx += uy * vz - uz * vy
            ny += uz * vx - ux * vz
            nz += ux * vy - uy * vx
        if nx == 0.0 and ny == 0.0 and nz == 0.0:
            nz = 1.0
    s = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    return nx * s, ny * s, nz * s


def no_lut(shape):
    """The ``lut`` argument that makes :func:`layer_depth` read the LDI array."""
    z = np.zeros((1, 1))
    return (False, np.zeros((1, 1, 1), np.uint32), z, z, 256, np.zeros(256, np.int64), np.zeros((256, 8), np.int64))


@nb.njit(cache=True, parallel=True)
def _normals_kernel(ldi, lut, method, delta, W, H, sx, sy, out, ortho=False):
    for i in nb.prange(ldi.shape[1]):
        for j in range(ldi.shape[2]):
            if math.isfinite(ldi[0, i, j]):
                a, b, c = normal_at(ldi, 0, i, j, lut, method, delta, W, H, sx, sy, ortho)
                out[i, j, 0] = a
                out[i, j, 1] = b
                out[i, j, 2] = c


def layer_normals(layer, camera, method="central", delta=1):
    """Normals of one whole depth image, (H, W, 3) view space, NaN where the layer is absent.

    The per-pixel kernel :func:`normal_at` is what the tracer calls at
    each intersection; this array version serves plots and tests.
    """
    if method not in NORMAL_METHODS:
        raise ValueError(f"normals: unknown method {method!r}; choose one of {sorted(NORMAL_METHODS)}")
    layer = np.ascontiguousarray(layer, dtype=np.float64)
    out = np.full(layer.shape + (3,), np.nan)
    W, H, sx, sy = camera.kernel_args()
    _normals_kernel(layer[None], no_lut(layer.shape), NORMAL_METHODS[method], int(delta), W, H, sx, sy, out,
                    bool(getattr(camera, "ortho", False)))
    return out
