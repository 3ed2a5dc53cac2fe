"""Radiance storage: the photons' deposits, in fixed point, one buffer per worker (§4.4, §5.1).

A photon step deposits into every voxel its segment crosses (a 3D DDA;
Amanatides and Woo 1987) the radiance interpolated along the segment and
the radiance-weighted unit direction, both weighted by the length of the
segment inside the voxel (in voxels): :func:`deposit_segment`.

Determinism: deposits are accumulated as 64-bit fixed-point integers, in one
buffer per worker, and the buffers are summed at the end (in parallel, by
:func:`merge_buffers`; the buffers are kept for the next march, as fresh
pages cost more to map than zeroing mapped ones: :func:`take_workspace`,
:func:`give_workspace`). Integer addition is associative, so the result is
bit-identical whatever the number of threads or the order in which photons
are processed; and a deposit can be *exactly* undone by subtracting it,
which is how the march applies the paper's stopping rule after tracing.

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.4 and §5.1.
.. [2] J. Amanatides, A. Woo, "A Fast Voxel Traversal Algorithm for Ray
   Tracing", Eurographics 1987.
"""

from __future__ import annotations

import math
import threading
from typing import NamedTuple

import numba as nb
import numpy as np

from .grid import dda_start, voxel_segment

__all__ = ["Deposits", "deposit_segment", "merge_buffers", "take_workspace", "give_workspace", "release_workspace"]


class Deposits(NamedTuple):
    """Where and how the steps deposit (fixed point, module docstring)."""

    rows: np.ndarray  # (buffers * nx * py * pz, 6) int64 view of the (buffers, nx, py, pz, 6) deposits
    buffers: int
    nx: int  # the volume's voxels
    ny: int
    nz: int
    py: int  # padded rows (>= ny, >= nz)
    pz: int
    sr: float  # fixed-point scale of radiance
    sd: float  # and of direction
    start: int  # the first step of a photon that deposits
    sign: int  # +1 adds the deposits, -1 removes them again


@nb.njit(cache=True)
def deposit_segment(dep, g, lo, ih, a, b, l0, l1, d):
    """Add radiance and radiance-weighted direction to every voxel of segment a -> b (3D DDA).

    ``dep`` (:class:`Deposits`) holds the (records, 6) view of the
    (buffers, nx, py, pz, 6) int64 deposits (py >= ny, pz >= nz: padded
    rows), written in buffer ``g``; ``lo`` and ``ih`` place the volume
    (:class:`~refraction_ref.volumetric.grid.VolumeBox`). ``a``, ``b`` are the end points, ``l0``,
    ``l1`` the RGB radiance there and ``d`` the unit direction, 3-tuples.
    The radiance is interpolated linearly along the segment and weighted by
    the length of the segment inside each voxel (in voxels); values are
    converted to fixed point with scale ``dep.sr`` (radiance) and ``dep.sd``
    (direction) by truncation, and added with sign ``dep.sign``.

    Parameters
    ----------
    dep : Deposits
        Deposit buffers and their fixed-point scales.
    g : int
        Buffer index.
    lo, ih : (3,) float64
        Lower corner and inverse voxel size of the volume.
    a, b : 3-tuples of float
        Segment end points, world units.
    l0, l1 : 3-tuples of float
        RGB radiance at ``a`` and ``b``.
    d : 3-tuple of float
        Unit direction of the segment.

    Returns
    -------
    None
        ``dep.rows`` is added to in place.

    References
    ----------
    Sun et al. (2008), §4.4 (radiance stored in the voxels the photon crosses)
    and §5.1 (radiance storage); Amanatides and Woo (1987).
    """
    accr, nx, ny, nz, py, pz = dep.rows, dep.nx, dep.ny, dep.nz, dep.py, dep.pz
    sr, sd, sgn = dep.sr, dep.sd, dep.sign
    l0r, l0g, l0b = l0
    l1r, l1g, l1b = l1
    dx, dy, dz = d
    u0, w0, t0, du, dw, dt = voxel_segment(lo, ih, a, b)
    lv = math.sqrt(du * du + dw * dw + dt * dt)
    if not lv > 0.0:
        return
    i, j, k, si, sj, sk, ti, tj, tk, di, dj, dk = dda_start(u0, w0, t0, du, dw, dt, nx, ny, nz)
    # value(t) = (a + b t) * (length in voxel), pre-scaled to fixed point
    c = lv * sr * sgn
    ar, br = l0r * c, (l1r - l0r) * c
    ag, bg = l0g * c, (l1g - l0g) * c
    ab, bb = l0b * c, (l1b - l0b) * c
    e = sd / sr
    ex, ey, ez = dx * e, dy * e, dz * e
    sti = si * py * pz
    stj = sj * pz
    stk = sk
    rec = ((g * nx + i) * py + j) * pz + k
    t = 0.0
    for _ in range(nx + ny + nz + 3):
        tn = min(ti, min(tj, min(tk, 1.0)))
        w = tn - t
        if w > 0.0:
            tm = 0.5 * (t + tn)
            r = (ar + br * tm) * w
            gg = (ag + bg * tm) * w
            b = (ab + bb * tm) * w
            sm = r + gg + b
            accr[rec, 0] += np.int64(r)
            accr[rec, 1] += np.int64(gg)
            accr[rec, 2] += np.int64(b)
            accr[rec, 3] += np.int64(ex * sm)
            accr[rec, 4] += np.int64(ey * sm)
            accr[rec, 5] += np.int64(ez * sm)
        if tn >= 1.0:
            return
        if ti <= tj and ti <= tk:
            i += si
            ti += di
            rec += sti
            if i < 0 or i >= nx:
                return
        elif tj <= tk:
            j += sj
            tj += dj
            rec += stj
            if j < 0 or j >= ny:
                return
        else:
            k += sk
            tk += dk
            rec += stk
            if k < 0 or k >= nz:
                return
        t = tn


@nb.njit(cache=True, parallel=True)
def merge_buffers(acc, sr, sd, out):
    """``out = sum over buffers of acc``, scaled back from fixed point (exact integer sums, any order).

    Parameters
    ----------
    acc : (buffers, nx, py, pz, 6) int64
        The deposit buffers (rows padded: ``py >= ny``, ``pz >= nz``).
    sr, sd : float
        Fixed-point scales of radiance and direction.
    out : (nx, ny, nz, 6) float64
        Written: radiance (RGB) and radiance-weighted direction.

    Returns
    -------
    None

    References
    ----------
    Sun et al. (2008), §5.1 (radiance storage).
    """
    nbuf = acc.shape[0]
    nx, ny, nz = out.shape[0], out.shape[1], out.shape[2]
    for i in nb.prange(nx):
        for j in range(ny):
            for k in range(nz):
                for c in range(6):
                    t = acc[0, i, j, k, c]
                    for b in range(1, nbuf):
                        t += acc[b, i, j, k, c]
                    out[i, j, k, c] = np.float64(t) / (sr if c < 3 else sd)


#: The deposit buffers of the last march, kept for the next one: fresh pages of a new
#: 100 MB buffer cost more to map (first touch) than zeroing mapped ones.
_WORKSPACE = []
_WORKSPACE_LOCK = threading.Lock()
_WORKSPACE_MAX_BYTES = 1 << 30


@nb.njit(cache=True, parallel=True)
def _zero(a):
    f = a.reshape(-1)
    n = f.shape[0]
    step = 1 << 16
    for b in nb.prange((n + step - 1) // step):
        for q in range(b * step, min(n, (b + 1) * step)):
            f[q] = 0


def take_workspace(shape):
    """Zeroed int64 deposit buffers of the given shape, reusing the last march's when it fits.

    Parameters
    ----------
    shape : tuple of int
        ``(buffers, nx, py, pz, 6)``.

    Returns
    -------
    ndarray of int64

    References
    ----------
    Sun et al. (2008), §5.1 (radiance storage).
    """
    with _WORKSPACE_LOCK:
        a = _WORKSPACE.pop() if _WORKSPACE else None
    if a is not None and a.shape == tuple(shape):
        _zero(a)
        return a
    return np.zeros(shape, np.int64)


def give_workspace(a):
    """Keep a march's deposit buffers for the next march (up to 1 GiB).

    Parameters
    ----------
    a : ndarray of int64
        From :func:`take_workspace`.

    Returns
    -------
    None

    References
    ----------
    Sun et al. (2008), §5.1 (radiance storage).
    """
    if a.nbytes <= _WORKSPACE_MAX_BYTES:
        with _WORKSPACE_LOCK:
            _WORKSPACE[:] = [a]


def release_workspace():
    """Free the deposit buffers kept between marches.

    References
    ----------
    Sun et al. (2008), §5.1 (radiance storage).
    """
    with _WORKSPACE_LOCK:
        _WORKSPACE.clear()
