"""Gradient of the index of refraction by central differences (§3, eq. 3; §4.4).

The photon and viewing passes need n and its gradient at arbitrary points
(eqs. 4-5). They read both from one packed array ``field[..., 0:4] = (n,
dn/dx, dn/dy, dn/dz)`` of float32, trilinearly interpolated between voxel
centres, so that one cache line serves the four values of a corner.

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §3 (eqs. 1-5) and §4.4; Table 1 lists
   "gradient generation after voxelization" as one of the stages.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["gradient_field", "voxel_size"]


def voxel_size(bounds, shape):
    """Per-axis voxel size ``(hi - lo) / shape`` of a volume.

    Parameters
    ----------
    bounds : (2, 3) array_like
        World-space lower and upper corners of the volume.
    shape : tuple of int
        Voxels per axis (only the first three entries are read).

    Returns
    -------
    (3,) float64
        Voxel side along x, y, z in world units.

    References
    ----------
    Sun et al. (2008), §4.1 (the voxel grid) and §4.4 (eq. 3's differences).
    """
    b = np.asarray(bounds, dtype=np.float64)
    return (b[1] - b[0]) / np.asarray(shape[:3], dtype=np.float64)


@nb.njit(cache=True, parallel=True)
def _central(n, hx, hy, hz, out):
    nx, ny, nz = n.shape
    for i in nb.prange(nx):
        i0 = max(i - 1, 0)
        i1 = min(i + 1, nx - 1)
        for j in range(ny):
            j0 = max(j - 1, 0)
            j1 = min(j + 1, ny - 1)
            for k in range(nz):
                k0 = max(k - 1, 0)
                k1 = min(k + 1, nz - 1)
                out[i, j, k, 0] = n[i, j, k]
                out[i, j, k, 1] = (n[i1, j, k] - n[i0, j, k]) / ((i1 - i0) * hx)
                out[i, j, k, 2] = (n[i, j1, k] - n[i, j0, k]) / ((j1 - j0) * hy)
                out[i, j, k, 3] = (n[i, j, k1] - n[i, j, k0]) / ((k1 - k0) * hz)


def gradient_field(ior, bounds):
    """Pack n and its central-difference gradient into one array.

    Parameters
    ----------
    ior : (nx, ny, nz) array_like
        Index of refraction at voxel centres.
    bounds : (2, 3) array_like
        World-space corners of the volume.

    Returns
    -------
    (nx, ny, nz, 4) float32
        ``(n, dn/dx, dn/dy, dn/dz)`` in world units; one-sided differences
        on the faces of the volume.

    References
    ----------
    Sun et al. (2008), §3 eq. 3 (dv/ds = grad n).
    """
    n = np.ascontiguousarray(ior, dtype=np.float64)
    h = voxel_size(bounds, n.shape)
    out = np.empty(n.shape + (4,), np.float32)
    _central(n, float(h[0]), float(h[1]), float(h[2]), out)
    return out
