"""Smart slicing: place reference planes only where the light can meet the receiver (§4.7.2).

1. Depth profile: divide the box depth into ``depth_levels`` equal levels and
   count the position-map texels of this receiver in each (Figs. 4-19, 5-9).
2. Empty levels hold no texel; runs of consecutive valid levels form the
   sub-boxes, of height ``h_i = h * hr_i`` with ``hr_i`` = valid levels in the
   run / ``depth_levels`` (eq. 4-21).
3. Each sub-box gets ``n_i = hr_i / (2 eps)`` planes (eq. 4-22), ``eps`` being
   the acceptance threshold as a fraction of ``h``; with the ``n`` requested
   planes ``eps = 1 / (2 n)`` so ``n_i = hr_i n``.

The sub-box planes are taken from the lattice of the normal slicing (the
planes whose acceptance slab meets the sub-box, about ``n_i`` of them), rather
than re-spaced inside each sub-box: every texel is then accepted by the very
plane that accepts it under normal slicing, and smart slicing provably changes
no texel, which is what Table 5-5 reports (intensity difference 0).

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.7.2 (eqs. 4-21, 4-22), §5.2.3, Tables 5-3 to 5-5.
"""

from __future__ import annotations

import numpy as np

__all__ = ["depth_profile", "sub_boxes", "smart_planes"]


def depth_profile(lm, box, levels):
    """Texel count per depth level of the receiver's own surface (Fig. 5-9).

    Returns
    -------
    (levels,) int64
    """
    z = lm.depth[lm.own]
    z = z[np.isfinite(z)]
    k = np.floor((z + box.h / 2.0) / box.h * levels).astype(np.int64)
    k = k[(k >= 0) & (k < levels)]
    return np.bincount(k, minlength=int(levels)).astype(np.int64)


def sub_boxes(profile):
    """Runs of consecutive valid levels: list of (first, last + 1) level indices (eq. 4-21)."""
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


def smart_planes(lm, box, n, levels, pidx=None):
    """Indices (into the normal slicing's ``n`` planes) of the planes smart slicing keeps.

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

    Returns
    -------
    keep : (n_used,) int64
        Increasing plane indices.
    info : dict
        ``profile`` (counts per level), ``sub_boxes`` (list of
        ``[h_i, hr_i, n_i]`` with ``n_i`` from eq. 4-22), ``empty_levels``.
    """
    prof = depth_profile(lm, box, levels)
    boxes = sub_boxes(prof)
    s = box.h / n
    keep = np.zeros(int(n), bool)
    sb = []
    for a, e in boxes:
        z0 = -box.h / 2.0 + box.h * a / levels
        z1 = -box.h / 2.0 + box.h * e / levels
        # planes whose slab [zeta_i - s/2, zeta_i + s/2) meets [z0, z1)
        i0 = max(int(np.floor((z0 + box.h / 2.0) / s)), 0)
        i1 = min(int(np.ceil((z1 + box.h / 2.0) / s)), int(n))
        keep[i0:i1] = True
        hr = (e - a) / levels
        sb.append([box.h * hr, hr, hr * n])  # h_i (eq. 4-21), hr_i, n_i = hr_i / (2 eps) (eq. 4-22)
    if pidx is not None:
        used = np.unique(pidx[pidx >= 0])
        keep[used[used < n]] = True
    return np.flatnonzero(keep).astype(np.int64), {
        "profile": prof.tolist(), "sub_boxes": sb, "empty_levels": int(np.count_nonzero(prof == 0))}
