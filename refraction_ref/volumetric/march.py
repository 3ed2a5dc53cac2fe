"""Adaptive photon marching with radiance deposition (§4.4, eqs. 4-6), and its smoothing.

Every photon carries a position x, a "velocity" v = n dx/ds (|v| = n) and an
RGB radiance L. One step:

1. **Step size** (§4.4, §5.3): the distance along v to the boundary of the
   octree leaf node containing x, clamped to ``[ds_min, smax]`` where smax
   is the node's maximum step (unbounded in constant nodes, ``ds_max``
   voxels where eps <= range < eps'). That is all of it with
   ``stepping = 'paper'`` (every step then applies eqs. 4-5 with the
   sampled gradient). With ``stepping = 'robust'`` a constant node is
   crossed in one straight step (its gradient is exactly zero: the octree
   is dilated), and a *stiffness bound*
   ``ds <= stiff * n / |grad n|`` then caps the step at sharp index steps
   (it overrides ds_min), so one step never changes |v| by more than the
   fraction ``stiff`` of n; and a step whose end point sees an index change
   larger than ``stiff * n`` that the gradient at its start does not predict
   (an index *jump*, e.g. an unblurred surface) is halved, up to 8 times.
2. **Advance**: forward differences (eqs. 4-5), ``x += ds v / n``,
   ``v += ds grad n``; or classic RK4 on the same system (eqs. 2-3).
3. **Attenuate** (eq. 6): ``L *= exp(-kappa(x_i) |x_{i+1} - x_i|)``.
4. **Deposit** into every voxel the segment crosses (a 3D DDA; Amanatides
   and Woo 1987) the radiance interpolated along the segment and the
   radiance-weighted unit direction, both weighted by the length of the
   segment inside the voxel (in voxels).

A photon dies when it leaves the volume (its exit point and direction are
recorded), when a step meets a diffuse receiver (the step ends on it; its
hit point, receiver and transmittance are recorded; an exiting photon goes
on straight, outside the volume, to the first receiver it meets there),
when its radiance falls below ``min_radiance`` of its start,
when |v| collapses, or at ``max_steps``. The paper's stopping rule (stop
iterating when fewer than ``stop_fraction`` of the photons are active) is
applied exactly: photons still active at that iteration have their later
deposits removed again (see below) and count as stopped.

Photon status codes (``photons["status"]`` of :func:`march_photons`, also
:data:`STATUS` by name). Three have the meaning of the oracle codes of
:mod:`refraction_ref.status` and use those names; the other two are the
march's own, with values that the oracle gives other meanings to (they are
never per-pixel statuses):

==  ===================  ==============================================================
 0  ``PHOTON_ACTIVE``    not traced (yet); not the oracle's ``MISSED``
 1  ``EXITED``           left the volume; ``exit_pos`` / ``exit_dir`` are valid
 2  ``LIMIT``            stopped at ``max_steps``, or cut by the stopping rule
 3  ``PHOTON_ABSORBED``  radiance fell below ``min_radiance`` of its start; not ``TIR``
 4  ``LOST``             |v| or n collapsed, or a non-finite state
 5  ``PHOTON_RECEIVED``  stopped on a receiver inside the volume (a diffuse surface, §6.2.2
                         Fig. 9); ``hit_pos`` / ``hit_receiver`` are valid
==  ===================  ==============================================================

Determinism: deposits are accumulated as 64-bit fixed-point integers, in one
buffer per worker, and the buffers are summed at the end (in parallel, by
:func:`_merge_buffers`; the buffers are kept for the next march, as fresh
pages cost more to map than zeroing mapped ones). Integer addition
is associative, so the result is bit-identical whatever the number of
threads or the order in which photons are processed; and a deposit can be
*exactly* undone by subtracting it, which is how the stopping rule is
applied after tracing.

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.4 (eqs. 4-6), §5.3.
.. [2] J. Amanatides, A. Woo, "A Fast Voxel Traversal Algorithm for Ray
   Tracing", Eurographics 1987.
"""

from __future__ import annotations

import math
import threading
from typing import NamedTuple

import numba as nb
import numpy as np

from ..filters import sym_tap
from ..status import EXITED, LIMIT, LOST

__all__ = ["march_photons", "smooth_radiance", "trace_paths", "release_workspace", "STATUS",
           "PHOTON_ACTIVE", "PHOTON_ABSORBED", "PHOTON_RECEIVED", "receiver_tuple"]

# The march's own photon codes (module docstring); EXITED, LIMIT and LOST come from refraction_ref.status.
#: photon not traced (yet): the initial status (same value as the oracle's MISSED, other meaning)
PHOTON_ACTIVE = 0
#: photon's radiance fell below ``min_radiance`` of its start (same value as the oracle's TIR, other meaning)
PHOTON_ABSORBED = 3

#: photon stopped on a receiver inside the volume (the march's own code; never a per-pixel status)
PHOTON_RECEIVED = 5

#: Photon status codes by name.
STATUS = {"active": PHOTON_ACTIVE, "exited": EXITED, "stopped": LIMIT, "absorbed": PHOTON_ABSORBED, "lost": LOST,
          "received": PHOTON_RECEIVED}

INTEG_EULER = 0
INTEG_RK4 = 1


@nb.njit(cache=True, inline="always")
def _lerp_axis(u, na):
    """Cell index and fraction of trilinear interpolation along one axis, clamped (NaN -> cell 0)."""
    if not u >= 0.0:
        return 0, 0.0
    if u >= na - 1:
        return na - 2, 1.0
    c = int(u)  # truncation is floor for u >= 0
    return c, u - c


@nb.njit(cache=True)  # a call, not inlined: its callers would compile its body at every call site
def sample_field(field, lo, ih, x, y, z):
    """Trilinear (n, dn/dx, dn/dy, dn/dz) at a world point (clamped to the volume).

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and its gradient at voxel centres
        (:func:`~refraction_ref.volumetric.gradient.gradient_field`).
    lo : (3,) float64
        Lower corner of the volume, world units.
    ih : (3,) float64
        Inverse voxel size per axis.
    x, y, z : float
        World point.

    Returns
    -------
    n, dndx, dndy, dndz : float
        Interpolated index and gradient (per world unit).

    References
    ----------
    Sun et al. (2008), §4.4 (n and its gradient at the photon, eqs. 4-5).
    """
    nx, ny, nz = field.shape[0], field.shape[1], field.shape[2]
    i, fx = _lerp_axis((x - lo[0]) * ih[0] - 0.5, nx)
    j, fy = _lerp_axis((y - lo[1]) * ih[1] - 0.5, ny)
    k, fz = _lerp_axis((z - lo[2]) * ih[2] - 0.5, nz)
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    for di in range(2):
        wx = fx if di else 1.0 - fx
        for dj in range(2):
            wy = fy if dj else 1.0 - fy
            for dk in range(2):
                wgt = wx * wy * (fz if dk else 1.0 - fz)
                a0 += wgt * field[i + di, j + dj, k + dk, 0]
                a1 += wgt * field[i + di, j + dj, k + dk, 1]
                a2 += wgt * field[i + di, j + dj, k + dk, 2]
                a3 += wgt * field[i + di, j + dj, k + dk, 3]
    return a0, a1, a2, a3


@nb.njit(cache=True)  # a call, not inlined: its callers would compile its body at every call site
def advance(field, lo, ih, integ, p, v, g, ds):
    """One step of eqs. 4-5 (``integ`` 0) or of RK4 on eqs. 2-3 (``integ`` 1).

    ``p = (x, y, z)``, ``v = (vx, vy, vz)``; ``g = (n, dn/dx, dn/dy, dn/dz)``
    is the field at p, already sampled by the caller. Returns
    ``(x, y, z, vx, vy, vz)`` after the step ``ds``.

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and its gradient (RK4 samples it at the inner stages).
    lo, ih : (3,) float64
        Lower corner and inverse voxel size of the volume.
    integ : int
        ``INTEG_EULER`` (0) or ``INTEG_RK4`` (1).
    p, v : 3-tuples of float
        Position and velocity ``n dx/ds``.
    g : 4-tuple of float
        ``(n, dn/dx, dn/dy, dn/dz)`` at ``p``.
    ds : float
        Step length, world units.

    Returns
    -------
    tuple of 6 floats
        New position and velocity.

    References
    ----------
    Sun et al. (2008), §4.4, eqs. 4-5; §3, eqs. 2-3.
    """
    x, y, z = p
    vx, vy, vz = v
    n, gx, gy, gz = g
    if integ == 0:
        s = ds / n
        return x + s * vx, y + s * vy, z + s * vz, vx + ds * gx, vy + ds * gy, vz + ds * gz
    h2 = 0.5 * ds
    # k1
    k1x, k1y, k1z = vx / n, vy / n, vz / n
    l1x, l1y, l1z = gx, gy, gz
    # k2
    v2x, v2y, v2z = vx + h2 * l1x, vy + h2 * l1y, vz + h2 * l1z
    n2, g2x, g2y, g2z = sample_field(field, lo, ih, x + h2 * k1x, y + h2 * k1y, z + h2 * k1z)
    k2x, k2y, k2z = v2x / n2, v2y / n2, v2z / n2
    # k3
    v3x, v3y, v3z = vx + h2 * g2x, vy + h2 * g2y, vz + h2 * g2z
    n3, g3x, g3y, g3z = sample_field(field, lo, ih, x + h2 * k2x, y + h2 * k2y, z + h2 * k2z)
    k3x, k3y, k3z = v3x / n3, v3y / n3, v3z / n3
    # k4
    v4x, v4y, v4z = vx + ds * g3x, vy + ds * g3y, vz + ds * g3z
    n4, g4x, g4y, g4z = sample_field(field, lo, ih, x + ds * k3x, y + ds * k3y, z + ds * k3z)
    k4x, k4y, k4z = v4x / n4, v4y / n4, v4z / n4
    c = ds / 6.0
    return (x + c * (k1x + 2.0 * k2x + 2.0 * k3x + k4x),
            y + c * (k1y + 2.0 * k2y + 2.0 * k3y + k4y),
            z + c * (k1z + 2.0 * k2z + 2.0 * k3z + k4z),
            vx + c * (gx + 2.0 * g2x + 2.0 * g3x + g4x),
            vy + c * (gy + 2.0 * g2y + 2.0 * g3y + g4y),
            vz + c * (gz + 2.0 * g2z + 2.0 * g3z + g4z))


@nb.njit(cache=True, inline="always")
def cell(u, na):
    """``min(max(floor(u), 0), na - 1)`` (truncation is floor for u >= 0; NaN -> 0).

    Parameters
    ----------
    u : float
        Coordinate in voxel units along one axis.
    na : int
        Voxels along that axis.

    Returns
    -------
    int
        Voxel index in ``0 .. na - 1``.

    References
    ----------
    Sun et al. (2008), §4.4 (voxel of the photon).
    """
    if not u > 0.0:
        return 0
    c = int(u)
    return c if c < na - 1 else na - 1


@nb.njit(cache=True, inline="always")
def voxel_of(lo, ih, nx, ny, nz, x, y, z):
    """Voxel ``(i, j, k)`` holding a world point, clamped to the grid.

    Parameters
    ----------
    lo, ih : (3,) float64
        Lower corner and inverse voxel size of the volume.
    nx, ny, nz : int
        Voxels per axis.
    x, y, z : float
        World point.

    Returns
    -------
    i, j, k : int
        Voxel indices (:func:`cell` per axis).

    References
    ----------
    Sun et al. (2008), §4.4 (octree node of the photon's voxel).
    """
    return cell((x - lo[0]) * ih[0], nx), cell((y - lo[1]) * ih[1], ny), cell((z - lo[2]) * ih[2], nz)


@nb.njit(cache=True, inline="always")
def _axis_distance(xa, da, lo, h, ih, na, lev):
    if da == 0.0:
        return np.inf
    u = (xa - lo) * ih
    c = int(u) if u > 0.0 else 0
    b0 = (c >> lev) << lev  # the node's first voxel (nodes of level lev cover 2^lev voxels)
    if da > 0.0:
        return (min(b0 + (1 << lev), na) - u) * h / da
    return (b0 - u) * h / da


@nb.njit(cache=True, inline="always")
def node_distance(lo, h, ih, shape_n, lev, x, y, z, dx, dy, dz):
    """Distance along the unit direction d from x to the boundary of its level-``lev`` node (Fig. 5).

    Parameters
    ----------
    lo, h, ih : (3,) float64
        Lower corner, voxel size and its inverse.
    shape_n : (3,) int64
        Voxels per axis.
    lev : int
        Octree level of the node (a level-``lev`` node spans ``2**lev`` voxels).
    x, y, z : float
        World point inside the node.
    dx, dy, dz : float
        Unit direction.

    Returns
    -------
    float
        Distance (world units, >= 0) to the node's boundary; ``inf`` when the
        direction is zero.

    References
    ----------
    Sun et al. (2008), §4.4 and Fig. 5 (step to the leaf node's boundary).
    """
    t = min(_axis_distance(x, dx, lo[0], h[0], ih[0], shape_n[0], lev),
            min(_axis_distance(y, dy, lo[1], h[1], ih[1], shape_n[1], lev),
                _axis_distance(z, dz, lo[2], h[2], ih[2], shape_n[2], lev)))
    return max(t, 0.0)


@nb.njit(cache=True, inline="always")
def segment_exit(lo, hi, x, y, z, x1, y1, z1):
    """Fraction s in [0, 1] of the segment x -> x1 still inside the box (1 when x1 is inside).

    Parameters
    ----------
    lo, hi : (3,) float64
        Corners of the box.
    x, y, z : float
        Segment start (inside the box).
    x1, y1, z1 : float
        Segment end.

    Returns
    -------
    float
        Fraction of the segment inside, in ``[0, 1]``.

    References
    ----------
    Sun et al. (2008), §4.4 (a photon leaving the volume).
    """
    s = 1.0
    for a in range(3):
        p0 = x if a == 0 else (y if a == 1 else z)
        p1 = x1 if a == 0 else (y1 if a == 1 else z1)
        d = p1 - p0
        if p1 > hi[a] and d > 0.0:
            s = min(s, (hi[a] - p0) / d)
        elif p1 < lo[a] and d < 0.0:
            s = min(s, (lo[a] - p0) / d)
    return max(s, 0.0)


class _Box(NamedTuple):
    """Where the voxel grid lies in the world (:func:`_geometry`)."""

    lo: np.ndarray  # (3,) float64 lower corner
    hi: np.ndarray  # (3,) float64 upper corner
    h: np.ndarray  # (3,) float64 voxel size
    ih: np.ndarray  # (3,) float64 1 / h
    shape_n: np.ndarray  # (3,) int64 voxels per axis
    hmin: float  # smallest voxel side


class _Grid(NamedTuple):
    """The volume the photons march through: index field, media, octree, and its box (flat:
    numba's parallel loops pass the fields of a tuple, not of a tuple inside a tuple)."""

    field: np.ndarray  # (nx, ny, nz, 4) float32: n and grad n
    ext: np.ndarray  # (nx, ny, nz, 3) float32: extinction kappa per scene unit
    level: np.ndarray  # (nx, ny, nz): level of the octree leaf holding each voxel
    smax: np.ndarray  # (nx, ny, nz) float32: maximum step in voxels (inf: constant node)
    lo: np.ndarray  # the fields of _Box
    hi: np.ndarray
    h: np.ndarray
    ih: np.ndarray
    shape_n: np.ndarray
    hmin: float


class _Photons(NamedTuple):
    """The photons' start states, (P, 3) float64 each (:func:`~.photons.generate_photons`)."""

    pos: np.ndarray
    dirs: np.ndarray
    rad: np.ndarray


class _Knobs(NamedTuple):
    """Step control and termination of one march (module docstring)."""

    ds_min: float  # minimum step, world units
    stiff: float  # stiffness bound
    integ: int  # INTEG_EULER or INTEG_RK4
    max_steps: int
    min_rad: float  # a photon dies below this fraction of its start radiance
    record: int  # steps kept per photon in the path (0: none)
    paper: int  # 1: stepping 'paper' (no stiffness cap, no halving, no straight shortcut); 0: 'robust'
    n_half: float  # the half-contrast index level: a photon beyond it has met refractive material
    side: float  # +1 (object denser than the outside) or -1


class _Recv(NamedTuple):
    """Diffuse receivers the photons stop on (:func:`receiver_tuple`); T = 0 for none."""

    tris: np.ndarray  # (T, 3, 3) float64 world vertices, grouped by receiver
    lo: np.ndarray  # (R, 3) float64 each receiver's bounding box
    hi: np.ndarray  # (R, 3)
    start: np.ndarray  # (R + 1,) int64: receiver r owns tris[start[r]:start[r + 1]]


def receiver_tuple(tris=None, owner=None):
    """The receivers of a march from a triangle soup and its owners (None: no receivers).

    Parameters
    ----------
    tris : (T, 3, 3) float64, optional
    owner : (T,) int, optional
        Receiver index of each triangle (0 .. R - 1).

    Returns
    -------
    _Recv
        Triangles grouped by receiver with each receiver's bounding box and the
        start of its triangles; empty arrays when there are no receivers.

    References
    ----------
    Sun et al. (2008), §4.4 (photons stop on diffuse surfaces), §6 (caustics on
    receivers).
    """
    if tris is None or len(tris) == 0:
        z = np.zeros((0, 3))
        return _Recv(np.zeros((0, 3, 3)), z, z.copy(), np.zeros(1, np.int64))
    owner = np.asarray(owner, np.int64)
    order = np.argsort(owner, kind="stable")
    t = np.ascontiguousarray(np.asarray(tris, np.float64)[order])
    o = owner[order]
    R = int(o.max()) + 1
    start = np.searchsorted(o, np.arange(R + 1)).astype(np.int64)
    lo = np.full((R, 3), np.inf)
    hi = np.full((R, 3), -np.inf)
    for r in range(R):
        if start[r + 1] > start[r]:
            v = t[start[r]:start[r + 1]].reshape(-1, 3)
            lo[r], hi[r] = v.min(axis=0), v.max(axis=0)
    return _Recv(t, lo, hi, start)


@nb.njit(cache=True)
def _segment_receiver(recv, x, y, z, dx, dy, dz, tmax):
    """Smallest t in (0, tmax] where ``x + t d`` meets a receiver triangle (two-sided, Moller-Trumbore).

    Returns ``(t, q)``, q the triangle's index in ``recv.tris``; ``(inf, -1)`` when none.
    """
    tris, rlo, rhi, start = recv.tris, recv.lo, recv.hi, recv.start
    best = np.inf
    br = -1
    ax0, ax1 = min(x, x + tmax * dx), max(x, x + tmax * dx)
    ay0, ay1 = min(y, y + tmax * dy), max(y, y + tmax * dy)
    az0, az1 = min(z, z + tmax * dz), max(z, z + tmax * dz)
    for r in range(rlo.shape[0]):
        pad = 1e-9 * (1.0 + abs(rlo[r, 0]) + abs(rlo[r, 1]) + abs(rlo[r, 2]) + abs(rhi[r, 0]) + abs(rhi[r, 1])
                      + abs(rhi[r, 2]))
        if (ax1 < rlo[r, 0] - pad or ax0 > rhi[r, 0] + pad or ay1 < rlo[r, 1] - pad or ay0 > rhi[r, 1] + pad
                or az1 < rlo[r, 2] - pad or az0 > rhi[r, 2] + pad):
            continue
        for q in range(start[r], start[r + 1]):
            v0x, v0y, v0z = tris[q, 0, 0], tris[q, 0, 1], tris[q, 0, 2]
            e1x, e1y, e1z = tris[q, 1, 0] - v0x, tris[q, 1, 1] - v0y, tris[q, 1, 2] - v0z
            e2x, e2y, e2z = tris[q, 2, 0] - v0x, tris[q, 2, 1] - v0y, tris[q, 2, 2] - v0z
            px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
            det = e1x * px + e1y * py + e1z * pz
            if det == 0.0 or det != det:
                continue
            inv = 1.0 / det
            tx, ty, tz = x - v0x, y - v0y, z - v0z
            u = (tx * px + ty * py + tz * pz) * inv
            if u < 0.0 or u > 1.0:
                continue
            qx, qy, qz = ty * e1z - tz * e1y, tz * e1x - tx * e1z, tx * e1y - ty * e1x
            w = (dx * qx + dy * qy + dz * qz) * inv
            if w < 0.0 or u + w > 1.0:
                continue
            t = (e2x * qx + e2y * qy + e2z * qz) * inv
            if t > 0.0 and t <= tmax and t < best:
                best = t
                br = q
    return best, br


class _Deposits(NamedTuple):
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


class _Outputs(NamedTuple):
    """Per-photon arrays the march fills (see :func:`march_photons`, Returns)."""

    steps: np.ndarray  # (P,) int32
    status: np.ndarray  # (P,) int8
    drift: np.ndarray  # (P,) float64
    exit_pos: np.ndarray  # (P, 3)
    exit_dir: np.ndarray  # (P, 3)
    paths: np.ndarray  # (P, record + 1, 3); (1, 1, 3) unused when record is 0
    touched: np.ndarray  # (P,) int8: 1 when the photon met refractive material (beyond n_half)
    hit_pos: np.ndarray  # (P, 3): where it met a receiver (NaN: none)
    hit_recv: np.ndarray  # (P,) int32: which receiver triangle (index in _Recv.tris; -1: none)
    hit_trans: np.ndarray  # (P, 3): its transmittance exp(-int kappa) there


@nb.njit(cache=True)
def deposit_segment(dep, g, lo, ih, a, b, l0, l1, d):
    """Add radiance and radiance-weighted direction to every voxel of segment a -> b (3D DDA).

    ``dep`` (:class:`_Deposits`) holds the (records, 6) view of the
    (buffers, nx, py, pz, 6) int64 deposits (py >= ny, pz >= nz: padded
    rows), written in buffer ``g``; ``lo`` and ``ih`` place the volume
    (:class:`_Box`). ``a``, ``b`` are the end points, ``l0``,
    ``l1`` the RGB radiance there and ``d`` the unit direction, 3-tuples.
    The radiance is interpolated linearly along the segment and weighted by
    the length of the segment inside each voxel (in voxels); values are
    converted to fixed point with scale ``dep.sr`` (radiance) and ``dep.sd``
    (direction) by truncation, and added with sign ``dep.sign``.

    Parameters
    ----------
    dep : _Deposits
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
    ax, ay, az = a
    bx, by, bz = b
    l0r, l0g, l0b = l0
    l1r, l1g, l1b = l1
    dx, dy, dz = d
    u0 = (ax - lo[0]) * ih[0]
    w0 = (ay - lo[1]) * ih[1]
    t0 = (az - lo[2]) * ih[2]
    du = (bx - lo[0]) * ih[0] - u0
    dw = (by - lo[1]) * ih[1] - w0
    dt = (bz - lo[2]) * ih[2] - t0
    lv = math.sqrt(du * du + dw * dw + dt * dt)
    if not lv > 0.0:
        return
    i = cell(u0, nx)
    j = cell(w0, ny)
    k = cell(t0, nz)
    si = 1 if du > 0 else -1
    sj = 1 if dw > 0 else -1
    sk = 1 if dt > 0 else -1
    inf = np.inf
    ti = ((i + (1 if du > 0 else 0)) - u0) / du if du != 0.0 else inf
    tj = ((j + (1 if dw > 0 else 0)) - w0) / dw if dw != 0.0 else inf
    tk = ((k + (1 if dt > 0 else 0)) - t0) / dt if dt != 0.0 else inf
    di = abs(1.0 / du) if du != 0.0 else inf
    dj = abs(1.0 / dw) if dw != 0.0 else inf
    dk = abs(1.0 / dt) if dt != 0.0 else inf
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


@nb.njit(cache=True, inline="always")
def _robust_step(field, lo, ih, integ, state, ds, stiff, hmin):
    """One 'robust' step from ``state = (x, y, z, vx, vy, vz, n, gx, gy, gz)`` (module docstring).

    The step is capped by the stiffness bound and halved (up to 8 times)
    while it crosses an index jump the local gradient does not predict.
    Returns ``(ds, x1, y1, z1, vx1, vy1, vz1, cn, cgx, cgy, cgz)``: the step
    taken, the state after it, and the field sampled at its end (carried
    into the next step).

    References
    ----------
    Sun et al. (2008), §4.4, eqs. 4-5.
    """
    x, y, z, vx, vy, vz, n, gx, gy, gz = state
    gn = math.sqrt(gx * gx + gy * gy + gz * gz)
    if gn * ds > stiff * n:
        ds = stiff * n / gn
    # stiffness: a step across an index jump that the local gradient does not predict is halved
    for _ in range(8):
        x1, y1, z1, vx1, vy1, vz1 = advance(field, lo, ih, integ, (x, y, z), (vx, vy, vz),
                                            (n, gx, gy, gz), ds)
        cn, cgx, cgy, cgz = sample_field(field, lo, ih, x1, y1, z1)
        dn = cn - n
        if abs(dn) <= stiff * n or ds <= 0.125 * hmin:
            break
        pred = gx * (x1 - x) + gy * (y1 - y) + gz * (z1 - z)
        if abs(dn - pred) <= 0.5 * abs(dn):
            break
        ds *= 0.5
    return ds, x1, y1, z1, vx1, vy1, vz1, cn, cgx, cgy, cgz


@nb.njit(cache=True, inline="always")
def _attenuate(ext, i, j, k, seg, lrad, trans):
    """Radiance ``lrad`` and transmittance ``trans`` (RGB 3-tuples) after ``seg`` world units in voxel (i, j, k).

    Beer-Lambert with the voxel's extinction (Sun et al. 2008, eq. 6);
    returns ``(nr, ng, nb, tr_r, tr_g, tr_b)``.
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
def _put3(a, p, v):
    """``a[p, :] = v`` for a 3-tuple ``v``, one component per statement."""
    a[p, 0] = v[0]
    a[p, 1] = v[1]
    a[p, 2] = v[2]


@nb.njit(cache=True)
def _trace_one(p, grid, photons, knobs, dep, g, out, path, recv):
    """Trace photon p to its end; returns (steps, status, max relative |v|-n drift).

    Deposits into buffer ``g`` of ``dep``, writes ``out.exit_pos`` /
    ``out.exit_dir`` of an exiting photon, and, when ``knobs.record`` is
    K > 0, the start point and the end points of the first K steps into
    ``path`` ((K + 1, 3); rows of steps not taken are left as they are).
    """
    # the named tuples unpacked by name (a reordered field cannot swap two arguments)
    field, ext, level, smax = grid.field, grid.ext, grid.level, grid.smax
    lo, hi, h, ih, shape_n, hmin = grid.lo, grid.hi, grid.h, grid.ih, grid.shape_n, grid.hmin
    pos, dirs, rad = photons.pos, photons.dirs, photons.rad
    ds_min, stiff, integ, max_steps = knobs.ds_min, knobs.stiff, knobs.integ, knobs.max_steps
    min_rad, record = knobs.min_rad, knobs.record
    paper = knobs.paper
    n_half = knobs.n_half
    side = knobs.side
    dep_from = dep.start
    exit_pos, exit_dir = out.exit_pos, out.exit_dir
    touched_out = out.touched
    hit_pos = out.hit_pos
    hit_recv = out.hit_recv
    hit_trans = out.hit_trans
    nrecv = recv.tris.shape[0]
    touched = 0
    tr_r, tr_g, tr_b = 1.0, 1.0, 1.0
    nx, ny, nz = field.shape[0], field.shape[1], field.shape[2]
    x, y, z = pos[p, 0], pos[p, 1], pos[p, 2]
    n = sample_field(field, lo, ih, x, y, z)[0]
    vx, vy, vz = n * dirs[p, 0], n * dirs[p, 1], n * dirs[p, 2]
    lr, lg, lb = rad[p, 0], rad[p, 1], rad[p, 2]
    lmax0 = max(lr, max(lg, lb))
    thr = min_rad * lmax0
    steps = 0
    status = PHOTON_ACTIVE
    drift = 0.0
    nudge = 1e-4 * hmin
    carried = False
    cn, cgx, cgy, cgz = 0.0, 0.0, 0.0, 0.0
    if record > 0:
        path[0, 0] = x
        path[0, 1] = y
        path[0, 2] = z
    while True:
        if steps >= max_steps:
            status = LIMIT
            break
        i, j, k = voxel_of(lo, ih, nx, ny, nz, x, y, z)
        cap = smax[i, j, k]
        # robust stepping: a constant octree node (zero gradient, dilated octree) is crossed in one straight
        # step; the paper's stepping applies eqs. 4-5 at every step
        const = cap == np.inf and paper == 0
        if const:  # a constant octree node: straight line to its boundary, no field sampling
            n = np.float64(field[i, j, k, 0])
            gx, gy, gz = 0.0, 0.0, 0.0
        elif carried:
            n, gx, gy, gz = cn, cgx, cgy, cgz
        else:
            n, gx, gy, gz = sample_field(field, lo, ih, x, y, z)
        carried = False
        if side * (n - n_half) > 0.0:
            touched = 1
        vn = math.sqrt(vx * vx + vy * vy + vz * vz)
        if not (vn > 1e-12 * n) or not (n > 0.0):
            status = LOST
            break
        dr = abs(vn - n) / n
        if dr > drift:
            drift = dr
        ivn = 1.0 / vn
        ux, uy, uz = vx * ivn, vy * ivn, vz * ivn
        ds = node_distance(lo, h, ih, shape_n, level[i, j, k], x, y, z, ux, uy, uz) + nudge
        ds = max(ds, ds_min)
        if const:
            x1, y1, z1, vx1, vy1, vz1 = x + ds * ux, y + ds * uy, z + ds * uz, vx, vy, vz
        elif paper != 0:  # §4.4 / §5.3: clamp(ds_octree, ds_min, ds_max), one step of eqs. 4-5
            ds = min(ds, cap * hmin)
            x1, y1, z1, vx1, vy1, vz1 = advance(field, lo, ih, integ, (x, y, z), (vx, vy, vz), (n, gx, gy, gz), ds)
        else:
            ds = min(ds, cap * hmin)
            ds, x1, y1, z1, vx1, vy1, vz1, cn, cgx, cgy, cgz = _robust_step(
                field, lo, ih, integ, (x, y, z, vx, vy, vz, n, gx, gy, gz), ds, stiff, hmin)
            carried = True
        if not (math.isfinite(x1) and math.isfinite(y1) and math.isfinite(z1)
                and math.isfinite(vx1) and math.isfinite(vy1) and math.isfinite(vz1)):
            status = LOST
            break
        s = segment_exit(lo, hi, x, y, z, x1, y1, z1)
        hitr = -1
        if nrecv > 0:  # a diffuse receiver on the step ends it there
            th, hr = _segment_receiver(recv, x, y, z, x1 - x, y1 - y, z1 - z, s)
            if hr >= 0:
                s = th
                hitr = hr
        ex, ey, ez = x + s * (x1 - x), y + s * (y1 - y), z + s * (z1 - z)
        sx, sy, sz = ex - x, ey - y, ez - z
        seg = math.sqrt(sx * sx + sy * sy + sz * sz)
        nr, ng, nb_, tr_r, tr_g, tr_b = _attenuate(ext, i, j, k, seg, (lr, lg, lb), (tr_r, tr_g, tr_b))
        if steps >= dep_from and seg > 0.0:
            deposit_segment(dep, g, lo, ih, (x, y, z), (ex, ey, ez), (lr, lg, lb), (nr, ng, nb_),
                            (sx / seg, sy / seg, sz / seg))
        steps += 1
        if steps <= record:
            path[steps, 0] = ex
            path[steps, 1] = ey
            path[steps, 2] = ez
        if hitr >= 0:
            status = PHOTON_RECEIVED
            _put3(hit_pos, p, (ex, ey, ez))
            hit_recv[p] = hitr
            _put3(hit_trans, p, (tr_r, tr_g, tr_b))
            break
        if s < 1.0:
            status = EXITED
            if not const and s > 0.0:  # the direction at the exit: redo the step over the part inside
                vx1, vy1, vz1 = advance(field, lo, ih, integ, (x, y, z), (vx, vy, vz), (n, gx, gy, gz), s * ds)[3:]
            v1 = math.sqrt(vx1 * vx1 + vy1 * vy1 + vz1 * vz1)
            _put3(exit_pos, p, (ex, ey, ez))
            _put3(exit_dir, p, (vx1 / v1, vy1 / v1, vz1 / v1))
            _put3(hit_trans, p, (tr_r, tr_g, tr_b))
            break
        x, y, z, vx, vy, vz = x1, y1, z1, vx1, vy1, vz1
        lr, lg, lb = nr, ng, nb_
        if max(lr, max(lg, lb)) < thr or lmax0 <= 0.0:
            status = PHOTON_ABSORBED
            break
    touched_out[p] = touched
    return steps, status, drift


@nb.njit(cache=True, parallel=True)
def _march_kernel(grid, photons, sel, knobs, dep, out, recv):
    """Trace the photons ``sel`` (indices into ``photons``), chunks of 256 spread over the deposit buffers."""
    nbuf = dep.buffers
    # one output array per statement (see view._view_kernel: numba's dead-code elimination)
    out_steps = out.steps
    out_status = out.status
    out_drift = out.drift
    paths = out.paths
    rec = knobs.record > 0
    dummy_path = np.zeros((1, 3))
    chunk = 256
    for g in nb.prange(nbuf):
        for q in range(sel.shape[0]):
            if (q // chunk) % nbuf != g:
                continue
            p = sel[q]
            st, ss, dr = _trace_one(p, grid, photons, knobs, dep, np.int64(g), out,  # int64: one signature
                                    paths[p] if rec else dummy_path, recv)
            out_steps[p] = st
            out_status[p] = ss
            out_drift[p] = dr


@nb.njit(cache=True, parallel=True)
def _skipped_attenuation(ext, lo, ih, a, b, out):
    """``out = exp(-integral of kappa)`` per channel along each straight segment a -> b (3D DDA; parallel over photons).

    The segment a photon started on a proxy skipped (from the volume's face
    to the proxy, where the index is the outside's): eq. 6 integrated
    exactly voxel by voxel, so that the photon reaches the proxy with the
    radiance the light has there.
    """
    nx, ny, nz = ext.shape[0], ext.shape[1], ext.shape[2]
    for p in nb.prange(a.shape[0]):
        u0 = (a[p, 0] - lo[0]) * ih[0]
        w0 = (a[p, 1] - lo[1]) * ih[1]
        t0 = (a[p, 2] - lo[2]) * ih[2]
        du = (b[p, 0] - lo[0]) * ih[0] - u0
        dw = (b[p, 1] - lo[1]) * ih[1] - w0
        dt = (b[p, 2] - lo[2]) * ih[2] - t0
        wx, wy, wz = b[p, 0] - a[p, 0], b[p, 1] - a[p, 1], b[p, 2] - a[p, 2]
        length = math.sqrt(wx * wx + wy * wy + wz * wz)  # world length of the segment
        tr, tg, tb = 0.0, 0.0, 0.0
        if length > 0.0:
            i = cell(u0, nx)
            j = cell(w0, ny)
            k = cell(t0, nz)
            si = 1 if du > 0 else -1
            sj = 1 if dw > 0 else -1
            sk = 1 if dt > 0 else -1
            ti = ((i + (1 if du > 0 else 0)) - u0) / du if du != 0.0 else np.inf
            tj = ((j + (1 if dw > 0 else 0)) - w0) / dw if dw != 0.0 else np.inf
            tk = ((k + (1 if dt > 0 else 0)) - t0) / dt if dt != 0.0 else np.inf
            di = abs(1.0 / du) if du != 0.0 else np.inf
            dj = abs(1.0 / dw) if dw != 0.0 else np.inf
            dk = abs(1.0 / dt) if dt != 0.0 else np.inf
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
        out[p, 0] = math.exp(-tr)
        out[p, 1] = math.exp(-tg)
        out[p, 2] = math.exp(-tb)


@nb.njit(cache=True, parallel=True)
def _exit_receivers(sel, exit_pos, exit_dir, recv, reach, hit_pos, hit_recv):
    """Exited photons ``sel`` go on straight outside the volume to the first receiver (parallel over photons)."""
    for m in nb.prange(sel.shape[0]):
        p = sel[m]
        t, r = _segment_receiver(recv, exit_pos[p, 0], exit_pos[p, 1], exit_pos[p, 2],
                                 exit_dir[p, 0], exit_dir[p, 1], exit_dir[p, 2], reach)
        if r >= 0:
            for c in range(3):
                hit_pos[p, c] = exit_pos[p, c] + t * exit_dir[p, c]
            hit_recv[p] = r


def half_contrast(field_or_ior, outside_ior):
    """``(n_half, side)``: the index level halfway to the volume's largest contrast with the outside.

    A point with ``side * (n - n_half) > 0`` is inside refractive material
    (the viewing pass's ``hit``; the march's "met the object" flag).

    Parameters
    ----------
    field_or_ior : ndarray
        ``(nx, ny, nz, 4)`` gradient field (its channel 0) or ``(nx, ny, nz)``
        index of refraction.
    outside_ior : float
        Index of refraction outside the objects.

    Returns
    -------
    n_half : float
        ``outside_ior`` plus half the largest contrast; ``inf`` for a volume
        without contrast.
    side : float
        ``+1`` when the material's index is above the outside's, else ``-1``.

    References
    ----------
    Sun et al. (2008), §4.5 (rays meeting the refractive object in the viewing
    pass).
    """
    a = np.asarray(field_or_ior)
    n = a[..., 0] if a.ndim == 4 else a
    lo, hi = float(n.min()), float(n.max())
    c = hi - outside_ior if abs(hi - outside_ior) >= abs(lo - outside_ior) else lo - outside_ior
    if c == 0.0:
        return float("inf"), 1.0
    return float(outside_ior + 0.5 * c), (1.0 if c > 0 else -1.0)


@nb.njit(cache=True, parallel=True)
def _merge_buffers(acc, sr, sd, out):
    """``out = sum over buffers of acc``, scaled back from fixed point (exact integer sums, any order)."""
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


@nb.njit(cache=True)
def _spread3(v):
    v = v & 0x1FFFFF
    v = (v | (v << 32)) & 0x1F00000000FFFF
    v = (v | (v << 16)) & 0x1F0000FF0000FF
    v = (v | (v << 8)) & 0x100F00F00F00F00F
    v = (v | (v << 4)) & 0x10C30C30C30C30C3
    v = (v | (v << 2)) & 0x1249249249249249
    return v


@nb.njit(cache=True, parallel=True)
def _morton_keys(pos, lo, ih, out):
    for p in nb.prange(pos.shape[0]):
        a = np.int64(max(0.0, (pos[p, 0] - lo[0]) * ih[0] * 2.0))
        b = np.int64(max(0.0, (pos[p, 1] - lo[1]) * ih[1] * 2.0))
        c = np.int64(max(0.0, (pos[p, 2] - lo[2]) * ih[2] * 2.0))
        out[p] = _spread3(a) | (_spread3(b) << 1) | (_spread3(c) << 2)


def locality_order(pos, bounds, shape):
    """Photon processing order along a Morton curve of their start points (half-voxel cells).

    Photons that start close together cross the same voxels, so processing
    them together keeps the deposit buffers in cache. The order does not
    change any result (integer deposits), only the speed.

    Parameters
    ----------
    pos : (P, 3) float64
        Photon start points, world units.
    bounds : (2, 3) array_like
        World-space corners of the volume.
    shape : tuple of int
        Voxels per axis.

    Returns
    -------
    (P,) int64
        Permutation of the photons.

    References
    ----------
    Sun et al. (2008), §4.4 and §5.1 (photon tracing and radiance storage).
    """
    lo, hi, h, ih, shape_n, hmin = _geometry(bounds, shape)
    keys = np.empty(len(pos), np.int64)
    _morton_keys(np.ascontiguousarray(pos, dtype=np.float64), lo, ih, keys)
    return np.argsort(keys, kind="stable")


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


def _take_workspace(shape):
    """Zeroed int64 deposit buffers of the given shape, reusing the last march's when it fits."""
    with _WORKSPACE_LOCK:
        a = _WORKSPACE.pop() if _WORKSPACE else None
    if a is not None and a.shape == tuple(shape):
        _zero(a)
        return a
    return np.zeros(shape, np.int64)


def _give_workspace(a):
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


def _geometry(bounds, shape):
    """The :class:`_Box` of a volume of ``shape`` spanning ``bounds``."""
    b = np.asarray(bounds, dtype=np.float64)
    shape_n = np.asarray(shape[:3], dtype=np.int64)
    h = (b[1] - b[0]) / shape_n
    return _Box(b[0].copy(), b[1].copy(), h, 1.0 / h, shape_n, float(h.min()))


def _integ_code(integrator):
    return {"euler": INTEG_EULER, "rk4": INTEG_RK4}[integrator]


def _grid(field, extinction, level, smax, bounds):
    return _Grid(np.ascontiguousarray(field), np.ascontiguousarray(extinction, dtype=np.float32),
                 np.ascontiguousarray(level), np.ascontiguousarray(smax), *_geometry(bounds, field.shape))


def _new_outputs(P, paths):
    """Fresh per-photon outputs of a march (:class:`_Outputs`): nothing hit, nothing exited yet."""
    return _Outputs(np.zeros(P, np.int32), np.full(P, PHOTON_ACTIVE, np.int8), np.zeros(P, np.float64),
                    np.full((P, 3), np.nan), np.full((P, 3), np.nan), paths, np.zeros(P, np.int8),
                    np.full((P, 3), np.nan), np.full(P, -1, np.int32), np.full((P, 3), np.nan))


def _stopping_rule(grid, photons, knobs, dep, out, recv, stop_fraction):
    """The paper's stopping rule (§4.4): cut the march when fewer than ``stop_fraction * P`` photons are active.

    The photons that ran past the cut are traced again with their deposits
    from the cut on removed (``dep`` with ``start`` = the cut, ``sign`` -1),
    and their outputs in ``out`` truncated there.

    Parameters
    ----------
    grid, photons, knobs, dep, out, recv : named tuples
        The march's (:func:`march_photons`); ``dep`` is its deposit buffer.
    stop_fraction : float or None
        None or 0: no stopping rule.

    Returns
    -------
    int
        Photons cut by the rule.

    References
    ----------
    Sun et al. (2008), §4.4.
    """
    steps, P = out.steps, len(out.steps)
    if not (P and stop_fraction is not None and stop_fraction > 0):  # 0: no stopping rule
        return 0
    k = int(math.ceil(stop_fraction * P)) - 1
    if k >= P:
        return 0
    cut = int(np.sort(steps)[::-1][max(k, 0)]) if k >= 0 else 0
    late = np.flatnonzero(steps > cut)
    if not len(late):
        return 0
    # trace them again, removing every deposit from step ``cut`` on (and recording nothing)
    _march_kernel(grid, photons, late.astype(np.int64), knobs._replace(record=0),
                  dep._replace(start=cut, sign=-1), _new_outputs(P, np.zeros((1, 1, 3))), recv)
    steps[late] = cut
    out.status[late] = LIMIT
    out.exit_pos[late] = np.nan
    out.exit_dir[late] = np.nan
    out.hit_pos[late] = np.nan
    out.hit_recv[late] = -1
    if knobs.record:
        out.paths[late, cut + 1:] = np.nan
    return int(len(late))


def _photon_info(out, recv, truncated, max_steps, buffers):
    """The per-photon results of a march as :func:`march_photons` returns them (its ``photons``)."""
    P = len(out.steps)
    steps, drift = out.steps, out.drift
    hit_tri = out.hit_recv.astype(np.int64)
    hit_receiver = np.where(hit_tri >= 0, np.searchsorted(recv.start, hit_tri, side="right") - 1, -1)
    return {
        "touched": out.touched.astype(bool), "hit_pos": out.hit_pos, "hit_receiver": hit_receiver.astype(np.int32),
        "hit_tri": hit_tri,
        "hit_trans": out.hit_trans, "propagated": int(np.count_nonzero(steps > 0)),
        "exit_pos": out.exit_pos, "exit_dir": out.exit_dir, "status": out.status, "steps": steps,
        "total_steps": int(steps.sum(dtype=np.int64)), "truncated": truncated,
        "drift_max": float(drift.max()) if P else 0.0,
        "drift_median": float(np.median(drift)) if P else 0.0,
        "drift_p99": float(np.percentile(drift, 99)) if P else 0.0,
        "max_steps": int(max_steps), "buffers": int(buffers),
    }


def march_photons(field, extinction, level, smax, bounds, pos, dirs, rad, *, ds_min=1.0, stiff=0.25,
                  integrator="euler", max_steps=0, min_radiance=1e-3, stop_fraction=1e-3, buffers=None,
                  record=0, stepping="robust", receivers=None, outside_ior=1.0, entry=None):
    """Trace photons through the volume and deposit their radiance (§4.4).

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and its gradient (:func:`~refraction_ref.volumetric.gradient.gradient_field`).
    extinction : (nx, ny, nz, 3) float32
        kappa per voxel (per scene unit).
    level, smax : from :func:`~refraction_ref.volumetric.octree.build_octree`
    bounds : (2, 3)
    pos, dirs, rad : (P, 3) float64
        Photons (:func:`~refraction_ref.volumetric.photons.generate_photons`).
    ds_min : float
        Minimum step in voxels (of the smallest voxel side).
    stiff : float
        Stiffness bound (module docstring).
    integrator : {'euler', 'rk4'}
    max_steps : int
        Per-photon limit; 0 = ``8 * max(shape) / ds_min``.
    min_radiance, stop_fraction : float
        Termination thresholds (§4.4). ``stop_fraction=None`` applies no
        stopping rule (every photon runs to its own end).
    buffers : int, optional
        Deposit buffers (default: the numba thread count, fewer if memory
        is short). Does not change the result.
    record : int
        K >= 0: keep the first K steps of every photon's path (``paths``).
        Does not change any other result; 0 allocates nothing.
    stepping : {'robust', 'paper'}
        'paper': §4.4 / §5.3 as written (give it the undilated octree,
        ``build_octree(..., dilate=False)``); 'robust' (this function's
        default, for callers of earlier versions): stiffness cap, step
        halving, straight steps across constant nodes. The scene knob
        ``volumetric.stepping`` defaults to 'paper'.
    receivers : _Recv, optional
        From :func:`receiver_tuple`: diffuse surfaces the photons stop on.
    outside_ior : float
        Index outside the objects: a photon that crosses the half-contrast
        level (:func:`half_contrast`) has met refractive material
        (``touched``).
    entry : (P, 3) float64, optional
        Where each photon's texel ray entered the volume, when it starts
        later, on a proxy (§4.3): its radiance is first attenuated by the
        extinction along the straight segment ``entry -> pos`` it skipped
        (eq. 6, voxel by voxel). The transmittance ``hit_trans`` includes it.

    Returns
    -------
    sums : (nx, ny, nz, 6) float64
        Deposited radiance (RGB) and radiance-weighted direction, unsmoothed.
    photons : dict
        ``exit_pos``, ``exit_dir`` (P, 3; NaN unless exited), ``status``
        (P,) int8 (:data:`STATUS`), ``steps`` (P,) int32 (after the
        stopping rule), ``total_steps``, ``truncated`` (photons cut by the
        stopping rule), ``drift_max`` / ``drift_median`` / ``drift_p99`` (relative
        ``||v| - n| / n``), ``max_steps``; with ``record`` K > 0 also
        ``paths`` (P, K + 1, 3) float64: the start point, then the position
        after each of the first K steps (world; a step that leaves the
        volume ends on its face), NaN after the photon stopped (after
        ``steps``, so a photon cut by the stopping rule ends at the cut).
        ``touched`` (P,) bool: the photon met refractive material;
        ``hit_pos`` (P, 3) (NaN: none), ``hit_receiver`` (P,) int32 (-1:
        none), ``hit_tri`` (P,) int64 (the triangle, an index into
        ``receivers.tris``; -1: none), ``hit_trans`` (P, 3): where the
        photon met a receiver (inside
        the volume, status 5, or straight on after exiting, status 1), and
        its transmittance there; ``propagated``: photons that took a step.

    References
    ----------
    Sun et al. (2008), §4.4, eqs. 4-6.
    """
    record = int(record)
    if record < 0:
        raise ValueError(f"record must be >= 0, got {record}")
    grid = _grid(field, extinction, level, smax, bounds)
    hmin = grid.hmin
    P = len(pos)
    nx, ny, nz = (int(s) for s in field.shape[:3])
    if max_steps <= 0:
        max_steps = int(math.ceil(8 * max(nx, ny, nz) / max(ds_min, 1e-3))) + 16
    vox_bytes = nx * ny * nz * 48
    if buffers is None:
        buffers = max(1, min(nb.get_num_threads(), int(2 * 2**30 // max(vox_bytes, 1))))
    # one voxel of padding on the two inner axes: the rows of a buffer are then not a power of two
    # bytes apart, so a photon walking along y or x does not keep hitting the same cache sets
    acc = _take_workspace((int(buffers), nx, ny + 1, nz + 1, 6))
    total = max(float(np.sum(np.max(rad, axis=1))) if P else 1.0, 1e-300)
    sr = 2.0 ** 58 / (16.0 * total)  # 16 = generous bound on one photon's length per voxel
    sd = sr / 3.0
    paths = np.full((P, record + 1, 3), np.nan) if record else np.zeros((1, 1, 3))
    if stepping not in ("paper", "robust"):
        raise ValueError(f"stepping must be 'paper' or 'robust', got {stepping!r}")
    recv = receiver_tuple() if receivers is None else receivers
    out = _new_outputs(P, paths)
    rad = np.ascontiguousarray(rad, dtype=np.float64)
    pre_trans = None
    if entry is not None and P:
        pre_trans = np.empty_like(rad)
        _skipped_attenuation(grid.ext, grid.lo, grid.ih, np.ascontiguousarray(entry, dtype=np.float64),
                             np.ascontiguousarray(pos, dtype=np.float64), pre_trans)
        rad = rad * pre_trans
    photons = _Photons(np.ascontiguousarray(pos, dtype=np.float64), np.ascontiguousarray(dirs, dtype=np.float64),
                       rad)
    n_half, side = half_contrast(field, float(outside_ior))
    knobs = _Knobs(float(ds_min) * hmin, float(stiff), _integ_code(integrator), int(max_steps),
                   float(min_radiance), record, 1 if stepping == "paper" else 0, n_half, side)
    dep = _Deposits(acc.reshape(-1, 6), int(buffers), nx, ny, nz, acc.shape[2], acc.shape[3], sr, sd, 0, 1)
    if P:
        _march_kernel(grid, photons, locality_order(pos, bounds, field.shape), knobs, dep, out, recv)
    # the paper's stopping rule: iterate until fewer than stop_fraction * P photons are active
    truncated = _stopping_rule(grid, photons, knobs, dep, out, recv, stop_fraction)
    if P and recv.tris.shape[0]:
        ex = np.flatnonzero(out.status == EXITED).astype(np.int64)
        reach = 1e6 * (1.0 + float(np.abs(grid.lo).max() + np.abs(grid.hi).max()))
        _exit_receivers(ex, out.exit_pos, out.exit_dir, recv, reach, out.hit_pos, out.hit_recv)
    if pre_trans is not None:
        out.hit_trans[:] *= pre_trans
    sums = np.empty((nx, ny, nz, 6))
    _merge_buffers(acc, sr, sd, sums)
    _give_workspace(acc)
    info = _photon_info(out, recv, truncated, max_steps, buffers)
    if record:
        info["paths"] = paths
    return sums, info


def trace_paths(field, extinction, level, smax, bounds, pos, dirs, *, ds_min=1.0, stiff=0.25,
                integrator="euler", max_steps=0, max_points=100000, stepping="robust"):
    """The polylines followed by a few photons (for tests and figures); no deposition.

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and its gradient (:func:`~refraction_ref.volumetric.gradient.gradient_field`).
    extinction : (nx, ny, nz, 3) float32
        kappa per voxel (per scene unit).
    level, smax : ndarray
        From :func:`~refraction_ref.volumetric.octree.build_octree`.
    bounds : (2, 3) array_like
        World-space corners of the volume.
    pos, dirs : (P, 3) float64
        Photon start points and directions.
    ds_min, stiff, integrator, max_steps, stepping
        As in :func:`march_photons`.
    max_points : int
        Most points kept per path (the start point included).

    Returns
    -------
    list of (k, 3) float64
        Start point and the end point of every step (clipped at the volume).

    References
    ----------
    Sun et al. (2008), §4.4, eqs. 4-5 and Fig. 5.
    """
    grid = _grid(field, extinction, level, smax, bounds)
    nx, ny, nz = (int(s) for s in field.shape[:3])
    if max_steps <= 0:
        max_steps = int(math.ceil(8 * max(nx, ny, nz) / max(ds_min, 1e-3))) + 16
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    dirs = np.ascontiguousarray(dirs, dtype=np.float64)
    photons = _Photons(pos, dirs, np.ones_like(pos))
    K = max(min(max_points, max_steps + 1), 1) - 1  # steps kept after the start point
    if K == 0:
        return [pos[p:p + 1].copy() for p in range(len(pos))]
    knobs = _Knobs(float(ds_min) * grid.hmin, float(stiff), _integ_code(integrator), int(max_steps), 0.0, K,
                   1 if stepping == "paper" else 0, float("inf"), 1.0)
    dep = _Deposits(np.zeros((1, 6), np.int64), 1, nx, ny, nz, 1, 1, 1.0, 1.0, 1 << 62, 0)  # never deposits
    P = len(pos)
    out = _new_outputs(P, np.zeros((1, 1, 3)))
    recv = receiver_tuple()
    paths = []
    for p in range(len(pos)):
        path = np.empty((K + 1, 3))
        steps = _trace_one(p, grid, photons, knobs, dep, 0, out, path, recv)[0]
        paths.append(path[: min(steps, K) + 1].copy())
    return paths


def smooth_radiance(sums):
    """3x3x3 approximate Gaussian ([1, 2, 1] / 4 per axis) of the deposits, then unit directions (§4.4).

    Parameters
    ----------
    sums : (nx, ny, nz, 6) float64
        Deposited radiance (RGB) and radiance-weighted direction
        (:func:`march_photons`).

    Returns
    -------
    radiance : (nx, ny, nz, 3) float32
    direction : (nx, ny, nz, 3) float32
        Unit mean photon direction (zero where no photon passed).

    References
    ----------
    Sun et al. (2008), §4.4 (smoothing of the stored radiance) and §5.1.
    """
    # voxelize.separable_correlate (x, then y, then z passes; bit-identical to scipy) and the split, fused one
    # x slab at a time: every value is formed by the same operations, but no intermediate volume is written
    w = np.array([0.25, 0.5, 0.25])
    src = np.ascontiguousarray(sums, dtype=np.float64)
    rad = np.empty(src.shape[:3] + (3,), np.float32)
    direction = np.empty(src.shape[:3] + (3,), np.float32)
    nx = src.shape[0]
    chunks = max(1, min(nx, 4 * nb.get_num_threads()))  # slabs per chunk: any split gives the same values
    _smooth_split(src, w, np.linspace(0, nx, chunks + 1).astype(np.int64), rad, direction)
    return rad, direction


@nb.njit(cache=True, parallel=True)
def _smooth_split(a, w, bounds, rad, direction):
    """``voxelize.sym_tap`` along x, y, then z (the passes of ``voxelize.separable_correlate``), then the split:
    radiance rounded to float32, and the unit direction by the operations of ``np.linalg.norm(d, axis=-1)``
    (sqrt of the squares summed in order) and ``d / norm`` where the norm is > 0, rounded to float32;
    slab by slab, parallel over chunks of x slabs (``bounds``), each with its own scratch."""
    nx, ny, nz, nc = a.shape
    r = w.shape[0] // 2
    for ch in nb.prange(bounds.shape[0] - 1):
        xb = np.empty((ny, nz, nc))
        zb = np.empty((nz, nc))
        yrow = np.empty((nz, nc))
        for i in range(bounds[ch], bounds[ch + 1]):
            for j in range(ny):
                for k in range(nz):
                    line = a[:, j, k, :]
                    for c in range(nc):
                        xb[j, k, c] = sym_tap(line, i, c, w, r)
            for j in range(ny):
                for k in range(nz):
                    line = xb[:, k, :]
                    for c in range(nc):
                        yrow[k, c] = sym_tap(line, j, c, w, r)
                for k in range(nz):
                    for c in range(nc):
                        zb[k, c] = sym_tap(yrow, k, c, w, r)
                for k in range(nz):
                    for c in range(3):
                        rad[i, j, k, c] = np.float32(zb[k, c])
                    d0 = zb[k, 3]
                    d1 = zb[k, 4]
                    d2 = zb[k, 5]
                    nrm = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                    if nrm > 0:
                        direction[i, j, k, 0] = np.float32(d0 / nrm)
                        direction[i, j, k, 1] = np.float32(d1 / nrm)
                        direction[i, j, k, 2] = np.float32(d2 / nrm)
                    else:
                        direction[i, j, k, 0] = np.float32(0.0)
                        direction[i, j, k, 1] = np.float32(0.0)
                        direction[i, j, k, 2] = np.float32(0.0)
