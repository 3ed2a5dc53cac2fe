"""Smart slicing: place reference planes only where the light can meet the receiver (§4.7.2).

1. Depth profile: divide the box depth into ``depth_levels`` equal levels and
   count the position-map texels of this receiver in each (Figs. 4-19, 5-9).
2. Empty levels hold no texel; runs of consecutive valid levels form the
   sub-boxes, of height ``h_i = h * hr_i`` with ``hr_i`` = valid levels in the
   run / ``depth_levels`` (eq. 4-21).
3. Each sub-box gets ``n_i = hr_i / (2 eps)`` planes (eq. 4-22), ``eps`` being
   the acceptance threshold as a fraction of ``h``; with the ``n`` requested
   planes ``eps = 1 / (2 n)`` so ``n_i = hr_i n``.

Two ways to place the sub-boxes' planes (``levelmap.smart_spacing``):

* ``"respace"`` (the default): eq. 4-22 as the
  thesis means it: each sub-box ``i`` is sliced anew by the plane slicing of
  §4.2.1 (eqs. 4-6 to 4-9 on the sub-box) with ``n_i = round(hr_i / (2
  eps))`` **planes** (at least one), ``eps = s / (2 h)`` the normal slicing's
  acceptance threshold as a fraction of ``h``, so ``n_i = hr_i`` times the
  normal slicing's slice count (``planes - 1`` on the thesis's lattice).
  ``n_i`` counts planes, as the thesis's Table 5-4 does: a sphere lit from
  above fills about half of its box's depth levels (``hr = 1/2``) and the
  table gives 3 -> 1 and 101 -> 50 planes, i.e. ``hr (planes - 1)`` (read
  as a slice count, ``n_i + 1`` planes, it would give 2 and 51).
  On the thesis's lattice (placement ``component`` or ``thesis``) the
  ``n_i`` planes run from the sub-box's top face to its bottom face,
  spacing ``h_i / (n_i - 1)`` (one plane at its centre when ``n_i = 1``);
  on the ``tight`` lattice they sit at the centres of ``n_i`` equal slabs. A
  texel is accepted by the nearest plane of its own sub-box. The planes
  move, so texels change (measured by eq. 2-9 in the Tipprasert tables).
* ``"lattice"``: the planes of the normal slicing whose acceptance slab
  meets a sub-box (about ``n_i`` of them) are kept and the others dropped,
  rather than re-spaced: every texel is then accepted by the very plane
  that accepts it under normal slicing, and smart slicing provably changes
  no texel (what the thesis's Table 5-5 reports, intensity difference 0,
  "the development of smart slicing is intended for eliminating unnecessary
  plane", §5.2.4).

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.7.2 (eqs. 4-21, 4-22), §5.2.3, Tables 5-3 to 5-5.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .knobs import SPACINGS
from .planes import CENTRED, plane_lattice

__all__ = ["DepthLevels", "SubBoxPlanes", "depth_profile", "sub_boxes", "sub_box_bounds", "sub_box_planes", "normal_slices",
           "smart_planes", "respaced_planes", "SPACINGS"]


class DepthLevels(NamedTuple):
    """The depth profile's levels: level ``floor((zeta - zlo) / h * count)`` (Fig. 5-9).

    Attributes
    ----------
    zlo : float
        The box's face nearest the light, ``-h/2``.
    h : float
        The box's extent along ``T0``.
    count : int
        ``levels.depth_levels``.
    """

    zlo: float
    h: float
    count: int


class SubBoxPlanes(NamedTuple):
    """The re-spaced planes of the sub-boxes (eq. 4-22), as the acceptance kernel reads them.

    Attributes
    ----------
    sub_of : (levels,) int64
        The sub-box of each depth level, -1 for an empty level.
    z0 : (B,) float64
        Each sub-box's first plane's slab start (faces) or top (slabs).
    spacing : (B,) float64
        Its plane spacing.
    count : (B,) int64
        Its planes, ``n_i``.
    first : (B,) int64
        The index of its first plane among all sub-boxes' planes.
    faces : bool
        Planes on the sub-box's faces (``component``, ``thesis``), else at slab centres.
    """

    sub_of: np.ndarray
    z0: np.ndarray
    spacing: np.ndarray
    count: np.ndarray
    first: np.ndarray
    faces: bool


@nb.njit(cache=True, parallel=True)
def _profile(depth, own, dl, counts):
    """counts[b, k]: texels of band b of rows in level k (bands in parallel, merged by the caller)."""
    zlo = dl.zlo
    h = dl.h
    levels = dl.count
    H, W = depth.shape
    nbands = counts.shape[0]
    for b in nb.prange(nbands):
        for i in range(b * H // nbands, (b + 1) * H // nbands):
            for j in range(W):
                z = depth[i, j]
                if own[i, j] and np.isfinite(z):
                    k = np.int64(np.floor((z - zlo) / h * levels))
                    if k >= 0 and k < levels:
                        counts[b, k] += 1


@nb.njit(cache=True, parallel=True)
def _respaced_index(depth, own, dl, sub, out):
    """out[i, j]: the plane of the texel's own sub-box nearest to it (eq. 4-22's slicing), -1 for none.

    ``sub.count[b]``: the sub-box's planes; ``sub.faces``: planes on the faces (index ``0 .. n_i - 1``
    nearest), else slab centres (slab index)."""
    # unpacked by name outside the prange loop (numba#7135)
    zlo = dl.zlo
    h = dl.h
    levels = dl.count
    sub_of = sub.sub_of
    z0 = sub.z0
    si = sub.spacing
    n_i = sub.count
    first = sub.first
    thesis = sub.faces
    H, W = depth.shape
    for i in nb.prange(H):
        for j in range(W):
            out[i, j] = -1
            z = depth[i, j]
            if not (own[i, j] and np.isfinite(z)):
                continue
            k = np.int64(np.floor((z - zlo) / h * levels))
            if k < 0 or k >= levels:
                continue
            b = sub_of[k]
            if b < 0:
                continue
            if thesis:
                q = np.int64(np.floor((z - z0[b]) / si[b] + 0.5))
                q = min(max(q, 0), n_i[b] - 1)
            else:
                q = np.int64(np.floor((z - z0[b]) / si[b]))
                q = min(max(q, 0), n_i[b] - 1)
            out[i, j] = first[b] + q


def depth_profile(lm, box, levels):
    """Texel count per depth level of the receiver's own surface (Fig. 5-9).

    Level ``k`` holds the depths ``[-h/2 + k h / levels, -h/2 + (k + 1) h / levels)``.

    Parameters
    ----------
    lm : LevelMap
        The receiver's level map (position-map depth ``zeta`` and ownership).
    box : Box
        Its reference box (extent ``h`` along ``T0``).
    levels : int
        Number of equal depth levels.

    Returns
    -------
    (levels,) int64

    References
    ----------
    Tipprasert (2006), §4.7.2, Figs. 4-19 and 5-9.
    """
    nbands = max(1, min(lm.depth.shape[0], 32))
    counts = np.zeros((nbands, int(levels)), np.int64)
    _profile(lm.depth, lm.own, DepthLevels(-box.h / 2.0, box.h, int(levels)), counts)
    return counts.sum(axis=0)


def sub_boxes(profile):
    """Runs of consecutive valid levels: list of (first, last + 1) level indices (eq. 4-21).

    Parameters
    ----------
    profile : (levels,) array_like of int
        Texel count per depth level (:func:`depth_profile`).

    Returns
    -------
    list of (int, int)
        Half-open level ranges ``(first, last + 1)`` of the runs of non-empty
        levels, in depth order.

    References
    ----------
    Tipprasert (2006), §4.7.2, eq. 4-21.
    """
    valid = np.asarray(profile) > 0
    out = []
    k = 0
    L = len(valid)
    while k < L:
        if valid[k]:
            e = k
            while e < L and valid[e]:
                e += 1
            out.append((k, e))
            k = e
        else:
            k += 1
    return out


def sub_box_bounds(box, run, levels):
    """Eq. 4-21: a sub-box's depths and its height as a fraction of the box's.

    Parameters
    ----------
    box : Box
        The reference box (extent ``h`` along ``T0``).
    run : (int, int)
        The sub-box's levels ``(first, last + 1)`` (:func:`sub_boxes`).
    levels : int
        Depth levels of the profile.

    Returns
    -------
    z0, z1 : float
        Its top and bottom depths, ``-h/2 + h a / levels`` and ``-h/2 + h e / levels``.
    hr : float
        ``hr_i = (e - a) / levels``, so that ``h_i = h hr_i``.

    References
    ----------
    Tipprasert (2006), §4.7.2, eq. 4-21.
    """
    a, e = run
    z0 = -box.h / 2.0 + box.h * a / levels
    z1 = -box.h / 2.0 + box.h * e / levels
    return z0, z1, (e - a) / levels


def sub_box_planes(hr, slices):
    """Eq. 4-22: ``n_i = hr_i / (2 eps)``, a sub-box's share of the normal slicing's slices.

    With ``eps = s / (2 h)`` the normal slicing's acceptance threshold as a
    fraction of ``h``, ``1 / (2 eps)`` is its slice count (:func:`normal_slices`).

    Parameters
    ----------
    hr : float
        ``hr_i`` (:func:`sub_box_bounds`).
    slices : int
        The normal slicing's slices.

    Returns
    -------
    float
        ``n_i``, unrounded.

    References
    ----------
    Tipprasert (2006), §4.7.2, eq. 4-22; Table 5-4 (``n_i`` counts planes).
    """
    return hr * slices


def smart_planes(lm, box, n, levels, placement, pidx=None):
    """Indices (into the normal slicing's ``n`` planes) of the planes smart slicing keeps (``"lattice"``).

    Parameters
    ----------
    lm : LevelMap
    box : Box
    n : int
        Planes requested.
    levels : int
        Depth levels of the profile.
    pidx : (Hc, Wc) int32, optional
        The plane index map; planes it uses are always kept (a guard against
        rounding at level boundaries; they are within the sub-boxes anyway).
    placement : {"component", "thesis", "tight"}
        The normal slicing's lattice (``caustics.placement``,
        :func:`~refraction_ref.levelmap.planes.plane_lattice`).

    Returns
    -------
    keep : (n_used,) int64
        Increasing plane indices.
    info : dict
        ``profile`` (counts per level), ``sub_boxes`` (list of
        ``[h_i, hr_i, n_i]`` with ``n_i`` from eq. 4-22), ``empty_levels``.

    References
    ----------
    Tipprasert (2006), §4.7.2, eqs. 4-21, 4-22.
    """
    prof = depth_profile(lm, box, levels)
    boxes = sub_boxes(prof)
    lat = plane_lattice(box, n, placement)
    s, zlo = lat.s, lat.zlo
    slices = normal_slices(n, placement)
    keep = np.zeros(int(n), bool)
    sb = []
    for run in boxes:
        z0, z1, hr = sub_box_bounds(box, run, levels)
        # planes whose slab [zlo + s i, zlo + s (i + 1)) meets [z0, z1)
        i0 = max(int(np.floor((z0 - zlo) / s)), 0)
        i1 = min(int(np.ceil((z1 - zlo) / s)), int(n))
        keep[i0:i1] = True
        sb.append([box.h * hr, hr, sub_box_planes(hr, slices)])  # h_i (eq. 4-21), hr_i, n_i (eq. 4-22)
    if pidx is not None:
        used = np.unique(pidx[pidx >= 0])
        keep[used[used < n]] = True
    return np.flatnonzero(keep).astype(np.int64), {
        "profile": prof.tolist(), "sub_boxes": sb, "empty_levels": int(np.count_nonzero(prof == 0))}


def normal_slices(n, placement):
    """Eq. 4-6: the normal slicing's slices, ``planes - 1`` (planes on the faces) or ``planes`` (tight slabs).

    Parameters
    ----------
    n : int
        Planes (``levelmap.planes``).
    placement : {"component", "thesis", "tight"}
        ``caustics.placement``; one plane on the faces' lattice counts one slice.

    Returns
    -------
    int

    References
    ----------
    Tipprasert (2006), §4.2.1, eq. 4-6.
    """
    return max(int(n) - 1, 1) if placement in CENTRED else int(n)


def respaced_planes(lm, box, n, levels, placement):
    """Eq. 4-22: each sub-box sliced anew with ``n_i = round(hr_i / (2 eps))`` planes (``"respace"``).

    Parameters
    ----------
    lm : LevelMap
    box : Box
    n : int
        Planes requested (the normal slicing; its ``eps`` sets ``n_i``).
    levels : int
        Depth levels of the profile.
    placement : {"tight", "component", "thesis"}
        ``"component"``, ``"thesis"``: ``max(n_i, 1)`` planes from the
        sub-box's top face to its bottom face, spacing ``h_i / (n_i - 1)``
        (one plane at its centre when ``n_i = 1``); ``"tight"``:
        ``max(n_i, 1)`` planes at slab centres.

    Returns
    -------
    zeta : (k,) float64
        The planes' depths, nearest the light first.
    pidx : (Hc, Wc) int32
        The plane accepting each texel (the nearest of its sub-box), -1 for none.
    info : dict
        As :func:`smart_planes`, ``n_i`` the planes actually used.

    References
    ----------
    Tipprasert (2006), §4.7.2, eqs. 4-21, 4-22; §4.2.1, eqs. 4-6 to 4-9.
    """
    levels = int(levels)
    prof = depth_profile(lm, box, levels)
    boxes = sub_boxes(prof)
    slices = normal_slices(n, placement)
    thesis = placement in CENTRED
    sub_of = np.full(levels, -1, np.int64)
    z0 = np.zeros(max(len(boxes), 1))
    si = np.ones(max(len(boxes), 1))
    n_i = np.zeros(max(len(boxes), 1), np.int64)
    first = np.zeros(max(len(boxes), 1), np.int64)
    zeta, sb = [], []
    for b, (a, e) in enumerate(boxes):
        sub_of[a:e] = b
        lo, hi, hr = sub_box_bounds(box, (a, e), levels)
        # n_i = hr_i / (2 eps) planes (eq. 4-22; Table 5-4 counts planes), at least one per sub-box
        k = max(int(round(sub_box_planes(hr, slices))), 1)
        first[b] = len(zeta)
        z0[b] = lo
        if thesis:
            if k == 1:  # one plane at the sub-box's centre, accepting all of it
                zeta.append((lo + hi) / 2.0)
                z0[b], si[b] = (lo + hi) / 2.0, 2.0 * (hi - lo) + 1.0
            else:
                si[b] = (hi - lo) / (k - 1)  # k planes on the sub-box's faces and between (eqs. 4-6 to 4-9)
                zeta.extend(lo + si[b] * np.arange(k))
        else:
            si[b] = (hi - lo) / k
            zeta.extend(lo + si[b] * (np.arange(k) + 0.5))
        n_i[b] = k
        sb.append([box.h * hr, hr, k])
    pidx = np.empty(lm.depth.shape, np.int32)
    _respaced_index(lm.depth, lm.own, DepthLevels(-box.h / 2.0, box.h, levels),
                    SubBoxPlanes(sub_of, z0, si, n_i, first, thesis), pidx)
    return np.asarray(zeta, np.float64), pidx, {
        "profile": prof.tolist(), "sub_boxes": sb, "empty_levels": int(np.count_nonzero(prof == 0))}
