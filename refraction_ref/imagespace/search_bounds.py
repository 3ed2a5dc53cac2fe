"""Bounds that restrict the binary search, one per layer (Chaudhari 2008, §3.7).

The search for the intersection with layer ``n`` runs from the current
point to where the ray reaches the layer's largest depth ``Zmax(n)``.

``mip``
    The thesis's way: the layer's MIP level of ``mip_size`` x ``mip_size``
    texels (a box filter, as the GPU builds it; absent texels are left out
    of the average) is reduced with *max* to one value, and a small constant
    is added because an averaged MIP level underestimates the true maximum.
``global``
    The exact maximum over the full-resolution layer (no margin needed).

For the backward searches that follow total internal reflection, the
matching *minimum* bounds (minus the margin) are returned as well.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..schedule import coprime_stride, strided

__all__ = ["search_bounds", "mip_level"]


@nb.njit(cache=True, parallel=True)
def _mip_reduce(ldi, f, zmax, zmin):
    """Max and min over the f x f box-filtered MIP texels of every layer (absent texels skipped).

    One row of MIP texels per task. The layers are packed front to back (a
    texel absent from layer n is absent from every deeper one), so a MIP
    texel's layers are visited only until all its texels are absent: the
    work follows the fragments, not ``L x H x W``.
    """
    L, H, W = ldi.shape
    hb = (H + f - 1) // f
    wb = (W + f - 1) // f
    rhi = np.full((hb, L), -np.inf)
    rlo = np.full((hb, L), np.inf)
    step = coprime_stride(hb)
    for r in nb.prange(hb):
        bi = strided(r, step, hb)  # MIP rows spread over the threads (see ..schedule)
        i0 = bi * f
        i1 = min(i0 + f, H)
        for bj in range(wb):
            j0 = bj * f
            j1 = min(j0 + f, W)
            for n in range(L):
                s = 0.0
                c = 0
                for i in range(i0, i1):
                    for j in range(j0, j1):
                        v = ldi[n, i, j]
                        if v < np.inf:
                            s += v
                            c += 1
                if c == 0:
                    break  # absent here, so from every deeper layer too
                m = s / c
                if m > rhi[bi, n]:
                    rhi[bi, n] = m
                if m < rlo[bi, n]:
                    rlo[bi, n] = m
    for n in range(L):
        hi = -np.inf
        lo = np.inf
        for bi in range(hb):
            hi = max(hi, rhi[bi, n])
            lo = min(lo, rlo[bi, n])
        zmax[n] = hi
        zmin[n] = lo


def mip_level(layer, size):
    """Box-filtered MIP level of a depth image with at most ``size`` texels a side.

    Texels are averaged over ``f x f`` blocks, ``f = ceil(max(H, W) / size)``;
    absent (infinite) texels are excluded, and a block with none present is
    absent (NaN).

    Parameters
    ----------
    layer : (H, W) float
        One layered depth image, ``+inf`` where absent.
    size : int
        Most texels of the MIP level along its longer side.

    Returns
    -------
    (ceil(H / f), ceil(W / f)) float64
        Mean depth of the present texels of each block, NaN where none is.

    References
    ----------
    Chaudhari (2008), §3.7 (MIP level of each layer, reduced to its maximum).
    """
    H, W = layer.shape
    f = max(1, int(np.ceil(max(H, W) / size)))
    Hp, Wp = -(-H // f) * f, -(-W // f) * f
    a = np.full((Hp, Wp), np.nan)
    a[:H, :W] = np.where(np.isfinite(layer), layer, np.nan)
    blocks = a.reshape(Hp // f, f, Wp // f, f)
    valid = np.isfinite(blocks)
    n = valid.sum(axis=(1, 3))
    s = np.where(valid, blocks, 0.0).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, s / np.maximum(n, 1), np.nan)


def search_bounds(ldi, mode="mip", mip_size=256, margin=0.0):
    """Per-layer search bounds.

    Parameters
    ----------
    ldi : (L, H, W) float32 or float64
        Layered depth images (``+inf`` where absent), packed front to back
        as :func:`~refraction_ref.imagespace.peel.peel_layers` writes them:
        a texel absent from layer n is absent from all deeper layers.
    mode : {'mip', 'global'}
    mip_size : int
        MIP level resolution (the thesis uses 256x256 for 512x512 images).
    margin : float
        The small constant added to the MIP maxima (and subtracted from
        the minima), in depth units.

    Returns
    -------
    zmax, zmin : (L,) float64
        Search bounds per layer; ``-inf``/``+inf`` for a layer absent everywhere.

    References
    ----------
    Chaudhari (2008), §3.7; Oliveira and Brauwers (2007), parallel reduction.
    """
    L, H, W = ldi.shape
    zmax = np.full(L, -np.inf)
    zmin = np.full(L, np.inf)
    if mode == "global":
        f = 1
    elif mode == "mip":
        f = max(1, int(np.ceil(max(H, W) / mip_size)))
    else:
        raise ValueError(f"search_bounds: unknown mode {mode!r}; use 'mip' or 'global'")
    if L:
        _mip_reduce(np.ascontiguousarray(ldi), f, zmax, zmin)
    if mode == "mip":
        present = np.isfinite(zmax)
        zmax[present] += margin
        zmin[present] -= margin
    return zmax, zmin
