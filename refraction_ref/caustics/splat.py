"""Splatting photons into a receiver's caustic map and gathering them (Chaudhari 2008, §4.1).

Splat
    Each photon that reached receiver ``r`` at a point ``p`` with face
    normal ``n`` adds the irradiance ``Phi |n . V| / A_texel`` to the map
    (``V`` the map's normal, ``A_texel`` a texel's area on the map plane,
    ``1 / |n . V|`` the receiver area a texel covers), spread over the four
    texels around its map position with bilinear weights. Weights that
    would fall off the map are folded onto the border texel, so the total
    flux is kept exactly.
Gather
    The image-space photon gathering of Wyman and Davis (2006): a Gaussian
    over a ``window`` x ``window`` square of texels (``window = 7`` in the
    thesis's citation), normalised to unit sum and applied separably, with
    mirror folding at the map's border so that it too keeps the total flux.
    ``sigma = (window - 1) / 6``: the window spans +-3 sigma, the usual
    truncation of a Gaussian (99.7% of its weight).

Determinism: photons are binned into bands of 8 map rows (in photon index
order, as the rasterizer bins triangles) and each band is owned by one
thread, which adds its photons in index order; the gather computes each
texel independently (both passes of the separable filter own rows of their
output). The exact reference's maps of its two interleaved halves come from
the same footprint and binning as the whole map
(:func:`splat_bilinear_groups`): each (band, map) pair is one thread's, which
adds that map's photons in index order. Results are bit-identical whatever
the thread count.

References
----------
.. [1] C. Wyman, S. Davis, "Interactive Image-Space Techniques for
   Approximating Caustics", I3D 2006 (photon gathering with a Gaussian
   filter in a 7x7 window).
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §2.3.2, §4.1.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..filters import gather_gaussian
from ..filters import gather_taps as gaussian_weights
from ..raster import BAND, bin_bands

__all__ = ["splat_bilinear", "splat_bilinear_groups", "receiver_photons", "gather_gaussian", "gaussian_weights", "accumulate_light", "channel_mean", "finite_maps"]


@nb.njit(cache=True, parallel=True)
def _footprint(col, row, Hc, Wc, rows, j0s, i0s, fx, fy):
    for k0 in nb.prange(col.shape[0]):
        k = np.int64(k0)
        x = col[k] - 0.5
        y = row[k] - 0.5
        if not (math.isfinite(x) and math.isfinite(y)):
            rows[k, 0] = 1
            rows[k, 1] = 0
            i0s[k] = 0
            j0s[k] = 0
            fx[k] = 0.0
            fy[k] = 0.0
            continue
        x = min(max(x, -1.0), Wc + 0.0)
        y = min(max(y, -1.0), Hc + 0.0)
        i0 = np.int64(math.floor(y))
        j0 = np.int64(math.floor(x))
        i0s[k] = i0
        j0s[k] = j0
        fy[k] = y - i0
        fx[k] = x - j0
        rows[k, 0] = min(max(i0, 0), Hc - 1)
        rows[k, 1] = min(max(i0 + 1, 0), Hc - 1)


class _SplatFootprint(NamedTuple):
    """Each photon's bilinear footprint in the map (:func:`_footprint`) and what it deposits."""

    i0s: np.ndarray  # (N,) int64 row of the footprint's first texel (may be -1 or Hc: folded at the border)
    j0s: np.ndarray  # (N,) int64 its column
    fx: np.ndarray  # (N,) float64 bilinear fractions
    fy: np.ndarray  # (N,)
    val: np.ndarray  # (N, C) float64 the photon's deposit


@nb.njit(cache=True, inline="always")
def _deposit(k, fp, Hc, Wc, r0, r1, out):
    # photon k's bilinear weights added into out (Hc, Wc, C), rows r0..r1 only (its band); out is
    # an array of its own, not a tuple's (Numba drops stores into a tuple's arrays in prange)
    i0s, j0s, fx, fy, val = fp.i0s, fp.j0s, fp.fx, fp.fy, fp.val
    for di in range(2):
        i = min(max(i0s[k] + di, 0), Hc - 1)
        if i < r0 or i > r1:
            continue
        wy = fy[k] if di == 1 else 1.0 - fy[k]
        for dj in range(2):
            j = min(max(j0s[k] + dj, 0), Wc - 1)
            w = wy * (fx[k] if dj == 1 else 1.0 - fx[k])
            if w == 0.0:
                continue
            for c in range(val.shape[1]):
                out[i, j, c] += w * val[k, c]


@nb.njit(cache=True, parallel=True)
def _splat_kernel(fp, counts, items, Hc, Wc, band, out):
    nb_bands = counts.shape[0] - 1
    for b in nb.prange(nb_bands):
        r0 = b * band
        r1 = min(r0 + band, Hc) - 1
        for q in range(counts[b], counts[b + 1]):
            _deposit(items[q], fp, Hc, Wc, r0, r1, out)


def _footprint_bands(col, row, Hc, Wc):
    """Each point's bilinear footprint (corner texel, fractions) and the points binned by map-row band."""
    col = np.ascontiguousarray(col, dtype=np.float64)
    row = np.ascontiguousarray(row, dtype=np.float64)
    n = len(col)
    rows = np.empty((n, 2), np.int64)
    i0s = np.empty(n, np.int64)
    j0s = np.empty(n, np.int64)
    fx = np.empty(n)
    fy = np.empty(n)
    _footprint(col, row, Hc, Wc, rows, j0s, i0s, fx, fy)
    counts, items = bin_bands(rows, Hc, BAND)
    return i0s, j0s, fx, fy, counts, items


def _map_values(shape, values):
    """The map's ``Hc, Wc`` and the points' values as a float64 ``(N, C)`` array (one column for 1-D values)."""
    val = np.ascontiguousarray(values, dtype=np.float64)
    if val.ndim == 1:
        val = val[:, None]
    return int(shape[0]), int(shape[1]), val


def splat_bilinear(col, row, values, shape, out=None):
    """Add point values into a map with bilinear weights, deterministically.

    Parameters
    ----------
    col, row : (N,) array_like
        Continuous map positions (texel centres at ``+0.5``). Non-finite
        positions are skipped.
    values : (N, C) array_like
        What each point deposits (irradiance contributions).
    shape : (Hc, Wc)
    out : (Hc, Wc, C) float64, optional
        Accumulated into when given.

    Returns
    -------
    (Hc, Wc, C) float64
        The sum over points of the value times the bilinear weight; weights
        off the map are folded onto the border texels, so
        ``out.sum(axis=(0, 1)) == values.sum(axis=0)`` up to round-off.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    .. [2] C. Wyman, S. Davis, "Interactive Image-Space Techniques for
       Approximating Caustics", I3D 2006 (splatting and gathering).
    """
    Hc, Wc, val = _map_values(shape, values)
    if out is None:
        out = np.zeros((Hc, Wc, val.shape[1]))
    n = val.shape[0]
    if n == 0:
        return out
    i0s, j0s, fx, fy, counts, items = _footprint_bands(col, row, Hc, Wc)
    # caustics crowd photons into a few bands: the threads take bands one at a time (dynamic
    # scheduling), not equal runs of bands; which thread adds a band does not change its sums
    with nb.parallel_chunksize(1):
        _splat_kernel(_SplatFootprint(i0s, j0s, fx, fy, val), counts, items, Hc, Wc, BAND, out)
    return out


@nb.njit(cache=True, parallel=True)
def _group_counts_kernel(counts, items, grp, gc):
    # gc[b, g]: how many of band b's items are of group g
    ng = gc.shape[1]
    for b0 in nb.prange(counts.shape[0] - 1):
        b = np.int64(b0)
        for p in range(counts[b], counts[b + 1]):
            g = grp[items[p]]
            if 0 <= g < ng:
                gc[b, g] += 1


@nb.njit(cache=True, parallel=True)
def _group_fill_kernel(counts, items, grp, goff, gitems):
    # band b's items of group g, in their order, at gitems[goff[b ng + g]:goff[b ng + g + 1]]
    ng = (goff.shape[0] - 1) // (counts.shape[0] - 1)
    for b0 in nb.prange(counts.shape[0] - 1):
        b = np.int64(b0)
        pos = goff[b * ng:(b + 1) * ng].copy()
        for p in range(counts[b], counts[b + 1]):
            k = items[p]
            g = grp[k]
            if 0 <= g < ng:
                gitems[pos[g]] = k
                pos[g] += 1


class _GroupBins(NamedTuple):
    """The points binned by band (``counts``, ``items``) and, within a band, by group (``goff``, ``gitems``)."""

    counts: np.ndarray  # (bands + 1,) int64: band b's points are items[counts[b]:counts[b + 1]]
    items: np.ndarray  # (N',) int64 point indices
    goff: np.ndarray  # (bands * ng + 1,) int64: band b's points of group g at gitems[goff[b ng + g]:...]
    gitems: np.ndarray  # int64 point indices


@nb.njit(cache=True, parallel=True)
def _splat_groups_kernel(fp, bins, Hc, Wc, band, out):
    # out[0]: every photon; out[1 + g]: the photons of group g. Work item q is (band q // M,
    # map q % M): each owned by one thread, which adds the band's photons (of its group) in
    # index order, so every map is the one _splat_kernel makes of its photons alone, and a
    # crowded band's maps go to different threads
    # the named tuple unpacked before the parallel loop, one field per statement (DEVELOPERS.md)
    counts = bins.counts
    items = bins.items
    goff = bins.goff
    gitems = bins.gitems
    M = out.shape[0]
    ng = M - 1
    nb_bands = counts.shape[0] - 1
    for q0 in nb.prange(nb_bands * M):
        q = np.int64(q0)
        b = q // M
        m = q % M
        r0 = b * band
        r1 = min(r0 + band, Hc) - 1
        if m == 0:
            p0, p1 = counts[b], counts[b + 1]
        else:
            p0, p1 = goff[b * ng + m - 1], goff[b * ng + m]
        om = out[m]
        for p in range(p0, p1):
            _deposit(items[p] if m == 0 else gitems[p], fp, Hc, Wc, r0, r1, om)


def splat_bilinear_groups(col, row, values, shape, groups, ng):
    """:func:`splat_bilinear` of every point, and of the points of each group ``0 .. ng - 1`` alone,
    from one footprint and one binning (the same bits as separate calls on each subset).

    Parameters
    ----------
    col, row, values, shape
        As for :func:`splat_bilinear`.
    groups : (N,) array_like of int
        Each point's group (negative: in none but the whole map).
    ng : int
        Number of groups.

    Returns
    -------
    (1 + ng, Hc, Wc, C) float64
        Row 0 the map of every point, row ``1 + g`` that of group ``g`` (points of other
        groups, e.g. negative, in none).

    References
    ----------
    Chaudhari 2008, §4.1; Wyman and Davis 2006 (splatting and gathering), as :func:`splat_bilinear`.
    """
    Hc, Wc, val = _map_values(shape, values)
    ng = int(ng)
    out = np.zeros((1 + ng, Hc, Wc, val.shape[1]))
    n = val.shape[0]
    if n == 0:
        return out
    grp = np.ascontiguousarray(groups, dtype=np.int64) if ng else np.zeros(n, np.int64)
    i0s, j0s, fx, fy, counts, items = _footprint_bands(col, row, Hc, Wc)
    # each band's items split by group (their order kept), so a group's map reads only its photons
    nbands = len(counts) - 1
    gc = np.zeros((nbands, max(ng, 1)), np.int64)
    if ng:
        _group_counts_kernel(counts, items, grp, gc)
    goff = np.zeros(nbands * ng + 1, np.int64)
    np.cumsum(gc[:, :ng].ravel(), out=goff[1:])
    gitems = np.empty(max(int(goff[-1]), 1), np.int64)
    if ng:
        _group_fill_kernel(counts, items, grp, goff, gitems)
    with nb.parallel_chunksize(1):
        _splat_groups_kernel(_SplatFootprint(i0s, j0s, fx, fy, val), _GroupBins(counts, items, goff, gitems), Hc, Wc,
                             BAND, out)
    return out


class _ReceiverPhotons(NamedTuple):
    """The photons of one receiver, as :func:`_receiver_photons_kernel` reads them."""

    P: np.ndarray  # (M, 3) float64 hit points
    face: np.ndarray  # (M,) int64 receiver triangle of each
    idx: np.ndarray  # (N,) int64 the photons on this receiver
    normals: np.ndarray  # (T, 3) float64 the receivers' face normals
    flux: np.ndarray  # (M, C) float64


class _CausticMapFrame(NamedTuple):
    """A receiver's caustic map: its frame and texels."""

    frame: np.ndarray  # (5, 3) centre, U, V, W, (w, d, 0)
    texel_area: float
    Hc: float
    Wc: float


@nb.njit(cache=True, parallel=True)
def _receiver_photons_kernel(photons, box, col, row, val):
    # per photon idx[k] on the receiver: its map position (levelmap.planes.to_map: q = p - centre,
    # col = (q.U / w + 0.5) Wc, row = (q.W / d + 0.5) Hc, vec3.dot's order) and its irradiance
    # flux |n.V| / A_texel (splat_maps's NumPy expressions, operation for operation)
    P = photons.P
    face = photons.face
    idx = photons.idx
    normals = photons.normals
    flux = photons.flux
    frame = box.frame
    texel_area = box.texel_area
    Hc = box.Hc
    Wc = box.Wc
    cx, cy, cz = frame[0, 0], frame[0, 1], frame[0, 2]
    ux, uy, uz = frame[1, 0], frame[1, 1], frame[1, 2]
    vx, vy, vz = frame[2, 0], frame[2, 1], frame[2, 2]
    wx, wy, wz = frame[3, 0], frame[3, 1], frame[3, 2]
    bw, bd = frame[4, 0], frame[4, 1]
    C = flux.shape[1]
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        i = idx[k]
        f = face[i]
        cosv = abs(normals[f, 0] * vx + normals[f, 1] * vy + normals[f, 2] * vz)
        qx = P[i, 0] - cx
        qy = P[i, 1] - cy
        qz = P[i, 2] - cz
        col[k] = ((qx * ux + qy * uy + qz * uz) / bw + 0.5) * Wc
        row[k] = ((qx * wx + qy * wy + qz * wz) / bd + 0.5) * Hc
        s = cosv / texel_area
        for c in range(C):
            val[k, c] = flux[i, c] * s


def receiver_photons(P, face, idx, normals, box, flux):
    """Map positions (col, row) and splat values (N, C) of the photons ``idx`` on receiver ``box``.

    Parameters
    ----------
    P : (M, 3) float64
        Photon hit points.
    face : (M,) int64
        Receiver triangle hit by each photon.
    idx : (N,) int64
        The photons on this receiver.
    normals : (T, 3) float64
        The receivers' face normals.
    box : Box
        The receiver's caustic-map box.
    flux : (M, C) float64
        Each photon's flux.

    Returns
    -------
    col, row : (N,) float64
        Map positions.
    val : (N, C) float64
        Irradiance deposits (flux over the texel area, times the cosine).

    References
    ----------
    Chaudhari 2008, §4.1 (the photons' irradiance on a receiver's map); Wyman and Davis 2006 (splatting).
    """
    Hc, Wc = box.size
    frame = np.array([box.center, box.U, box.V, box.W, [box.w, box.d, 0.0]], dtype=np.float64)
    n = len(idx)
    col, row, val = np.empty(n), np.empty(n), np.empty((n, flux.shape[1]))
    if n:
        _receiver_photons_kernel(_ReceiverPhotons(P, face, idx, normals, flux),
                                 _CausticMapFrame(frame, float(box.texel_area), float(Hc), float(Wc)), col, row, val)
    return col, row, val


@nb.njit(cache=True, inline="always")
def _texel_mean(m, i, j):
    # m[i, j].mean() as NumPy takes it: the channels summed in order, then divided by their count
    C = m.shape[2]
    s = 0.0
    for c in range(C):
        s += m[i, j, c]
    return s / C


@nb.njit(cache=True, parallel=True)
def _accumulate_kernel(m, radiance, unit, rgb):
    # unit += m.mean(axis=2), rgb += m * L
    H, W, C = m.shape
    for i0 in nb.prange(H):
        i = np.int64(i0)
        for j in range(W):
            for c in range(C):
                rgb[i, j, c] += m[i, j, c] * radiance[c]
            unit[i, j] += _texel_mean(m, i, j)


@nb.njit(cache=True, parallel=True)
def _channel_mean_kernel(m, out):
    H, W = m.shape[0], m.shape[1]
    for i0 in nb.prange(H):
        i = np.int64(i0)
        for j in range(W):
            out[i, j] = _texel_mean(m, i, j)


def channel_mean(m):
    """``m.mean(axis=2)`` of an (Hc, Wc, C) map on every thread, bit for bit NumPy's
    (the channels summed in order, then divided by ``C``).

    Parameters
    ----------
    m : (Hc, Wc, C) float64

    Returns
    -------
    (Hc, Wc) float64

    References
    ----------
    Chaudhari 2008, §4.1 (the caustic maps' mean over the channels).
    """
    m = np.ascontiguousarray(m, dtype=np.float64)
    out = np.empty(m.shape[:2])
    _channel_mean_kernel(m, out)
    return out


@nb.njit(cache=True, parallel=True)
def _finite_kernel(a, out32):
    # np.nan_to_num(a, nan=0, posinf=0, neginf=0) in place, and its float32 copy
    for i0 in nb.prange(a.shape[0]):
        i = np.int64(i0)
        for j in range(a.shape[1]):
            x = a[i, j]
            if not math.isfinite(x):
                x = 0.0
                a[i, j] = 0.0
            out32[i, j] = np.float32(x)


def finite_maps(a):
    """``a`` with NaN and infinities set to 0, in place, and as float32 (the maps' output dtype).

    Parameters
    ----------
    a : (Hc, Wc) or (Hc, Wc, C) float64, C-contiguous

    Returns
    -------
    a, a32
        The same array, and its float32 copy.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    flat = a.reshape(a.shape[0], -1)
    out = np.empty(flat.shape, np.float32)
    _finite_kernel(flat, out)
    return a, out.reshape(a.shape)


def accumulate_light(m, radiance, unit, rgb):
    """``unit += m.mean(axis=2)`` and ``rgb += m * radiance`` in place, on every thread.

    Parameters
    ----------
    m : (Hc, Wc, 3) float64
        One light's map of one receiver (a unit light).
    radiance : (3,) array_like
        The light's RGB radiance.
    unit : (Hc, Wc) float64
    rgb : (Hc, Wc, 3) float64

    References
    ----------
    Chaudhari 2008, §4.1 (one light's caustic map, lit); Wyman and Davis 2006 (splatting and gathering).
    """
    _accumulate_kernel(np.ascontiguousarray(m, dtype=np.float64), np.asarray(radiance, dtype=np.float64),
                       unit, rgb)
