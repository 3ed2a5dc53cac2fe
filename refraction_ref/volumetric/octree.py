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
clipped to the grid. With ``dilate`` (``volumetric.stepping = 'robust'``)
the level-0 range of a voxel includes its 26 neighbours, because the
interpolated n and the central-difference gradient in a voxel depend on
them: a node is marked constant only when every index its voxels'
interpolation and differences read lies within the tolerance, so its gradient
is small there (at most the tolerance over the voxel size), not exactly zero,
and the march crosses it in one straight step. Without it (``stepping = 'paper'``, §4.2 as written) a voxel's
level-0 range is its own value (zero), so every voxel is at least a
constant level-0 node.

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.2 (Fig. 4) and §5.3.
.. [2] G. Ziegler, R. Dimitrov, C. Theobalt, H.-P. Seidel, "Real-Time
   Quadtree Analysis Using HistoPyramids", 2007.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .knobs import VOLUMETRIC_DEFAULTS, octree_dilations

#: the knobs' defaults: a function's default is the scene's (Sun et al. 2008's own settings)
_D = VOLUMETRIC_DEFAULTS
#: level-0 dilation of the default stepping ('paper': none)
_DILATE = octree_dilations(_D["stepping"])[0]

__all__ = ["minmax_pyramid", "leaf_levels", "build_octree"]


@nb.njit(cache=True, parallel=True)
def _dilate_minmax(n, mn, mx):
    """Min and max of every voxel's 3x3x3 neighbourhood (edges clamped); parallel over x slabs."""
    nx, ny, nz = n.shape
    for i in nb.prange(nx):
        for j in range(ny):
            for k in range(nz):
                a = n[i, j, k]
                b = a
                for ii in range(max(i - 1, 0), min(i + 2, nx)):
                    for jj in range(max(j - 1, 0), min(j + 2, ny)):
                        for kk in range(max(k - 1, 0), min(k + 2, nz)):
                            v = n[ii, jj, kk]
                            if v < a:
                                a = v
                            if v > b:
                                b = v
                mn[i, j, k] = a
                mx[i, j, k] = b


@nb.njit(cache=True, parallel=True)
def _copy_minmax(n, mn, mx):
    """Level 0 without dilation: min = max = the voxel's own value (§4.2); parallel over x slabs."""
    nx, ny, nz = n.shape
    for i in nb.prange(nx):
        for j in range(ny):
            for k in range(nz):
                mn[i, j, k] = n[i, j, k]
                mx[i, j, k] = n[i, j, k]


@nb.njit(cache=True, parallel=True)
def _reduce_minmax(mn, mx, omn, omx):
    """2x2x2 min / max reduction, odd sizes by edge replication; parallel over the coarse x slabs."""
    nx, ny, nz = mn.shape
    ox, oy, oz = omn.shape
    for a in nb.prange(ox):
        for b in range(oy):
            for c in range(oz):
                lo = mn[2 * a, 2 * b, 2 * c]
                hi = mx[2 * a, 2 * b, 2 * c]
                for i in range(2 * a, min(2 * a + 2, nx)):
                    for j in range(2 * b, min(2 * b + 2, ny)):
                        for k in range(2 * c, min(2 * c + 2, nz)):
                            if mn[i, j, k] < lo:
                                lo = mn[i, j, k]
                            if mx[i, j, k] > hi:
                                hi = mx[i, j, k]
                omn[a, b, c] = lo
                omx[a, b, c] = hi


def _pyramid_flat(n, dilate):
    """The pyramid in two flat buffers (min, max), with per-level offsets and shapes."""
    K = max(1, math.ceil(math.log2(max(n.shape))))
    shapes = [tuple(n.shape)]
    for _ in range(K):
        shapes.append(tuple((s + 1) // 2 for s in shapes[-1]))
    sizes = [int(np.prod(s)) for s in shapes]
    off = np.zeros(len(shapes) + 1, np.int64)
    np.cumsum(sizes, out=off[1:])
    fmn = np.empty(off[-1])
    fmx = np.empty(off[-1])
    lv = [(fmn[off[k]:off[k + 1]].reshape(shapes[k]), fmx[off[k]:off[k + 1]].reshape(shapes[k]))
          for k in range(len(shapes))]
    if dilate:
        _dilate_minmax(n, *lv[0])
    else:
        _copy_minmax(n, *lv[0])
    for k in range(K):
        _reduce_minmax(*lv[k], *lv[k + 1])
    return lv, fmn, fmx, off, np.array(shapes, np.int64)


def minmax_pyramid(ior, dilate=_DILATE):
    """Min and max of n per node, for levels 0 (voxels) to K (one node).

    Parameters
    ----------
    ior : (nx, ny, nz) array_like
        Index of refraction at voxel centres.
    dilate : bool
        Level 0 spans each voxel's 3x3x3 neighbourhood (``stepping =
        'robust'``); without it (the default stepping, 'paper') a voxel's
        range is its own value.

    Returns
    -------
    list of (nmin, nmax)
        Level k arrays have shape ``ceil(shape / 2^k)``; K = ceil(log2(max shape)).

    References
    ----------
    Sun et al. (2008), §4.2 (Fig. 4) and §5.3.
    """
    n = np.ascontiguousarray(ior, dtype=np.float64)
    return _pyramid_flat(n, dilate)[0]


@nb.njit(cache=True, parallel=True)
def _leaf_kernel(fmn, fmx, off, shapes, eps, eps2, ds_max, level, step_max):
    """Per voxel: the coarsest level whose node range is < eps2, and inf step if < eps (parallel over x)."""
    nx, ny, nz = level.shape
    K = shapes.shape[0] - 1
    for i in nb.prange(nx):
        for j in range(ny):
            for k in range(nz):
                lev = 0
                sm = np.float32(ds_max)
                for L in range(K, -1, -1):
                    q = off[L] + ((i >> L) * shapes[L, 1] + (j >> L)) * shapes[L, 2] + (k >> L)
                    rng = fmx[q] - fmn[q]
                    if rng < eps2:
                        lev = L
                        if rng < eps:
                            sm = np.float32(np.inf)
                        break
                level[i, j, k] = lev
                step_max[i, j, k] = sm


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
    step_max : (nx, ny, nz) float32
        Maximum step in voxels (``inf`` inside constant nodes).

    References
    ----------
    Sun et al. (2008), §4.2 and §5.3 (secondary tolerance, maximum step).
    """
    shapes = np.array([m.shape for m, _ in pyr], np.int64)
    off = np.zeros(len(pyr) + 1, np.int64)
    np.cumsum([m.size for m, _ in pyr], out=off[1:])
    fmn = np.concatenate([np.ravel(m) for m, _ in pyr]).astype(np.float64)
    fmx = np.concatenate([np.ravel(m) for _, m in pyr]).astype(np.float64)
    return _leaf_flat(fmn, fmx, off, shapes, shape, eps, eps2, ds_max)


def _leaf_flat(fmn, fmx, off, shapes, shape, eps, eps2, ds_max):
    level = np.empty(tuple(int(s) for s in shape), np.int8)
    step_max = np.empty(level.shape, np.float32)
    _leaf_kernel(fmn, fmx, off, shapes, float(eps), float(eps2), float(ds_max), level, step_max)
    return level, step_max


def build_octree(ior, eps=_D["eps"], eps2=_D["eps2"], ds_max=_D["ds_max"], dilate=_DILATE):
    """Dense leaf-level octree of an index volume.

    Parameters
    ----------
    ior : (nx, ny, nz) array
    eps, eps2, ds_max : float
        Tolerances and step limit (§5.3).
    dilate : bool
        Level-0 ranges over each voxel's 3x3x3 neighbourhood (the 'robust'
        stepping), or each voxel's own value (the paper's §4.2, ``stepping =
        'paper'``, the default); :func:`~refraction_ref.volumetric.knobs.octree_dilations`
        says which each pass reads.

    Returns
    -------
    level, step_max : see :func:`leaf_levels`
    stats : dict
        ``constant_fraction`` (voxels in constant nodes), ``limited_fraction``
        (eps <= range < eps2), ``levels`` histogram, ``constant_index`` (the
        whole volume is one constant node), ``n_min`` / ``n_max`` (the range
        of the index).

    References
    ----------
    Sun et al. (2008), §4.2 and §5.3.
    """
    n = np.ascontiguousarray(ior, dtype=np.float64)
    pyr, fmn, fmx, off, shapes = _pyramid_flat(n, bool(dilate))  # parallel kernels; min / max are exact in any order
    level, step_max = _leaf_flat(fmn, fmx, off, shapes, n.shape, float(eps), float(eps2), float(ds_max))
    const = np.isinf(step_max)
    top_mn, top_mx = pyr[-1]
    stats = {
        "constant_fraction": float(np.count_nonzero(const)) / const.size,
        "limited_fraction": float(np.count_nonzero(~const & (level > 0))) / const.size,
        "levels": np.bincount(level.ravel().astype(np.int64), minlength=len(pyr)).tolist(),
        "constant_index": bool(float(top_mx.max() - top_mn.min()) < eps),
        "n_min": float(top_mn.min()), "n_max": float(top_mx.max()),
    }
    return level, step_max, stats
