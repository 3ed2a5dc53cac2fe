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
texel independently. Results are bit-identical whatever the thread count.

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

import numba as nb
import numpy as np

from ..raster import BAND, bin_bands

__all__ = ["splat_bilinear", "gather_gaussian", "gaussian_weights"]


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


@nb.njit(cache=True, parallel=True)
def _splat_kernel(i0s, j0s, fx, fy, val, counts, items, Hc, Wc, band, out):
    C = val.shape[1]
    nb_bands = counts.shape[0] - 1
    for b in nb.prange(nb_bands):
        r0 = b * band
        r1 = min(r0 + band, Hc) - 1
        for q in range(counts[b], counts[b + 1]):
            k = items[q]
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
                    for c in range(C):
                        out[i, j, c] += w * val[k, c]


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
    """
    Hc, Wc = int(shape[0]), int(shape[1])
    val = np.ascontiguousarray(values, dtype=np.float64)
    if val.ndim == 1:
        val = val[:, None]
    if out is None:
        out = np.zeros((Hc, Wc, val.shape[1]))
    n = val.shape[0]
    if n == 0:
        return out
    col = np.ascontiguousarray(col, dtype=np.float64)
    row = np.ascontiguousarray(row, dtype=np.float64)
    rows = np.empty((n, 2), np.int64)
    i0s = np.empty(n, np.int64)
    j0s = np.empty(n, np.int64)
    fx = np.empty(n)
    fy = np.empty(n)
    _footprint(col, row, Hc, Wc, rows, j0s, i0s, fx, fy)
    counts, items = bin_bands(rows, Hc, BAND)
    _splat_kernel(i0s, j0s, fx, fy, val, counts, items, Hc, Wc, BAND, out)
    return out


def gaussian_weights(window):
    """Normalised 1-D Gaussian taps of a ``window``-texel gathering kernel, ``sigma = (window - 1) / 6``."""
    r = int(window) // 2
    if r == 0:
        return np.ones(1)
    x = np.arange(-r, r + 1, dtype=np.float64)
    sigma = (int(window) - 1) / 6.0
    w = np.exp(-0.5 * (x / sigma) ** 2)
    return w / w.sum()


@nb.njit(cache=True, parallel=True)
def _fold_rows(a, w, out):
    """out[i, j] = sum_k w[k] a[i, j - k + r] with mirror folding at the ends of each row."""
    H, N, C = a.shape
    r = (w.shape[0] - 1) // 2
    for i0 in nb.prange(H):
        i = np.int64(i0)
        for j in range(N):
            for c in range(C):
                s = 0.0
                for t in range(-r, r + 1):
                    wt = w[t + r]
                    src = j - t
                    if 0 <= src < N:
                        s += wt * a[i, src, c]
                    src = -1 - j - t  # mass that left through the first edge, mirrored back
                    if 0 <= src < N:
                        s += wt * a[i, src, c]
                    src = 2 * N - 1 - j - t  # ... through the last edge
                    if 0 <= src < N:
                        s += wt * a[i, src, c]
                out[i, j, c] = s


def gather_gaussian(E, window=7):
    """Image-space photon gathering: a separable, flux-conserving Gaussian (Wyman & Davis 2006).

    Parameters
    ----------
    E : (Hc, Wc) or (Hc, Wc, C) array_like
        Splatted map.
    window : int
        Odd window size in texels; 1 returns the map unchanged.

    Returns
    -------
    ndarray
        Same shape, float64. The sum over the map is kept (mirror folding
        at the border).
    """
    a = np.asarray(E, dtype=np.float64)
    squeeze = a.ndim == 2
    if squeeze:
        a = a[..., None]
    w = gaussian_weights(window)
    r = (len(w) - 1) // 2
    if r == 0:
        return a[..., 0].copy() if squeeze else a.copy()
    r = min(r, min(a.shape[0], a.shape[1]) - 1)
    if r <= 0:
        return a[..., 0].copy() if squeeze else a.copy()
    if r < (len(w) - 1) // 2:
        w = w[(len(w) - 1) // 2 - r: (len(w) - 1) // 2 + r + 1]
        w = w / w.sum()
    tmp = np.empty_like(a)
    _fold_rows(np.ascontiguousarray(a), w, tmp)
    out = np.empty((a.shape[1], a.shape[0], a.shape[2]))
    _fold_rows(np.ascontiguousarray(tmp.transpose(1, 0, 2)), w, out)
    out = np.ascontiguousarray(out.transpose(1, 0, 2))
    return out[..., 0] if squeeze else out
