"""A receiver's reference box and its map frame (Tipprasert 2006, eqs. 4-1 to 4-3): every caustic map's texels.

A receiver's caustic map lies on the face of a box aligned with the refracted
light ``T0`` (axes ``U, V = -T0, W``, eq. 4-1; extents ``w, h, d``, eq. 4-3):
the level map's position maps and planes (:mod:`refraction_ref.levelmap.planes`),
the exact water reference's maps and the caustic frames (``caustic_frame_r``)
are all laid in it. Conventions (map coordinates, placement ``"component"``,
``"thesis"`` and ``"tight"``): :mod:`refraction_ref.levelmap.planes`'s
docstring and ``docs/oracle.md``.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.2.1.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..vec3 import affine, dot

__all__ = ["Box", "PLACEMENTS", "CENTRED", "box_axes", "reference_box", "to_map", "dir_to_map", "from_map", "frame_of"]

#: where a receiver's box sits (``caustics.placement``): eq. 4-3 read per axis (the component of ``P_a``
#: along the axis, the default), eq. 4-3 read literally (the whole vector's length ``|P_a|``), or the tight box
PLACEMENTS = ("component", "thesis", "tight")

#: the placements of eqs. 4-2/4-3: box centred on the receiver's origin ``P_0``, the thesis's plane lattice
#: of eqs. 4-6 to 4-9 (planes on the box faces); ``"tight"`` has slab-centred planes
CENTRED = ("component", "thesis")


class Box(NamedTuple):
    """An oriented bounding box and its map resolution.

    Attributes
    ----------
    center : (3,) ; U, V, W : (3,) unit axes ; T0 = -V
    w, h, d : float, extents along U, V, W
    size : (Hc, Wc) texels of the maps laid over the U x W face
    """

    center: np.ndarray
    U: np.ndarray
    V: np.ndarray
    W: np.ndarray
    w: float
    h: float
    d: float
    size: tuple

    @property
    def T0(self):
        return -self.V

    @property
    def texel_area(self):
        """World area of one texel of the map plane (perpendicular to V)."""
        return (self.w / self.size[1]) * (self.d / self.size[0])

    @property
    def texel_size(self):
        return max(self.w / self.size[1], self.d / self.size[0])


def box_axes(T0):
    """The box axes ``U, V, W`` of eq. 4-1 for the refracted light direction ``T0``.

    Parameters
    ----------
    T0 : (3,) array_like
        The refracted light direction (``V = -T0``).

    Returns
    -------
    U, V, W : (3,) float64
        Unit axes: ``U = V x N``, ``W = U x V`` with ``N`` the world z axis (x
        when z is nearly parallel to ``V``).

    References
    ----------
    Tipprasert (2006), §4.2.1, eq. 4-1.
    """
    V = -np.asarray(T0, dtype=np.float64)
    V = V / np.linalg.norm(V)
    N = np.array([0.0, 0.0, 1.0]) if abs(V[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    U = np.cross(V, N)
    U /= np.linalg.norm(U)
    W = np.cross(U, V)
    W /= np.linalg.norm(W)
    return U, V, W


def reference_box(vertices, T0, size, placement, origin=None):
    """Bounding box of a receiver aligned with ``V = -T0`` (eqs. 4-1 to 4-3).

    Parameters
    ----------
    vertices : (N, 3) array_like
        The receiver's world-space vertices.
    T0 : (3,) array_like
        Refracted light direction (:func:`refracted_axis`).
    size : int or (Hc, Wc)
        Texels of the maps.
    placement : {"tight", "component", "thesis"}
        No default: the caustic maps' boxes are tight, the level map's follow
        ``caustics.placement``. ``"tight"``: the tight box of the vertices; ``"component"``: centred
        on ``origin`` with extents ``2 max |(P - P_0) . a|`` along each axis
        ``a`` (eq. 4-3 with ``|P_a|`` the component of the farthest vertex
        along ``a``: the smallest box centred on ``P_0`` that encloses the
        receiver); ``"thesis"``: centred on ``origin`` with extents twice the
        whole length ``|P_a - P_0|`` of that vertex (eq. 4-3 read literally,
        larger; module docstring).
    origin : (3,) array_like, optional
        ``P_0`` (``"component"``, ``"thesis"``; default the vertices'
        bounding-box centre).

    Returns
    -------
    Box
        Degenerate extents (a flat receiver seen edge-on or face-on) are
        widened to ``1e-6`` of the largest extent so every division is finite.

    References
    ----------
    Tipprasert (2006), §4.2.1, eqs. 4-1 to 4-3.
    """
    v = np.asarray(vertices, dtype=np.float64)
    U, V, W = box_axes(T0)
    R = np.stack([U, V, W])
    if placement in CENTRED:
        o = (v.min(axis=0) + v.max(axis=0)) / 2.0 if origin is None else np.asarray(origin, dtype=np.float64)
        loc = affine(v - o, R.T)
        far = np.argmax(np.abs(loc), axis=0)  # v_x, v_y, v_z: farthest along each local axis
        if placement == "component":
            # w, h, d = 2 |P_x . U|, 2 |P_y . V|, 2 |P_z . W| (eq. 4-3 per axis): encloses the receiver, no more
            ext = 2.0 * np.abs(loc[far, np.arange(3)])
        else:
            ext = 2.0 * np.linalg.norm(loc[far], axis=1)  # w, h, d = 2 |P_x|, 2 |P_y|, 2 |P_z| (eq. 4-3 literally)
        centre = o
    else:
        loc = affine(v, R.T)
        lo, hi = loc.min(axis=0), loc.max(axis=0)
        centre = ((lo + hi) / 2.0) @ R
        ext = hi - lo
    floor = 1e-6 * max(float(ext.max()), 1e-12)
    ext = np.maximum(ext, floor)
    sz = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))
    return Box(np.asarray(centre, dtype=np.float64), U, V, W, float(ext[0]), float(ext[1]), float(ext[2]), sz)


def to_map(box, p):
    """World points (..., 3) to map coordinates (col, row, zeta), (..., 3).

    Parameters
    ----------
    box : Box
        The reference box defining the map frame.
    p : (..., 3) array_like
        World points.

    Returns
    -------
    (..., 3) float64
        ``col`` and ``row`` in texel units (centres at ``+0.5``) and ``zeta``,
        the depth along ``T0`` from the box centre (world units).

    References
    ----------
    Tipprasert (2006), §4.2.1 (box axes, eq. 4-1) and §4.2.2 (eqs. 4-10 to 4-13).
    """
    q = np.asarray(p, dtype=np.float64) - box.center
    Hc, Wc = box.size
    col = (dot(q, box.U) / box.w + 0.5) * Wc
    row = (dot(q, box.W) / box.d + 0.5) * Hc
    zeta = -dot(q, box.V)
    return np.stack([col, row, zeta], axis=-1)


def dir_to_map(box, t):
    """World directions (..., 3) to map-space rates (dcol, drow, dzeta) per unit length.

    Parameters
    ----------
    box : Box
        As for :func:`to_map`.
    t : (..., 3) array_like
        World directions.

    Returns
    -------
    (..., 3) float64
        Texels of column and row and world units of ``zeta`` travelled per unit
        length along ``t``.

    References
    ----------
    Tipprasert (2006), §4.2.1 and §4.4 (edge rays of the beams, Fig. 4-14).
    """
    t = np.asarray(t, dtype=np.float64)
    Hc, Wc = box.size
    return np.stack([dot(t, box.U) * (Wc / box.w), dot(t, box.W) * (Hc / box.d), -dot(t, box.V)], axis=-1)


def from_map(box, col, row, zeta):
    """Map coordinates back to world points (..., 3).

    Parameters
    ----------
    box : Box
        The reference box defining the map frame.
    col, row : array_like
        Map coordinates in texel units (texel centres at ``+0.5``).
    zeta : array_like
        Depth along ``T0`` from the box centre, broadcast with ``col``, ``row``.

    Returns
    -------
    (..., 3) float64
        World points, the inverse of :func:`to_map`.

    References
    ----------
    Tipprasert (2006), §4.2.2 (positions from the position map's depth).
    """
    Hc, Wc = box.size
    a = (np.asarray(col) / Wc - 0.5) * box.w
    b = (np.asarray(row) / Hc - 0.5) * box.d
    return (box.center + a[..., None] * box.U + b[..., None] * box.W
            - np.asarray(zeta)[..., None] * box.V)


def frame_of(box):
    """``caustic_frame`` (4, 3): origin, u axis, v axis (full edges), normal (docs/oracle.md).

    The rectangle is the box face nearest the light; the normal is ``V``
    (towards the light); texel (a, b) holds the first receiver surface seen
    from ``origin + (b + .5)/Wc u + (a + .5)/Hc v`` looking along ``-V``.

    Parameters
    ----------
    box : Box
        The reference box of a receiver.

    Returns
    -------
    (4, 3) float64
        Rows ``origin``, ``u``, ``v``, ``normal`` in world units.

    References
    ----------
    Tipprasert (2006), §4.2.1 and §4.5 (caustics map over the box face).
    """
    origin = box.center - box.w / 2.0 * box.U - box.d / 2.0 * box.W + box.h / 2.0 * box.V
    return np.stack([origin, box.w * box.U, box.d * box.W, box.V]).astype(np.float64)
