"""Intersection test of the beams against the reference planes (eq. 4-15).

A receiver texel whose first-surface depth ``zeta`` (position map) lies within
``eps = s / 2`` of plane ``i`` accepts the fragments drawn on that plane. With
the planes at slab centres (see :mod:`.planes`) the acceptance ranges are the
half-open slabs ``[zeta_i - eps, zeta_i + eps)``: every texel of the box is
accepted by exactly one plane, never two, so additive blending never counts a
beam twice, and smart slicing can drop the planes no texel accepts without
changing any texel.

The beam of a water triangle meets the plane ``zeta = zeta_p`` where each edge
ray ``o_k + lambda_k T_k`` has ``lambda_k = (zeta_p - zeta(o_k)) / (T_k . T0)``;
the three points form the intersection triangle (Fig. 4-14). A plane above a
water vertex (``lambda_k < 0``) cuts no beam there.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.4 (eq. 4-15), Fig. 4-14.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["plane_index_map", "plane_rects"]


@nb.njit(cache=True, parallel=True)
def _plane_index(depth, own, zlo, s, n, out):
    """out[i, j]: plane ``floor((zeta - zlo) / s)`` accepting the texel (eq. 4-15), -1 for none."""
    H, W = depth.shape
    for i in nb.prange(H):
        for j in range(W):
            out[i, j] = -1
            if own[i, j]:
                k = np.int64(np.floor((depth[i, j] - zlo) / s))
                if k >= 0 and k < n:
                    out[i, j] = k


def plane_index_map(lm, box, n, placement):
    """Plane accepting each texel: ``|zeta - zeta_i| < eps`` (eq. 4-15), ``-1`` for none.

    Parameters
    ----------
    lm : LevelMap
    box : Box
    n : int
        Number of planes of the normal slicing (smart slicing only removes
        planes of this lattice, see :mod:`.smart_slicing`).
    placement : {"component", "thesis", "tight"}
        ``caustics.placement``: the lattice (:func:`~refraction_ref.levelmap.planes.plane_lattice`).

    Returns
    -------
    (Hc, Wc) int32
        Texels whose first surface is another receiver, or lies outside the
        planes' acceptance slabs, get ``-1``.

    References
    ----------
    Tipprasert (2006), §4.4, eq. 4-15.
    """
    from .planes import plane_lattice

    lat = plane_lattice(box, n, placement)
    out = np.empty(lm.depth.shape, np.int32)
    _plane_index(lm.depth, lm.own, lat.zlo, lat.s, int(n), out)
    return out


@nb.njit(cache=True, parallel=True)
def _rects(pidx, n, out):
    """Per plane, the rows and columns of its texels: bands of rows in parallel, then merged in band order."""
    H, W = pidx.shape
    nb_ = min(H, 32)
    rlo = np.full((nb_, n), H, np.int64)
    rhi = np.full((nb_, n), -1, np.int64)
    clo = np.full((nb_, n), W, np.int64)
    chi = np.full((nb_, n), -1, np.int64)
    for b in nb.prange(nb_):
        for i in range(b * H // nb_, (b + 1) * H // nb_):
            for j in range(W):
                k = pidx[i, j]
                if k >= 0 and k < n:
                    rlo[b, k] = min(rlo[b, k], i)
                    rhi[b, k] = max(rhi[b, k], i)
                    clo[b, k] = min(clo[b, k], j)
                    chi[b, k] = max(chi[b, k], j)
    for k in range(n):
        out[k, 0] = H
        out[k, 1] = -1
        out[k, 2] = W
        out[k, 3] = -1
        for b in range(nb_):
            out[k, 0] = min(out[k, 0], rlo[b, k])
            out[k, 1] = max(out[k, 1], rhi[b, k])
            out[k, 2] = min(out[k, 2], clo[b, k])
            out[k, 3] = max(out[k, 3], chi[b, k])


def plane_rects(pidx, n):
    """Scissor rectangle (row0, row1, col0, col1) of the texels each plane accepts.

    Empty planes get ``row0 > row1``. Fragments outside the rectangle would
    fail the depth test anyway; it is the bounding-volume test of §6.1.

    Parameters
    ----------
    pidx : (Hc, Wc) int
        Plane accepting each texel, ``-1`` for none (:func:`plane_index_map`).
    n : int
        Number of planes.

    Returns
    -------
    (n, 4) int64
        ``row0, row1, col0, col1`` of each plane, inclusive texel indices.

    References
    ----------
    Tipprasert (2006), §4.4 (eq. 4-15) and §6.1 (bounding-volume test).
    """
    out = np.empty((int(n), 4), np.int64)
    _rects(np.ascontiguousarray(pidx, dtype=np.int32), int(n), out)
    return out
