"""Smoothing of the stored radiance: a 3x3x3 approximate Gaussian, then unit mean directions (§4.4).

The radiance the photons stored is smoothed before the viewing pass reads
it: ``[1, 2, 1] / 4`` along x, y and z in turn (the passes of
:func:`~refraction_ref.filters.separable_correlate`, the same values), then
the radiance-weighted direction of each voxel normalised.

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.4 and §5.1.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..filters import sym_tap

__all__ = ["smooth_radiance"]


def smooth_radiance(sums):
    """3x3x3 approximate Gaussian ([1, 2, 1] / 4 per axis) of the deposits, then unit directions (§4.4).

    Parameters
    ----------
    sums : (nx, ny, nz, 6) float64
        Deposited radiance (RGB) and radiance-weighted direction
        (:func:`~refraction_ref.volumetric.march.march_photons`).

    Returns
    -------
    radiance : (nx, ny, nz, 3) float32
    direction : (nx, ny, nz, 3) float32
        Unit mean photon direction (zero where no photon passed).

    References
    ----------
    Sun et al. (2008), §4.4 (smoothing of the stored radiance) and §5.1.
    """
    # filters.separable_correlate (x, then y, then z passes; bit-identical to scipy) and the split, fused one
    # x slab at a time: every value is formed by the same operations, but no intermediate volume is written
    w = np.array([0.25, 0.5, 0.25])
    src = np.ascontiguousarray(sums, dtype=np.float64)
    rad = np.empty(src.shape[:3] + (3,), np.float32)
    direction = np.empty(src.shape[:3] + (3,), np.float32)
    nx = src.shape[0]
    chunks = max(1, min(nx, 4 * nb.get_num_threads()))  # slabs per chunk: any split gives the same values
    _smooth_split(src, w, np.linspace(0, nx, chunks + 1).astype(np.int64), rad, direction)
    return rad, direction


@nb.njit(cache=True, parallel=True)
def _smooth_split(a, w, bounds, rad, direction):
    """``filters.sym_tap`` along x, y, then z (the passes of ``filters.separable_correlate``), then the split:
    radiance rounded to float32, and the unit direction by the operations of ``np.linalg.norm(d, axis=-1)``
    (sqrt of the squares summed in order) and ``d / norm`` where the norm is > 0, rounded to float32;
    slab by slab, parallel over chunks of x slabs (``bounds``), each with its own scratch."""
    nx, ny, nz, nc = a.shape
    r = w.shape[0] // 2
    for ch in nb.prange(bounds.shape[0] - 1):
        xb = np.empty((ny, nz, nc))
        zb = np.empty((nz, nc))
        yrow = np.empty((nz, nc))
        for i in range(bounds[ch], bounds[ch + 1]):
            for j in range(ny):
                for k in range(nz):
                    line = a[:, j, k, :]
                    for c in range(nc):
                        xb[j, k, c] = sym_tap(line, i, c, w, r)
            for j in range(ny):
                for k in range(nz):
                    line = xb[:, k, :]
                    for c in range(nc):
                        yrow[k, c] = sym_tap(line, j, c, w, r)
                for k in range(nz):
                    for c in range(nc):
                        zb[k, c] = sym_tap(yrow, k, c, w, r)
                for k in range(nz):
                    for c in range(3):
                        rad[i, j, k, c] = np.float32(zb[k, c])
                    d0 = zb[k, 3]
                    d1 = zb[k, 4]
                    d2 = zb[k, 5]
                    nrm = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                    if nrm > 0:
                        direction[i, j, k, 0] = np.float32(d0 / nrm)
                        direction[i, j, k, 1] = np.float32(d1 / nrm)
                        direction[i, j, k, 2] = np.float32(d2 / nrm)
                    else:
                        direction[i, j, k, 0] = np.float32(0.0)
                        direction[i, j, k, 1] = np.float32(0.0)
                        direction[i, j, k, 2] = np.float32(0.0)
