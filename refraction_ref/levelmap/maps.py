"""Position map and diffuse map of a receiver: orthographic renderings along the
reference box (eqs. 4-10 to 4-13).

The view volume ``OV`` (eq. 4-10) spans the box: ``lp, rp = -+w/2``,
``bp, tp = -+h/2`` mapped onto the map's rows (the box's W extent here),
``np, fp = -+d/2`` (eq. 4-11), looking along ``-V`` (eq. 4-13: the camera
looks down the box's negative y axis). The near plane is pushed up to the
water: every receiver between the light and the box is drawn too, so a
receiver shadows the ones below it (the first surface along ``-V`` wins).

The position map stores the depth ``zeta`` of that first surface (the thesis
stores the depth buffer; positions follow from it and the texel), a
visibility buffer stores which receiver triangle it is, from which the
receiver index, the face normal (for the cosine of eq. 4-18 on the receiver)
and the diffuse colour (the diffuse map) are read.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.2.2.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ..raster import ortho_setup, rasterize_ortho
from ..caustics.receivers import Receivers  # the receivers' triangle soup, shared with the caustics

__all__ = ["Receivers", "LevelMap", "LevelMapPair", "level_map", "receiver_selection", "map_setup", "map_point"]


class LevelMap(NamedTuple):
    """A receiver's level map without its planes.

    Attributes
    ----------
    depth : (Hc, Wc) float64, ``zeta`` of the first surface, ``+inf`` on none
    tri : (Hc, Wc) int64, receiver triangle of that surface, ``-1`` on none
    own : (Hc, Wc) bool, the first surface belongs to this receiver
    normal : (Hc, Wc, 3) float64, its unit face normal (zero where none)
    diffuse : (Hc, Wc, 3) float32, the diffuse map (albedo where own, else 0)
    """

    depth: np.ndarray
    tri: np.ndarray
    own: np.ndarray
    normal: np.ndarray
    diffuse: np.ndarray


class LevelMapPair(NamedTuple):
    """One (receiver, light) pair's reference box, the receiver triangles drawn and its level map.

    Attributes
    ----------
    box : Box
        The reference box (eqs. 4-1 to 4-3).
    sel : (T',) int64
        The receiver triangles drawn into its maps (:func:`receiver_selection`).
    setup : RasterSetup
        Their map-space triangles (:func:`map_setup`), reused by the slices
        of the slice-image baseline.
    lm : LevelMap
        Position and diffuse maps (eqs. 4-10 to 4-13).
    receiver : int
        The receiver whose box this is.
    """

    box: object
    sel: np.ndarray
    setup: object
    lm: LevelMap
    receiver: int


class _MapSource(NamedTuple):
    """The visibility buffer and what each triangle id resolves to."""

    ids: np.ndarray  # (Hc, Wc) index into sel, -1 where none
    sel: np.ndarray  # (T',) receiver triangles drawn
    owner: np.ndarray  # (T,) receiver of each triangle
    normals: np.ndarray  # (T, 3) unit face normals
    albedo: np.ndarray  # (3,) receiver r's albedo
    r: int


@nb.njit(cache=True, parallel=True)
def _fill(src, tri, own, normal, diffuse):
    """Triangle, ownership, normal and diffuse map of every texel, rows in parallel."""
    ids = src.ids
    sel = src.sel
    owner = src.owner
    normals = src.normals
    albedo = src.albedo
    r = src.r
    H, W = ids.shape
    for i in nb.prange(H):
        for j in range(W):
            k = ids[i, j]
            if k < 0:
                tri[i, j] = -1
                own[i, j] = False
                for c in range(3):
                    normal[i, j, c] = 0.0
                    diffuse[i, j, c] = 0.0
                continue
            t = sel[k]
            tri[i, j] = t
            mine = owner[t] == r
            own[i, j] = mine
            for c in range(3):
                normal[i, j, c] = normals[t, c]
                diffuse[i, j, c] = np.float32(albedo[c]) if mine else np.float32(0.0)


def level_map(receivers, r, box, shadows=True, setup=None):
    """Render receiver ``r``'s position and diffuse maps (eqs. 4-10 to 4-13).

    Parameters
    ----------
    receivers : Receivers
    r : int
        The receiver whose box this is.
    box : Box
    shadows : bool
        Draw the other receivers too, so that they occlude this one.
    setup : RasterSetup, optional
        :func:`map_setup` of the same triangles, to reuse.

    Returns
    -------
    lm : LevelMap
    sel : (T',) int64
        The receiver triangles drawn (indices into ``receivers.tris``).
    setup : RasterSetup
        Their snapped, binned map-space triangles (reused by the slices of
        the slice-image baseline).

    References
    ----------
    Tipprasert (2006), §4.2.2, eqs. 4-10 to 4-13.
    """
    sel = receiver_selection(receivers, r, shadows)
    if setup is None:
        setup = map_setup(receivers, sel, box)
    depth, ids = rasterize_ortho(setup, box.size)
    Hc, Wc = ids.shape
    tri = np.empty((Hc, Wc), np.int64)
    own = np.empty((Hc, Wc), np.bool_)
    normal = np.empty((Hc, Wc, 3), np.float64)
    diffuse = np.empty((Hc, Wc, 3), np.float32)
    src = _MapSource(np.ascontiguousarray(ids), np.ascontiguousarray(sel, np.int64), receivers.owner, receivers.normals,
                  np.ascontiguousarray(receivers.albedo[r], np.float64), int(r))
    _fill(src, tri, own, normal, diffuse)
    return LevelMap(depth, tri, own, normal, diffuse), sel, setup


def receiver_selection(receivers, r, shadows=True):
    """Triangles drawn into receiver ``r``'s maps: all receivers (shadows) or ``r``'s own.

    Parameters
    ----------
    receivers : Receivers
        The receivers' triangle soup (``tris``, ``owner``).
    r : int
        The receiver whose maps these are.
    shadows : bool
        Draw every receiver (so others occlude ``r``), else only ``r``'s own.

    Returns
    -------
    (T',) int64
        Indices into ``receivers.tris``.

    References
    ----------
    Tipprasert (2006), §4.2.2 (position and diffuse maps).
    """
    return np.arange(len(receivers.tris)) if shadows else np.flatnonzero(receivers.owner == r)


@nb.njit(cache=True, inline="always")
def map_point(frame, px, py, pz):
    """:func:`~.planes.to_map` of one world point, inside a kernel.

    Parameters
    ----------
    frame : (6, 3) float64
        The box's rows ``center, U, V, W, (w, d, 0), (Wc, Hc, 0)``.
    px, py, pz : float
        The world point.

    Returns
    -------
    x, y, z : float
        Its map coordinates: texel column and row, depth along ``-V``.

    References
    ----------
    Tipprasert (2006), §4.2.1 (box axes, eq. 4-1) and §4.2.2 (eqs. 4-10 to 4-13).
    """
    qx = px - frame[0, 0]
    qy = py - frame[0, 1]
    qz = pz - frame[0, 2]
    x = ((qx * frame[1, 0] + qy * frame[1, 1] + qz * frame[1, 2]) / frame[4, 0] + 0.5) * frame[5, 0]
    y = ((qx * frame[3, 0] + qy * frame[3, 1] + qz * frame[3, 2]) / frame[4, 1] + 0.5) * frame[5, 1]
    return x, y, -(qx * frame[2, 0] + qy * frame[2, 1] + qz * frame[2, 2])


@nb.njit(cache=True, parallel=True)
def _tris_to_map(tris, sel, frame, out):
    """:func:`~.planes.to_map` of the vertices of triangles ``tris[sel]``, triangles in parallel."""
    for m in nb.prange(sel.shape[0]):
        t = sel[m]
        for k in range(3):
            x, y, z = map_point(frame, tris[t, k, 0], tris[t, k, 1], tris[t, k, 2])
            out[m, k, 0] = x
            out[m, k, 1] = y
            out[m, k, 2] = z


def map_setup(receivers, sel, box):
    """Snap and bin the selected receiver triangles in ``box``'s map coordinates.

    Parameters
    ----------
    receivers : Receivers
        The receivers' triangle soup.
    sel : (T',) int
        Triangles to draw (:func:`receiver_selection`).
    box : Box
        The reference box whose map coordinates (col, row, zeta) they are put in.

    Returns
    -------
    RasterSetup
        The triangles in map space, snapped and binned for
        :func:`~refraction_ref.raster.rasterize_ortho`.

    References
    ----------
    Tipprasert (2006), §4.2.2, eqs. 4-10 to 4-13 (orthographic view volume of
    the box).
    """
    Hc, Wc = box.size
    frame = np.array([box.center, box.U, box.V, box.W, [box.w, box.d, 0.0], [Wc, Hc, 0.0]], np.float64)
    tri = np.empty((len(sel), 3, 3))
    _tris_to_map(receivers.tris, np.ascontiguousarray(sel, np.int64), frame, tri)
    return ortho_setup(tri, box.size)
