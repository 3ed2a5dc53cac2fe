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

import numpy as np

from ..raster import ortho_setup, rasterize_ortho
from ..receivers import Receivers  # the receivers' triangle soup, shared with the caustics
from .planes import to_map

__all__ = ["Receivers", "LevelMap", "level_map", "receiver_selection", "map_setup"]


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
        the volumetric baseline).
    """
    sel = receiver_selection(receivers, r, shadows)
    if setup is None:
        setup = map_setup(receivers, sel, box)
    depth, ids = rasterize_ortho(setup, box.size)
    hit = ids >= 0
    tri = np.where(hit, sel[np.maximum(ids, 0)], -1)
    own = hit & (receivers.owner[np.maximum(tri, 0)] == r)
    normal = np.where(hit[..., None], receivers.normals[np.maximum(tri, 0)], 0.0)
    diffuse = np.where(own[..., None], receivers.albedo[r], 0.0).astype(np.float32)
    return LevelMap(depth, tri, own, normal, diffuse), sel, setup


def receiver_selection(receivers, r, shadows=True):
    """Triangles drawn into receiver ``r``'s maps: all receivers (shadows) or ``r``'s own."""
    return np.arange(len(receivers.tris)) if shadows else np.flatnonzero(receivers.owner == r)


def map_setup(receivers, sel, box):
    """Snap and bin the selected receiver triangles in ``box``'s map coordinates."""
    return ortho_setup(to_map(box, receivers.tris[sel]), box.size)
