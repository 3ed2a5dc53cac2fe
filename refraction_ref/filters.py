"""The separable Gaussian filters of the three methods and of the quality metric, in one place.

Three filters, not one, because three sources ask for three different
Gaussians, each with its own taps and edge rule:

========================= ======================== ======================= =====================================
filter                    taps                     edge rule               asked for by
========================= ======================== ======================= =====================================
:func:`gaussian_blur`     ``window`` taps,         clamped (SciPy          Sun et al. 2008 §4.1: the index
(3-D volumes)             ``sigma = window / 6``   ``mode="nearest"``)     volume is blurred by a 9x9x9 Gaussian
                                                                           whose deviation is one sixth of the
                                                                           window (the gradient of ``n`` must
                                                                           be smooth); clamping keeps the
                                                                           outside index at the volume's border
:func:`gather_gaussian`   ``window`` taps,         mirror folding (the     Chaudhari 2008 §2.3.2 / §4.1 citing
(2-D maps, channels)      ``sigma = (window-1)/6`` weight that would leave Wyman & Davis 2006: photons gathered
                          (+-3 sigma in the        the map comes back)     over a 7x7 window with a Gaussian;
                          window)                                          folding keeps the total flux
:func:`gaussian_filter_   SciPy's: radius          zero outside (SciPy     the relative-L1 quality metric
zero` (2-D maps)          ``int(4 sigma + 0.5)``,  ``mode="constant"``)    (:func:`refraction_ref.metrics.
                          sigma given in texels                            relative_l1`) blurs both maps by one
                                                                           texel before comparing them, as an
                                                                           SSIM-like Gaussian window does, so a
                                                                           sub-texel shift is not an error;
                                                                           texels outside the receiver were
                                                                           zeroed and nothing comes in from
                                                                           beyond the map
========================= ======================== ======================= =====================================

Shared arithmetic, where sharing changes no bit: :func:`window_taps` computes
the taps of both window-sized filters (the same expression, only sigma
differs); :func:`sym_tap` and the zero-edge kernel add the same terms in the
same order, SciPy's symmetric-filter branch (the centre tap first, then the
pairs ``x[-k] + x[+k]`` from the widest in), and differ only in the edge rule
and in the loop order (the 2-D kernel walks whole rows, along memory). The
gather's fold sums ``t = -r .. r`` with three mirrored sources each, another
order, so it has kernels of its own. Every kernel writes each output from one
thread only: results are bit-identical whatever the thread count.

References
----------
.. [1] X. Sun, K. Zhou, E. Stollnitz, J. Shi, B. Guo, "Interactive
   Relighting of Dynamic Refractive Objects", ACM TOG 27(3), 2008, §4.1.
.. [2] C. Wyman, S. Davis, "Interactive Image-Space Techniques for
   Approximating Caustics", I3D 2006 (photon gathering with a Gaussian
   filter in a 7x7 window).
.. [3] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §2.3.2, §4.1.
.. [4] Z. Wang, A. C. Bovik, H. R. Sheikh, E. P. Simoncelli, "Image Quality
   Assessment: From Error Visibility to Structural Similarity", IEEE TIP
   13(4), 2004 (the Gaussian-weighted comparison window).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from scipy import ndimage

__all__ = ["window_taps", "gather_taps", "scipy_gaussian_taps", "sym_tap", "separable_correlate",
           "gaussian_blur", "gather_gaussian", "gaussian_filter_zero"]


# ---------------------------------------------------------------------------
# taps
# ---------------------------------------------------------------------------

def window_taps(window, sigma):
    """Normalised taps of a Gaussian over ``window`` texels (``window // 2`` either side).

    Parameters
    ----------
    window : int
        Window size; below 2 there is one tap.
    sigma : float
        Standard deviation in texels.

    Returns
    -------
    (2 (window // 2) + 1,) float64
        ``exp(-x^2 / (2 sigma^2))`` at ``x = -r .. r``, divided by its sum
        (``[1.0]`` when ``r = 0``).

    References
    ----------
    Sun et al. (2008), §4.1 (``sigma = window / 6``); Wyman and Davis (2006)
    via Chaudhari (2008), §2.3.2 (``sigma = (window - 1) / 6``).
    """
    r = int(window) // 2
    if r == 0:
        return np.ones(1)
    x = np.arange(-r, r + 1, dtype=np.float64)
    w = np.exp(-0.5 * (x / sigma) ** 2)
    return w / w.sum()


def gather_taps(window):
    """Taps of the photon-gathering Gaussian: :func:`window_taps` with ``sigma = (window - 1) / 6``.

    Parameters
    ----------
    window : int
        Odd window size in texels (7 in Wyman and Davis 2006).

    Returns
    -------
    (2 (window // 2) + 1,) float64
        Normalised taps; the window spans +-3 sigma (99.7 % of the weight).

    References
    ----------
    Chaudhari (2008), §2.3.2 and §4.1, citing Wyman and Davis (2006).
    """
    return window_taps(window, (int(window) - 1) / 6.0)


def scipy_gaussian_taps(sigma, truncate=4.0):
    """SciPy's ``gaussian_filter1d`` taps for ``sigma``, the same operations on the same values.

    Parameters
    ----------
    sigma : float
        Standard deviation in texels.
    truncate : float
        Radius in deviations: ``radius = int(truncate * sigma + 0.5)``.

    Returns
    -------
    (2 radius + 1,) float64
        ``scipy.ndimage._filters._gaussian_kernel1d`` reversed (the
        correlation taps), unit sum.
    """
    sd = float(sigma)
    radius = int(truncate * sd + 0.5)
    sigma2 = sigma * sigma
    x = np.arange(-radius, radius + 1)
    phi_x = np.exp(-0.5 / sigma2 * x ** 2)
    phi_x = phi_x / phi_x.sum()
    return np.ascontiguousarray(phi_x[::-1])


# ---------------------------------------------------------------------------
# clamped edges: the index volume of Sun et al. 2008 (§4.1)
# ---------------------------------------------------------------------------

@nb.njit(cache=True, inline="always")
def sym_tap(line, x, c, w, r):
    """One output of a symmetric correlation with clamped edges.

    ``line[x] w[r] + sum_{j=-r..-1} (line[x + j] + line[x - j]) w[r + j]``,
    indices clamped to the line. The terms are added in SciPy's
    symmetric-filter order, so a whole pass is
    ``scipy.ndimage.correlate1d(..., mode="nearest")`` bit for bit.

    Parameters
    ----------
    line : (n, C) float64 ndarray
        One line of a volume along the filtered axis.
    x : int
        Position on the line.
    c : int
        Channel.
    w : (2 r + 1,) float64 ndarray
        Symmetric taps.
    r : int
        Radius, ``len(w) // 2``.

    Returns
    -------
    float
        The filtered value.
    """
    n = line.shape[0]
    acc = line[x, c] * w[r]
    for jj in range(-r, 0):
        acc += (line[max(x + jj, 0), c] + line[min(x - jj, n - 1), c]) * w[r + jj]
    return acc


@nb.njit(cache=True, parallel=True)
def _sym_correlate_axis(a, w, axis, out):
    """``scipy.ndimage.correlate1d(a, w, axis, mode="nearest")`` for a symmetric ``w``, bit for bit.

    ``a`` and ``out`` are (nx, ny, nz, C) float64 (every value by :func:`sym_tap`);
    each parallel slab writes only its own outputs, so the result does not
    depend on the thread count.
    """
    nx, ny, nz, nc = a.shape
    r = w.shape[0] // 2
    if axis == 0:
        for j in nb.prange(ny):
            for i in range(nx):
                for k in range(nz):
                    line = a[:, j, k, :]
                    for c in range(nc):
                        out[i, j, k, c] = sym_tap(line, i, c, w, r)
    elif axis == 1:
        for i in nb.prange(nx):
            for j in range(ny):
                for k in range(nz):
                    line = a[i, :, k, :]
                    for c in range(nc):
                        out[i, j, k, c] = sym_tap(line, j, c, w, r)
    else:
        for i in nb.prange(nx):
            for j in range(ny):
                line = a[i, j]
                for k in range(nz):
                    for c in range(nc):
                        out[i, j, k, c] = sym_tap(line, k, c, w, r)


def separable_correlate(a, w):
    """Correlate a volume with the symmetric taps ``w`` along x, then y, then z, edges clamped.

    Equal bit for bit to three ``scipy.ndimage.correlate1d`` passes (mode
    ``nearest``), but parallel over slabs.

    Parameters
    ----------
    a : (nx, ny, nz) or (nx, ny, nz, C) array_like
        Volume; trailing channels are filtered independently.
    w : (2 r + 1,) array_like
        Taps. Anything but symmetric odd-length taps on a 3-D or 4-D array
        goes through SciPy itself.

    Returns
    -------
    ndarray
        Same shape, float64 (never the caller's array).

    References
    ----------
    Sun et al. (2008), §4.1.
    """
    a = np.asarray(a, dtype=np.float64)
    w = np.ascontiguousarray(w, dtype=np.float64)
    if a.ndim not in (3, 4) or w.ndim != 1 or len(w) % 2 != 1 or not np.array_equal(w, w[::-1]):
        out = a
        for ax in range(3):
            out = ndimage.correlate1d(out, w, axis=ax, mode="nearest")
        return out
    src = np.ascontiguousarray(a.reshape(a.shape[:3] + (-1,)))
    x = np.empty_like(src)
    y = np.empty_like(src)
    _sym_correlate_axis(src, w, 0, x)  # never writes into the caller's array
    _sym_correlate_axis(x, w, 1, y)
    _sym_correlate_axis(y, w, 2, x)
    return x.reshape(a.shape)


def gaussian_blur(a, window):
    """Separable Gaussian of ``window`` taps per axis, ``sigma = window / 6``, edges clamped.

    The blur of the index volume (and of the absorption volume) after
    voxelization: Sun et al. ask for a 9x9x9 window with a deviation one sixth
    of the window, which spreads each boundary over a band of voxels so that
    the gradient of the index is smooth. Clamped edges keep a constant field
    (the outside index) constant up to the border.

    Parameters
    ----------
    a : (nx, ny, nz) or (nx, ny, nz, C) array_like
        Volume; trailing channels are blurred independently.
    window : int
        Taps per axis; ``window <= 1`` returns a copy.

    Returns
    -------
    ndarray
        Same shape, float64.

    References
    ----------
    Sun et al. (2008), §4.1.
    """
    a = np.asarray(a, dtype=np.float64)
    if window <= 1:
        return a.copy()
    return separable_correlate(a, window_taps(window, window / 6.0))


# ---------------------------------------------------------------------------
# mirror folding: photon gathering (Wyman & Davis 2006; Chaudhari 2008 §4.1)
# ---------------------------------------------------------------------------

@nb.njit(cache=True, inline="always")
def _fold_sources(k, t, n):
    """The texels tap ``t`` of texel ``k`` reads along an axis of length ``n``, in summation order.

    The direct source ``k - t``, then the mass that left through the first
    edge, mirrored back (``-1 - k - t``), then through the last edge
    (``2 n - 1 - k - t``); only those inside ``[0, n)`` count.
    """
    return k - t, -1 - k - t, 2 * n - 1 - k - t


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
                    for src in _fold_sources(j, t, N):
                        if 0 <= src < N:
                            s += wt * a[i, src, c]
                out[i, j, c] = s


@nb.njit(cache=True, parallel=True)
def _fold_cols(a, w, out):
    """out[i, j] = sum_k w[k] a[i - k + r, j] with mirror folding at the ends of each column.

    :func:`_fold_rows` applied to ``a.transpose(1, 0, 2)`` and transposed back, term for
    term in the same order (the same bits), without the two transposed copies: each
    thread owns rows of ``out`` and reads along rows of ``a``.
    """
    N, Wc, C = a.shape
    r = (w.shape[0] - 1) // 2
    for i0 in nb.prange(N):
        i = np.int64(i0)
        # each texel's sum starts at 0 and takes the terms in _fold_rows's order (t, then the two
        # mirrors); whole rows at a time, so the inner loop runs along memory
        for j in range(Wc):
            for c in range(C):
                out[i, j, c] = 0.0
        for t in range(-r, r + 1):
            wt = w[t + r]
            for src in _fold_sources(i, t, N):
                if 0 <= src < N:
                    for j in range(Wc):
                        for c in range(C):
                            out[i, j, c] += wt * a[src, j, c]


def gather_gaussian(E, window=7):
    """Image-space photon gathering: a separable, flux-conserving Gaussian (Wyman & Davis 2006).

    Taps :func:`gather_taps` (``sigma = (window - 1) / 6``), applied along
    rows, then along columns, with mirror folding at the map's border: the
    weight a tap would put outside the map lands on the mirrored texel
    inside, so the sum over the map is kept. On a map smaller than the
    window the radius shrinks to ``min(Hc, Wc) - 1`` and the cut taps are
    renormalised.

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

    References
    ----------
    Chaudhari (2008), §2.3.2 and §4.1, citing Wyman and Davis (2006).
    """
    a = np.asarray(E, dtype=np.float64)
    squeeze = a.ndim == 2
    if squeeze:
        a = a[..., None]
    w = gather_taps(window)
    r = (len(w) - 1) // 2
    if r == 0:
        return a[..., 0].copy() if squeeze else a.copy()
    r = min(r, min(a.shape[0], a.shape[1]) - 1)
    if r <= 0:
        return a[..., 0].copy() if squeeze else a.copy()
    if r < (len(w) - 1) // 2:
        w = w[(len(w) - 1) // 2 - r: (len(w) - 1) // 2 + r + 1]
        w = w / w.sum()
    tmp = np.empty(a.shape)
    _fold_rows(np.ascontiguousarray(a), w, tmp)
    out = np.empty(a.shape)
    _fold_cols(tmp, w, out)
    return out[..., 0] if squeeze else out


# ---------------------------------------------------------------------------
# zero outside: the quality metric's blur (relative L1 of caustic maps)
# ---------------------------------------------------------------------------

@nb.njit(cache=True, parallel=True)
def _correlate_zero(a, fw, axis, out):
    """``scipy.ndimage.correlate1d(a, fw, axis, mode="constant")`` for symmetric taps ``fw``.

    Operation for operation (odd length): each texel starts at
    ``x[0] * fw[0]`` and adds ``(x[-k] + x[+k]) * fw[-k]`` for k from the
    widest in (ni_filters.c's symmetric branch, :func:`sym_tap`'s order; the
    constant 0 outside the map). Rows of ``out`` on the threads, whole rows at
    a time (the inner loops run along memory).
    """
    H, W = a.shape
    r = (fw.shape[0] - 1) // 2
    for i0 in nb.prange(H):
        i = np.int64(i0)
        w0 = fw[r]
        for j in range(W):
            out[i, j] = a[i, j] * w0
        for jj in range(-r, 0):
            wt = fw[r + jj]
            if axis == 0:
                lo, hi = i + jj, i - jj
                lo_in = lo >= 0
                hi_in = hi < H
                for j in range(W):
                    x = a[lo, j] if lo_in else 0.0
                    y = a[hi, j] if hi_in else 0.0
                    out[i, j] += (x + y) * wt
            else:
                for j in range(W):
                    x = a[i, j + jj] if j + jj >= 0 else 0.0
                    y = a[i, j - jj] if j - jj < W else 0.0
                    out[i, j] += (x + y) * wt


def gaussian_filter_zero(a, sigma):
    """``scipy.ndimage.gaussian_filter(a, sigma, mode="constant")`` of a 2-D map, bit for bit, in parallel.

    The quality metric's blur: the relative L1 error of caustic maps compares
    them after a Gaussian of ``sigma`` texels (one by default), a
    Gaussian-weighted window in the spirit of SSIM, so that a sub-texel shift
    of a sharp caustic is not counted as an error. Zero outside the map: the
    caller zeroes the texels outside the receiver, and nothing is invented
    beyond the border (a constant field therefore darkens within
    ``int(4 sigma + 0.5)`` texels of the border).

    Parameters
    ----------
    a : (H, W) array_like
        Map (float64); other shapes, a radius of 0, or taps that are not
        symmetric to the last bit go through SciPy itself.
    sigma : float
        Standard deviation in texels (> 0).

    Returns
    -------
    (H, W) float64
        Filtered along axis 0, then axis 1, as SciPy filters them.
    """
    fw = scipy_gaussian_taps(sigma)
    r = (len(fw) - 1) // 2
    a = np.asarray(a)
    if a.ndim != 2 or r == 0 or np.any(np.abs(fw[r + 1:] - fw[:r][::-1]) > np.finfo(np.float64).eps):
        return ndimage.gaussian_filter(a, sigma, mode="constant")
    tmp = np.empty(a.shape)
    _correlate_zero(np.ascontiguousarray(a), fw, 0, tmp)
    out = np.empty(a.shape)
    _correlate_zero(tmp, fw, 1, out)
    return out
