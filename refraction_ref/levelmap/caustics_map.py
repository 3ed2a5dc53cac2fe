"""Caustics map: intersection triangles drawn with additive blending, each
fragment kept only where it passes the position-map depth test (eqs. 4-16 to 4-18).

Eq. 4-18 gives the intensity of an intersection area,

.. math:: I_c = I_i \\frac{A_w \\cos\\theta_i}{A_d \\cos\\theta_t} e^{-K d},

the flux ``Phi = I_i A_w cos(theta_i) e^{-Kd}`` over the beam's cross-section
perpendicular to its axis, ``A_d cos(theta_t)``. On a reference plane (normal
``V``) the intersection triangle has area ``A_p`` and the perpendicular
cross-section is ``A_p |T . V|`` (``T`` the beam axis). ``caustic_map`` holds
the irradiance on the receiver, flux per unit *receiver* area, which is
``I_c`` times the cosine between the beam and the receiver normal ``n``:

.. math:: E = \\frac{\\Phi\\, |T \\cdot n|}{A_p\\, |T \\cdot V|} .

The distance ``d`` of ``e^{-Kd}`` is known at each vertex of the intersection
triangle (the length of the edge ray from the water to the plane); the thesis
interpolates the vertex *intensities*, here the *distance* is interpolated
and each fragment continues it to the texel's own depth,
``d + (zeta - zeta_p) / (T . T0)`` (``zeta`` read from the position map it
already fetches for the depth test), before taking the exponential. Both
are exact along straight beams, so a flat water over a flat floor gives the
closed form whatever the number of planes.

Caustic singularities stay finite: the area used is ``max(|A_p|, one texel)``,
so a beam focused (or folded, ``A_p < 0``) to less than a texel deposits at
most its flux over one texel's area in each texel centre it covers.

Coverage uses the fixed-point edge functions and top-left rule of
:mod:`refraction_ref.raster`: neighbouring beams share their edge rays, so
their intersection triangles tile a plane and no texel is counted twice. Work
is split in bands of rows, triangles in index order, so sums are
bit-identical whatever the thread count.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.5 (eqs. 4-16 to 4-18), Fig. 4-15.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..raster import BAND, MAX_COORD, bin_bands, edge_setup, edge_values, oriented_triangle, pixel_span
from .planes import dir_to_map, to_map

__all__ = ["BeamSet", "beams_in_map", "cull_beams", "splat_plane"]


class _Beams(NamedTuple):
    """A :class:`BeamSet`'s arrays as the kernels take them (:attr:`BeamSet.arrays`)."""

    O: np.ndarray  # (F, 3, 3) edge-ray origins (col, row, zeta)
    D: np.ndarray  # (F, 3, 3) edge-ray rates per unit length
    flux: np.ndarray  # (F,)
    inv_tv: np.ndarray  # (F,) 1 / |T . V|
    tbar: np.ndarray  # (F, 3) world beam axis
    tdz: np.ndarray  # (F,) T . T0


class _Grid(NamedTuple):
    """The caustics map drawn into: size, rows per band, scissor rectangle."""

    W: int
    H: int
    band: int
    rect: np.ndarray  # (4,) int64 (row0, row1, col0, col1)


class _Plane(NamedTuple):
    """The reference plane drawn and the water's absorption."""

    zp: float  # plane depth
    K: float  # absorption coefficient
    texel_area: float


class _Sections(NamedTuple):
    """Intersection triangles of the candidate beams with the plane (filled by :func:`_sections`)."""

    cand: np.ndarray  # (M,) beam of each section
    X: np.ndarray  # (M, 3) int64 snapped columns, 1/256 texel
    Y: np.ndarray  # (M, 3) int64 snapped rows
    C: np.ndarray  # (M, 3) edge-ray lengths from the water to the plane
    B: np.ndarray  # (M,) irradiance factor flux / (|T . V| area)
    rows: np.ndarray  # (M, 2) rows each may cover, (1, 0) when none


class _Bins(NamedTuple):
    """The sections binned into bands of rows (:func:`~refraction_ref.raster.bin_bands`)."""

    counts: np.ndarray
    tris: np.ndarray


class _Receiver(NamedTuple):
    """Where fragments land: the depth test and the receiving surface."""

    accept: np.ndarray  # (Hc, Wc) a fragment is kept where accept == key
    key: int
    zeta: np.ndarray  # (Hc, Wc) receiver depth
    normal: np.ndarray  # (Hc, Wc, 3) receiver unit normal


class BeamSet:
    """Illumination volumes expressed in one box's map coordinates.

    Attributes
    ----------
    O, D : (F, 3, 3) float64
        Edge-ray origins ``(col, row, zeta)`` and rates per unit length.
    flux : (F,) float64
    tbar : (F, 3) float64 world beam axis; tdz : (F,) its ``T . T0``;
    inv_tv : (F,) ``1 / |T . V|``
    """

    def __init__(self, vols, box):
        self.O = np.ascontiguousarray(to_map(box, vols.origins))
        self.D = np.ascontiguousarray(dir_to_map(box, vols.dirs))
        self.flux = np.ascontiguousarray(vols.flux)
        self.tbar = np.ascontiguousarray(vols.mean_dir)
        self.tdz = np.ascontiguousarray(-(vols.mean_dir @ box.V))
        with np.errstate(divide="ignore"):
            self.inv_tv = np.where(self.tdz > 1e-12, 1.0 / np.maximum(self.tdz, 1e-12), 0.0)

    @property
    def arrays(self):
        """The arrays as one :class:`_Beams` named tuple (what the kernels take)."""
        return _Beams(self.O, self.D, self.flux, self.inv_tv, self.tbar, self.tdz)


def beams_in_map(vols, box):
    """Express illumination volumes in the map coordinates of ``box``."""
    return BeamSet(vols, box)


def cull_beams(beams, box, zmin, zmax):
    """Beams that carry flux and may cross the map between depths ``zmin`` and ``zmax``.

    The cross-section moves linearly with the plane depth, so its bounding
    rectangle over ``[zmin, zmax]`` is that of the two end sections (the
    bounding-volume test of §6.1). Changes no texel.

    Returns
    -------
    (M,) int64
        Indices of the candidate beams, increasing.
    """
    Hc, Wc = box.size
    O, D = beams.O, beams.D
    ok = (beams.flux > 0) & np.all(D[..., 2] > 0, axis=1)
    hi = np.full((len(O), 2), -np.inf)
    lo2 = np.full((len(O), 2), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for z in (zmin, zmax):
            lam = (z - O[..., 2]) / D[..., 2]
            lam = np.where(ok[:, None], np.maximum(lam, 0.0), 0.0)
            p = O[..., :2] + lam[..., None] * D[..., :2]
            hi = np.maximum(hi, p.max(axis=1))
            lo2 = np.minimum(lo2, p.min(axis=1))
    inside = (hi[:, 0] >= 0) & (hi[:, 1] >= 0) & (lo2[:, 0] <= Wc) & (lo2[:, 1] <= Hc)
    # beams entirely below the box never reach a plane above their water vertices
    top = O[..., 2].max(axis=1) <= zmax
    return np.flatnonzero(ok & inside & top).astype(np.int64)


@nb.njit(cache=True, parallel=True)
def _sections(beams, grid, plane, sec):
    """Intersection triangles of the candidate beams ``sec.cand`` with the plane ``zeta = plane.zp``."""
    # the named tuples unpacked by name, outside the prange loop (inside it, Numba
    # drops stores into arrays taken from a tuple: numba#7135)
    O, D, flux, inv_tv = beams.O, beams.D, beams.flux, beams.inv_tv
    zp, texel_area, rect = plane.zp, plane.texel_area, grid.rect
    cand, X, Y, C, B, rows = sec.cand, sec.X, sec.Y, sec.C, sec.B, sec.rows
    for m in nb.prange(cand.shape[0]):
        t = cand[m]
        ok = flux[t] > 0.0
        lam0 = 0.0
        lam1 = 0.0
        lam2 = 0.0
        fc = np.empty(3)
        fr = np.empty(3)
        for k in range(3):
            dz = D[t, k, 2]
            lam = -1.0
            if dz > 0.0:
                lam = (zp - O[t, k, 2]) / dz
            if not (lam >= 0.0):
                ok = False
                lam = 0.0
            c = O[t, k, 0] + lam * D[t, k, 0]
            r = O[t, k, 1] + lam * D[t, k, 1]
            if not (abs(c) < MAX_COORD and abs(r) < MAX_COORD):
                ok = False
                c = 0.0
                r = 0.0
            X[m, k] = np.int64(np.round(c * 256.0))
            Y[m, k] = np.int64(np.round(r * 256.0))
            fc[k] = c
            fr[k] = r
            if k == 0:
                lam0 = lam
            elif k == 1:
                lam1 = lam
            else:
                lam2 = lam
        if ok:
            # area of the (unsnapped) intersection triangle in texels, at least one texel
            af = (fc[1] - fc[0]) * (fr[2] - fr[0]) - (fr[1] - fr[0]) * (fc[2] - fc[0])
            a_tex = max(0.5 * abs(af), 1.0)
            B[m] = flux[t] * inv_tv[t] / (a_tex * texel_area)
            C[m, 0] = lam0
            C[m, 1] = lam1
            C[m, 2] = lam2
            lo = min(Y[m, 0], min(Y[m, 1], Y[m, 2]))
            hi = max(Y[m, 0], max(Y[m, 1], Y[m, 2]))
            xlo = min(X[m, 0], min(X[m, 1], X[m, 2]))
            xhi = max(X[m, 0], max(X[m, 1], X[m, 2]))
            i0, i1 = pixel_span(lo, hi, rect[0], rect[1])
            j0, j1 = pixel_span(xlo, xhi, rect[2], rect[3])
            if j0 > j1 or i0 > i1:
                i0, i1 = 1, 0
        else:
            i0, i1 = 1, 0
        rows[m, 0] = i0
        rows[m, 1] = i1


@nb.njit(cache=True, parallel=True)
def _splat(beams, sec, bins, grid, recv, plane, out):
    """Additive blending of intersection triangles; fragments pass where ``recv.accept == recv.key``."""
    # unpacked by name, outside the prange loop (see _sections)
    tbar, tdz = beams.tbar, beams.tdz
    cand, X, Y, C, B, rows = sec.cand, sec.X, sec.Y, sec.C, sec.B, sec.rows
    counts, tris = bins.counts, bins.tris
    H, band, rect = grid.H, grid.band, grid.rect
    accept, key, zeta, normal = recv.accept, recv.key, recv.zeta, recv.normal
    zp, K = plane.zp, plane.K
    nb_bands = counts.shape[0] - 1
    for b in nb.prange(nb_bands):
        r0 = b * band
        r1 = min(r0 + band, H) - 1
        for q in range(counts[b], counts[b + 1]):
            m = tris[q]
            t = cand[m]
            # a folded beam (negative area): same coverage, re-oriented
            x0, y0, x1, y1, x2, y2, c0, c1, c2, area, _ = oriented_triangle(X, Y, C, m)
            if area == 0:
                continue
            i0 = max(rows[m, 0], r0)
            i1 = min(rows[m, 1], r1)
            j0, j1 = pixel_span(min(x0, min(x1, x2)), max(x0, max(x1, x2)), rect[2], rect[3])
            if j0 > j1 or i0 > i1:
                continue
            a0, a1, a2, b0, b1, b2 = edge_setup(x0, y0, x1, y1, x2, y2)
            inv_area = 1.0 / area
            tx = tbar[t, 0]
            ty = tbar[t, 1]
            tz = tbar[t, 2]
            kk = K / tdz[t] if K > 0.0 else 0.0
            base = B[m]
            px0 = 256 * j0 + 128
            for i in range(i0, i1 + 1):
                w0, w1, w2 = edge_values(x0, y0, x1, y1, x2, y2, px0, 256 * i + 128)
                for j in range(j0, j1 + 1):
                    if j > j0:
                        w0 -= 256 * a0
                        w1 -= 256 * a1
                        w2 -= 256 * a2
                    if w0 + b0 < 0 or w1 + b1 < 0 or w2 + b2 < 0:
                        continue
                    if accept[i, j] != key:  # depth test against the position map (eq. 4-15)
                        continue
                    g = abs(tx * normal[i, j, 0] + ty * normal[i, j, 1] + tz * normal[i, j, 2])
                    if K > 0.0:
                        lam = (w0 * c0 + w1 * c1 + w2 * c2) * inv_area
                        g *= math.exp(-K * lam - kk * (zeta[i, j] - zp))
                    out[i, j] += base * g


def splat_plane(beams, cand, box, zp, K, rect, accept, key, zeta, normal, out):
    """Draw every candidate beam's intersection triangle with plane ``zp`` into ``out``.

    Parameters
    ----------
    beams : BeamSet
    cand : (M,) int64
        Candidate beams (:func:`cull_beams`).
    box : Box
    zp : float
        Plane depth.
    K : float
        Absorption coefficient of the water.
    rect : (4,) int64
        Scissor rectangle (row0, row1, col0, col1).
    accept : (Hc, Wc) int32 and key : int
        A fragment is kept where ``accept == key``: the plane index map
        (level map, eq. 4-15) or a slice mask (volumetric baseline).
    zeta, normal : (Hc, Wc), (Hc, Wc, 3)
        Depth and unit normal of the receiver surface at each texel.
    out : (Hc, Wc) float64
        Accumulated irradiance (additive blending).

    Returns
    -------
    int
        Number of intersection triangles drawn.
    """
    Hc, Wc = box.size
    M = len(cand)
    if M == 0 or rect[0] > rect[1]:
        return 0
    sec = _Sections(cand, np.empty((M, 3), np.int64), np.empty((M, 3), np.int64), np.empty((M, 3), np.float64),
                    np.zeros(M, np.float64), np.empty((M, 2), np.int64))
    grid = _Grid(Wc, Hc, BAND, np.ascontiguousarray(rect, dtype=np.int64))
    plane = _Plane(float(zp), float(K), float(box.texel_area))
    arrays = beams.arrays
    _sections(arrays, grid, plane, sec)
    bins = _Bins(*bin_bands(sec.rows, Hc, BAND))
    _splat(arrays, sec, bins, grid, _Receiver(accept, int(key), zeta, normal), plane, out)
    return int(np.count_nonzero(sec.rows[:, 0] <= sec.rows[:, 1]))
