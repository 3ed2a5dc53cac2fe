"""Peeling layered depth images out of the occupancy bitmask (Chaudhari 2008, §3.4).

Layer ``n`` of a pixel is the ``n``-th set bit of its ``S``-bit mask, counted
from the front; its depth is ``Zmin + b / (S - 1) * (Zmax - Zmin)`` for bit
index ``b`` (§3.4.1).

* :func:`peel_layers` is the separate peeling pass of §3.4.2: one pass over
  every pixel that finds each set bit with a 5-step binary search over the
  bit positions of its 32-bit word and writes up to 32 layered depth images
  (the LDI array).
* :func:`layer_depth_lut` is the on-the-fly variant of §3.4.1: the depth of
  one layer of one pixel, found when the tracer needs it, with look-up tables
  of pre-computed answers for 8-bit values (population count, and the
  position of the k-th set bit of a byte).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..schedule import coprime_stride, strided

__all__ = ["peel_layers", "depth_complexity", "layer_depth_lut", "POPCOUNT8", "SELECT8", "lowest_set_bit"]


def _tables():
    pop = np.zeros(256, np.int64)
    sel = np.full((256, 8), -1, np.int64)
    for v in range(256):
        k = 0
        for b in range(8):
            if v >> b & 1:
                sel[v, k] = b
                k += 1
        pop[v] = k
    return pop, sel


#: population count of every byte, and the index of its k-th set bit
POPCOUNT8, SELECT8 = _tables()


@nb.njit(cache=True, inline="always")
def lowest_set_bit(w):
    """Index of the lowest set bit of a non-zero 32-bit word by binary search (5 steps).

    Parameters
    ----------
    w : uint32
        A non-zero 32-bit word of an occupancy mask.

    Returns
    -------
    int
        Bit position 0..31 of its lowest set bit (the nearest slice of the word).

    References
    ----------
    Chaudhari (2008), §3.4 and Fig. 3.1 (binary search for each set bit).
    """
    x = w & (~w + np.uint32(1))  # isolate the lowest set bit (two's complement)
    pos = 0
    if x & np.uint32(0xFFFF0000):
        pos += 16
    if x & np.uint32(0xFF00FF00):
        pos += 8
    if x & np.uint32(0xF0F0F0F0):
        pos += 4
    if x & np.uint32(0xCCCCCCCC):
        pos += 2
    if x & np.uint32(0xAAAAAAAA):
        pos += 1
    return pos


@nb.njit(cache=True, parallel=True)
def _popcount_kernel(bits, total):
    H, W, K = bits.shape
    step = coprime_stride(H)
    for r in nb.prange(H):
        i = strided(r, step, H)  # rows spread over the threads (see ..schedule)
        for j in range(W):
            n = 0
            for w in range(K):
                word = bits[i, j, w]
                while word != 0:
                    n += 1
                    word = word & (word - np.uint32(1))
            total[i, j] = n


@nb.njit(cache=True, parallel=True)
def _peel_kernel(bits, zlo, zhi, slices, L, ldi):
    H, W, K = bits.shape
    inv = 1.0 / (slices - 1)
    step = coprime_stride(H)
    for r in nb.prange(H):
        i = strided(r, step, H)  # rows spread over the threads (see ..schedule)
        for k in range(L):  # absent everywhere first: contiguous rows, not L scattered writes per pixel
            for j in range(W):
                ldi[k, i, j] = np.inf
        for j in range(W):
            lo = zlo[i, j]
            rng = zhi[i, j] - lo
            n = 0
            for w in range(K):
                word = bits[i, j, w]
                while word != 0 and n < L:
                    b = 32 * w + lowest_set_bit(word)
                    ldi[n, i, j] = lo + b * inv * rng
                    n += 1
                    word = word & (word - np.uint32(1))  # clear the bit just found


def depth_complexity(bits):
    """Set bits per pixel of an occupancy mask, (H, W) int32.

    Parameters
    ----------
    bits : (H, W, S // 32) uint32
        Occupancy masks from :func:`~refraction_ref.imagespace.voxelize.voxelize_bitmask`.

    Returns
    -------
    (H, W) int32
        Number of set bits (occupied slices) of each pixel.

    References
    ----------
    Chaudhari (2008), §3.4 (number of layers to peel).
    """
    total = np.zeros(bits.shape[:2], np.int32)
    _popcount_kernel(np.ascontiguousarray(bits), total)
    return total


def peel_layers(bits, zlo, zhi, slices, layers=32, total=None, peel_all=False):
    """Separate peeling pass: the LDI array of up to ``layers`` depth images.

    Parameters
    ----------
    bits : (H, W, S // 32) uint32
        Occupancy masks from :func:`~refraction_ref.imagespace.voxelize.voxelize_bitmask`.
    zlo, zhi : (H, W) float64
        The depth range the slices span at each pixel.
    slices : int
        S.
    layers : int
        Layer limit (the thesis's is 32: 8 render targets x 4 channels).
        No more layers are peeled than the scene's depth complexity.
    total : (H, W) int32, optional
        :func:`depth_complexity` of ``bits``, if already known.
    peel_all : bool
        Peel all ``layers`` whatever the depth complexity (``L = layers``),
        as the thesis's single pass writes all 32 channels of its 8 render
        targets (§3.4.2); the layers beyond the depth complexity are
        ``+inf`` everywhere.

    Returns
    -------
    ldi : (L, H, W) float32
        Depth of each layer, front to back, ``L = min(layers, max(total))``
        (``L = layers`` with ``peel_all``)
        (32-bit floats, as in the thesis's render targets; also halves the
        tracer's memory traffic);
        ``+inf`` where the pixel has fewer layers.
    total : (H, W) int32
        Set bits per pixel (above ``layers``: the layer limit cuts the
        pixel's depth complexity).

    References
    ----------
    Chaudhari (2008), §3.4.2 and Fig. 3.1.
    """
    H, W, _ = bits.shape
    if total is None:
        total = depth_complexity(bits)
    L = int(layers) if peel_all else int(min(layers, total.max(initial=0)))
    ldi = np.empty((L, H, W), np.float32)
    if L:
        _peel_kernel(np.ascontiguousarray(bits), np.ascontiguousarray(zlo, dtype=np.float64),
                     np.ascontiguousarray(zhi, dtype=np.float64), int(slices), L, ldi)
    return ldi, total


@nb.njit(cache=True)
def layer_depth_lut(bits, i, j, n, lo, hi, slices, pop8, sel8):
    """Depth of layer ``n`` at pixel (i, j) found on the fly with 8-bit look-up tables.

    Returns ``+inf`` when the pixel has ``n`` layers or fewer.

    Parameters
    ----------
    bits : (H, W, S // 32) uint32
        Occupancy masks.
    i, j : int
        Pixel row and column.
    n : int
        Layer index, 0 the nearest.
    lo, hi : float
        Depth range the pixel's slices span (view-space depth).
    slices : int
        S.
    pop8 : (256,) int64
        :data:`POPCOUNT8`, the population count of every byte.
    sel8 : (256, 8) int64
        :data:`SELECT8`, the index of the k-th set bit of every byte.

    Returns
    -------
    float
        View-space depth of the layer, ``lo + b / (S - 1) * (hi - lo)`` for
        its bit index ``b``.

    References
    ----------
    Chaudhari (2008), §3.4.1.
    """
    K = bits.shape[2]
    for w in range(K):
        word = bits[i, j, w]
        for byte in range(4):
            v = (word >> np.uint32(8 * byte)) & np.uint32(0xFF)
            c = pop8[v]
            if n < c:
                b = 32 * w + 8 * byte + sel8[v, n]
                return lo + b / (slices - 1) * (hi - lo)
            n -= c
    return np.inf
