"""Caustics casting (eq. 4-20): several lights' caustics maps cast into one per receiver.

Several lights each have their own reference planes and caustics map
(Fig. 4-17); ``caustic_map_r`` is given in the frame of the first light's
box, and the maps of the other lights are cast into it by projective texture
mapping: each texel's surface point is projected into the other light's map,
and its value taken where that map sees the same surface (its position-map
depth agrees within two texels, scaled by the surface slope), i.e. the sum
over lights of eq. 4-20.

The camera image applies eq. 4-19, ``I_o = I_c I_d + I_a``, with ``I_c`` the
irradiance looked up (nearest texel) in the receiver's caustics map, ``I_d``
its albedo (the diffuse map) and ``I_a = ambient * albedo``: the view through
the water (``image``) and the direct view (``image_direct``), both drawn by
:mod:`.view` (:func:`~.view.shade_point`).

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.6 (eq. 4-19), §4.7.1 (eq. 4-20), §2.5.
"""

from __future__ import annotations

import numpy as np

from .planes import from_map, to_map
from ..vec3 import dot

__all__ = ["cast_between"]


def cast_between(E_l, box_l, lm_l, box_0, lm_0, out):
    """Add light ``l``'s caustics map, cast onto the surface seen in frame 0, to ``out``.

    Parameters
    ----------
    E_l : (Hc_l, Wc_l) float
        Light ``l``'s caustics map (irradiance per texel of its box).
    box_l : Box
        Light ``l``'s reference box of the receiver.
    lm_l : LevelMap
        The receiver's level map in ``box_l`` (position map and ownership).
    box_0 : Box
        The first light's reference box, the frame of ``out``.
    lm_0 : LevelMap
        The receiver's level map in ``box_0``.
    out : (Hc_0, Wc_0) float
        Caustics map in frame 0, added to in place.

    Returns
    -------
    int
        Texels that received light ``l``'s value.

    References
    ----------
    Tipprasert (2006), §4.7.1 (eq. 4-20, Fig. 4-17), §2.5 (projective texture
    mapping).
    """
    ii, jj = np.nonzero(lm_0.own & np.isfinite(lm_0.depth))
    if len(ii) == 0:
        return 0
    pts = from_map(box_0, jj + 0.5, ii + 0.5, lm_0.depth[ii, jj])
    q = to_map(box_l, pts)
    Hc, Wc = box_l.size
    j = np.floor(q[:, 0]).astype(np.int64)
    i = np.floor(q[:, 1]).astype(np.int64)
    inside = (i >= 0) & (i < Hc) & (j >= 0) & (j < Wc)
    i, j = np.where(inside, i, 0), np.where(inside, j, 0)
    cosv = np.abs(dot(lm_0.normal[ii, jj], box_l.V))
    tol = 2.0 * max(box_l.texel_size, box_0.texel_size) / np.maximum(cosv, 0.05)
    ok = inside & lm_l.own[i, j] & (np.abs(q[:, 2] - lm_l.depth[i, j]) <= tol)
    out[ii[ok], jj[ok]] += E_l[i[ok], j[ok]]
    return int(np.count_nonzero(ok))
