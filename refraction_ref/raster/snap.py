"""Triangle set-up: near-plane clipping, snapping to fixed point, binning into bands of rows.

The set-up stage of a GPU's rasterizer, done once per mesh and view and
kept for several passes (:class:`RasterSetup`): view-space triangles are
clipped against the near plane (Sutherland-Hodgman), their vertices
projected and snapped to 1/256 pixel, each triangle's rows found from its
snapped bounding box, and the triangles listed per band of :data:`BAND`
rows (:func:`bin_bands`), in index order, for the band kernels of
:mod:`.blend`. :func:`ortho_setup` does the same for triangles already given
in texel units (the orthographic maps of the level-map and volumetric
methods).

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §4.2 (transformed vertices kept for
   several passes).
.. [2] I. E. Sutherland, G. W. Hodgman, "Reentrant Polygon Clipping",
   CACM 17(1), 1974.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .coverage import pixel_span

__all__ = ["BAND", "MAX_COORD", "RasterSetup", "SnappedVertices", "bin_bands", "clip_near", "ortho_setup",
           "raster_setup", "raster_stats"]

#: rows per band: the unit of parallel work, and the ``band`` of :func:`bin_bands`
BAND = 8
#: guard band in pixels: a vertex with ``|col|`` or ``|row|`` beyond it drops its
#: triangle (keeps the fixed-point edge functions far from int64 overflow)
MAX_COORD = float(1 << 22)


class SnappedVertices(NamedTuple):
    """Per-vertex results of snapping, indexed by vertex (what :func:`_gather` reads through the faces)."""

    X: np.ndarray  # (V,) int64 column, 1/256-pixel fixed point (0 outside the guard band)
    Y: np.ndarray  # (V,) int64 row
    D: np.ndarray  # (V,) float64 attribute: 1/depth (perspective) or depth (orthographic, texel)
    ok: np.ndarray  # (V,) bool: inside the guard band (and in front of the eye)


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
def _gather(faces, snapped, W, H, X, Y, D, rows):
    """Gather snapped triangles; rows[t] = the pixel rows they may cover, (1, 0) when none.

    ``snapped`` (:class:`SnappedVertices`) is only read; the outputs are plain
    arguments, not fields of a tuple, as the band kernels' are (numba#7135).
    """
    XV, YV, DV, okv = snapped.X, snapped.Y, snapped.D, snapped.ok
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


def _vertex_buffers(n):
    """Empty :class:`SnappedVertices` of ``n`` vertices."""
    return SnappedVertices(np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.float64),
                           np.empty(n, np.bool_))


def _gather_and_bin(faces, snapped, W, H):
    """Per-triangle snapped vertices and row ranges (:func:`_gather`), binned into bands (:func:`bin_bands`)."""
    T = faces.shape[0]
    X = np.empty((T, 3), np.int64)
    Y = np.empty((T, 3), np.int64)
    D = np.empty((T, 3), np.float64)
    rows = np.empty((T, 2), np.int64)
    _gather(faces, snapped, W, H, X, Y, D, rows)
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
        reusable by several :func:`~refraction_ref.raster.rasterize` calls;
        ``dropped`` counts the triangles beyond the guard band.

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
    okv = snapped.ok
    dropped = int(np.count_nonzero(~okv[fc].all(axis=1))) if not okv.all() else 0
    return RasterSetup(X, Y, D, rows, counts, tris, int(T), dropped, (H, W))



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
    """Snap and bin triangles given in texel coordinates for :func:`~refraction_ref.raster.rasterize_ortho`.

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
        Reusable by several :func:`~refraction_ref.raster.rasterize_ortho` calls
        (e.g. one per slab).
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


def raster_stats(rs):
    """Triangle counts of a set-up: how many there are, beyond the guard band, of zero area.

    Parameters
    ----------
    rs : RasterSetup
        From :func:`raster_setup` or :func:`ortho_setup`.

    Returns
    -------
    dict
        ``triangles`` (after near-plane clipping), ``dropped`` (beyond the
        guard band: they draw nothing) and ``degenerate`` (zero area once
        snapped: they draw nothing either).
    """
    X, Y = rs.X, rs.Y
    ax = (X[:, 1] - X[:, 0]) * (Y[:, 2] - Y[:, 0]) - (Y[:, 1] - Y[:, 0]) * (X[:, 2] - X[:, 0])
    return {"triangles": rs.triangles, "dropped": rs.dropped, "degenerate": int(np.count_nonzero(ax == 0))}
