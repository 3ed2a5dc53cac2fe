"""Coverage: which pixel centres a snapped triangle covers, row by row.

Exact integer edge functions on vertices snapped to 1/256 pixel (as GPUs
do) and the top-left tie rule of D3D / Vulkan / WebGPU, so that a pixel
centre on an edge shared by two triangles yields exactly one fragment. The
five public helpers are ``numba.njit(inline="always")`` functions meant to
be called from other njit kernels (the rasterizer's band kernel, the level
map's intersection triangles and beams), into which they are inlined;
changing one does not invalidate the Numba caches of kernels in *other*
files that inline it (Numba keys a cache on the caller's source file only):
clear them with ``find refraction_ref -name '*.nb[ic]' -delete``.

References
----------
.. [1] J. Pineda, "A Parallel Algorithm for Polygon Rasterization",
   SIGGRAPH 1988 (edge functions).
"""

from __future__ import annotations

import numba as nb

__all__ = ["SUBPIXEL", "oriented_triangle", "pixel_span", "edge_setup", "edge_values", "row_span"]

#: fixed-point steps per pixel (8 sub-pixel bits)
SUBPIXEL = 256


@nb.njit(cache=True, inline="always")
def _bias(ax, ay, bx, by):
    # top-left rule (D3D / Vulkan / WebGPU, rows growing downwards): with the
    # triangle oriented clockwise on screen, a left edge points up (dy < 0)
    # and a top edge points right (dy == 0, dx > 0); they own the pixel
    # centres on them, the reverse edges of their neighbours do not.
    dy = by - ay
    dx = bx - ax
    if dy < 0 or (dy == 0 and dx > 0):
        return 0
    return -1


@nb.njit(cache=True, inline="always")
def oriented_triangle(X, Y, A, t):
    """Snapped triangle ``t`` with its attribute ``A``, re-oriented to a positive area.

    No culling: a triangle given the other way round has vertices 1 and 2
    swapped (with their attributes), so that :func:`edge_setup` and
    :func:`edge_values`, which assume a positive area (clockwise on screen,
    rows growing downwards), apply to either orientation.

    Parameters
    ----------
    X, Y : (T, 3) int64 ndarray
        Vertex columns and rows in 1/256-pixel fixed point.
    A : (T, 3) float64 ndarray
        A per-vertex attribute (depth, 1/depth, path length, ...).
    t : int
        Triangle index.

    Returns
    -------
    tuple
        ``(x0, y0, x1, y1, x2, y2, a0, a1, a2, area, flipped)``: ``area`` is
        twice the screen area in fixed point (exact integer, >= 0; 0 for a
        degenerate triangle, which covers nothing), ``flipped`` whether
        vertices 1 and 2 were swapped.
    """
    x0 = X[t, 0]
    y0 = Y[t, 0]
    x1 = X[t, 1]
    y1 = Y[t, 1]
    x2 = X[t, 2]
    y2 = Y[t, 2]
    a0 = A[t, 0]
    a1 = A[t, 1]
    a2 = A[t, 2]
    area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
    if area < 0:
        return x0, y0, x2, y2, x1, y1, a0, a2, a1, -area, True
    return x0, y0, x1, y1, x2, y2, a0, a1, a2, area, False


@nb.njit(cache=True, inline="always")
def pixel_span(lo, hi, first, last):
    """Pixels whose centre ``256 k + 128`` lies in [lo, hi] (1/256-pixel fixed point), clamped to [first, last].

    Integer floor divisions only, so a bounding box computed from snapped
    vertices never misses a pixel centre that the edge functions cover.

    Parameters
    ----------
    lo, hi : int
        Fixed-point extent of a triangle along one axis (min and max of its
        snapped vertex coordinates).
    first, last : int
        Clamp range (the image, or a scissor rectangle).

    Returns
    -------
    k0, k1 : int
        First and last pixel index; ``k0 > k1`` when no centre lies in the
        range.
    """
    return max(-((128 - lo) // 256), first), min((hi - 128) // 256, last)


@nb.njit(cache=True, inline="always")
def edge_setup(x0, y0, x1, y1, x2, y2):
    """Column steps and top-left biases of a triangle's three edges (positive area, rows down).

    Edge ``k`` is the edge opposite vertex ``k``. The bias implements the
    top-left fill rule of D3D / Vulkan / WebGPU: a pixel centre lying
    exactly on an edge belongs to the triangle only if that edge is a left
    or a top edge. An edge shared by two triangles is a left/top edge of
    exactly one of them, so with the exact integer edge functions a centre
    on a shared edge (or vertex) yields exactly one fragment: closed meshes
    give an even fragment count per pixel, and meshes tiling a plane
    (neighbouring beams' cross-sections) cover each texel once.

    Parameters
    ----------
    x0, y0, x1, y1, x2, y2 : int
        Snapped vertices in 1/256-pixel fixed point, oriented to a positive
        area (:func:`oriented_triangle`).

    Returns
    -------
    a0, a1, a2 : int
        Column steps: edge function ``k`` decreases by ``256 a_k`` from one
        pixel centre to the next in a row.
    b0, b1, b2 : int
        Biases (0 or -1): the centre is covered when every
        ``w_k + b_k >= 0``, ``w_k`` from :func:`edge_values`.
    """
    return (y2 - y1, y0 - y2, y1 - y0,
            _bias(x1, y1, x2, y2), _bias(x2, y2, x0, y0), _bias(x0, y0, x1, y1))


@nb.njit(cache=True, inline="always")
def edge_values(x0, y0, x1, y1, x2, y2, px, py):
    """The three edge functions at the sample ``(px, py)``.

    Exact integer arithmetic on fixed-point coordinates (no round-off, so
    two triangles sharing an edge evaluate it to exactly opposite values);
    pixel centre ``(i, j)`` is the sample ``(256 j + 128, 256 i + 128)``.

    Parameters
    ----------
    x0, y0, x1, y1, x2, y2 : int
        Snapped vertices in 1/256-pixel fixed point, positive area
        (:func:`oriented_triangle`).
    px, py : int
        Sample position in the same fixed point.

    Returns
    -------
    w0, w1, w2 : int
        Twice the signed areas of the sub-triangles opposite each vertex,
        so also the sample's unnormalised barycentric weights (they sum to
        the triangle's ``area``); the sample is covered when every
        ``w_k + b_k >= 0`` (biases from :func:`edge_setup`).
    """
    return ((x2 - x1) * (py - y1) - (y2 - y1) * (px - x1),
            (x0 - x2) * (py - y2) - (y0 - y2) * (px - x2),
            (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0))


@nb.njit(cache=True, inline="always")
def _edge_cut(s, q, lo, hi):
    """Narrow [lo, hi] (offsets from the row's first column) to the ``k`` with ``s - q k >= 0``."""
    if q > 0:
        hi = min(hi, s // q)  # floor division: the largest k with q k <= s
    elif q < 0:
        lo = max(lo, -((-s) // q))  # the smallest k with q k <= s, q negative (a ceiling)
    elif s < 0:
        hi = lo - 1  # an edge parallel to the rows, the row outside it
    return lo, hi


@nb.njit(cache=True, inline="always")
def row_span(v, e, i, j0, j1):
    """The covered pixel centres of row ``i`` between columns ``j0`` and ``j1``: the scanline step.

    The one scanline kernel of every triangle drawn with the rasterizer's
    coverage rule (the band kernel of :mod:`.blend`, the intersection triangles of
    :mod:`~refraction_ref.levelmap.caustics_map`). A triangle meets a row in
    one run of pixels; its ends are solved exactly from the integer edge
    functions (``w_k - 256 a_k (j - j0) + b_k >= 0`` for the three edges), so
    the run holds the very pixels a test of every centre from ``j0`` to
    ``j1`` would keep, and the edge values returned are the same integers as
    those stepped there (no floating point involved: a caller interpolating
    its attributes from them gets the same bits).

    Walk the run as::

        ja, jb, w0, w1, w2 = row_span(v, e, i, j0, j1)
        for j in range(ja, jb + 1):
            if j > ja:
                w0 -= 256 * a0; w1 -= 256 * a1; w2 -= 256 * a2
            ...  # every (i, j) here is covered

    Parameters
    ----------
    v : tuple of 6 int
        ``(x0, y0, x1, y1, x2, y2)``, snapped vertices in 1/256-pixel fixed
        point with a positive area (:func:`oriented_triangle`).
    e : tuple of 6 int
        ``(a0, a1, a2, b0, b1, b2)`` from :func:`edge_setup`.
    i : int
        Row.
    j0, j1 : int
        Columns to consider (:func:`pixel_span` of the triangle, clamped to
        the image or a scissor rectangle).

    Returns
    -------
    ja, jb : int
        First and last covered column; ``ja > jb`` when the row has none.
    w0, w1, w2 : int
        The edge functions (:func:`edge_values`) at the centre of ``(i, ja)``.

    References
    ----------
    J. Pineda, "A Parallel Algorithm for Polygon Rasterization", SIGGRAPH
    1988 (incremental edge functions); the top-left rule of D3D / Vulkan.
    """
    x0, y0, x1, y1, x2, y2 = v
    a0, a1, a2, b0, b1, b2 = e
    w0, w1, w2 = edge_values(x0, y0, x1, y1, x2, y2, 256 * j0 + 128, 256 * i + 128)
    lo = 0
    hi = j1 - j0
    lo, hi = _edge_cut(w0 + b0, 256 * a0, lo, hi)
    lo, hi = _edge_cut(w1 + b1, 256 * a1, lo, hi)
    lo, hi = _edge_cut(w2 + b2, 256 * a2, lo, hi)
    return j0 + lo, j0 + hi, w0 - 256 * a0 * lo, w1 - 256 * a1 * lo, w2 - 256 * a2 * lo

