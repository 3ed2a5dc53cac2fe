"""The one triangle rasterizer shared by every method.

A CPU stand-in for the GPU's raster stage with its blend units: no culling,
no hidden-surface removal, one fragment per covered pixel centre, the
perspective-correct view-space depth of that fragment, and a per-pixel blend
operation. Every blend mode the three papers use is one call:

========== ============================================================
``op``     per-pixel result
========== ============================================================
``min``    smallest fragment depth (``+inf`` where nothing is drawn)
``minmax`` both in one pass, as the thesis's R/G max-blend trick does
``nearest`` the nearest depth and the index of its triangle (a visibility
           buffer; used by the orthographic maps of the level-map method)
``max``    largest fragment depth (``-inf`` where nothing is drawn)
``count``  number of fragments (the depth complexity)
``or``     bitmask occupancy: slice bit set with logical OR
``add``    bitmask occupancy with *additive* blending (a 32-bit add per
           word, so two fragments in one slice carry into the next bit,
           exactly as on a GPU without logical-OR blending)
``collect`` the ``capacity`` nearest fragment depths, sorted, plus the
           total count (an A-buffer / k-buffer of exact float depths)
========== ============================================================

Coverage is decided with exact integer edge functions on vertices snapped
to 1/256 pixel (as GPUs do) and a top-left tie rule, so a pixel centre on an
edge shared by two triangles yields exactly one fragment: closed meshes
give an even fragment count per pixel, and additive blending never sees a
spurious duplicate. Triangles crossing the near plane are clipped; zero-area
triangles produce no fragments. The image is split into bands of rows and
each band is rasterized by one thread, triangles in index order, so every
result is bit-identical whatever the thread count.

Public toolkit
--------------
Kernels elsewhere that draw their own triangles or splat their own points
(with a blend the ops above do not cover) reuse the rasterizer's pieces, so
that they inherit its coverage rule and its determinism:

========================== ==========================================================
name                       used by
========================== ==========================================================
:data:`SUBPIXEL`           the 1/256-pixel fixed point the helpers below assume
:data:`BAND`               :mod:`~refraction_ref.caustics.splat`,
                           :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray` (rows per band)
:data:`MAX_COORD`          :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray` (guard band)
:func:`bin_bands`          :mod:`~refraction_ref.caustics.splat` (photons),
                           :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray` (beams)
:func:`oriented_triangle`  :mod:`~refraction_ref.levelmap.caustics_map`
:func:`pixel_span`         :mod:`~refraction_ref.levelmap.caustics_map`
:func:`edge_setup`         :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray`
:func:`edge_values`        :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray`
:func:`row_span`           :mod:`~refraction_ref.levelmap.caustics_map` (the scanline
                           step: the covered run of a row, as :func:`_raster_band` walks it)
========================== ==========================================================

:func:`bin_bands` is a parallel kernel called from Python. The five drawing
helpers are ``numba.njit(inline="always")`` functions meant to be called
from other njit kernels, into which they are inlined; changing one does not
invalidate the Numba caches of kernels in *other* files that inline it
(Numba keys a cache on the caller's source file only): clear them with
``find refraction_ref -name '*.nb[ic]' -delete``.

References
----------
.. [1] J. Pineda, "A Parallel Algorithm for Polygon Rasterization",
   SIGGRAPH 1988 (edge functions).
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.3 (min/max pass with max blending,
   bitmask voxelization with additive blending).
.. [3] E. Eisemann, X. Décoret, "Fast Scene Voxelization and Applications",
   I3D 2006 (slicing by bitwise blending).
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .schedule import coprime_stride, strided

__all__ = ["rasterize", "raster_setup", "RasterSetup", "Fragments", "clip_near", "OPS", "ortho_setup",
           "rasterize_ortho", "ortho_fragments",
           # public toolkit (see the module docstring)
           "SUBPIXEL", "BAND", "MAX_COORD", "bin_bands", "oriented_triangle", "pixel_span", "edge_setup", "row_span",
           "edge_values"]

OPS = {"min": 0, "max": 1, "count": 2, "or": 3, "add": 4, "collect": 5, "minmax": 6, "nearest": 7}

#: fixed-point steps per pixel (8 sub-pixel bits)
SUBPIXEL = 256
#: rows per band: the unit of parallel work, and the ``band`` of :func:`bin_bands`
BAND = 8
#: guard band in pixels: a vertex with ``|col|`` or ``|row|`` beyond it drops its
#: triangle (keeps the fixed-point edge functions far from int64 overflow)
MAX_COORD = float(1 << 22)
_NO_SLAB = np.zeros(4)


@nb.njit(cache=True)
def _clip_near_kernel(tv, near, out):
    """Clip view-space triangles (T, 3, 3) against depth >= near."""
    m = 0
    for t in range(tv.shape[0]):
        inside = 0
        for k in range(3):
            if -tv[t, k, 2] >= near:
                inside += 1
        if inside == 3:
            out[m] = tv[t]
            m += 1
            continue
        if inside == 0:
            continue
        # Sutherland-Hodgman on the plane z = -near, polygon of at most 4 vertices
        poly = np.empty((4, 3))
        n = 0
        for k in range(3):
            a = tv[t, k]
            b = tv[t, (k + 1) % 3]
            da = -a[2] - near
            db = -b[2] - near
            if da >= 0.0:
                poly[n] = a
                n += 1
            if (da >= 0.0) != (db >= 0.0):
                s = da / (da - db)
                poly[n] = a + s * (b - a)
                poly[n, 2] = -near
                n += 1
        for k in range(1, n - 1):
            out[m, 0] = poly[0]
            out[m, 1] = poly[k]
            out[m, 2] = poly[k + 1]
            m += 1
    return m


def clip_near(tri_view, near):
    """Clip view-space triangles against the near plane.

    Parameters
    ----------
    tri_view : (T, 3, 3) ndarray
        Triangle vertices in view space.
    near : float
        Near clip depth (> 0).

    Returns
    -------
    (T', 3, 3) ndarray
        Triangles entirely at depth >= near (a crossing triangle becomes one
        or two triangles, one entirely behind is dropped).
    """
    tv = np.ascontiguousarray(tri_view, dtype=np.float64)
    if tv.size == 0 or -tv[..., 2].max() >= near:  # nothing crosses the near plane
        return tv
    out = np.empty((2 * tv.shape[0], 3, 3))
    m = _clip_near_kernel(tv, float(near), out)
    return out[:m]


@nb.njit(cache=True, parallel=True)
def _snap_vertices(vv, W, H, sx, sy, XV, YV, DV, okv, ortho=False):
    """Project view-space vertices to 1/256-pixel fixed point; flag those outside the guard band.

    ``ortho``: orthographic projection (no division by the depth).
    """
    for k in nb.prange(vv.shape[0]):
        d = -vv[k, 2]
        s = 1.0 if ortho else d
        col = (vv[k, 0] / (s * sx) * 0.5 + 0.5) * W
        row = (0.5 - vv[k, 1] / (s * sy) * 0.5) * H
        okv[k] = abs(col) < MAX_COORD and abs(row) < MAX_COORD and d > 0.0
        if okv[k]:
            XV[k] = np.int64(np.round(col * 256.0))
            YV[k] = np.int64(np.round(row * 256.0))
        else:
            XV[k] = 0
            YV[k] = 0
        if ortho:
            DV[k] = d  # orthographic: the depth itself varies linearly on screen
        else:
            DV[k] = 1.0 / d if d > 0.0 else 0.0  # 1/d is what varies linearly on screen


@nb.njit(cache=True, parallel=True)
def _gather(faces, XV, YV, DV, okv, W, H, X, Y, D, rows):
    """Gather snapped triangles; rows[t] = the pixel rows they may cover, (1, 0) when none."""
    for t in nb.prange(faces.shape[0]):
        ok = True
        for k in range(3):
            v = faces[t, k]
            ok = ok and okv[v]
            X[t, k] = XV[v]
            Y[t, k] = YV[v]
            D[t, k] = DV[v]
        lo = min(Y[t, 0], min(Y[t, 1], Y[t, 2]))
        hi = max(Y[t, 0], max(Y[t, 1], Y[t, 2]))
        xlo = min(X[t, 0], min(X[t, 1], X[t, 2]))
        xhi = max(X[t, 0], max(X[t, 1], X[t, 2]))
        # pixel rows / columns whose centre (256 i + 128) lies in [lo, hi]
        i0, i1 = pixel_span(lo, hi, 0, H - 1)
        j0, j1 = pixel_span(xlo, xhi, 0, W - 1)
        if not ok or j0 > j1:
            i0, i1 = 1, 0  # outside the guard band, or no pixel centre in its box
        rows[t, 0] = i0
        rows[t, 1] = i1


@nb.njit(cache=True, parallel=True)
def bin_bands(rows, H, band):
    """Bin items (triangles, photons, beams) into bands of rows: one list per band.

    A parallel counting sort over a fixed number of chunks of items, so the
    lists come out in item index order whatever the thread count. A kernel
    that then gives each band to one thread, and walks its list in order,
    accumulates in the same order on every run: bit-identical results.

    Parameters
    ----------
    rows : (T, 2) int64 ndarray
        First and last row ``(i0, i1)`` that item ``t`` may touch, already
        clamped to ``[0, H - 1]``; ``i0 > i1`` (e.g. ``(1, 0)``) marks an
        item that touches nothing and is listed nowhere.
    H : int
        Number of rows of the target image.
    band : int
        Rows per band, a power of two (a row's band is then a shift, not an
        integer division, which would dominate this loop); usually
        :data:`BAND`.

    Returns
    -------
    counts : (nbands + 1,) int64 ndarray
        CSR offsets, ``nbands = ceil(H / band)``: band ``b``'s items are
        ``tris[counts[b]:counts[b + 1]]``.
    tris : (N,) int64 ndarray
        Item indices, increasing within each band; an item spanning several
        bands is listed in each of them.

    Raises
    ------
    ValueError
        When ``band`` is not a power of two.
    """
    sh = 0
    while (1 << sh) < band:
        sh += 1
    if (1 << sh) != band:
        raise ValueError("bin_bands: band must be a power of two")
    T = rows.shape[0]
    nb_bands = (H + band - 1) >> sh
    C = max(1, min(64, T // 4096))
    cnt = np.zeros((C, nb_bands), np.int64)
    for c in nb.prange(C):
        for t in range(c * T // C, (c + 1) * T // C):
            i0 = rows[t, 0]
            i1 = rows[t, 1]
            if i0 <= i1:  # then 0 <= i0 <= i1
                for b in range(i0 >> sh, (i1 >> sh) + 1):
                    cnt[c, b] += 1
    # band b's list: chunk 0's triangles, then chunk 1's, ... (each in index order)
    counts = np.zeros(nb_bands + 1, np.int64)
    start = np.empty((C, nb_bands), np.int64)
    pos = 0
    for b in range(nb_bands):
        counts[b] = pos
        for c in range(C):
            start[c, b] = pos
            pos += cnt[c, b]
    counts[nb_bands] = pos
    tris = np.empty(pos, np.int64)
    for c in nb.prange(C):
        for t in range(c * T // C, (c + 1) * T // C):
            i0 = rows[t, 0]
            i1 = rows[t, 1]
            if i0 <= i1:
                for b in range(i0 >> sh, (i1 >> sh) + 1):
                    tris[start[c, b]] = t
                    start[c, b] += 1
    return counts, tris


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
    coverage rule (:func:`_raster_band`, the intersection triangles of
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


@nb.njit(cache=True, inline="always")
def _set_slice_bit(bits, i, j, d, lo, hi, slices, add):
    """Set the bit of slice ``round((d - lo) / (hi - lo) * (S - 1))`` in pixel (i, j)'s mask.

    Logical OR, or (``add``) a 32-bit add whose carry moves two fragments of
    one slice into the next bit and is lost past bit 31 (Chaudhari §3.3).
    """
    rng = hi - lo
    s = 0
    if rng > 0.0:
        s = np.int64(np.floor((d - lo) / rng * (slices - 1) + 0.5))
        if s < 0:
            s = 0
        elif s > slices - 1:
            s = slices - 1
    w = s >> 5
    m = np.uint32(1) << np.uint32(s & 31)
    if add:
        bits[i, j, w] = np.uint32((np.uint64(bits[i, j, w]) + np.uint64(m)) & np.uint64(0xFFFFFFFF))
    else:
        bits[i, j, w] = bits[i, j, w] | m


class _Tris(NamedTuple):
    """Snapped triangles binned into bands of rows (the kernel half of a :class:`RasterSetup`)."""

    X: np.ndarray  # (T, 3) int64 vertex columns, 1/256-pixel fixed point
    Y: np.ndarray  # (T, 3) int64 vertex rows
    D: np.ndarray  # (T, 3) float64 attribute: 1/depth (perspective) or depth (orthographic)
    rows: np.ndarray  # (T, 2) int64 rows each triangle may cover
    counts: np.ndarray  # (nbands + 1,) CSR offsets of the band lists (bin_bands)
    tris: np.ndarray  # triangle indices, band by band


class _Grid(NamedTuple):
    """The image rasterized into: size, rows per band, how depth interpolates."""

    W: int
    H: int
    band: int
    perspective: bool  # 1/depth linear on screen; depth itself when False (orthographic)


class _Blend(NamedTuple):
    """Settings of the blend operations (the op itself is an argument of its own, see :func:`_raster_band`)."""

    zlo: np.ndarray  # (H, W) slice range of ops 'or' / 'add' ((1, 1) unused)
    zhi: np.ndarray
    slices: int
    slab: np.ndarray  # (4,) (z0, s, klo, khi) of op 'nearest'; s <= 0: no restriction


class _Targets(NamedTuple):
    """The per-pixel buffers blended into ((1, 1[, 1]) placeholders for those an op does not use)."""

    fbuf: np.ndarray  # (H, W) float64: 'min', 'max', 'nearest'
    ibuf: np.ndarray  # (H, W) int32: 'count', 'collect'
    bits: np.ndarray  # (H, W, S // 32) uint32: 'or', 'add'
    layers: np.ndarray  # (2, H, W) 'minmax' / (capacity, H, W) 'collect' float64
    ids: np.ndarray  # (H, W) int64: 'nearest'


class _Record(NamedTuple):
    """Fragment record of op 'minmax' (:class:`Fragments`); length-1 arrays: none kept."""

    off: np.ndarray  # (nbands + 1,) first slot of each band
    pix: np.ndarray  # int32 pixel index i * W + j
    depth: np.ndarray  # float64
    n: np.ndarray  # (nbands,) fragments written per band
    facing: np.ndarray  # int8 -1 / +1


@nb.njit(cache=True)
def _raster_band(b, op, tri, grid, blend, out, rec):
    """Rasterize the binned triangles of band ``b`` with blend ``op`` (see ``OPS``).

    Depth is interpolated perspective-correctly (1/d linear on screen) when
    ``grid.perspective``, linearly otherwise (orthographic maps). ``slab`` =
    (z0, s, klo, khi) restricts op 'nearest' to fragments whose slab index
    ``floor((d - z0) / s)`` lies in [klo, khi] (no restriction when s <= 0).
    With op 'minmax' and ``rec.pix`` longer than 1, every fragment is also
    recorded, band by band from ``rec.off[b]`` (``rec.n[b]`` of them), for
    passes that blend the same fragments again; ``rec.facing`` gets the
    triangle's screen orientation (-1 as given, +1 when it was flipped).

    Not inlined into the kernels' ``prange`` loops: there Numba drops
    stores into arrays taken from a named tuple (numba#7135; the writes to
    ``rec.n`` went missing), here the tuples are ordinary arguments. A
    constant ``op`` (:func:`_minmax_kernel`) gets a specialisation of its
    own (``op`` typed as that literal), whose other blend branches Numba
    prunes, as inlining did before.
    """
    # the named tuples unpacked by name (a reordered field cannot swap two arguments)
    X, Y, D, rows, counts, tris = tri.X, tri.Y, tri.D, tri.rows, tri.counts, tri.tris
    W, H, band, perspective = grid.W, grid.H, grid.band, grid.perspective
    zlo, zhi, slices, slab = blend.zlo, blend.zhi, blend.slices, blend.slab
    fbuf, ibuf, bits, layers, ids = out.fbuf, out.ibuf, out.bits, out.layers, out.ids
    frag_off, frag_pix, frag_d, frag_n, frag_s = rec.off, rec.pix, rec.depth, rec.n, rec.facing
    keep = frag_pix.shape[0] > 1
    r0 = b * band
    r1 = min(r0 + band, H) - 1
    nf = frag_off[b] if keep else 0
    for q in range(counts[b], counts[b + 1]):
        t = tris[q]
        x0, y0, x1, y1, x2, y2, d0, d1, d2, area, flipped = oriented_triangle(X, Y, D, t)
        if area == 0:
            continue
        facing = np.int8(1) if flipped else np.int8(-1)
        i0 = max(rows[t, 0], r0)
        i1 = min(rows[t, 1], r1)
        j0, j1 = pixel_span(min(x0, min(x1, x2)), max(x0, max(x1, x2)), 0, W - 1)
        if j0 > j1 or i0 > i1:
            continue
        e = edge_setup(x0, y0, x1, y1, x2, y2)
        a0, a1, a2 = e[0], e[1], e[2]
        v = (x0, y0, x1, y1, x2, y2)
        inv_area = 1.0 / area
        for i in range(i0, i1 + 1):
            # the row's covered run (row_span), its edge functions stepped incrementally
            ja, jb, w0, w1, w2 = row_span(v, e, i, j0, j1)
            for j in range(ja, jb + 1):
                if j > ja:
                    w0 -= 256 * a0
                    w1 -= 256 * a1
                    w2 -= 256 * a2
                # D holds 1/depth for perspective set-ups, depth for orthographic ones:
                # either way the attribute interpolates linearly on screen
                if perspective:
                    d = 1.0 / ((w0 * d0 + w1 * d1 + w2 * d2) * inv_area)
                else:
                    d = (w0 * d0 + w1 * d1 + w2 * d2) * inv_area
                if op == 0:
                    if d < fbuf[i, j]:
                        fbuf[i, j] = d
                elif op == 1:
                    if d > fbuf[i, j]:
                        fbuf[i, j] = d
                elif op == 2:
                    ibuf[i, j] += 1
                elif op == 3 or op == 4:
                    _set_slice_bit(bits, i, j, d, zlo[i, j], zhi[i, j], slices, op == 4)
                elif op == 7:
                    if slab[1] > 0.0:
                        kf = np.floor((d - slab[0]) / slab[1])
                        if kf < slab[2] or kf > slab[3]:
                            continue
                    if d < fbuf[i, j]:
                        fbuf[i, j] = d
                        ids[i, j] = t
                elif op == 6:
                    if d < layers[0, i, j]:
                        layers[0, i, j] = d
                    if d > layers[1, i, j]:
                        layers[1, i, j] = d
                    if keep:
                        frag_pix[nf] = i * W + j
                        frag_d[nf] = d
                        frag_s[nf] = facing
                        nf += 1
                else:
                    n = ibuf[i, j]
                    cap = layers.shape[0]
                    k = min(n, cap)
                    # insertion keeping the `cap` nearest depths sorted
                    while k > 0 and layers[k - 1, i, j] > d:
                        if k < cap:
                            layers[k, i, j] = layers[k - 1, i, j]
                        k -= 1
                    if k < cap:
                        layers[k, i, j] = d
                    ibuf[i, j] = n + 1
    if keep:
        frag_n[b] = nf - frag_off[b]


@nb.njit(cache=True, parallel=True)
def _raster_kernel(op, tri, grid, blend, out, rec):
    """All bands in parallel, any blend ``op`` (see :func:`_raster_band`)."""
    nbands = tri.counts.shape[0] - 1
    step = coprime_stride(nbands)
    for k in nb.prange(nbands):
        b = strided(k, step, nbands)  # bands spread over the threads (see .schedule)
        _raster_band(b, op, tri, grid, blend, out, rec)


@nb.njit(cache=True, parallel=True)
def _minmax_kernel(tri, grid, layers, rec):
    """All bands in parallel, op 'minmax' (the hot min/max pass of Chaudhari §3.3).

    The same band traversal as :func:`_raster_kernel`, compiled with the
    op fixed so that the other blend branches drop out of the inner loop.
    ``layers`` (2, H, W) need not be initialised: each band first clears
    its own rows to (+inf, -inf).
    """
    f1 = np.zeros((1, 1))
    i1 = np.zeros((1, 1), np.int32)
    b1 = np.zeros((1, 1, 1), np.uint32)
    t1 = np.zeros((1, 1), np.int64)
    blend = _Blend(f1, f1, 256, np.zeros(4))
    out = _Targets(f1, i1, b1, layers, t1)
    W, H, band = grid.W, grid.H, grid.band
    nbands = tri.counts.shape[0] - 1
    step = coprime_stride(nbands)
    for k in nb.prange(nbands):
        b = strided(k, step, nbands)  # bands spread over the threads (see .schedule)
        for i in range(b * band, min(b * band + band, H)):
            for j in range(W):
                layers[0, i, j] = np.inf
                layers[1, i, j] = -np.inf
        _raster_band(b, 6, tri, grid, blend, out, rec)


class RasterSetup(NamedTuple):
    """Projected, snapped and binned triangles, reusable by several passes.

    The CPU counterpart of keeping transformed vertices on the GPU
    (stream-out, Chaudhari 2008 §4.2): the min/max pass and the
    voxelization pass rasterize the same triangles.
    """

    X: np.ndarray
    Y: np.ndarray
    D: np.ndarray
    rows: np.ndarray
    counts: np.ndarray
    tris: np.ndarray
    triangles: int
    dropped: int
    shape: tuple


@nb.njit(cache=True, parallel=True)
def _band_capacity(X, rows, counts, tris, W, band):
    """Upper bound of the fragments of each band: the pixel centres in its triangles' boxes."""
    nbands = counts.shape[0] - 1
    off = np.zeros(nbands + 1, np.int64)
    for b in nb.prange(nbands):
        r0 = b * band
        r1 = r0 + band - 1
        c = 0
        for q in range(counts[b], counts[b + 1]):
            t = tris[q]
            i0 = max(rows[t, 0], r0)
            i1 = min(rows[t, 1], r1)
            xlo = min(X[t, 0], min(X[t, 1], X[t, 2]))
            xhi = max(X[t, 0], max(X[t, 1], X[t, 2]))
            j0, j1 = pixel_span(xlo, xhi, 0, W - 1)
            if i1 >= i0 and j1 >= j0:
                c += (i1 - i0 + 1) * (j1 - j0 + 1)
        off[b + 1] = c
    for b in range(nbands):  # running sum: the bands' first slots
        off[b + 1] += off[b]
    return off


@nb.njit(cache=True, parallel=True)
def _blend_fragments(frag_off, frag_n, frag_pix, frag_d, W, op, zlo, zhi, slices, bits):
    """Blend recorded fragments into occupancy bitmasks (op 3 'or', 4 'add'), band by band."""
    nbands = frag_n.shape[0]
    step = coprime_stride(nbands)
    for k in nb.prange(nbands):
        b = strided(k, step, nbands)
        for q in range(frag_off[b], frag_off[b] + frag_n[b]):
            pix = frag_pix[q]
            i = pix // W
            j = pix - i * W
            _set_slice_bit(bits, i, j, frag_d[q], zlo[i, j], zhi[i, j], slices, op == 4)


class Fragments(NamedTuple):
    """Every fragment of a pass, grouped by band of rows in rasterization order.

    Recorded by :func:`rasterize` with ``op='minmax', keep_fragments=True``;
    a later pass over the same triangles (the voxelization of Chaudhari
    §3.3) then blends these fragments instead of rasterizing again - the
    same fragments a GPU's second rasterization produces.
    """

    offsets: np.ndarray
    counts: np.ndarray
    pix: np.ndarray
    depth: np.ndarray
    shape: tuple
    facing: np.ndarray = None  # -1 / +1: the triangle's orientation on screen


_FRAGMENT_LIMIT = 64 * 2**20  # recorded fragments at most (~0.8 GiB); beyond, passes re-rasterize
_NO_FRAGMENTS = _Record(np.zeros(1, np.int64), np.zeros(1, np.int32), np.zeros(1), np.zeros(1, np.int64),
                        np.zeros(1, np.int8))


def _tris(rs):
    """The kernel arrays of a :class:`RasterSetup`."""
    return _Tris(rs.X, rs.Y, rs.D, rs.rows, rs.counts, rs.tris)


def _record(fr):
    """The kernel arrays of a :class:`Fragments` being recorded."""
    return _Record(fr.offsets, fr.pix, fr.depth, fr.counts, fr.facing)


def _fragment_buffers(rs, W):
    """Empty :class:`Fragments` sized by the band capacities of a set-up; None beyond the limit."""
    off = _band_capacity(rs.X, rs.rows, rs.counts, rs.tris, W, BAND)
    if off[-1] > _FRAGMENT_LIMIT:
        return None
    n = max(int(off[-1]), 2)
    return Fragments(off, np.zeros(len(off) - 1, np.int64), np.empty(n, np.int32), np.empty(n),
                     rs.shape, np.empty(n, np.int8))


def _vertex_buffers(n):
    """Empty per-vertex buffers of a set-up: fixed-point x, y, the depth attribute, in-guard-band flag."""
    return np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.float64), np.empty(n, np.bool_)


def _gather_and_bin(faces, snapped, W, H):
    """Per-triangle snapped vertices and row ranges (:func:`_gather`), binned into bands (:func:`bin_bands`)."""
    T = faces.shape[0]
    X = np.empty((T, 3), np.int64)
    Y = np.empty((T, 3), np.int64)
    D = np.empty((T, 3), np.float64)
    rows = np.empty((T, 2), np.int64)
    _gather(faces, *snapped, W, H, X, Y, D, rows)
    counts, tris = bin_bands(rows, H, BAND)
    return X, Y, D, rows, counts, tris


def raster_setup(tri_view, camera, clip=True, faces=None):
    """Clip, project to fixed-point screen coordinates and bin triangles into row bands.

    Parameters
    ----------
    tri_view : (T, 3, 3) ndarray, or (V, 3) vertices when ``faces`` is given
        View-space geometry.
    camera : Camera
    clip : bool
        Clip against the near plane.
    faces : (T, 3) int ndarray, optional
        Indexed triangles: vertices are then projected once each (the
        common case, when no triangle crosses the near plane).

    Returns
    -------
    RasterSetup
        Snapped vertices (1/256 pixel), per-vertex depth attribute (1/depth,
        or depth for an orthographic camera), row ranges and band lists,
        reusable by several :func:`rasterize` calls; ``dropped`` counts the
        triangles beyond the guard band.

    References
    ----------
    Chaudhari (2008), §4.2 (transformed vertices kept for several passes).
    """
    W, H, sx, sy = camera.kernel_args()
    if faces is not None:
        vv = np.ascontiguousarray(tri_view, dtype=np.float64).reshape(-1, 3)
        fc = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        if clip and len(vv) and -vv[:, 2].max() < camera.near:
            tri_view, faces = vv[fc], None  # something crosses the near plane: clip the soup
    if faces is None:
        tv = np.ascontiguousarray(tri_view, dtype=np.float64).reshape(-1, 3, 3)
        if clip:
            tv = clip_near(tv, camera.near)
        vv = tv.reshape(-1, 3)
        fc = np.arange(len(vv), dtype=np.int64).reshape(-1, 3)
    T = fc.shape[0]
    snapped = _vertex_buffers(len(vv))
    _snap_vertices(vv, W, H, sx, sy, *snapped, bool(getattr(camera, "ortho", False)))
    X, Y, D, rows, counts, tris = _gather_and_bin(fc, snapped, W, H)
    okv = snapped[3]
    dropped = int(np.count_nonzero(~okv[fc].all(axis=1))) if not okv.all() else 0
    return RasterSetup(X, Y, D, rows, counts, tris, int(T), dropped, (H, W))


def rasterize(tri_view, camera, op, *, zlo=None, zhi=None, slices=256, capacity=32,
              clip=True, return_stats=False, keep_fragments=False):
    """Rasterize view-space triangles with one GPU-style blend operation.

    Parameters
    ----------
    tri_view : (T, 3, 3) array_like or RasterSetup
        Triangle vertices in view space (see :class:`~refraction_ref.camera.Camera`),
        or the result of :func:`raster_setup` to skip the set-up.
    camera : Camera
        Image size and projection (perspective, or orthographic: the
        depth is then interpolated linearly on screen).
    op : {'min', 'max', 'count', 'or', 'add', 'collect'}
        Per-pixel blend (see the module docstring).
    zlo, zhi : (H, W) ndarray, optional
        Per-pixel depth range mapped onto the slices (``or`` and ``add``):
        slice ``b = round((d - zlo) / (zhi - zlo) * (S - 1))``, the inverse of
        Chaudhari's ``depth = Zmin + b / (S - 1) * (Zmax - Zmin)`` (§3.4.1).
    slices : int
        Number of slices S, a multiple of 32 (``or`` and ``add``).
    capacity : int
        Depths kept per pixel (``collect``).
    clip : bool
        Clip against the near plane first (default). Pass False when the
        triangles are already clipped.
    return_stats : bool
        Also return a dict with ``triangles``, ``dropped`` (beyond the guard
        band) and ``degenerate`` counts.
    keep_fragments : bool
        With ``op='minmax'``: also return the :class:`Fragments` (None when
        there would be more than ``_FRAGMENT_LIMIT``). ``tri_view`` may be
        such a record for ops ``or`` and ``add``, which then blend the
        recorded fragments without rasterizing again (identical result).

    Returns
    -------
    ndarray or tuple
        ``min``/``max``: (H, W) float64 depth; ``minmax``: a tuple of both;
        ``nearest``: a tuple (depth, triangle index, -1 where empty);
        ``count``: (H, W) int32;
        ``or``/``add``: (H, W, S // 32) uint32; ``collect``: a tuple
        ``(depths (capacity, H, W) float64 with +inf padding, count (H, W) int32)``.

    References
    ----------
    Chaudhari (2008), §3.3.
    """
    if op not in OPS:
        raise ValueError(f"rasterize: unknown op {op!r}; expected one of {sorted(OPS)}")
    W, H, sx, sy = camera.kernel_args()
    if isinstance(tri_view, Fragments):
        if op not in ("or", "add"):
            raise ValueError(f"rasterize: recorded fragments serve ops 'or' and 'add', not {op!r}")
        if tri_view.shape != (H, W):
            raise ValueError(f"rasterize: the fragments were recorded for {tri_view.shape}, the camera is {(H, W)}")
        if slices % 32 or slices < 32:
            raise ValueError(f"rasterize: slices must be a positive multiple of 32, got {slices}")
        if zlo is None or zhi is None:
            raise ValueError("rasterize: op 'or'/'add' needs the per-pixel bounds zlo and zhi")
        bits = np.zeros((H, W, slices // 32), np.uint32)
        fr = tri_view
        _blend_fragments(fr.offsets, fr.counts, fr.pix, fr.depth, W, OPS[op],
                         np.ascontiguousarray(zlo, dtype=np.float64), np.ascontiguousarray(zhi, dtype=np.float64),
                         int(slices), bits)
        return bits
    rs = tri_view if isinstance(tri_view, RasterSetup) else raster_setup(tri_view, camera, clip)
    if rs.shape != (H, W):
        raise ValueError(f"rasterize: the set-up was made for {rs.shape}, the camera is {(H, W)}")
    X, Y, D, rows, counts, tris = rs.X, rs.Y, rs.D, rs.rows, rs.counts, rs.tris
    code = OPS[op]
    dummy_f = np.zeros((1, 1))
    dummy_i = np.zeros((1, 1), np.int32)
    dummy_b = np.zeros((1, 1, 1), np.uint32)
    dummy_l = np.zeros((1, 1, 1))
    fbuf, ibuf, bits, layers = dummy_f, dummy_i, dummy_b, dummy_l
    lo, hi = dummy_f, dummy_f
    if code == 0:
        fbuf = np.full((H, W), np.inf)
    elif code == 1:
        fbuf = np.full((H, W), -np.inf)
    elif code == 2:
        ibuf = np.zeros((H, W), np.int32)
    elif code in (3, 4):
        if slices % 32 or slices < 32:
            raise ValueError(f"rasterize: slices must be a positive multiple of 32, got {slices}")
        if zlo is None or zhi is None:
            raise ValueError("rasterize: op 'or'/'add' needs the per-pixel bounds zlo and zhi")
        bits = np.zeros((H, W, slices // 32), np.uint32)
        lo = np.ascontiguousarray(zlo, dtype=np.float64)
        hi = np.ascontiguousarray(zhi, dtype=np.float64)
    elif code == 6:
        layers = np.empty((2, H, W))  # initialised band by band in the kernel
    elif code != 7:  # 'collect' ('nearest' needs no A-buffer: a (capacity, H, W) one cost it 64 MB at 512^2)
        ibuf = np.zeros((H, W), np.int32)
        layers = np.full((int(capacity), H, W), np.inf)
    ids = np.zeros((1, 1), np.int64)
    if code == 7:
        fbuf = np.full((H, W), np.inf)
        ids = np.full((H, W), -1, np.int64)
    fr = _fragment_buffers(rs, W) if keep_fragments and code == 6 else None
    rec = _NO_FRAGMENTS if fr is None else _record(fr)
    # depth is interpolated linearly on screen for an orthographic camera
    grid = _Grid(W, H, BAND, not getattr(camera, "ortho", False))
    tri = _Tris(X, Y, D, rows, counts, tris)
    if code == 6:
        _minmax_kernel(tri, grid, layers, rec)
    else:
        _raster_kernel(code, tri, grid, _Blend(lo, hi, int(slices), _NO_SLAB),
                       _Targets(fbuf, ibuf, bits, layers, ids), rec)
    if code in (0, 1):
        res = fbuf
    elif code == 7:
        res = (fbuf, ids)
    elif code == 2:
        res = ibuf
    elif code in (3, 4):
        res = bits
    elif code == 6:
        res = (layers[0], layers[1])
        if keep_fragments:
            res = res + (fr,)
    else:
        res = (layers, ibuf)
    if return_stats:
        ax = (X[:, 1] - X[:, 0]) * (Y[:, 2] - Y[:, 0]) - (Y[:, 1] - Y[:, 0]) * (X[:, 2] - X[:, 0])
        area = int(np.count_nonzero(ax == 0))
        return res, {"triangles": rs.triangles, "dropped": rs.dropped, "degenerate": area}
    return res


# ---------------------------------------------------------------------------
# Orthographic rasterization (level-map position / diffuse maps, Tipprasert
# 2006 §4.2.2, and the slice images of the volumetric baseline, §5.2.1).
# Appended: the perspective functions above are unchanged.
# ---------------------------------------------------------------------------


@nb.njit(cache=True, parallel=True)
def _snap_texels(vv, XV, YV, DV, okv):
    """Snap (col, row, depth) vertices given in texel units to 1/256 texel."""
    for k in nb.prange(vv.shape[0]):
        c = vv[k, 0]
        r = vv[k, 1]
        z = vv[k, 2]
        okv[k] = abs(c) < MAX_COORD and abs(r) < MAX_COORD and np.isfinite(z)
        XV[k] = np.int64(np.round(c * 256.0)) if okv[k] else 0
        YV[k] = np.int64(np.round(r * 256.0)) if okv[k] else 0
        DV[k] = z if okv[k] else 0.0


def ortho_setup(tri_tex, shape):
    """Snap and bin triangles given in texel coordinates for :func:`rasterize_ortho`.

    Parameters
    ----------
    tri_tex : (T, 3, 3) array_like
        Vertices as ``(col, row, depth)``: continuous texel units (texel
        (i, j) has its centre at ``col = j + 0.5``, ``row = i + 0.5``) and a
        depth that is interpolated linearly (orthographic projection).
    shape : (H, W)

    Returns
    -------
    RasterSetup
        Reusable by several :func:`rasterize_ortho` calls (e.g. one per slab).
    """
    H, W = int(shape[0]), int(shape[1])
    vv = np.ascontiguousarray(tri_tex, dtype=np.float64).reshape(-1, 3)
    T = len(vv) // 3
    fc = np.arange(3 * T, dtype=np.int64).reshape(-1, 3)
    snapped = _vertex_buffers(len(vv))
    _snap_texels(vv, *snapped)
    X, Y, Z, rows, counts, tris = _gather_and_bin(fc, snapped, W, H)
    dropped = int(np.count_nonzero(rows[:, 0] > rows[:, 1]))
    return RasterSetup(X, Y, Z, rows, counts, tris, int(T), dropped, (H, W))


def rasterize_ortho(tri_tex, shape, slab=None):
    """Orthographic rasterization keeping the nearest fragment and its triangle.

    The orthographic counterpart of :func:`rasterize` with ``op='min'``,
    with the same fixed-point coverage and top-left rule, plus the index of
    the triangle that produced the kept fragment (a visibility buffer, from
    which normals, owners and colours are looked up). Depth is interpolated
    linearly in screen space, as an orthographic projection does.

    Parameters
    ----------
    tri_tex : (T, 3, 3) array_like or RasterSetup
        Triangles as ``(col, row, depth)`` in texel units (see
        :func:`ortho_setup`), or a set-up from it.
    shape : (H, W)
    slab : (z0, s, klo, khi), optional
        Keep only fragments whose slab index ``floor((depth - z0) / s)`` lies
        in ``[klo, khi]`` (the near and far clip planes of the slice images
        of Iwasaki et al.; written as an index so that it agrees bit for bit
        with a plane-index map computed with the same expression).

    Returns
    -------
    depth : (H, W) float64
        Nearest fragment depth, ``+inf`` where nothing is drawn.
    ids : (H, W) int64
        Triangle index of that fragment, ``-1`` where nothing is drawn. Ties
        go to the first triangle in index order.

    References
    ----------
    N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene with
    Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
    University, 2006, §4.2.2 (eqs. 4-10 to 4-13).
    """
    H, W = int(shape[0]), int(shape[1])
    rs = tri_tex if isinstance(tri_tex, RasterSetup) else ortho_setup(tri_tex, (H, W))
    if rs.shape != (H, W):
        raise ValueError(f"rasterize_ortho: the set-up was made for {rs.shape}, asked for {(H, W)}")
    z0, s, klo, khi = (0.0, 0.0, 0.0, 0.0) if slab is None else (float(v) for v in slab)
    if slab is not None and not s > 0.0:
        raise ValueError(f"rasterize_ortho: slab thickness must be > 0, got {s}")
    depth = np.full((H, W), np.inf)
    ids = np.full((H, W), -1, np.int64)
    d1 = np.zeros((1, 1))
    _raster_kernel(OPS["nearest"], _tris(rs), _Grid(W, H, BAND, False),
                   _Blend(d1, d1, 256, np.array([z0, s, klo, khi], dtype=np.float64)),
                   _Targets(depth, np.zeros((1, 1), np.int32), np.zeros((1, 1, 1), np.uint32), np.zeros((1, 1, 1)),
                            ids), _NO_FRAGMENTS)
    return depth, ids


def ortho_fragments(tri_tex, shape):
    """Every fragment of an orthographic rasterization, with its depth and facing.

    Parameters
    ----------
    tri_tex : (T, 3, 3) array_like or RasterSetup
        Triangles as ``(col, row, depth)`` in texel units (:func:`ortho_setup`).
    shape : (H, W)

    Returns
    -------
    Fragments
        Grouped by band of rows, triangles in index order within a band;
        ``facing`` is -1 for triangles counter-clockwise in (col, row) and
        +1 for the others. Used by the solid voxelization of the volumetric
        method to count surface crossings along each column.

    Raises
    ------
    MemoryError
        When the fragments would exceed the recording limit.
    """
    H, W = int(shape[0]), int(shape[1])
    rs = tri_tex if isinstance(tri_tex, RasterSetup) else ortho_setup(tri_tex, (H, W))
    fr = _fragment_buffers(rs, W)
    if fr is None:
        raise MemoryError(f"ortho_fragments: more than {_FRAGMENT_LIMIT} fragments; lower the resolution")
    layers = np.empty((2, H, W))
    _minmax_kernel(_tris(rs), _Grid(W, H, BAND, False), layers, _record(fr))
    return fr
