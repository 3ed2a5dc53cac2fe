"""The octree of nearly constant index, stored densely as leaf levels (§4.2, §5.3).

A min/max pyramid of the index (like a mipmap, or the histogram pyramids of
Ziegler et al. 2007) is read from the coarsest level to the finest; each
voxel is labelled with the first (coarsest) level whose node around it has
a small enough range of n. The result is a dense (nx, ny, nz) array of
levels, 0 being a single voxel and K the whole volume, which a photon reads
at its position to find the node it is in and the distance to that node's
boundary (Fig. 5).

The modified octree of §5.3 adds a per-voxel maximum step: a voxel is
labelled with the coarsest node whose range is below the *secondary*
tolerance eps'; its step is unbounded when that node's range is also below
eps (the node is constant, the photon goes straight to its boundary), and
``ds_max`` voxels (8 in the paper) otherwise.

Any grid size works: nodes of level k cover voxels ``[a 2^k, (a + 1) 2^k)``
clipped to the grid. The level-0 range of a voxel includes its 26
neighbours, because the interpolated n and the central-difference gradient
in a voxel depend on them: a node marked constant then has an exactly zero
gradient everywhere inside it.

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.2 (Fig. 4) and §5.3.
.. [2] G. Ziegler, R. Dimitrov, C. Theobalt, H.-P. Seidel, "Real-Time
   Quadtree Analysis Using HistoPyramids", 2007.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

__all__ = ["minmax_pyramid", "leaf_levels", "build_octree"]


def _reduce(a, fn):
    """2x2x2 reduction with edge replication for odd sizes."""
    pad = [(0, s % 2) for s in a.shape]
    if any(p[1] for p in pad):
        a = np.pad(a, pad, mode="edge")
    s = a.shape
    return fn(a.reshape(s[0] // 2, 2, s[1] // 2, 2, s[2] // 2, 2), axis=(1, 3, 5))


def minmax_pyramid(ior):
    """Min and max of n per node, for levels 0 (dilated voxels) to K (one node).

    Returns
    -------
    list of (nmin, nmax)
        Level k arrays have shape ``ceil(shape / 2^k)``; K = ceil(log2(max shape)).
    """
    n = np.asarray(ior, dtype=np.float64)
    mn = ndimage.minimum_filter(n, size=3, mode="nearest")
    mx = ndimage.maximum_filter(n, size=3, mode="nearest")
    K = max(1, math.ceil(math.log2(max(n.shape))))
    pyr = [(mn, mx)]
    for _ in range(K):
        mn, mx = _reduce(mn, np.min), _reduce(mx, np.max)
        pyr.append((mn, mx))
    return pyr


def _expand(a, k, shape):
    """Node values of level k broadcast to every voxel."""
    for ax in range(3):
        a = np.repeat(a, 2 ** k, axis=ax)
    return a[: shape[0], : shape[1], : shape[2]]


def leaf_levels(pyr, shape, eps, eps2, ds_max):
    """Label every voxel with its leaf level and maximum step (§4.2, §5.3).

    Parameters
    ----------
    pyr : list
        From :func:`minmax_pyramid`.
    shape : (3,) int
    eps, eps2 : float
        Primary and secondary tolerances (0.005 and 0.02 in the paper).
    ds_max : float
        Step limit, in voxels, of nodes whose range is in [eps, eps2).

    Returns
    -------
    level : (nx, ny, nz) int8
    smax : (nx, ny, nz) float32
        Maximum step in voxels (``inf`` inside constant nodes).
    """
    level = np.full(shape, -1, np.int8)
    smax = np.full(shape, np.float32(ds_max), np.float32)
    for k in range(len(pyr) - 1, -1, -1):
        mn, mx = pyr[k]
        rng = mx - mn
        ok2 = rng < eps2
        if not ok2.any():
            continue
        ok2v = _expand(ok2, k, shape)
        okv = _expand(rng < eps, k, shape)
        new = (level < 0) & ok2v
        level[new] = k
        smax[new & okv] = np.inf
    level[level < 0] = 0  # a single voxel is always a node (its range is not constant: ds_min decides)
    return level, smax


def build_octree(ior, eps=0.005, eps2=0.02, ds_max=8.0):
    """Dense leaf-level octree of an index volume.

    Returns
    -------
    level, smax : see :func:`leaf_levels`
    stats : dict
        ``constant_fraction`` (voxels in constant nodes), ``limited_fraction``
        (eps <= range < eps2), ``levels`` histogram, ``constant_index`` (the
        whole volume is one constant node), ``n_min`` / ``n_max`` (the range
        of the index).

    References
    ----------
    Sun et al. (2008), §4.2 and §5.3.
    """
    n = np.asarray(ior)
    pyr = minmax_pyramid(n)
    level, smax = leaf_levels(pyr, n.shape, float(eps), float(eps2), float(ds_max))
    const = np.isinf(smax)
    top_mn, top_mx = pyr[-1]
    stats = {
        "constant_fraction": float(np.count_nonzero(const)) / const.size,
        "limited_fraction": float(np.count_nonzero(~const & (level > 0))) / const.size,
        "levels": np.bincount(level.ravel().astype(np.int64), minlength=len(pyr)).tolist(),
        "constant_index": bool(float(top_mx.max() - top_mn.min()) < eps),
        "n_min": float(top_mn.min()), "n_max": float(top_mx.max()),
    }
    return level, smax, stats
