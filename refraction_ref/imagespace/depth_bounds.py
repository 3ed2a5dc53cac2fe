"""Min / max depth pass (Chaudhari 2008, §3.3).

The mesh is rasterized once without culling or hidden-surface removal, and
each pixel keeps the smallest (Zmin) and largest (Zmax) fragment depth: the
thesis writes ``d`` and ``Zfar - d`` to two channels with *max* blending.
These per-pixel *local bounds* make the slicing of the voxelization pass
tight; the *global bounds* are their extremes over the image.
"""

from __future__ import annotations

import numpy as np

from ..raster import rasterize

__all__ = ["depth_bounds", "global_bounds"]


def depth_bounds(tri_view, camera, keep_fragments=False):
    """Per-pixel local depth bounds.

    Parameters
    ----------
    tri_view : (T, 3, 3) ndarray or RasterSetup
        Triangles in view space, as :func:`~refraction_ref.raster.rasterize` takes them.
    camera : Camera
        The view they are rasterized in.
    keep_fragments : bool
        Also return the fragments.

    Returns
    -------
    zmin, zmax : (H, W) float64
        Nearest and farthest fragment depth; ``+inf`` / ``-inf`` where no
        fragment was drawn.
    fragments : Fragments or None
        Only with ``keep_fragments``: this pass's fragments, which the
        voxelization pass blends again instead of re-rasterizing the mesh.

    References
    ----------
    Chaudhari (2008), §3.3, first rendering pass.
    """
    return rasterize(tri_view, camera, "minmax", clip=True, keep_fragments=keep_fragments)


def global_bounds(zmin, zmax):
    """Global object bounds (scalars) from the local ones; (inf, -inf) for an empty view.

    Uncovered pixels hold ``zmin = +inf`` and ``zmax = -inf``, so the plain
    extremes are the bounds of the covered ones.

    Parameters
    ----------
    zmin, zmax : (H, W) float64
        Local depth bounds from :func:`depth_bounds` (``+inf`` / ``-inf`` where
        no fragment was drawn).

    Returns
    -------
    lo, hi : float
        Smallest ``zmin`` and largest ``zmax`` over the image, view-space depth;
        ``(inf, -inf)`` when no pixel is covered.

    References
    ----------
    Chaudhari (2008), §3.3 (global bounds of the voxelization's slicing).
    """
    if zmin.size == 0:
        return np.inf, -np.inf
    lo, hi = float(np.min(zmin)), float(np.max(zmax))
    if not np.isfinite(lo):
        return np.inf, -np.inf
    return lo, hi
