"""Per-ray variant (the thesis's further-work idea, §6.3): place each
intersection triangle where the beam actually hits, instead of on every plane.

1. Every edge ray of a candidate beam searches the position map for its hit:
   it is marched in depth with steps that move it at most half a texel
   sideways, and stops at the first texel whose first-surface depth it has
   reached (a hit on this receiver, or blocked by another).
2. Each beam is drawn once, over the texels of the bounding rectangle of its
   cross-sections at the depths its rays hit (padded by one texel): every
   texel tests itself against the beam's cross-section *at its own depth*
   (the plane ``zeta = position-map depth``). This is the level map with a
   plane at every texel depth, so the cost no longer grows with the planes
   and there is no plane-quantisation error; intensity is eq. 4-18 as in
   :mod:`.caustics_map` (absorption to the texel's own depth).

Where an edge ray misses the receiver (it passes beside it, or another
receiver blocks it), the region is widened to the cross-sections over the
receiver's whole depth range, so beams straddling a silhouette or a map edge
are still drawn in full.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §6.3 ("placing the intersection triangle on actual
   hit"), §4.5 (eq. 4-18).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..raster import BAND, MAX_COORD, bin_bands, edge_setup, oriented_triangle, row_span
from .caustics_map import receiver_cosine, section_irradiance, section_texels

__all__ = ["search_hits", "per_ray_caustics"]


class _Regions(NamedTuple):
    """Each candidate beam's texel rectangle, binned into bands of rows."""

    cand: np.ndarray  # (M,) beam index
    rows: np.ndarray  # (M, 2) first and last row, (1, 0) when none
    cols: np.ndarray  # (M, 2) first and last column
    counts: np.ndarray  # band lists (bin_bands of rows)
    tris: np.ndarray


class _PerRayGrid(NamedTuple):
    """The caustics map: size and rows per band."""

    W: int
    H: int
    band: int


class _PerRayTexels(NamedTuple):
    """The receiving surface, texel by texel."""

    accept: np.ndarray  # (Hc, Wc) bool: texels of this receiver inside the box
    depth: np.ndarray  # (Hc, Wc) position-map depth
    normal: np.ndarray  # (Hc, Wc, 3) unit normal


class _PerRayScale(NamedTuple):
    """Absorption (``water.absorption``) and texel size."""

    K: float
    texel_area: float


@nb.njit(cache=True, parallel=True)
def _search(O, D, cand, depth, own, ztop, zbot, hit):
    """hit[m, k] = depth where edge ray k of beam cand[m] meets this receiver, NaN if not."""
    H, W = depth.shape
    for m in nb.prange(cand.shape[0]):
        t = cand[m]
        for k in range(3):
            hit[m, k] = np.nan
            dz = D[t, k, 2]
            if dz <= 0.0:
                continue
            a = D[t, k, 0] / dz  # texels per unit depth
            b = D[t, k, 1] / dz
            z = max(O[t, k, 2], ztop)
            ze = zbot
            if z >= ze:
                continue
            lat = max(abs(a), abs(b))
            step = ze - z
            if lat * step > 0.5:
                step = 0.5 / lat
            while z < ze:
                z1 = min(z + step, ze)
                zm = 0.5 * (z + z1)
                c = O[t, k, 0] + a * (zm - O[t, k, 2])
                r = O[t, k, 1] + b * (zm - O[t, k, 2])
                j = int(math.floor(c))
                i = int(math.floor(r))
                if i >= 0 and i < H and j >= 0 and j < W:
                    dd = depth[i, j]
                    if dd <= z1:
                        if own[i, j]:
                            hit[m, k] = max(dd, z)
                        break
                z = z1


@nb.njit(cache=True, parallel=True)
def _regions(O, D, cand, hit, zlo_own, zhi_own, W, H, rows, cols):
    for m in nb.prange(cand.shape[0]):
        t = cand[m]
        zl = np.inf
        zh = -np.inf
        nh = 0
        for k in range(3):
            if hit[m, k] == hit[m, k]:
                zl = min(zl, hit[m, k])
                zh = max(zh, hit[m, k])
                nh += 1
        rows[m, 0] = 1
        rows[m, 1] = 0
        cols[m, 0] = 1
        cols[m, 1] = 0
        if nh < 3:
            zl = min(zl, zlo_own)
            zh = max(zh, zhi_own)
        c0 = np.inf
        c1 = -np.inf
        r0 = np.inf
        r1 = -np.inf
        for zz in (zl, zh):
            for k in range(3):
                lam = max((zz - O[t, k, 2]) / D[t, k, 2], 0.0)
                c = O[t, k, 0] + lam * D[t, k, 0]
                r = O[t, k, 1] + lam * D[t, k, 1]
                c0 = min(c0, c)
                c1 = max(c1, c)
                r0 = min(r0, r)
                r1 = max(r1, r)
        i0 = max(int(math.floor(r0)) - 1, 0)
        i1 = min(int(math.floor(r1)) + 1, H - 1)
        j0 = max(int(math.floor(c0)) - 1, 0)
        j1 = min(int(math.floor(c1)) + 1, W - 1)
        if i0 <= i1 and j0 <= j1:
            rows[m, 0] = i0
            rows[m, 1] = i1
            cols[m, 0] = j0
            cols[m, 1] = j1


@nb.njit(cache=True, parallel=True)
def _splat_own_depth(beams, reg, grid, texels, scale, out):
    """Each beam drawn over its region, every texel at its own depth (step 2)."""
    # the named tuples unpacked by name, outside the prange loop (inside it, Numba
    # drops stores into arrays taken from a tuple: numba#7135)
    O = beams.O
    D = beams.D
    flux = beams.flux
    inv_tv = beams.inv_tv
    tbar = beams.tbar
    cand = reg.cand
    rows = reg.rows
    cols = reg.cols
    counts = reg.counts
    tris = reg.tris
    H = grid.H
    band = grid.band
    accept = texels.accept
    depth = texels.depth
    normal = texels.normal
    K = scale.K
    texel_area = scale.texel_area
    nb_bands = counts.shape[0] - 1
    for b in nb.prange(nb_bands):
        # this texel's triangle as triangle 0 of (1, 3) arrays, the rasterizer's layout
        X = np.empty((1, 3), np.int64)
        Y = np.empty((1, 3), np.int64)
        L = np.empty((1, 3))
        FC = np.empty(3)
        FR = np.empty(3)
        r0b = b * band
        r1b = min(r0b + band, H) - 1
        for q in range(counts[b], counts[b + 1]):
            m = tris[q]
            t = cand[m]
            i0 = max(rows[m, 0], r0b)
            i1 = min(rows[m, 1], r1b)
            tx = tbar[t, 0]
            ty = tbar[t, 1]
            tz = tbar[t, 2]
            for i in range(i0, i1 + 1):
                for j in range(cols[m, 0], cols[m, 1] + 1):
                    if not accept[i, j]:
                        continue
                    zt = depth[i, j]
                    ok = True
                    for k in range(3):
                        lam = (zt - O[t, k, 2]) / D[t, k, 2]
                        if not (lam >= 0.0):
                            ok = False
                            break
                        L[0, k] = lam
                        c = O[t, k, 0] + lam * D[t, k, 0]
                        r = O[t, k, 1] + lam * D[t, k, 1]
                        if not (abs(c) < MAX_COORD and abs(r) < MAX_COORD):
                            ok = False
                            break
                        X[0, k] = np.int64(np.round(c * 256.0))
                        Y[0, k] = np.int64(np.round(r * 256.0))
                        FC[k] = c
                        FR[k] = r
                    if not ok:
                        continue
                    # re-oriented (a folded beam) and tested as the rasterizer does: a run of one pixel
                    x0, y0, x1, y1, x2, y2, l0, l1, l2, area, _ = oriented_triangle(X, Y, L, 0)
                    if area == 0:
                        continue
                    ja, jb, w0, w1, w2 = row_span((x0, y0, x1, y1, x2, y2), edge_setup(x0, y0, x1, y1, x2, y2),
                                                  i, j, j)
                    if ja > jb:
                        continue
                    a_tex = section_texels(FC[0], FR[0], FC[1], FR[1], FC[2], FR[2])  # unsnapped, >= one texel
                    base = section_irradiance(flux[t], inv_tv[t], a_tex, texel_area)
                    g = receiver_cosine(tx, ty, tz, normal, i, j)
                    if K > 0.0:
                        g *= math.exp(-K * (w0 * l0 + w1 * l1 + w2 * l2) / area)
                    out[i, j] += base * g


def search_hits(beams, cand, lm, box):
    """Depth at which each edge ray of each candidate beam hits this receiver (step 1).

    Each ray is marched in depth with steps that move it at most half a
    texel sideways, and stops at the first texel whose position-map depth
    it has reached.

    Parameters
    ----------
    beams : BeamSet
        Beams in the map coordinates of ``box``.
    cand : (M,) int64
        Candidate beams.
    lm : LevelMap
        The receiver's maps (``depth``, ``own``).
    box : Box
        Its box; the march spans depths ``[-h/2, h/2]``.

    Returns
    -------
    (M, 3) float64
        ``NaN`` where the ray misses the receiver or another receiver blocks it.

    References
    ----------
    Tipprasert (2006), §6.3 ("placing the intersection triangle on actual hit").
    """
    hit = np.empty((len(cand), 3))
    _search(beams.O, beams.D, cand, lm.depth, lm.own, -box.h / 2.0, box.h / 2.0 * (1 + 1e-9), hit)
    return hit


def per_ray_caustics(beams, cand, lm, box, K, out):
    """Accumulate the per-ray caustics of receiver ``lm`` into ``out`` (steps 1 and 2).

    Parameters
    ----------
    beams, cand, box : BeamSet, (M,) int64, Box
        As for :func:`search_hits`.
    lm : LevelMap
        The receiver's maps (``depth``, ``own``, ``normal``).
    K : float
        Absorption coefficient of the water.
    out : (Hc, Wc) float64
        Accumulated irradiance; each texel tests every beam's cross-section
        at its own depth (the rasterizer's coverage rule, :func:`~refraction_ref.raster.row_span`
        over one pixel) and adds eq. 4-18's intensity.

    Returns
    -------
    dict
        ``rays_hit`` and ``beams_drawn`` counts.

    References
    ----------
    Tipprasert (2006), §6.3 (intersection triangles at the actual hits), §4.5
    (eq. 4-18).
    """
    Hc, Wc = box.size
    if len(cand) == 0:
        return {"rays_hit": 0, "beams_drawn": 0}
    hit = search_hits(beams, cand, lm, box)
    ownz = lm.depth[lm.own]
    zlo, zhi = (float(ownz.min()), float(ownz.max())) if ownz.size else (0.0, 0.0)
    rows = np.empty((len(cand), 2), np.int64)
    cols = np.empty((len(cand), 2), np.int64)
    _regions(beams.O, beams.D, cand, hit, zlo, zhi, Wc, Hc, rows, cols)
    counts, tris = bin_bands(rows, Hc, BAND)
    accept = lm.own & (lm.depth >= -box.h / 2.0) & (lm.depth <= box.h / 2.0)
    _splat_own_depth(beams.arrays, _Regions(cand, rows, cols, counts, tris), _PerRayGrid(Wc, Hc, BAND),
                     _PerRayTexels(accept, lm.depth, lm.normal), _PerRayScale(float(K), float(box.texel_area)), out)
    return {"rays_hit": int(np.count_nonzero(np.isfinite(hit))),
            "beams_drawn": int(np.count_nonzero(rows[:, 0] <= rows[:, 1]))}
