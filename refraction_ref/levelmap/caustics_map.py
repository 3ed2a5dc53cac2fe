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

from ..raster import BAND, MAX_COORD, bin_bands, edge_setup, oriented_triangle, pixel_span, row_span
from ..raster.blend import step_edges
from .maps import map_point

__all__ = ["BeamSet", "PlaneSet", "ReceiverTexels", "beams_in_map", "cull_beams", "splat_plane", "splat_planes",
           "section_texels", "section_irradiance", "receiver_cosine", "GROUP_SECTIONS"]


class _Beams(NamedTuple):
    """A :class:`BeamSet`'s arrays as the kernels take them (:attr:`BeamSet.arrays`)."""

    O: np.ndarray  # (F, 3, 3) edge-ray origins (col, row, zeta)
    D: np.ndarray  # (F, 3, 3) edge-ray rates per unit length
    flux: np.ndarray  # (F,)
    inv_tv: np.ndarray  # (F,) 1 / |T . V|
    tbar: np.ndarray  # (F, 3) world beam axis
    tdz: np.ndarray  # (F,) T . T0


class _CausticsGrid(NamedTuple):
    """The caustics map drawn into: size, rows per band."""

    W: int
    H: int
    band: int


class _SplatPlanes(NamedTuple):
    """The reference planes drawn in one kernel launch, the water's absorption and the texel size."""

    zeta: np.ndarray  # (G,) plane depths
    key: np.ndarray  # (G,) int64: a fragment of plane g is kept where accept == key[g]
    rect: np.ndarray  # (G, 4) int64 scissor rectangles (row0, row1, col0, col1)
    K: float  # absorption coefficient
    texel_area: float


class PlaneSet(NamedTuple):
    """Reference planes to draw: their depths, depth-test keys and scissor rectangles.

    Attributes
    ----------
    zeta : (G,) float64
        Plane depths along ``T0`` (map depth).
    key : (G,) int64
        A fragment of plane ``g`` is kept where the receiver's ``accept == key[g]``.
    rect : (G, 4) int64
        Scissor rectangle (row0, row1, col0, col1) of each plane; ``row0 > row1`` draws nothing.
    """

    zeta: np.ndarray
    key: np.ndarray
    rect: np.ndarray


class ReceiverTexels(NamedTuple):
    """Where fragments land: the depth test and the receiving surface, texel by texel.

    Attributes
    ----------
    accept : (Hc, Wc) int32
        A fragment of plane ``g`` is kept where ``accept == key[g]``: the plane
        index map (level map, eq. 4-15) or a slice mask (slice-image baseline).
    depth : (Hc, Wc) float64
        The receiver's depth ``zeta`` (position map).
    normal : (Hc, Wc, 3) float64
        The receiver's unit normal.
    """

    accept: np.ndarray
    depth: np.ndarray
    normal: np.ndarray


class _Sections(NamedTuple):
    """Intersection triangles of the candidate beams with the planes (filled by :func:`_sections`).

    Section ``s`` is beam ``cand[s % M]`` on plane ``s // M`` (plane-major).
    """

    cand: np.ndarray  # (M,) candidate beams
    X: np.ndarray  # (G M, 3) int64 snapped columns, 1/256 texel
    Y: np.ndarray  # (G M, 3) int64 snapped rows
    C: np.ndarray  # (G M, 3) edge-ray lengths from the water to the plane
    B: np.ndarray  # (G M,) irradiance factor flux / (|T . V| area)
    rows: np.ndarray  # (G M, 2) rows each may cover, (1, 0) when none


class _Bins(NamedTuple):
    """The sections binned into bands of rows (:func:`~refraction_ref.raster.bin_bands`)."""

    counts: np.ndarray
    tris: np.ndarray


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
        F = len(vols.flux)
        self.O = np.empty((F, 3, 3))
        self.D = np.empty((F, 3, 3))
        self.flux = np.ascontiguousarray(vols.flux)
        self.tbar = np.ascontiguousarray(vols.mean_dir)
        self.tdz = np.empty(F)
        self.inv_tv = np.empty(F)
        Hc, Wc = box.size
        frame = np.array([box.center, box.U, box.V, box.W, [box.w, box.d, 0.0], [Wc, Hc, 0.0]], np.float64)
        _to_map(np.ascontiguousarray(vols.origins), np.ascontiguousarray(vols.dirs), self.tbar, frame, self.O, self.D,
                self.tdz, self.inv_tv)

    @property
    def arrays(self):
        """The arrays as one :class:`_Beams` named tuple (what the kernels take)."""
        return _Beams(self.O, self.D, self.flux, self.inv_tv, self.tbar, self.tdz)


@nb.njit(cache=True, parallel=True)
def _to_map(org, dirs, tbar, frame, O, D, tdz, inv_tv):
    """:func:`~.planes.to_map` of the edge-ray origins, :func:`~.planes.dir_to_map` of their directions, and
    each beam axis's ``T . T0`` and ``1 / |T . V|`` (0 where the beam does not go down the box), beams in parallel."""
    w = frame[4, 0]
    d = frame[4, 1]
    Wc = frame[5, 0]
    Hc = frame[5, 1]
    for f in nb.prange(org.shape[0]):
        for k in range(3):
            x, y, z = map_point(frame, org[f, k, 0], org[f, k, 1], org[f, k, 2])
            O[f, k, 0] = x
            O[f, k, 1] = y
            O[f, k, 2] = z
            tx = dirs[f, k, 0]
            ty = dirs[f, k, 1]
            tz = dirs[f, k, 2]
            D[f, k, 0] = (tx * frame[1, 0] + ty * frame[1, 1] + tz * frame[1, 2]) * (Wc / w)
            D[f, k, 1] = (tx * frame[3, 0] + ty * frame[3, 1] + tz * frame[3, 2]) * (Hc / d)
            D[f, k, 2] = -(tx * frame[2, 0] + ty * frame[2, 1] + tz * frame[2, 2])
        z = -(tbar[f, 0] * frame[2, 0] + tbar[f, 1] * frame[2, 1] + tbar[f, 2] * frame[2, 2])
        tdz[f] = z
        inv_tv[f] = 1.0 / z if z > 1e-12 else 0.0


def beams_in_map(vols, box):
    """Express illumination volumes in the map coordinates of ``box``.

    Parameters
    ----------
    vols : IlluminationVolumes
        The beams under the water surface (:func:`~.illumination.illumination_volumes`).
    box : Box
        A receiver's level-map box (:class:`~.planes.Box`).

    Returns
    -------
    BeamSet
        Edge-ray origins and rates in ``(col, row, zeta)``, each beam's flux,
        axis, ``T . T0`` and ``1 / |T . V|``.

    References
    ----------
    Tipprasert (2006), §4.5 (the illumination volumes intersected with the
    reference planes, Fig. 4-15).
    """
    return BeamSet(vols, box)


def cull_beams(beams, box, zmin, zmax):
    """Beams that carry flux and may cross the map between depths ``zmin`` and ``zmax``.

    The cross-section moves linearly with the plane depth, so its bounding
    rectangle over ``[zmin, zmax]`` is that of the two end sections (the
    bounding-volume test of §6.1). Changes no texel.

    Parameters
    ----------
    beams : BeamSet
        Beams in the map coordinates of ``box`` (:func:`beams_in_map`).
    box : Box
        The receiver's box; its map is ``box.size`` texels.
    zmin, zmax : float
        Depth range of the planes to draw (map depth ``zeta``).

    Returns
    -------
    (M,) int64
        Indices of the candidate beams, increasing.

    References
    ----------
    Tipprasert (2006), §6.1 (culling by bounding volumes, further work).
    """
    Hc, Wc = box.size
    O = beams.O
    D = beams.D
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


@nb.njit(cache=True, inline="always")
def section_texels(c0, r0, c1, r1, c2, r2):
    """Area of an intersection triangle in texels, at least one texel.

    The (unsnapped) triangle's vertices are ``(c_k, r_k)`` in texel units; a
    beam focused (or folded) to less than a texel counts one texel, so a
    caustic singularity deposits at most its flux over one texel's area.

    Parameters
    ----------
    c0, r0, c1, r1, c2, r2 : float
        Columns and rows of the three vertices.

    Returns
    -------
    float
        ``max(|A_p|, 1)``, texels.

    References
    ----------
    Tipprasert (2006), §4.5, eq. 4-18 (``A_d``, the intersection area), Fig. 4-14.
    """
    af = (c1 - c0) * (r2 - r0) - (r1 - r0) * (c2 - c0)
    return max(0.5 * abs(af), 1.0)


@nb.njit(cache=True, inline="always")
def section_irradiance(flux, inv_tv, area_texels, texel_area):
    """Eq. 4-18 on a reference plane: a beam's flux over its cross-section perpendicular to its axis.

    ``I_c = I_i A_w cos(theta_i) / (A_d cos(theta_t))`` with the flux
    ``Phi = I_i A_w cos(theta_i)`` (:func:`~.illumination.illumination_volumes`)
    and the perpendicular cross-section ``A_p |T . V|``; the receiver's
    cosine (:func:`receiver_cosine`) and the absorption ``exp(-K d)``
    (eq. 4-17) multiply it texel by texel.

    Parameters
    ----------
    flux : float
        ``Phi`` of the beam.
    inv_tv : float
        ``1 / |T . V|`` of its axis.
    area_texels : float
        The intersection triangle's area in texels (:func:`section_texels`).
    texel_area : float
        One texel's area on the plane, scene units.

    Returns
    -------
    float

    References
    ----------
    Tipprasert (2006), §4.5, eq. 4-18.
    """
    return flux * inv_tv / (area_texels * texel_area)


@nb.njit(cache=True, inline="always")
def receiver_cosine(tx, ty, tz, normal, i, j):
    """``|T . n|``: eq. 4-18's intensity as irradiance on the receiver of texel ``(i, j)``.

    Parameters
    ----------
    tx, ty, tz : float
        The beam axis ``T`` (world).
    normal : (Hc, Wc, 3) float64
        The receiver's unit normals.
    i, j : int
        The texel.

    Returns
    -------
    float

    References
    ----------
    Tipprasert (2006), §4.5, eq. 4-18 (``cos theta`` at the receiver).
    """
    return abs(tx * normal[i, j, 0] + ty * normal[i, j, 1] + tz * normal[i, j, 2])


@nb.njit(cache=True, parallel=True)
def _sections(beams, planes, grid, sec):
    """Intersection triangles of the candidate beams ``sec.cand`` with every plane ``zeta = planes.zeta[g]``."""
    # the named tuples unpacked by name, one field per statement, outside the prange loop (inside it,
    # Numba drops stores into arrays taken from a tuple: numba#7135)
    O = beams.O
    D = beams.D
    flux = beams.flux
    inv_tv = beams.inv_tv
    zetas = planes.zeta
    rects = planes.rect
    texel_area = planes.texel_area
    cand = sec.cand
    X = sec.X
    Y = sec.Y
    C = sec.C
    B = sec.B
    rows = sec.rows
    M = cand.shape[0]
    for s in nb.prange(X.shape[0]):
        g = s // M
        t = cand[s - g * M]
        zp = zetas[g]
        ok = flux[t] > 0.0
        lam0 = 0.0
        lam1 = 0.0
        lam2 = 0.0
        c0 = 0.0
        c1 = 0.0
        c2 = 0.0
        r0 = 0.0
        r1 = 0.0
        r2 = 0.0
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
            X[s, k] = np.int64(np.round(c * 256.0))
            Y[s, k] = np.int64(np.round(r * 256.0))
            if k == 0:
                lam0 = lam
                c0 = c
                r0 = r
            elif k == 1:
                lam1 = lam
                c1 = c
                r1 = r
            else:
                lam2 = lam
                c2 = c
                r2 = r
        i0, i1 = 1, 0
        if ok:
            B[s] = section_irradiance(flux[t], inv_tv[t], section_texels(c0, r0, c1, r1, c2, r2), texel_area)
            C[s, 0] = lam0
            C[s, 1] = lam1
            C[s, 2] = lam2
            lo = min(Y[s, 0], min(Y[s, 1], Y[s, 2]))
            hi = max(Y[s, 0], max(Y[s, 1], Y[s, 2]))
            xlo = min(X[s, 0], min(X[s, 1], X[s, 2]))
            xhi = max(X[s, 0], max(X[s, 1], X[s, 2]))
            i0, i1 = pixel_span(lo, hi, rects[g, 0], rects[g, 1])
            j0, j1 = pixel_span(xlo, xhi, rects[g, 2], rects[g, 3])
            if j0 > j1 or i0 > i1:
                i0, i1 = 1, 0
        rows[s, 0] = i0
        rows[s, 1] = i1


@nb.njit(cache=True, parallel=True)
def _splat(beams, sec, bins, grid, texels, planes, out):
    """Additive blending of intersection triangles, plane after plane; fragments pass where
    ``texels.accept == planes.key[g]`` (the depth test of eq. 4-15)."""
    # unpacked by name, one field per statement, outside the prange loop (see _sections)
    tbar = beams.tbar
    tdz = beams.tdz
    cand = sec.cand
    X = sec.X
    Y = sec.Y
    C = sec.C
    B = sec.B
    rows = sec.rows
    counts = bins.counts
    tris = bins.tris
    H = grid.H
    band = grid.band
    accept = texels.accept
    depth = texels.depth
    normal = texels.normal
    zetas = planes.zeta
    keys = planes.key
    rects = planes.rect
    K = planes.K
    M = cand.shape[0]
    nb_bands = counts.shape[0] - 1
    for b in nb.prange(nb_bands):
        r0 = b * band
        r1 = min(r0 + band, H) - 1
        for q in range(counts[b], counts[b + 1]):
            s = tris[q]
            g = s // M
            t = cand[s - g * M]
            key = keys[g]
            zp = zetas[g]
            # a folded beam (negative area): same coverage, re-oriented
            x0, y0, x1, y1, x2, y2, c0, c1, c2, area, _ = oriented_triangle(X, Y, C, s)
            if area == 0:
                continue
            i0 = max(rows[s, 0], r0)
            i1 = min(rows[s, 1], r1)
            j0, j1 = pixel_span(min(x0, min(x1, x2)), max(x0, max(x1, x2)), rects[g, 2], rects[g, 3])
            if j0 > j1 or i0 > i1:
                continue
            e = edge_setup(x0, y0, x1, y1, x2, y2)
            v = (x0, y0, x1, y1, x2, y2)
            inv_area = 1.0 / area
            tx = tbar[t, 0]
            ty = tbar[t, 1]
            tz = tbar[t, 2]
            kk = K / tdz[t] if K > 0.0 else 0.0
            base = B[s]
            for i in range(i0, i1 + 1):
                # the rasterizer's scanline step: the row's covered run, edge functions stepped along it
                ja, jb, w0, w1, w2 = row_span(v, e, i, j0, j1)
                for j in range(ja, jb + 1):
                    w0, w1, w2 = step_edges(j, ja, e, w0, w1, w2)
                    if accept[i, j] != key:  # depth test against the position map (eq. 4-15)
                        continue
                    g_ = receiver_cosine(tx, ty, tz, normal, i, j)
                    if K > 0.0:
                        lam = (w0 * c0 + w1 * c1 + w2 * c2) * inv_area
                        g_ *= math.exp(-K * lam - kk * (depth[i, j] - zp))
                    out[i, j] += base * g_


#: sections computed per pass: planes are drawn in groups of about this many beam sections, so that
#: a render launches a few parallel kernels per group rather than per plane (fork-join costs, which
#: dominate on a loaded machine) while the section buffers stay small (~100 bytes per section)
GROUP_SECTIONS = 1 << 18


def splat_planes(beams, cand, box, planes, texels, K, out):
    """Draw every candidate beam's intersection triangle with each plane of ``planes`` into ``out``.

    Planes are drawn in order, in groups of about :data:`GROUP_SECTIONS`
    sections per kernel launch; a texel receives its additions plane by plane,
    each plane's triangles in beam order, whatever the grouping and thread
    count (bit-identical to drawing one plane at a time).

    Parameters
    ----------
    beams : BeamSet
    cand : (M,) int64
        Candidate beams (:func:`cull_beams`, or every beam with flux).
    box : Box
    planes : PlaneSet
        Plane depths, depth-test keys and scissor rectangles.
    texels : ReceiverTexels
        The depth-test map, depth and unit normal of the receiver at each texel.
    K : float
        Absorption coefficient of the water (``water.absorption``).
    out : (Hc, Wc) float64
        Accumulated irradiance (additive blending).

    Returns
    -------
    int
        Number of intersection triangles drawn.

    References
    ----------
    Tipprasert (2006), §4.5, eqs. 4-15 to 4-18, Fig. 4-15 (steps 2.1 to 2.3).
    """
    Hc, Wc = box.size
    M = len(cand)
    zetas = np.asarray(planes.zeta, np.float64).reshape(-1)
    keys = np.asarray(planes.key, np.int64).reshape(-1)
    rects = np.ascontiguousarray(np.asarray(planes.rect, np.int64).reshape(-1, 4))
    live = np.flatnonzero(rects[:, 0] <= rects[:, 1])
    if M == 0 or len(live) == 0:
        return 0
    grid = _CausticsGrid(Wc, Hc, BAND)
    arrays = beams.arrays
    G = max(1, GROUP_SECTIONS // M)
    drawn = 0
    for a in range(0, len(live), G):
        idx = live[a:a + G]
        S = len(idx) * M
        group = _SplatPlanes(np.ascontiguousarray(zetas[idx]), np.ascontiguousarray(keys[idx]),
                             np.ascontiguousarray(rects[idx]), float(K), float(box.texel_area))
        sec = _Sections(cand, np.empty((S, 3), np.int64), np.empty((S, 3), np.int64), np.empty((S, 3), np.float64),
                        np.zeros(S, np.float64), np.empty((S, 2), np.int64))
        _sections(arrays, group, grid, sec)
        bins = _Bins(*bin_bands(sec.rows, Hc, BAND))
        _splat(arrays, sec, bins, grid, texels, group, out)
        drawn += int(np.count_nonzero(sec.rows[:, 0] <= sec.rows[:, 1]))
    return drawn


def splat_plane(beams, cand, box, plane, texels, K, out):
    """:func:`splat_planes` for one plane.

    Parameters
    ----------
    beams, cand, box : BeamSet, (M,) int64, Box
        As for :func:`splat_planes`.
    plane : PlaneSet
        One plane: ``zeta`` a float, ``key`` an int, ``rect`` (4,) int64.
    texels, K, out : ReceiverTexels, float, (Hc, Wc) float64
        As for :func:`splat_planes` (a fragment is kept where ``texels.accept == plane.key``).

    Returns
    -------
    int
        Number of this plane's intersection triangles drawn.

    References
    ----------
    Tipprasert (2006), §4.5, eqs. 4-15 to 4-18, Fig. 4-15.
    """
    one = PlaneSet([plane.zeta], [plane.key], np.asarray(plane.rect, np.int64).reshape(1, 4))
    return splat_planes(beams, cand, box, one, texels, K, out)
