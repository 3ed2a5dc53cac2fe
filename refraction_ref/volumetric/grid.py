"""The voxel grid the photons and viewing rays cross: where a point lies, and n and grad n there (§4.4).

A volume of ``(nx, ny, nz)`` voxels spans the world box ``[lo, hi]``; voxel
``(i, j, k)`` is centred at ``lo + (i + 0.5, j + 0.5, k + 0.5) h``. Every
pass reads it through the helpers here:

* :func:`volume_box` places the grid (:class:`VolumeBox`);
* :func:`cell` and :func:`voxel_of`: the voxel holding a point;
* :func:`node_distance`: the distance to the boundary of the octree node
  holding it (Fig. 5), the march's step;
* :func:`segment_exit`: how much of a step stays inside the box;
* :func:`sample_field`: n and its gradient, trilinear between voxel centres
  (what eqs. 4-5 read);
* :func:`half_contrast`: the index level that counts as refractive material.

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.4, §4.5 and Fig. 5.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

__all__ = ["VolumeBox", "volume_box", "cell", "voxel_segment", "dda_start", "voxel_of", "node_distance", "segment_exit",
           "sample_field", "half_contrast"]


class VolumeBox(NamedTuple):
    """Where the voxel grid lies in the world (:func:`volume_box`)."""

    lo: np.ndarray  # (3,) float64 lower corner
    hi: np.ndarray  # (3,) float64 upper corner
    h: np.ndarray  # (3,) float64 voxel size
    ih: np.ndarray  # (3,) float64 1 / h
    shape_n: np.ndarray  # (3,) int64 voxels per axis
    hmin: float  # smallest voxel side


def volume_box(bounds, shape):
    """The :class:`VolumeBox` of a volume of ``shape`` voxels spanning ``bounds``.

    Parameters
    ----------
    bounds : (2, 3) array_like
        World-space lower and upper corners.
    shape : tuple of int
        Voxels per axis (the first three entries are read).

    Returns
    -------
    VolumeBox

    References
    ----------
    Sun et al. (2008), §4.1 (the voxel grid).
    """
    b = np.asarray(bounds, dtype=np.float64)
    shape_n = np.asarray(shape[:3], dtype=np.int64)
    h = (b[1] - b[0]) / shape_n
    return VolumeBox(b[0].copy(), b[1].copy(), h, 1.0 / h, shape_n, float(h.min()))


@nb.njit(cache=True, inline="always")
def cell(u, na):
    """``min(max(floor(u), 0), na - 1)`` (truncation is floor for u >= 0; NaN -> 0).

    Parameters
    ----------
    u : float
        Coordinate in voxel units along one axis.
    na : int
        Voxels along that axis.

    Returns
    -------
    int
        Voxel index in ``0 .. na - 1``.

    References
    ----------
    Sun et al. (2008), §4.4 (voxel of the photon).
    """
    if not u > 0.0:
        return 0
    c = int(u)
    return c if c < na - 1 else na - 1


@nb.njit(cache=True, inline="always")
def voxel_segment(lo, ih, a, b):
    """The segment a -> b in voxel units: its start and its end minus its start.

    Parameters
    ----------
    lo, ih : (3,) float64
        Lower corner and inverse voxel size of the volume.
    a, b : 3-tuples of float
        The segment's ends, world units.

    Returns
    -------
    tuple of 6 floats
        ``(u0, w0, t0, du, dw, dt)``, the input of :func:`dda_start`.

    References
    ----------
    Sun et al. (2008), §4.1 (the voxel grid).
    """
    ax, ay, az = a
    bx, by, bz = b
    u0 = (ax - lo[0]) * ih[0]
    w0 = (ay - lo[1]) * ih[1]
    t0 = (az - lo[2]) * ih[2]
    return u0, w0, t0, (bx - lo[0]) * ih[0] - u0, (by - lo[1]) * ih[1] - w0, (bz - lo[2]) * ih[2] - t0


@nb.njit(cache=True, inline="always")
def dda_start(u0, w0, t0, du, dw, dt, nx, ny, nz):
    """The first voxel and the steps of a 3D DDA walk along ``u0 + t du`` (voxel units), ``t`` in [0, 1].

    Parameters
    ----------
    u0, w0, t0 : float
        The segment's start, voxel units.
    du, dw, dt : float
        The segment's end minus its start, voxel units.
    nx, ny, nz : int
        Voxels along each axis.

    Returns
    -------
    tuple
        ``(i, j, k, si, sj, sk, ti, tj, tk, di, dj, dk)``: the start voxel
        (:func:`cell`), the step sign per axis, ``t`` at the first boundary
        crossed on each axis and ``t`` between two boundaries on it (``inf``
        along an axis the segment does not move on).

    References
    ----------
    Sun et al. (2008), §4.3 and §4.4 (the voxels a segment crosses); Amanatides
    and Woo (1987).
    """
    i = cell(u0, nx)
    j = cell(w0, ny)
    k = cell(t0, nz)
    si = 1 if du > 0 else -1
    sj = 1 if dw > 0 else -1
    sk = 1 if dt > 0 else -1
    ti = ((i + (1 if du > 0 else 0)) - u0) / du if du != 0.0 else np.inf
    tj = ((j + (1 if dw > 0 else 0)) - w0) / dw if dw != 0.0 else np.inf
    tk = ((k + (1 if dt > 0 else 0)) - t0) / dt if dt != 0.0 else np.inf
    di = abs(1.0 / du) if du != 0.0 else np.inf
    dj = abs(1.0 / dw) if dw != 0.0 else np.inf
    dk = abs(1.0 / dt) if dt != 0.0 else np.inf
    return i, j, k, si, sj, sk, ti, tj, tk, di, dj, dk


@nb.njit(cache=True, inline="always")
def voxel_of(lo, ih, nx, ny, nz, x, y, z):
    """Voxel ``(i, j, k)`` holding a world point, clamped to the grid.

    Parameters
    ----------
    lo, ih : (3,) float64
        Lower corner and inverse voxel size of the volume.
    nx, ny, nz : int
        Voxels per axis.
    x, y, z : float
        World point.

    Returns
    -------
    i, j, k : int
        Voxel indices (:func:`cell` per axis).

    References
    ----------
    Sun et al. (2008), §4.4 (octree node of the photon's voxel).
    """
    return cell((x - lo[0]) * ih[0], nx), cell((y - lo[1]) * ih[1], ny), cell((z - lo[2]) * ih[2], nz)


@nb.njit(cache=True, inline="always")
def _axis_distance(xa, da, lo, h, ih, na, lev):
    if da == 0.0:
        return np.inf
    u = (xa - lo) * ih
    c = int(u) if u > 0.0 else 0
    b0 = (c >> lev) << lev  # the node's first voxel (nodes of level lev cover 2^lev voxels)
    if da > 0.0:
        return (min(b0 + (1 << lev), na) - u) * h / da
    return (b0 - u) * h / da


@nb.njit(cache=True, inline="always")
def node_distance(box, lev, p, d):
    """Distance along the unit direction d from p to the boundary of its level-``lev`` node (Fig. 5).

    Parameters
    ----------
    box : VolumeBox or a named tuple with its fields
        ``lo``, ``h``, ``ih`` and ``shape_n`` place the grid.
    lev : int
        Octree level of the node (a level-``lev`` node spans ``2**lev`` voxels).
    p : 3-tuple of float
        World point inside the node.
    d : 3-tuple of float
        Unit direction.

    Returns
    -------
    float
        Distance (world units, >= 0) to the node's boundary; ``inf`` when the
        direction is zero.

    References
    ----------
    Sun et al. (2008), §4.4 and Fig. 5 (step to the leaf node's boundary).
    """
    lo, h, ih, shape_n = box.lo, box.h, box.ih, box.shape_n
    x, y, z = p
    dx, dy, dz = d
    t = min(_axis_distance(x, dx, lo[0], h[0], ih[0], shape_n[0], lev),
            min(_axis_distance(y, dy, lo[1], h[1], ih[1], shape_n[1], lev),
                _axis_distance(z, dz, lo[2], h[2], ih[2], shape_n[2], lev)))
    return max(t, 0.0)


@nb.njit(cache=True, inline="always")
def segment_exit(lo, hi, x, y, z, x1, y1, z1):
    """Fraction s in [0, 1] of the segment x -> x1 still inside the box (1 when x1 is inside).

    Parameters
    ----------
    lo, hi : (3,) float64
        Corners of the box.
    x, y, z : float
        Segment start (inside the box).
    x1, y1, z1 : float
        Segment end.

    Returns
    -------
    float
        Fraction of the segment inside, in ``[0, 1]``.

    References
    ----------
    Sun et al. (2008), §4.4 (a photon leaving the volume).
    """
    s = 1.0
    for a in range(3):
        p0 = x if a == 0 else (y if a == 1 else z)
        p1 = x1 if a == 0 else (y1 if a == 1 else z1)
        d = p1 - p0
        if p1 > hi[a] and d > 0.0:
            s = min(s, (hi[a] - p0) / d)
        elif p1 < lo[a] and d < 0.0:
            s = min(s, (lo[a] - p0) / d)
    return max(s, 0.0)


@nb.njit(cache=True, inline="always")
def _lerp_axis(u, na):
    """Cell index and fraction of trilinear interpolation along one axis, clamped (NaN -> cell 0)."""
    if not u >= 0.0:
        return 0, 0.0
    if u >= na - 1:
        return na - 2, 1.0
    c = int(u)  # truncation is floor for u >= 0
    return c, u - c


@nb.njit(cache=True)  # a call, not inlined: its callers would compile its body at every call site
def sample_field(field, lo, ih, x, y, z):
    """Trilinear (n, dn/dx, dn/dy, dn/dz) at a world point (clamped to the volume).

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and its gradient at voxel centres
        (:func:`~refraction_ref.volumetric.gradient.gradient_field`).
    lo : (3,) float64
        Lower corner of the volume, world units.
    ih : (3,) float64
        Inverse voxel size per axis.
    x, y, z : float
        World point.

    Returns
    -------
    n, dndx, dndy, dndz : float
        Interpolated index and gradient (per world unit).

    References
    ----------
    Sun et al. (2008), §4.4 (n and its gradient at the photon, eqs. 4-5).
    """
    nx, ny, nz = field.shape[0], field.shape[1], field.shape[2]
    i, fx = _lerp_axis((x - lo[0]) * ih[0] - 0.5, nx)
    j, fy = _lerp_axis((y - lo[1]) * ih[1] - 0.5, ny)
    k, fz = _lerp_axis((z - lo[2]) * ih[2] - 0.5, nz)
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    for di in range(2):
        wx = fx if di else 1.0 - fx
        for dj in range(2):
            wy = fy if dj else 1.0 - fy
            for dk in range(2):
                wgt = wx * wy * (fz if dk else 1.0 - fz)
                a0 += wgt * field[i + di, j + dj, k + dk, 0]
                a1 += wgt * field[i + di, j + dj, k + dk, 1]
                a2 += wgt * field[i + di, j + dj, k + dk, 2]
                a3 += wgt * field[i + di, j + dj, k + dk, 3]
    return a0, a1, a2, a3


def half_contrast(field_or_ior, outside_ior):
    """``(n_half, side)``: the index level halfway to the volume's largest contrast with the outside.

    A point with ``side * (n - n_half) > 0`` is inside refractive material
    (the viewing pass's ``hit``; the march's "met the object" flag).

    Parameters
    ----------
    field_or_ior : ndarray
        ``(nx, ny, nz, 4)`` gradient field (its channel 0) or ``(nx, ny, nz)``
        index of refraction.
    outside_ior : float
        Index of refraction outside the objects.

    Returns
    -------
    n_half : float
        ``outside_ior`` plus half the largest contrast; ``inf`` for a volume
        without contrast.
    side : float
        ``+1`` when the material's index is above the outside's, else ``-1``.

    References
    ----------
    Sun et al. (2008), §4.5 (rays meeting the refractive object in the viewing
    pass).
    """
    a = np.asarray(field_or_ior)
    n = a[..., 0] if a.ndim == 4 else a
    lo, hi = float(n.min()), float(n.max())
    c = hi - outside_ior if abs(hi - outside_ior) >= abs(lo - outside_ior) else lo - outside_ior
    if c == 0.0:
        return float("inf"), 1.0
    return float(outside_ior + 0.5 * c), (1.0 if c > 0 else -1.0)
