"""Blending: the band kernels that walk the binned triangles and blend each fragment into its pixel.

Every blend mode of the three papers is one code of :data:`OPS`, all served
by one band kernel (:func:`_raster_band`): a band of rows is rasterized by
one thread, its triangles in index order, so every result is bit-identical
whatever the thread count. The min/max pass can record its fragments
(:class:`Fragments`) so that the voxelization pass blends the very same
fragments without rasterizing the mesh again.

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.3 (min/max pass with max blending,
   bitmask voxelization with additive blending).
.. [2] E. Eisemann, X. Décoret, "Fast Scene Voxelization and Applications",
   I3D 2006 (slicing by bitwise blending).
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ..schedule import coprime_stride, strided
from .coverage import edge_setup, oriented_triangle, pixel_span, row_span
from .snap import BAND

__all__ = ["OPS", "FRAGMENT_LIMIT", "Fragments", "step_edges"]

#: blend operation -> the code the kernels branch on
OPS = {"min": 0, "max": 1, "count": 2, "or": 3, "add": 4, "collect": 5, "minmax": 6, "nearest": 7}


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


class _RasterTris(NamedTuple):
    """Snapped triangles binned into bands of rows (the kernel half of a :class:`RasterSetup`)."""

    X: np.ndarray  # (T, 3) int64 vertex columns, 1/256-pixel fixed point
    Y: np.ndarray  # (T, 3) int64 vertex rows
    D: np.ndarray  # (T, 3) float64 attribute: 1/depth (perspective) or depth (orthographic)
    rows: np.ndarray  # (T, 2) int64 rows each triangle may cover
    counts: np.ndarray  # (nbands + 1,) CSR offsets of the band lists (bin_bands)
    tris: np.ndarray  # triangle indices, band by band


class _RasterGrid(NamedTuple):
    """The image rasterized into: size, rows per band, how depth interpolates."""

    W: int
    H: int
    band: int
    perspective: bool  # 1/depth linear on screen; depth itself when False (orthographic)


class _RasterBlend(NamedTuple):
    """Settings of the blend operations (the op itself is an argument of its own, see :func:`_raster_band`)."""

    zlo: np.ndarray  # (H, W) slice range of ops 'or' / 'add' ((1, 1) unused)
    zhi: np.ndarray
    slices: int
    slab: np.ndarray  # (4,) (z0, s, klo, khi) of op 'nearest'; s <= 0: no restriction


class _RasterTargets(NamedTuple):
    """The per-pixel buffers blended into ((1, 1[, 1]) placeholders for those an op does not use)."""

    fbuf: np.ndarray  # (H, W) float64: 'min', 'max', 'nearest'
    ibuf: np.ndarray  # (H, W) int32: 'count', 'collect'
    bits: np.ndarray  # (H, W, S // 32) uint32: 'or', 'add'
    layers: np.ndarray  # (2, H, W) 'minmax' / (capacity, H, W) 'collect' float64
    ids: np.ndarray  # (H, W) int64: 'nearest'


class _RasterRecord(NamedTuple):
    """Fragment record of op 'minmax' (:class:`Fragments`); length-1 arrays: none kept."""

    off: np.ndarray  # (nbands + 1,) first slot of each band
    pix: np.ndarray  # int32 pixel index i * W + j
    depth: np.ndarray  # float64
    n: np.ndarray  # (nbands,) fragments written per band
    facing: np.ndarray  # int8 -1 / +1


@nb.njit(cache=True, inline="always")
def step_edges(j, ja, e, w0, w1, w2):
    """The edge functions of pixel ``j`` of a row's covered run, from those of pixel ``j - 1``.

    The scanline step of :func:`~.coverage.row_span`'s walk, shared by every
    kernel that walks such runs (:func:`_raster_band`, the intersection
    triangles of :mod:`~refraction_ref.levelmap.caustics_map`). Integer
    arithmetic only, inlined: the callers' bits are those of the step
    written out in place.

    Parameters
    ----------
    j, ja : int
        The pixel, and the first of the run (whose values ``row_span`` returned).
    e : tuple of 6 int
        ``(a0, a1, a2, b0, b1, b2)`` from :func:`~.coverage.edge_setup`.
    w0, w1, w2 : int
        Edge functions at pixel ``j - 1`` (at ``ja`` when ``j == ja``).

    Returns
    -------
    w0, w1, w2 : int
        Edge functions at pixel ``j``.

    References
    ----------
    J. Pineda, "A Parallel Algorithm for Polygon Rasterization", SIGGRAPH
    1988 (incremental edge functions).
    """
    if j > ja:
        return w0 - 256 * e[0], w1 - 256 * e[1], w2 - 256 * e[2]
    return w0, w1, w2


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
    prunes.
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
        v = (x0, y0, x1, y1, x2, y2)
        inv_area = 1.0 / area
        for i in range(i0, i1 + 1):
            # the row's covered run (row_span), its edge functions stepped incrementally
            ja, jb, w0, w1, w2 = row_span(v, e, i, j0, j1)
            for j in range(ja, jb + 1):
                w0, w1, w2 = step_edges(j, ja, e, w0, w1, w2)
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
    blend = _RasterBlend(f1, f1, 256, np.zeros(4))
    out = _RasterTargets(f1, i1, b1, layers, t1)
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

    Recorded by :func:`~refraction_ref.raster.rasterize` with ``op='minmax', keep_fragments=True``;
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


#: recorded fragments at most (~0.8 GiB); beyond, passes rasterize again
FRAGMENT_LIMIT = 64 * 2**20
_NO_FRAGMENTS = _RasterRecord(np.zeros(1, np.int64), np.zeros(1, np.int32), np.zeros(1), np.zeros(1, np.int64),
                              np.zeros(1, np.int8))


def _tris(rs):
    """The kernel arrays of a :class:`RasterSetup`."""
    return _RasterTris(rs.X, rs.Y, rs.D, rs.rows, rs.counts, rs.tris)


def _record(fr):
    """The kernel arrays of a :class:`Fragments` being recorded."""
    return _RasterRecord(fr.offsets, fr.pix, fr.depth, fr.counts, fr.facing)


def _fragment_buffers(rs, W):
    """Empty :class:`Fragments` sized by the band capacities of a set-up; None beyond the limit."""
    off = _band_capacity(rs.X, rs.rows, rs.counts, rs.tris, W, BAND)
    if off[-1] > FRAGMENT_LIMIT:
        return None
    n = max(int(off[-1]), 2)
    return Fragments(off, np.zeros(len(off) - 1, np.int64), np.empty(n, np.int32), np.empty(n),
                     rs.shape, np.empty(n, np.int8))

