"""The thesis's baseline: Iwasaki et al.'s volumetric-texture method, a stack of slice images (§5.2.1).

The scene value ``levelmap.variant = "volumetric"`` selects it; it is not
Sun 2008's volumetric method (``--method volumetric``). The thesis calls it
the "volumetric texture based" technique: its illumination map is a
volumetric texture, a set of slice images of the receiver.

For every sample plane (the reference planes of §4.2.1), a *slice image* of
the receivers is drawn: the part of the surface between the clip planes half
way to the previous and the next plane (Fig. 5-2), i.e. the plane's slab. The
intersection triangles of the beams with that plane are drawn into a caustics
buffer with additive blending (no depth test), multiplied by the slice image
(kept where the slice shows this receiver) and composited front to back into
the illumination map (Figs. 5-3, 5-4): a texel takes the caustics of the
first slice that shows any surface, as an opaque volume would.

The stack starts with one extra slice holding whatever lies between the
water and the box (other receivers), so receivers shadow each other exactly
as in the level map. The result is identical, texel for texel, to the level
map's (the thesis reports per-pixel identical images, §6.2); only the cost
differs: one receiver rendering, one buffer clear and one composite per
plane, the ``T(I)`` term of eq. 5-3 that the level map replaces by the single
position/diffuse map pass ``T(DP)`` (eqs. 5-5 to 5-7). Slices are rendered
one at a time here; a GPU keeps them all, ``planes x Hc x Wc`` texels
(§5.1), which ``memory_bytes`` reports.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §5.1, §5.2.1, Figs. 5-1 to 5-4, eqs. 5-1 to 5-7.
.. [2] K. Iwasaki, Y. Dobashi, T. Nishita, "A Fast Rendering Method for
   Refractive and Reflective Caustics Due to Water Surfaces", Computer
   Graphics Forum 22(3), 2003.
"""

from __future__ import annotations

import numpy as np

from ..raster import rasterize_ortho
from .caustics_map import PlaneSet, ReceiverTexels, splat_plane
from .intersection import plane_rects
from .planes import plane_lattice

__all__ = ["slice_image_caustics"]


def slice_image_caustics(beams, cand, pair, receivers, knobs, out):
    """Caustics of a pair's receiver with one slice image per sample plane (the thesis's baseline).

    Parameters
    ----------
    beams : BeamSet
    cand : (M,) int64
        Candidate beams.
    pair : LevelMapPair
        The (receiver, light) pair: its box, the receiver triangles drawn
        (``sel``, all of them or the receiver's own) and their raster set-up
        (:func:`~refraction_ref.raster.ortho_setup` in the box's map).
    receivers : Receivers
    knobs : LevelMapKnobs
        ``planes`` (sample planes, laid as the level map's by ``placement``,
        :func:`~refraction_ref.levelmap.planes.plane_lattice`), ``K``, and
        ``cull``: draw each intersection triangle only over the slice's texels
        (``levelmap.culling = "bounds"``), else over the whole map.
    out : (Hc, Wc) float64
        Receives the illumination map (overwritten where lit).

    Returns
    -------
    dict
        ``slices`` rendered, ``triangles`` drawn, ``memory_bytes`` of a GPU slice stack (16-bit).

    References
    ----------
    Tipprasert (2006), §5.1, §5.2.1, Figs. 5-1 to 5-4; Iwasaki et al. (2003).
    """
    box, sel, setup, r, n = pair.box, pair.sel, pair.setup, pair.receiver, knobs.planes
    Hc, Wc = box.size
    lat = plane_lattice(box, n, knobs.placement)
    zlo, s = lat.zlo, lat.s
    whole = np.array([0, Hc - 1, 0, Wc - 1], np.int64)
    # slice of everything between the water and the box (occluders)
    _, ids = rasterize_ortho(setup, box.size, slab=(zlo, s, -np.inf, -1.0))
    filled = ids >= 0
    cbuf = np.empty((Hc, Wc))
    drawn = 0
    for i in range(n):
        d_i, ids_i = rasterize_ortho(setup, box.size, slab=(zlo, s, float(i), float(i)))
        nonempty = ids_i >= 0
        tri = sel[np.maximum(ids_i, 0)]
        show = nonempty & ~filled & (receivers.owner[tri] == r)
        normal = receivers.normals[tri]
        accept = show.astype(np.int32)
        cbuf[...] = 0.0
        rect = plane_rects(np.where(show, 0, -1).astype(np.int32), 1)[0] if knobs.cull else whole
        plane = PlaneSet(float(lat.zeta[i]), 1, rect)
        drawn += splat_plane(beams, cand, box, plane, ReceiverTexels(accept, d_i, normal), knobs.K, cbuf)
        out[show] = cbuf[show]
        filled |= nonempty
    return {"slices": n + 1, "triangles": drawn, "memory_bytes": int((n + 1) * Hc * Wc * 2)}
