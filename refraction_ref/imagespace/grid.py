"""The voxel grid's x-y size (``imagespace.grid``), apart from the image's (Chaudhari 2008, §3.3, §4.1-4.2).

The thesis renders a 512x512 viewport and varies the size of the bitmask and
layered-depth textures (256x256 or 512x512, Tables 4.1-4.2). The passes of
§3.3-3.5 (min/max, voxelization, peeling, reduction, normals) run on a camera
with the image's view (the same field of view and aspect) and the grid's
pixel count; the trace still casts one ray per image pixel and samples the
layers at the ray's position in grid coordinates.

Importing this module is cheap (no kernels).
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["grid_size", "grid_camera", "at_pixels"]


def grid_size(grid, width, height):
    """The grid's ``(width, height)``: ``grid`` itself, or the image's size when it is None.

    Parameters
    ----------
    grid : sequence of 2 int or None
        ``imagespace.grid``.
    width, height : int
        The image's size.

    Returns
    -------
    (int, int)

    References
    ----------
    Chaudhari (2008), §3.3 (the bitmask texture's x-y size).
    """
    return (int(width), int(height)) if grid is None else (int(grid[0]), int(grid[1]))


def grid_camera(cam, grid):
    """The view the grid's passes render: ``cam`` with the grid's pixel count (same view).

    Parameters
    ----------
    cam : Camera
        The image's camera.
    grid : sequence of 2 int or None
        ``imagespace.grid`` (None: the image's size, ``cam`` itself).

    Returns
    -------
    Camera
        ``cam`` itself when the sizes agree (every output then bit-identical
        to a render without the knob), else a copy with the grid's width and
        height; its ``sx``, ``sy`` equal ``cam``'s since the aspects agree
        (:func:`~refraction_ref.imagespace.knobs.validate_imagespace`).

    References
    ----------
    Chaudhari (2008), §3.3 (the bitmask texture's x-y size), §4.1-4.2 (a
    512x512 viewport with 256x256 or 512x512 textures).
    """
    gw, gh = grid_size(grid, cam.width, cam.height)
    if (gw, gh) == (cam.width, cam.height):
        return cam
    return dataclasses.replace(cam, width=gw, height=gh)


def at_pixels(a, shape):
    """A grid-shaped array read at each image pixel's centre (the grid texel under it).

    Parameters
    ----------
    a : (Hg, Wg, ...) ndarray
        A per-texel array of the grid.
    shape : (H, W)
        The image's size.

    Returns
    -------
    (H, W, ...) ndarray
        ``a`` itself when the shapes agree, else ``a[rows, cols]`` with the
        texel under each pixel centre (row ``floor((i + 0.5) Hg / H)``).

    References
    ----------
    Chaudhari (2008), §3.3 (the per-texel depth range of the bitmask grid), §4.1-4.2.
    """
    H, W = shape
    Hg, Wg = a.shape[:2]
    if (Hg, Wg) == (H, W):
        return a
    rows = np.floor((np.arange(H) + 0.5) * Hg / H).astype(np.intp)
    cols = np.floor((np.arange(W) + 0.5) * Wg / W).astype(np.intp)
    return a[rows[:, None], cols[None, :]]
