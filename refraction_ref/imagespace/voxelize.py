"""Bitmask voxelization into S slices (Chaudhari 2008, §3.3).

Each fragment sets the bit of its slice ``b = round((d - Zmin) / (Zmax -
Zmin) * (S - 1))`` in a per-pixel occupancy mask of ``S`` bits, stored as
``S / 32`` uint32 words (word ``w`` holds slices ``32 w .. 32 w + 31``,
nearest first). ``Zmin``/``Zmax`` are the pixel's local bounds (the
thesis's choice, a distorted but tight grid) or the global bounds.

Blending is logical OR, or - as on the thesis's Direct3D 10 hardware, which
had no logical-OR blend - a 32-bit *add*: two fragments in one slice then
carry into the next bit ("the location of the feature would be shifted by
one voxel"), and a carry out of bit 31 of a word is lost.

The float-depth variant (``depth='float'``) keeps the exact fragment depths
instead (an A-buffer), to separate the bitmask's quantisation error from
the rest of the method.
"""

from __future__ import annotations

import numpy as np

from ..raster import rasterize

__all__ = ["voxelize_bitmask", "collect_depths", "slice_bounds"]


def slice_bounds(zmin, zmax, slicing="local"):
    """The depth range each pixel's slices span: local bounds or the global ones.

    Parameters
    ----------
    zmin, zmax : (H, W) float64
        Local depth bounds of the min/max pass (``+inf`` / ``-inf`` where
        uncovered).
    slicing : {'local', 'global'}
        ``'local'`` returns the per-pixel bounds as they are (the thesis's
        choice); anything else fills the image with the extremes over the
        covered pixels (0 for an empty view).

    Returns
    -------
    zlo, zhi : (H, W) float64

    References
    ----------
    Chaudhari (2008), §3.3 (slicing between local or global bounds).
    """
    if slicing == "local":
        return zmin, zmax
    cov = np.isfinite(zmin)
    lo = float(zmin[cov].min()) if cov.any() else 0.0
    hi = float(zmax[cov].max()) if cov.any() else 0.0
    return np.full_like(zmin, lo), np.full_like(zmax, hi)


def voxelize_bitmask(tri_view, camera, zlo, zhi, slices=256, blend="add"):
    """Rasterize the mesh into per-pixel occupancy bitmasks.

    Parameters
    ----------
    tri_view : (T, 3, 3) ndarray, RasterSetup or Fragments
        Triangles in view space (see :func:`~refraction_ref.raster.raster_setup`),
        or the fragments the min/max pass recorded (the same fragments, so
        the same result, without rasterizing the mesh a second time).
    camera : Camera
    zlo, zhi : (H, W) ndarray
        Depth range of the slices at each pixel (see :func:`slice_bounds`).
    slices : int
        S, a multiple of 32 (default 256, the thesis's 8 render targets of
        32 bits).
    blend : {'add', 'or'}, default 'add'
        The GPU's additive blending with carry (``imagespace.blend``'s
        default, §3.3), or a logical OR.

    Returns
    -------
    (H, W, S // 32) uint32

    References
    ----------
    Chaudhari (2008), §3.3; Eisemann and Décoret (2006).
    """
    return rasterize(tri_view, camera, blend, bounds=(zlo, zhi), slices=slices, clip=True)


def collect_depths(tri_view, camera, capacity=32):
    """Exact fragment depths per pixel, sorted front to back (an A-buffer).

    Parameters
    ----------
    tri_view : (T, 3, 3) ndarray or RasterSetup
        Triangles in view space (clipped to the near plane by
        :func:`~refraction_ref.raster.raster_setup` when given raw).
    camera : Camera
    capacity : int
        Most fragment depths kept per pixel.

    Returns
    -------
    depths : (L, H, W) float32
        ``+inf`` where a pixel has fewer fragments (32-bit, like the LDI
        array); ``L = min(capacity, max(total))``.
    total : (H, W) int32
        All fragments of the pixel, including those beyond ``capacity``.

    References
    ----------
    Chaudhari (2008), §3.3 (the float-depth variant keeps the fragment depths
    the bitmask of §3.3 quantises).
    """
    total = rasterize(tri_view, camera, "count", clip=True)
    cap = int(min(capacity, total.max(initial=0)))  # never more than the depth complexity
    d, n = rasterize(tri_view, camera, "collect", capacity=max(cap, 1), clip=True)
    return d[:cap].astype(np.float32), n
