"""Surface normals from depth images (Chaudhari 2008, §3.5).

Each rule (``imagespace.normals``) is one function; :func:`normal_at`
dispatches on the rule's code. Each reads one layered depth image ``d``
(view-space depth per pixel, ``+inf`` where the layer is absent) and returns
a unit normal in view space (x right, y up, z towards the viewer).
Orientation is not meaningful: the optics flip a normal to face the incident
ray.

``forward`` (eq. 3.1, :func:`normal_forward`)
    ``g_x = [1, 0, d(i+1, j) - d(i, j)]``, ``g_y = [0, 1, d(i, j+1) - d(i, j)]``,
    ``n = g_x x g_y``: one pixel is taken as one unit of depth, the crude
    estimate the thesis starts from.
``central`` (eq. 3.2, :func:`normal_central`)
    Perspective-corrected central differences with step ``delta``: each
    neighbour is unprojected to its view-space point ``p`` with its own
    depth, and ``grad_x d = (d(i+delta) - d(i-delta)) / (p(i+delta)_x -
    p(i-delta)_x)`` (likewise in y).
``cross`` (beyond the thesis, :func:`normal_cross`)
    The same four reads as ``central``, but the normal is the cross
    product of the full 3D differences ``p(i+delta) - p(i-delta)`` and
    ``p(j+delta) - p(j-delta)``: eq. 3.2 neglects that, in perspective, a
    step along a pixel row also moves the point in y (and vice versa),
    which is what limits its accuracy away from the image centre.
``mesh3x3`` (Fig. 3.4, right, :func:`normal_mesh3x3`)
    The normal of the little mesh formed by the 3x3 neighbourhood's
    view-space points: the sum of the 8 triangle normals around the centre
    (9 texture reads instead of 4).

Where a neighbour is absent (silhouette of the layer) the difference
becomes one-sided; where both are, that gradient component is taken as 0.

Sampling between texel centres (``imagespace.filter``, the thesis's hardware
filtering of §3.4.2): :func:`sample_depth` reads a layer's depth at any
screen position, bilinearly over the four texels around it when all four
hold the layer, at the nearest texel otherwise; :func:`normal_filtered`
blends those four texels' normals with the same weights.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..camera import unproject_pixel
from .knobs import CODES
from .peel import layer_depth_lut

__all__ = ["NORMAL_METHODS", "ViewGrid", "normal_at", "normal_forward", "normal_central", "normal_mesh3x3",
           "normal_cross", "normal_filtered", "sample_depth",
           "layer_normals", "layer_depth", "no_lut"]

#: the kernels' code of each normal rule (``imagespace.normals``)
NORMAL_METHODS = CODES["normals"]

#: docstring entries the normal rules share (their ``{name}`` placeholders), filled by :func:`_rule_doc`
_RULE_DOC = {
    "texel": """ldi : (L, H, W) ndarray
        Layered depth images, ``+inf`` where absent.
    n : int
        The layer.
    i, j : int64
        Row and column.
    lut : tuple
        On-the-fly peeling inputs (see :func:`layer_depth`).""",
    "step": """delta : int
        Texel step of the differences.""",
    "grid": """grid : ViewGrid
        The view the layers were rendered in.""",
    "normal": """nx, ny, nz : float
        Unit view-space normal; ``(0, 0, 1)`` where the texel lacks the layer.""",
}


def _rule_doc(fn):
    """Fill the shared entries (:data:`_RULE_DOC`) into a normal rule's docstring."""
    for name, text in _RULE_DOC.items():
        fn.__doc__ = fn.__doc__.replace("{" + name + "}", text)
    return fn


@nb.njit(cache=True, inline="always")
def layer_depth(ldi, n, i, j, lut):
    """Depth of layer ``n`` at pixel (i, j); ``+inf`` when absent or off screen.

    ``lut`` is ``(use_lut, bits, zlo, zhi, slices, pop8, sel8)``: with
    ``use_lut`` the depth is found on the fly in the bitmask (§3.4.1), else
    it is read from the peeled LDI array ``ldi`` (§3.4.2).

    Parameters
    ----------
    ldi : (L, H, W) float32 or float64
        Peeled layered depth images, ``+inf`` where absent.
    n : int
        Layer index, 0 the nearest.
    i, j : int
        Pixel row and column (any integers: off screen gives ``+inf``).
    lut : tuple
        ``(use_lut, bits, zlo, zhi, slices, pop8, sel8)``, see above;
        :func:`no_lut` makes one that reads ``ldi``.

    Returns
    -------
    float
        View-space depth of the layer at the pixel.

    References
    ----------
    Chaudhari (2008), §3.4.1 (on the fly) and §3.4.2 (LDI array).
    """
    H = ldi.shape[1]
    W = ldi.shape[2]
    if i < 0 or j < 0 or i >= H or j >= W:
        return np.inf
    if lut[0]:
        return layer_depth_lut(lut[1], i, j, n, lut[2][i, j], lut[3][i, j], lut[4], lut[5], lut[6])
    return ldi[n, i, j]


@nb.njit(cache=True, inline="always")
def _point(ldi, n, i, j, lut, grid):
    """The view-space point of layer ``n`` at texel (i, j)'s centre (unprojected with its own depth)."""
    d = layer_depth(ldi, n, i, j, lut)
    return unproject_pixel(j + 0.5, i + 0.5, d, grid.W, grid.H, grid.sx, grid.sy, grid.ortho)


@nb.njit(cache=True, inline="always")
def _slope(ldi, n, i, j, lut, grid, dc, di, dj, axis):
    """``(d(a) - d(b)) / (p(a) - p(b))[axis]`` of eq. 3.2 between the texels ``a = (i + di, j + dj)`` and
    ``b = (i - di, j - dj)``, each unprojected with its own depth; an absent one is replaced by the centre
    (depth ``dc``), and the slope is 0 where both are or their points coincide."""
    ia, ja, ib, jb = i + di, j + dj, i - di, j - dj
    da = layer_depth(ldi, n, ia, ja, lut)
    db = layer_depth(ldi, n, ib, jb, lut)
    if not math.isfinite(da):
        ia, ja, da = i, j, dc
    if not math.isfinite(db):
        ib, jb, db = i, j, dc
    if ia == ib and ja == jb:
        return 0.0
    qa = unproject_pixel(ja + 0.5, ia + 0.5, da, grid.W, grid.H, grid.sx, grid.sy, grid.ortho)
    qb = unproject_pixel(jb + 0.5, ib + 0.5, db, grid.W, grid.H, grid.sx, grid.sy, grid.ortho)
    pa = qa[0] if axis == 0 else qa[1]
    pb = qb[0] if axis == 0 else qb[1]
    if pa != pb:
        return (da - db) / (pa - pb)
    return 0.0


@nb.njit(cache=True, inline="always")
def _unit(nx, ny, nz):
    """``n / |n|`` as ``n * (1 / sqrt(n . n))``, the order every rule normalises in."""
    s = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    return nx * s, ny * s, nz * s


@nb.njit(cache=True, inline="always")
@_rule_doc
def normal_forward(ldi, n, i, j, lut):
    """Forward differences (eq. 3.1): the unit normal ``g_x x g_y`` of layer ``n`` at texel (i, j).

    ``g_x = [1, 0, d(i, j+1) - d(i, j)]`` and ``g_y = [0, 1, d(i-1, j) - d(i, j)]``
    (the row above is +y): one pixel is taken as one unit of depth. A
    difference to an absent neighbour is 0.

    Parameters
    ----------
    {texel}

    Returns
    -------
    {normal}

    References
    ----------
    Chaudhari 2008, eq. 3.1 (§3.5).
    """
    dc = layer_depth(ldi, n, i, j, lut)
    if not math.isfinite(dc):
        return 0.0, 0.0, 1.0
    dr = layer_depth(ldi, n, i, j + 1, lut)
    du = layer_depth(ldi, n, i - 1, j, lut)  # the row above is +y
    gx = dr - dc if math.isfinite(dr) else 0.0
    gy = du - dc if math.isfinite(du) else 0.0
    return _unit(gx, gy, 1.0)


@nb.njit(cache=True, inline="always")
@_rule_doc
def normal_central(ldi, n, i, j, lut, delta, grid):
    """Perspective-corrected central differences (eq. 3.2): the unit normal of layer ``n`` at texel (i, j).

    Each neighbour ``delta`` texels away is unprojected with its own depth,
    and ``grad_x d = (d(j+delta) - d(j-delta)) / (p(j+delta)_x - p(j-delta)_x)``
    (likewise in y); the surface ``z = -d(x, y)`` has the normal
    ``(grad_x d, grad_y d, 1)``. Where a neighbour is absent the difference
    is one-sided; where both are, that component is 0.

    Parameters
    ----------
    {texel}
    {step}
    grid : ViewGrid
        The view the layers were rendered in (an orthographic one unprojects
        without the perspective scaling, eq. 3.2 otherwise unchanged).

    Returns
    -------
    {normal}

    References
    ----------
    Chaudhari 2008, eq. 3.2 (§3.5).
    """
    dc = layer_depth(ldi, n, i, j, lut)
    if not math.isfinite(dc):
        return 0.0, 0.0, 1.0
    # x between the right and left neighbours, y between the ones above (+y) and below
    gx = _slope(ldi, n, i, j, lut, grid, dc, 0, delta, 0)
    gy = _slope(ldi, n, i, j, lut, grid, dc, -delta, 0, 1)
    # surface z = -d(x, y): normal (dd/dx, dd/dy, 1)
    return _unit(gx, gy, 1.0)


@nb.njit(cache=True, inline="always")
@_rule_doc
def normal_cross(ldi, n, i, j, lut, delta, grid):
    """The cross rule (beyond the thesis): the unit normal of layer ``n`` at texel (i, j).

    The same four reads as eq. 3.2, but the normal is the cross product of
    the full 3D differences ``p(j+delta) - p(j-delta)`` and
    ``p(i-delta) - p(i+delta)`` of the unprojected neighbours: eq. 3.2
    neglects that, in perspective, a step along a pixel row also moves the
    point in y (and vice versa). An absent neighbour is replaced by the
    centre texel.

    Parameters
    ----------
    {texel}
    {step}
    {grid}

    Returns
    -------
    nx, ny, nz : float
        Unit view-space normal; ``(0, 0, 1)`` where the texel lacks the layer
        or the differences are parallel.

    References
    ----------
    Chaudhari 2008, eq. 3.2 (§3.5), its neighbours in 3D.
    """
    if not math.isfinite(layer_depth(ldi, n, i, j, lut)):
        return 0.0, 0.0, 1.0
    jr, jl, iu, idn = j + delta, j - delta, i - delta, i + delta
    if not math.isfinite(layer_depth(ldi, n, i, jr, lut)):
        jr = j
    if not math.isfinite(layer_depth(ldi, n, i, jl, lut)):
        jl = j
    if not math.isfinite(layer_depth(ldi, n, iu, j, lut)):
        iu = i
    if not math.isfinite(layer_depth(ldi, n, idn, j, lut)):
        idn = i
    ax, ay, az = _point(ldi, n, i, jr, lut, grid)
    bx, by, bz = _point(ldi, n, i, jl, lut, grid)
    ux, uy, uz = ax - bx, ay - by, az - bz
    ax, ay, az = _point(ldi, n, iu, j, lut, grid)
    bx, by, bz = _point(ldi, n, idn, j, lut, grid)
    vx, vy, vz = ax - bx, ay - by, az - bz
    nx = uy * vz - uz * vy
    ny = uz * vx - ux * vz
    nz = ux * vy - uy * vx
    if nx == 0.0 and ny == 0.0 and nz == 0.0:
        nz = 1.0
    return _unit(nx, ny, nz)


@nb.njit(cache=True, inline="always")
@_rule_doc
def normal_mesh3x3(ldi, n, i, j, lut, grid):
    """The 3x3 mesh (Fig. 3.4, right): the unit normal of layer ``n`` at texel (i, j).

    The sum of the normals of the 8 triangles the centre's view-space point
    forms with each pair of consecutive ring neighbours (counter-clockwise
    on screen), skipping a triangle with an absent neighbour: 9 texture
    reads instead of 4.

    Parameters
    ----------
    {texel}
    {grid}

    Returns
    -------
    nx, ny, nz : float
        Unit view-space normal; ``(0, 0, 1)`` where the texel lacks the layer
        or no triangle has all its corners.

    References
    ----------
    Chaudhari 2008, Fig. 3.4 (§3.5).
    """
    if not math.isfinite(layer_depth(ldi, n, i, j, lut)):
        return 0.0, 0.0, 1.0
    cx, cy, cz = _point(ldi, n, i, j, lut, grid)
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
        ax, ay, az = _point(ldi, n, ai, aj, lut, grid)
        bx, by, bz = _point(ldi, n, bi, bj, lut, grid)
        ux, uy, uz = ax - cx, ay - cy, az - cz
        vx, vy, vz = bx - cx, by - cy, bz - cz
        nx += uy * vz - uz * vy
        ny += uz * vx - ux * vz
        nz += ux * vy - uy * vx
    if nx == 0.0 and ny == 0.0 and nz == 0.0:
        nz = 1.0
    return _unit(nx, ny, nz)


@nb.njit(cache=True, inline="always")
def normal_at(ldi, n, i, j, lut, normals, delta, grid):
    """Unit view-space normal of layer ``n`` at texel (i, j) by the rule ``normals``.

    Parameters
    ----------
    ldi : (L, H, W) ndarray
        Layered depth images, ``+inf`` where absent.
    n : int
        The layer.
    i, j : int
        Row and column.
    lut : tuple
        On-the-fly peeling inputs (see :func:`layer_depth`).
    normals : int
        The rule, a :data:`NORMAL_METHODS` code: 0 :func:`normal_forward`
        (eq. 3.1), 1 :func:`normal_central` (eq. 3.2), 2
        :func:`normal_mesh3x3` (Fig. 3.4), 3 :func:`normal_cross`.
    delta : int
        Step of the differences (``central``, ``cross``).
    grid : ViewGrid
        The view the layers were rendered in.

    Returns
    -------
    nx, ny, nz : float
        ``(0, 0, 1)`` where the texel lacks the layer.

    References
    ----------
    Chaudhari 2008, §3.5, eqs. 3.1 and 3.2, Fig. 3.4.
    """
    i = np.int64(i)  # a prange index may arrive unsigned; neighbour offsets need signed ints
    j = np.int64(j)
    if normals == 0:
        return normal_forward(ldi, n, i, j, lut)
    if normals == 1:
        return normal_central(ldi, n, i, j, lut, delta, grid)
    if normals == 3:
        return normal_cross(ldi, n, i, j, lut, delta, grid)
    return normal_mesh3x3(ldi, n, i, j, lut, grid)


@nb.njit(cache=True, inline="always")
def _footprint(ldi, n, r, c, lut, filter):
    """The texels a sample at screen position (r, c) reads, and its weights.

    Returns ``(i0, j0, k, fx, fy)``: the texels ``(i0 + a, j0 + b)`` for
    ``a, b < k``; ``k`` 2 (bilinear over the four texels around the position,
    weights ``fx``, ``fy``) when ``filter`` is 1 and all four hold layer ``n``,
    else 1 (the texel under the position); ``k`` 0 when that texel is off
    screen or lacks the layer.
    """
    H = ldi.shape[1]
    W = ldi.shape[2]
    if not (r >= 0.0 and c >= 0.0) or r >= H or c >= W:  # also NaN
        return np.int64(0), np.int64(0), 0, 0.0, 0.0
    i = np.int64(math.floor(r))
    j = np.int64(math.floor(c))
    if not math.isfinite(layer_depth(ldi, n, i, j, lut)):
        return i, j, 0, 0.0, 0.0
    if filter == 0:
        return i, j, 1, 0.0, 0.0
    u = c - 0.5
    v = r - 0.5
    fj = math.floor(u)
    fi = math.floor(v)
    i0 = np.int64(fi)
    j0 = np.int64(fj)
    for a in range(2):
        for b in range(2):
            if not math.isfinite(layer_depth(ldi, n, i0 + a, j0 + b, lut)):
                return i, j, 1, 0.0, 0.0  # nearest where any of the four lacks the layer
    return i0, j0, 2, u - fj, v - fi


@nb.njit(cache=True, inline="always")
def sample_depth(ldi, n, r, c, lut, filter):
    """Depth of layer ``n`` at screen position (row ``r``, column ``c``), pixel units.

    Texel (i, j) covers ``[i, i + 1) x [j, j + 1)``, its centre at
    ``(i + 0.5, j + 0.5)``; ``+inf`` off screen or where the texel under the
    position lacks the layer.

    ``filter`` 0 (nearest): the texel under the position. 1 (bilinear, the
    hardware filtering of §3.4.2): the bilinear interpolation of the four
    texels around the position when all four hold layer ``n``, the nearest
    texel where any of them lacks it (a GPU would blend in the cleared value
    there). It is written as differences (``a + f (b - a)``, rows then the
    column), so four equal depths give that depth exactly, and at a texel
    centre the texel's own depth.

    Parameters
    ----------
    ldi : (L, H, W) float32 or float64
        Peeled layered depth images, ``+inf`` where absent.
    n : int
        Layer index.
    r, c : float
        Screen position, row and column in pixel units.
    lut : tuple
        Depth source of :func:`layer_depth`.
    filter : int
        0 nearest, 1 bilinear (``CODES["filter"]``).

    Returns
    -------
    float64
        View-space depth of the layer at the position.

    References
    ----------
    Chaudhari (2008), §3.4.2 (hardware filtering) and §3.6.
    """
    i0, j0, k, fx, fy = _footprint(ldi, n, r, c, lut, filter)
    if k == 0:
        return np.inf
    out = 0.0
    for a in range(k):
        row = 0.0
        for b in range(k):
            d = np.float64(layer_depth(ldi, n, i0 + a, j0 + b, lut))
            row = d if b == 0 else row + fx * (d - row)
        out = row if a == 0 else out + fy * (row - out)
    return out


class ViewGrid(NamedTuple):
    """The image a set of layers was rendered in: its size, half extents and projection.

    Attributes
    ----------
    W, H : int
        Width and height in pixels.
    sx, sy : float
        Half extents of the image plane at unit distance (perspective) or
        of the window (orthographic), as :meth:`Camera.kernel_args` gives them.
    ortho : bool
        Orthographic projection (a directional light's view).
    """

    W: int
    H: int
    sx: float
    sy: float
    ortho: bool


@nb.njit(cache=True, inline="always")
def normal_filtered(ldi, n, r, c, lut, normals, delta, grid, filter):
    """Unit view-space normal of layer ``n`` at screen position (row ``r``, column ``c``).

    ``filter`` 0: the normal of the texel under the position (:func:`normal_at`
    at its centre). 1 (bilinear): the normals of the four texels around the
    position (each :func:`normal_at`), blended with the bilinear weights of
    :func:`sample_depth` and renormalised; the nearest texel's where any of
    the four lacks the layer. Eq. 3.2's differences are linear in the depths,
    so this is what a shader computing them from filtered depth reads at the
    probe's texture coordinate gets (§3.4.2, §3.6), up to the perspective
    scaling of the denominators; four equal normals give that normal exactly.

    Parameters
    ----------
    ldi : (L, H, W) ndarray
        Layer depths (``+inf`` where absent).
    n : int64
        The layer.
    r, c : float
        Screen position, pixel units (row, column).
    lut : tuple
        On-the-fly peeling inputs (:func:`no_lut` when unused).
    normals : int
        :data:`NORMAL_METHODS` code.
    delta : int
        Texel offset of the differences.
    grid : ViewGrid
        The image the layers were rendered in.
    filter : int
        ``CODES["filter"]`` code (:mod:`~refraction_ref.imagespace.knobs`).

    Returns
    -------
    nx, ny, nz : float
        The unit normal; ``(0, 0, 1)`` where the position lacks the layer.

    References
    ----------
    Chaudhari (2008), §3.4.2 (filtered reads), §3.5 (eq. 3.2), §3.6.
    """
    i0, j0, k, fx, fy = _footprint(ldi, n, r, c, lut, filter)
    if k == 0:
        return 0.0, 0.0, 1.0
    ox = 0.0
    oy = 0.0
    oz = 0.0
    fx0 = 0.0
    fy0 = 0.0
    fz0 = 1.0
    for a in range(k):
        rx = 0.0
        ry = 0.0
        rz = 0.0
        for b in range(k):
            ax, ay, az = normal_at(ldi, n, i0 + a, j0 + b, lut, normals, delta, grid)
            if a == 0 and b == 0:
                fx0, fy0, fz0 = ax, ay, az
            elif ax * fx0 + ay * fy0 + az * fz0 < 0.0:  # one orientation for the blend
                ax, ay, az = -ax, -ay, -az
            if b == 0:
                rx, ry, rz = ax, ay, az
            else:
                rx, ry, rz = rx + fx * (ax - rx), ry + fx * (ay - ry), rz + fx * (az - rz)
        if a == 0:
            ox, oy, oz = rx, ry, rz
        else:
            ox, oy, oz = ox + fy * (rx - ox), oy + fy * (ry - oy), oz + fy * (rz - oz)
    if k == 1:
        return ox, oy, oz
    s = ox * ox + oy * oy + oz * oz
    if not s > 0.0:
        return fx0, fy0, fz0
    s = 1.0 / math.sqrt(s)
    return ox * s, oy * s, oz * s


def no_lut(shape):
    """The ``lut`` argument that makes :func:`layer_depth` read the LDI array.

    Parameters
    ----------
    shape : tuple of int
        Shape of the depth image (unused: the tuple's arrays are placeholders
        of size one).

    Returns
    -------
    tuple
        ``(False, bits, zlo, zhi, 256, pop8, sel8)`` with placeholder arrays of
        the types the kernels expect.

    References
    ----------
    Chaudhari (2008), §3.4.2 (reading the separately peeled LDI array).
    """
    z = np.zeros((1, 1))
    return (False, np.zeros((1, 1, 1), np.uint32), z, z, 256, np.zeros(256, np.int64), np.zeros((256, 8), np.int64))


@nb.njit(cache=True, parallel=True)
def _normals_kernel(ldi, lut, normals, delta, grid, out):
    for i in nb.prange(ldi.shape[1]):
        for j in range(ldi.shape[2]):
            if math.isfinite(ldi[0, i, j]):
                a, b, c = normal_at(ldi, 0, i, j, lut, normals, delta, grid)
                out[i, j, 0] = a
                out[i, j, 1] = b
                out[i, j, 2] = c


def layer_normals(layer, camera, normals="central", delta=2):
    """Normals of one whole depth image, (H, W, 3) view space, NaN where the layer is absent.

    The per-pixel kernel :func:`normal_at` is what the tracer calls at
    each intersection; this array version serves plots and tests.

    Parameters
    ----------
    layer : (H, W) float
        One layered depth image, view-space depth, ``+inf`` where absent.
    camera : Camera
        The view the depth image was rendered from (unprojection of pixels).
    normals : {'forward', 'central', 'mesh3x3', 'cross'}, default 'central'
        The rule (``imagespace.normals``; see the module docstring).
    delta : int, default 2
        Pixel step of the differences (``central`` and ``cross``).

    Returns
    -------
    (H, W, 3) float64
        Unit view-space normals, NaN where the layer is absent.

    Raises
    ------
    ValueError
        For an unknown rule ``normals``.

    References
    ----------
    Chaudhari (2008), §3.5, eqs. 3.1, 3.2 and Fig. 3.4.
    """
    if normals not in NORMAL_METHODS:
        raise ValueError(f"normals: unknown method {normals!r}; choose one of {sorted(NORMAL_METHODS)}")
    layer = np.ascontiguousarray(layer, dtype=np.float64)
    out = np.full(layer.shape + (3,), np.nan)
    W, H, sx, sy = camera.kernel_args()
    grid = ViewGrid(W, H, sx, sy, bool(getattr(camera, "ortho", False)))
    _normals_kernel(layer[None], no_lut(layer.shape), NORMAL_METHODS[normals], int(delta), grid, out)
    return out
