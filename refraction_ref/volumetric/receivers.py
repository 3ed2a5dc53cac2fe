"""Diffuse receivers the photons stop on: inside the volume, or straight on after leaving it (§6.2.2, Fig. 9).

A march's receivers are a triangle soup grouped by receiver, with each
receiver's bounding box (:class:`MarchReceivers`, built by
:func:`receiver_tuple`). A step that meets one of its triangles ends there
(:func:`segment_receiver`, two-sided Moller-Trumbore); a photon that left the
volume goes on straight to the first receiver outside it
(:func:`exit_receivers`).

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.4 and §6.2.2 (Fig. 9: caustics on a
   diffuse receiver).
.. [2] T. Moller, B. Trumbore, "Fast, Minimum Storage Ray/Triangle
   Intersection", Journal of Graphics Tools 2(1), 1997.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

__all__ = ["MarchReceivers", "receiver_tuple", "segment_receiver", "exit_receivers"]


class MarchReceivers(NamedTuple):
    """Diffuse receivers the photons stop on (:func:`receiver_tuple`); T = 0 for none."""

    tris: np.ndarray  # (T, 3, 3) float64 world vertices, grouped by receiver
    lo: np.ndarray  # (R, 3) float64 each receiver's bounding box
    hi: np.ndarray  # (R, 3)
    start: np.ndarray  # (R + 1,) int64: receiver r owns tris[start[r]:start[r + 1]]


def receiver_tuple(tris=None, owner=None):
    """The receivers of a march from a triangle soup and its owners (None: no receivers).

    Parameters
    ----------
    tris : (T, 3, 3) float64, optional
    owner : (T,) int, optional
        Receiver index of each triangle (0 .. R - 1).

    Returns
    -------
    MarchReceivers
        Triangles grouped by receiver with each receiver's bounding box and the
        start of its triangles; empty arrays when there are no receivers.

    References
    ----------
    Sun et al. (2008), §4.4 (photons stop on diffuse surfaces), §6 (caustics on
    receivers).
    """
    if tris is None or len(tris) == 0:
        z = np.zeros((0, 3))
        return MarchReceivers(np.zeros((0, 3, 3)), z, z.copy(), np.zeros(1, np.int64))
    owner = np.asarray(owner, np.int64)
    order = np.argsort(owner, kind="stable")
    t = np.ascontiguousarray(np.asarray(tris, np.float64)[order])
    o = owner[order]
    R = int(o.max()) + 1
    start = np.searchsorted(o, np.arange(R + 1)).astype(np.int64)
    lo = np.full((R, 3), np.inf)
    hi = np.full((R, 3), -np.inf)
    for r in range(R):
        if start[r + 1] > start[r]:
            v = t[start[r]:start[r + 1]].reshape(-1, 3)
            lo[r], hi[r] = v.min(axis=0), v.max(axis=0)
    return MarchReceivers(t, lo, hi, start)


@nb.njit(cache=True)
def segment_receiver(recv, x, y, z, dx, dy, dz, tmax):
    """Smallest t in (0, tmax] where ``x + t d`` meets a receiver triangle (two-sided, Moller-Trumbore).

    Parameters
    ----------
    recv : MarchReceivers
        From :func:`receiver_tuple`.
    x, y, z : float
        Start of the segment.
    dx, dy, dz : float
        Its direction (not necessarily unit: t is in its units).
    tmax : float
        The segment's end.

    Returns
    -------
    t : float
        Where it meets the first triangle; ``inf`` when none.
    q : int
        That triangle's index in ``recv.tris``; -1 when none.

    References
    ----------
    Sun et al. (2008), §6.2.2 (photons stopped by a diffuse receiver, Fig. 9);
    Moller and Trumbore (1997).
    """
    tris, rlo, rhi, start = recv.tris, recv.lo, recv.hi, recv.start
    best = np.inf
    br = -1
    ax0, ax1 = min(x, x + tmax * dx), max(x, x + tmax * dx)
    ay0, ay1 = min(y, y + tmax * dy), max(y, y + tmax * dy)
    az0, az1 = min(z, z + tmax * dz), max(z, z + tmax * dz)
    for r in range(rlo.shape[0]):
        pad = 1e-9 * (1.0 + abs(rlo[r, 0]) + abs(rlo[r, 1]) + abs(rlo[r, 2]) + abs(rhi[r, 0]) + abs(rhi[r, 1])
                      + abs(rhi[r, 2]))
        if (ax1 < rlo[r, 0] - pad or ax0 > rhi[r, 0] + pad or ay1 < rlo[r, 1] - pad or ay0 > rhi[r, 1] + pad
                or az1 < rlo[r, 2] - pad or az0 > rhi[r, 2] + pad):
            continue
        for q in range(start[r], start[r + 1]):
            v0x, v0y, v0z = tris[q, 0, 0], tris[q, 0, 1], tris[q, 0, 2]
            e1x, e1y, e1z = tris[q, 1, 0] - v0x, tris[q, 1, 1] - v0y, tris[q, 1, 2] - v0z
            e2x, e2y, e2z = tris[q, 2, 0] - v0x, tris[q, 2, 1] - v0y, tris[q, 2, 2] - v0z
            px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
            det = e1x * px + e1y * py + e1z * pz
            if det == 0.0 or det != det:
                continue
            inv = 1.0 / det
            tx, ty, tz = x - v0x, y - v0y, z - v0z
            u = (tx * px + ty * py + tz * pz) * inv
            if u < 0.0 or u > 1.0:
                continue
            qx, qy, qz = ty * e1z - tz * e1y, tz * e1x - tx * e1z, tx * e1y - ty * e1x
            w = (dx * qx + dy * qy + dz * qz) * inv
            if w < 0.0 or u + w > 1.0:
                continue
            t = (e2x * qx + e2y * qy + e2z * qz) * inv
            if t > 0.0 and t <= tmax and t < best:
                best = t
                br = q
    return best, br


@nb.njit(cache=True, parallel=True)
def exit_receivers(sel, exit_pos, exit_dir, recv, reach, hit_pos, hit_recv):
    """Exited photons ``sel`` go on straight outside the volume to the first receiver; parallel over photons.

    Parameters
    ----------
    sel : (M,) int64
        The photons that left the volume.
    exit_pos, exit_dir : (P, 3) float64
        Where and along which unit direction each left it.
    recv : MarchReceivers
    reach : float
        The longest straight path searched (world units).
    hit_pos : (P, 3) float64
        Written for the photons that meet a receiver.
    hit_recv : (P,) int32
        Written with the triangle met (an index into ``recv.tris``).

    Returns
    -------
    None

    References
    ----------
    Sun et al. (2008), §6.2.2, Fig. 9 (caustics on a receiver outside the
    refractive volume).
    """
    for m in nb.prange(sel.shape[0]):
        p = sel[m]
        t, r = segment_receiver(recv, exit_pos[p, 0], exit_pos[p, 1], exit_pos[p, 2],
                                exit_dir[p, 0], exit_dir[p, 1], exit_dir[p, 2], reach)
        if r >= 0:
            for c in range(3):
                hit_pos[p, c] = exit_pos[p, c] + t * exit_dir[p, c]
            hit_recv[p] = r
