"""Extinction along light paths: eq. 6, ``L(x_{i+1}) = L(x_i) exp(-kappa(x_i) |x_{i+1} - x_i|)``.

Three forms, one per pass that reads it:

* :func:`attenuate`: a photon's radiance and transmittance over one march
  step, with the extinction of the voxel the step starts in (§4.4);
* :func:`skipped_attenuation`: exactly integrated, voxel by voxel
  (:func:`optical_depth`), along the straight segment a photon that starts
  on a proxy skipped (§4.3);
* :func:`transmit`: a viewing ray's transmittance over one step (§4.5).

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.3-§4.5, eq. 6.
.. [2] J. Amanatides, A. Woo, "A Fast Voxel Traversal Algorithm for Ray
   Tracing", Eurographics 1987.
"""

from __future__ import annotations

import math

import numba as nb

from .grid import dda_start, voxel_segment

__all__ = ["attenuate", "optical_depth", "skipped_attenuation", "transmit"]


@nb.njit(cache=True, inline="always")
def attenuate(ext, i, j, k, seg, lrad, trans):
    """Eq. 6 over one photon step: radiance ``lrad`` and transmittance ``trans`` after ``seg`` in voxel (i, j, k).

    Beer-Lambert with the voxel's extinction; a grey extinction (the common
    case) takes one ``exp`` for the three channels.

    Parameters
    ----------
    ext : (nx, ny, nz, 3) float32
        Extinction kappa per scene unit.
    i, j, k : int
        The voxel the step starts in.
    seg : float
        The step's length, world units.
    lrad, trans : 3-tuples of float
        RGB radiance and transmittance before the step.

    Returns
    -------
    tuple of 6 floats
        ``(nr, ng, nb, tr_r, tr_g, tr_b)``: radiance and transmittance after it.

    References
    ----------
    Sun et al. (2008), §4.4, eq. 6.
    """
    lr, lg, lb = lrad
    tr_r, tr_g, tr_b = trans
    kr, kg, kb = ext[i, j, k, 0], ext[i, j, k, 1], ext[i, j, k, 2]
    if kr == kg and kg == kb:  # grey extinction (the common case): one exp
        a = math.exp(-kr * seg) if kr != 0.0 else 1.0
        nr, ng, nb_ = lr * a, lg * a, lb * a
        tr_r, tr_g, tr_b = tr_r * a, tr_g * a, tr_b * a
    else:
        a_r = math.exp(-kr * seg)
        a_g = math.exp(-kg * seg)
        a_b = math.exp(-kb * seg)
        nr, ng, nb_ = lr * a_r, lg * a_g, lb * a_b
        tr_r, tr_g, tr_b = tr_r * a_r, tr_g * a_g, tr_b * a_b
    return nr, ng, nb_, tr_r, tr_g, tr_b


@nb.njit(cache=True, inline="always")
def optical_depth(ext, lo, ih, a, b):
    """``integral of kappa`` per channel along the straight segment a -> b, voxel by voxel (3D DDA).

    Parameters
    ----------
    ext, lo, ih
        The extinction volume and where it lies, as :func:`skipped_attenuation`
        reads them.
    a, b : 3-tuples of float
        Segment ends (world).

    Returns
    -------
    tuple of 3 floats
        The optical depth (RGB); zero for a segment of no length.

    References
    ----------
    Sun et al. (2008), §4.3, eq. 6; Amanatides and Woo (1987).
    """
    nx, ny, nz = ext.shape[0], ext.shape[1], ext.shape[2]
    u0, w0, t0, du, dw, dt = voxel_segment(lo, ih, a, b)
    wx, wy, wz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    length = math.sqrt(wx * wx + wy * wy + wz * wz)  # world length of the segment
    tr, tg, tb = 0.0, 0.0, 0.0
    if not length > 0.0:
        return tr, tg, tb
    i, j, k, si, sj, sk, ti, tj, tk, di, dj, dk = dda_start(u0, w0, t0, du, dw, dt, nx, ny, nz)
    t = 0.0
    for _ in range(nx + ny + nz + 3):
        tn = min(ti, min(tj, min(tk, 1.0)))
        w = (tn - t) * length
        if w > 0.0:
            tr += ext[i, j, k, 0] * w
            tg += ext[i, j, k, 1] * w
            tb += ext[i, j, k, 2] * w
        if tn >= 1.0:
            break
        if ti <= tj and ti <= tk:
            i = min(max(i + si, 0), nx - 1)
            ti += di
        elif tj <= tk:
            j = min(max(j + sj, 0), ny - 1)
            tj += dj
        else:
            k = min(max(k + sk, 0), nz - 1)
            tk += dk
        t = tn
    return tr, tg, tb


@nb.njit(cache=True, parallel=True)
def skipped_attenuation(ext, lo, ih, a, b, out):
    """Eq. 6 along straight segments: ``out = exp(-integral of kappa)`` per channel from a to b (3D DDA).

    The segment a photon started on a proxy skipped (from the volume's face
    to the proxy, where the index is the outside's): eq. 6 integrated
    exactly voxel by voxel, so that the photon reaches the proxy with the
    radiance the light has there. Parallel over photons.

    Parameters
    ----------
    ext : (nx, ny, nz, 3) float32
        Extinction kappa per scene unit.
    lo, ih : (3,) float64
        Lower corner and inverse voxel size of the volume.
    a, b : (P, 3) float64
        Segment ends (world).
    out : (P, 3) float64
        Written: the transmittance of each segment.

    Returns
    -------
    None

    References
    ----------
    Sun et al. (2008), §4.3 (proxy geometry) and eq. 6; Amanatides and Woo
    (1987).
    """
    for p in nb.prange(a.shape[0]):
        tr, tg, tb = optical_depth(ext, lo, ih, (a[p, 0], a[p, 1], a[p, 2]), (b[p, 0], b[p, 1], b[p, 2]))
        out[p, 0] = math.exp(-tr)
        out[p, 1] = math.exp(-tg)
        out[p, 2] = math.exp(-tb)


@nb.njit(cache=True, inline="always")
def transmit(src, i, j, k, seg, t, ek, eseg, ea):
    """Eq. 6 over one viewing step: transmittance ``t`` (RGB) after ``seg`` in voxel (i, j, k).

    ``ek``, ``eseg``, ``ea``: kappa, seg and exp(-kappa seg) of the last
    grey voxel, reused while kappa and seg do not change (grey, uniform
    media).

    Parameters
    ----------
    src : (nx, ny, nz, 9) float32
        The viewing pass's source volume; channels 6-8 hold kappa
        (:func:`~refraction_ref.volumetric.view.source_volume`).
    i, j, k : int
        The voxel the step starts in.
    seg : float
        The step's length, world units.
    t : 3-tuple of float
        Transmittance before the step.
    ek, eseg, ea : float
        The reused grey factor (kappa, seg, exp(-kappa seg)).

    Returns
    -------
    tuple of 6 floats
        ``(tr, tg, tb, ek, eseg, ea)``.

    References
    ----------
    Sun et al. (2008), §4.5 and eq. 6.
    """
    tr, tg, tb = t
    kr, kg, kb = src[i, j, k, 6], src[i, j, k, 7], src[i, j, k, 8]
    if kr == kg and kg == kb:
        if kr != 0.0:
            if kr != ek or seg != eseg:
                ek, eseg = kr, seg
                ea = math.exp(-kr * seg)
            tr *= ea
            tg *= ea
            tb *= ea
    else:
        if kr != 0.0:
            tr *= math.exp(-kr * seg)
        if kg != 0.0:
            tg *= math.exp(-kg * seg)
        if kb != 0.0:
            tb *= math.exp(-kb * seg)
    return tr, tg, tb, ek, eseg, ea
