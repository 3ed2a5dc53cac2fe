"""Adaptive photon marching (§4.4, eqs. 4-6): the march's loop, its stopping rule, its results.

Every photon carries a position x, a "velocity" v = n dx/ds (|v| = n) and an
RGB radiance L. One step:

1. **Step size** (§4.4, §5.3): the distance along v to the boundary of the
   octree leaf node containing x (:func:`~.grid.node_distance`), clamped to
   ``[ds_min, step_max]`` where step_max is the node's maximum step
   (unbounded in constant nodes, ``ds_max`` voxels where eps <= range <
   eps'). That is all of it with ``stepping = 'paper'`` (every step then
   applies eqs. 4-5 with the sampled gradient). With ``stepping = 'robust'``
   a constant node is crossed in one straight step (its gradient is taken
   as zero: the octree is dilated, :func:`~.knobs.octree_dilations`), and a
   *stiffness bound* ``ds <= stiff * n / |grad n|`` then caps the step at
   sharp index steps (it overrides ds_min), so one step never changes |v| by
   more than the fraction ``stiff`` of n; and a step whose end point sees an
   index change larger than ``stiff * n`` that the gradient at its start
   does not predict (an index *jump*, e.g. an unblurred surface) is halved,
   up to 8 times.
2. **Advance**: forward differences (eqs. 4-5), ``x += ds v / n``,
   ``v += ds grad n``; or classic RK4 on the same system (eqs. 2-3)
   (:mod:`.integrate`).
3. **Attenuate** (eq. 6): ``L *= exp(-kappa(x_i) |x_{i+1} - x_i|)``
   (:func:`~.extinction.attenuate`).
4. **Deposit** into every voxel the segment crosses the radiance
   interpolated along the segment and the radiance-weighted unit direction
   (:func:`~.deposit.deposit_segment`; fixed point, one buffer per worker,
   so the sums are the same bits on any number of threads).

A photon dies when it leaves the volume (its exit point and direction are
recorded), when a step meets a diffuse receiver (the step ends on it; its
hit point, receiver and transmittance are recorded; an exiting photon goes
on straight, outside the volume, to the first receiver it meets there:
:mod:`.receivers`), when its radiance falls below ``min_radiance`` of its
start, when |v| collapses, or at ``max_steps``. The paper's stopping rule
(stop iterating when fewer than ``stop_fraction`` of the photons are
active) is applied exactly: photons still active at that iteration have
their later deposits removed again (integer deposits are undone exactly)
and count as stopped.

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

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.4 (eqs. 4-6), §5.3.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..status import EXITED, LIMIT, LOST
from .deposit import Deposits, deposit_segment, give_workspace, merge_buffers, release_workspace, take_workspace
from .extinction import attenuate, skipped_attenuation
from .grid import half_contrast, node_distance, sample_field, segment_exit, volume_box, voxel_of
from .integrate import advance
from .knobs import ROBUST, march_knobs
from .receivers import receiver_tuple, segment_receiver, exit_receivers

__all__ = ["march_photons", "trace_paths", "march_grid", "locality_order", "release_workspace", "STATUS",
           "PHOTON_ACTIVE", "PHOTON_ABSORBED", "PHOTON_RECEIVED", "MarchGrid", "PhotonStarts", "MarchControl",
           "PhotonResults"]

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


class MarchGrid(NamedTuple):
    """The volume the photons march through: index field, extinction, octree, and where it lies
    (:func:`march_grid`; flat: numba's parallel loops pass the fields of a tuple, not of a tuple inside a tuple)."""

    field: np.ndarray  # (nx, ny, nz, 4) float32: n and grad n
    extinction: np.ndarray  # (nx, ny, nz, 3) float32: kappa per scene unit
    level: np.ndarray  # (nx, ny, nz): level of the octree leaf holding each voxel
    step_max: np.ndarray  # (nx, ny, nz) float32: maximum step in voxels (inf: constant node)
    lo: np.ndarray  # the fields of grid.VolumeBox
    hi: np.ndarray
    h: np.ndarray
    ih: np.ndarray
    shape_n: np.ndarray
    hmin: float


class PhotonStarts(NamedTuple):
    """The photons' start states, (P, 3) float64 each (:func:`~.photons.generate_photons`)."""

    pos: np.ndarray
    dirs: np.ndarray
    rad: np.ndarray


class MarchControl(NamedTuple):
    """Step control and termination of one march, in world units (:func:`_march_control`)."""

    ds_min: float  # minimum step, world units
    stiff: float  # stiffness bound
    integrator: int  # knobs.EULER or knobs.RK4
    max_steps: int  # resolved: > 0
    min_radiance: float  # a photon dies below this fraction of its start radiance
    record: int  # steps kept per photon in the path (0: none)
    stepping: int  # knobs.PAPER (no stiffness cap, no halving, no straight shortcut) or knobs.ROBUST
    n_half: float  # the half-contrast index level: a photon beyond it has met refractive material
    side: float  # +1 (object denser than the outside) or -1


class PhotonResults(NamedTuple):
    """Per-photon arrays the march fills (see :func:`march_photons`, Returns)."""

    steps: np.ndarray  # (P,) int32
    status: np.ndarray  # (P,) int8
    drift: np.ndarray  # (P,) float64
    exit_pos: np.ndarray  # (P, 3)
    exit_dir: np.ndarray  # (P, 3)
    paths: np.ndarray  # (P, record + 1, 3); (1, 1, 3) unused when record is 0
    touched: np.ndarray  # (P,) int8: 1 when the photon met refractive material (beyond n_half)
    hit_pos: np.ndarray  # (P, 3): where it met a receiver (NaN: none)
    hit_recv: np.ndarray  # (P,) int32: which receiver triangle (index in MarchReceivers.tris; -1: none)
    hit_trans: np.ndarray  # (P, 3): its transmittance exp(-int kappa) there


def march_grid(field, extinction, level, step_max, bounds):
    """The :class:`MarchGrid` the march kernels read, from the passes' volumes.

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and its gradient (:func:`~refraction_ref.volumetric.gradient.gradient_field`).
    extinction : (nx, ny, nz, 3) float32
        kappa per voxel (per scene unit).
    level, step_max : ndarray
        From :func:`~refraction_ref.volumetric.octree.build_octree`, built
        with the dilation the stepping needs
        (:func:`~refraction_ref.volumetric.knobs.octree_dilations`).
    bounds : (2, 3) array_like
        World-space corners of the volume.

    Returns
    -------
    MarchGrid

    References
    ----------
    Sun et al. (2008), §4.2 (octree), §4.4 (the volume the photons cross).
    """
    return MarchGrid(np.ascontiguousarray(field), np.ascontiguousarray(extinction, dtype=np.float32),
                     np.ascontiguousarray(level), np.ascontiguousarray(step_max), *volume_box(bounds, field.shape))


def _step_limit(knobs, grid):
    """``max_steps``, with 0 resolved to ``8 * max(shape) / ds_min`` (+ 16)."""
    if knobs.max_steps > 0:
        return int(knobs.max_steps)
    nx, ny, nz = (int(s) for s in grid.field.shape[:3])
    return int(math.ceil(8 * max(nx, ny, nz) / max(knobs.ds_min, 1e-3))) + 16


def _march_control(knobs, grid, record, n_half, side):
    """The kernels' :class:`MarchControl`: the knobs in world units, with the path record and material level."""
    return MarchControl(float(knobs.ds_min) * grid.hmin, float(knobs.stiff), int(knobs.integrator),
                        _step_limit(knobs, grid), float(knobs.min_radiance), int(record), int(knobs.stepping),
                        float(n_half), float(side))


@nb.njit(cache=True, inline="always")
def _robust_step(field, lo, ih, integrator, state, ds, stiff, hmin):
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
        x1, y1, z1, vx1, vy1, vz1 = advance(field, lo, ih, integrator, (x, y, z), (vx, vy, vz),
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
def _put3(a, p, v):
    """``a[p, :] = v`` for a 3-tuple ``v``, one component per statement."""
    a[p, 0] = v[0]
    a[p, 1] = v[1]
    a[p, 2] = v[2]


@nb.njit(cache=True)
def _trace_one(p, grid, photons, control, dep, g, out, path, recv):
    """Trace photon p to its end; returns (steps, status, max relative |v|-n drift).

    Deposits into buffer ``g`` of ``dep``, writes ``out.exit_pos`` /
    ``out.exit_dir`` of an exiting photon, and, when ``control.record`` is
    K > 0, the start point and the end points of the first K steps into
    ``path`` ((K + 1, 3); rows of steps not taken are left as they are).
    """
    # the named tuples unpacked by name (a reordered field cannot swap two arguments)
    field, ext, level, step_max = grid.field, grid.extinction, grid.level, grid.step_max
    lo, hi, ih, hmin = grid.lo, grid.hi, grid.ih, grid.hmin
    pos, dirs, rad = photons.pos, photons.dirs, photons.rad
    ds_min, stiff, integrator, max_steps = control.ds_min, control.stiff, control.integrator, control.max_steps
    min_radiance, record = control.min_radiance, control.record
    robust = control.stepping == ROBUST
    n_half = control.n_half
    side = control.side
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
    thr = min_radiance * lmax0
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
        cap = step_max[i, j, k]
        # robust stepping: a constant octree node (zero gradient, dilated octree) is crossed in one straight
        # step; the paper's stepping applies eqs. 4-5 at every step
        const = cap == np.inf and robust
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
        ds = node_distance(grid, level[i, j, k], (x, y, z), (ux, uy, uz)) + nudge
        ds = max(ds, ds_min)
        if const:
            x1, y1, z1, vx1, vy1, vz1 = x + ds * ux, y + ds * uy, z + ds * uz, vx, vy, vz
        elif not robust:  # §4.4 / §5.3: clamp(ds_octree, ds_min, ds_max), one step of eqs. 4-5
            ds = min(ds, cap * hmin)
            x1, y1, z1, vx1, vy1, vz1 = advance(field, lo, ih, integrator, (x, y, z), (vx, vy, vz), (n, gx, gy, gz), ds)
        else:
            ds = min(ds, cap * hmin)
            ds, x1, y1, z1, vx1, vy1, vz1, cn, cgx, cgy, cgz = _robust_step(
                field, lo, ih, integrator, (x, y, z, vx, vy, vz, n, gx, gy, gz), ds, stiff, hmin)
            carried = True
        if not (math.isfinite(x1) and math.isfinite(y1) and math.isfinite(z1)
                and math.isfinite(vx1) and math.isfinite(vy1) and math.isfinite(vz1)):
            status = LOST
            break
        s = segment_exit(lo, hi, x, y, z, x1, y1, z1)
        hitr = -1
        if nrecv > 0:  # a diffuse receiver on the step ends it there
            th, hr = segment_receiver(recv, x, y, z, x1 - x, y1 - y, z1 - z, s)
            if hr >= 0:
                s = th
                hitr = hr
        ex, ey, ez = x + s * (x1 - x), y + s * (y1 - y), z + s * (z1 - z)
        sx, sy, sz = ex - x, ey - y, ez - z
        seg = math.sqrt(sx * sx + sy * sy + sz * sz)
        nr, ng, nb_, tr_r, tr_g, tr_b = attenuate(ext, i, j, k, seg, (lr, lg, lb), (tr_r, tr_g, tr_b))
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
                vx1, vy1, vz1 = advance(field, lo, ih, integrator, (x, y, z), (vx, vy, vz), (n, gx, gy, gz), s * ds)[3:]
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
def _march_kernel(grid, photons, sel, control, dep, out, recv):
    """Trace the photons ``sel`` (indices into ``photons``), chunks of 256 spread over the deposit buffers."""
    nbuf = dep.buffers
    # one output array per statement (see view._view_kernel: numba's dead-code elimination)
    out_steps = out.steps
    out_status = out.status
    out_drift = out.drift
    paths = out.paths
    rec = control.record > 0
    dummy_path = np.zeros((1, 3))
    chunk = 256
    for g in nb.prange(nbuf):
        for q in range(sel.shape[0]):
            if (q // chunk) % nbuf != g:
                continue
            p = sel[q]
            st, ss, dr = _trace_one(p, grid, photons, control, dep, np.int64(g), out,  # int64: one signature
                                    paths[p] if rec else dummy_path, recv)
            out_steps[p] = st
            out_status[p] = ss
            out_drift[p] = dr


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


def locality_order(pos, box):
    """Photon processing order along a Morton curve of their start points (half-voxel cells).

    Photons that start close together cross the same voxels, so processing
    them together keeps the deposit buffers in cache. The order does not
    change any result (integer deposits), only the speed.

    Parameters
    ----------
    pos : (P, 3) float64
        Photon start points, world units.
    box : VolumeBox or MarchGrid
        Where the volume lies (its ``lo`` and ``ih``).

    Returns
    -------
    (P,) int64
        Permutation of the photons.

    References
    ----------
    Sun et al. (2008), §4.4 and §5.1 (photon tracing and radiance storage).
    """
    keys = np.empty(len(pos), np.int64)
    _morton_keys(np.ascontiguousarray(pos, dtype=np.float64), box.lo, box.ih, keys)
    return np.argsort(keys, kind="stable")


def _stopping_rule(grid, photons, control, dep, out, recv, stop_fraction):
    """The paper's stopping rule (§4.4): cut the march when fewer than ``stop_fraction * P`` photons are active.

    The photons that ran past the cut are traced again with their deposits
    from the cut on removed (``dep`` with ``start`` = the cut, ``sign`` -1),
    and their outputs in ``out`` truncated there.

    Parameters
    ----------
    grid, photons, control, dep, out, recv : named tuples
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
    _march_kernel(grid, photons, late.astype(np.int64), control._replace(record=0),
                  dep._replace(start=cut, sign=-1), _new_results(P, np.zeros((1, 1, 3))), recv)
    steps[late] = cut
    out.status[late] = LIMIT
    out.exit_pos[late] = np.nan
    out.exit_dir[late] = np.nan
    out.hit_pos[late] = np.nan
    out.hit_recv[late] = -1
    if control.record:
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


def _new_results(P, paths):
    """Fresh per-photon results of a march (:class:`PhotonResults`): nothing hit, nothing exited yet."""
    return PhotonResults(np.zeros(P, np.int32), np.full(P, PHOTON_ACTIVE, np.int8), np.zeros(P, np.float64),
                         np.full((P, 3), np.nan), np.full((P, 3), np.nan), paths, np.zeros(P, np.int8),
                         np.full((P, 3), np.nan), np.full(P, -1, np.int32), np.full((P, 3), np.nan))


def march_photons(grid, photons, knobs=None, *, entry=None, receivers=None, outside_ior=1.0, record=0,
                  buffers=None):
    """Trace photons through the volume and deposit their radiance (§4.4).

    Parameters
    ----------
    grid : MarchGrid
        The volume (:func:`march_grid`), its octree built for the knobs'
        stepping (:func:`~refraction_ref.volumetric.knobs.octree_dilations`).
    photons : (pos, dirs, rad), (P, 3) float64 each
        Photon start points, unit directions and radiance
        (:func:`~refraction_ref.volumetric.photons.generate_photons`).
    knobs : MarchKnobs, optional
        From :func:`~refraction_ref.volumetric.knobs.march_knobs` (default:
        the declared defaults). ``stop_fraction`` 0 applies no stopping rule
        (every photon runs to its own end).
    entry : (P, 3) float64, optional
        Where each photon's texel ray entered the volume, when it starts
        later, on a proxy (§4.3): its radiance is first attenuated by the
        extinction along the straight segment ``entry -> pos`` it skipped
        (eq. 6, voxel by voxel). The transmittance ``hit_trans`` includes it.
    receivers : MarchReceivers, optional
        From :func:`~refraction_ref.volumetric.receivers.receiver_tuple`:
        diffuse surfaces the photons stop on.
    outside_ior : float
        Index outside the objects: a photon that crosses the half-contrast
        level (:func:`~refraction_ref.volumetric.grid.half_contrast`) has
        met refractive material (``touched``).
    record : int
        K >= 0: keep the first K steps of every photon's path (``paths``).
        Does not change any other result; 0 allocates nothing.
    buffers : int, optional
        Deposit buffers (default: the numba thread count, fewer if memory
        is short). Does not change the result.

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
    knobs = march_knobs() if knobs is None else knobs
    record = int(record)
    if record < 0:
        raise ValueError(f"record must be >= 0, got {record}")
    pos, dirs, rad = photons
    P = len(pos)
    nx, ny, nz = (int(s) for s in grid.field.shape[:3])
    vox_bytes = nx * ny * nz * 48
    if buffers is None:
        buffers = max(1, min(nb.get_num_threads(), int(2 * 2**30 // max(vox_bytes, 1))))
    # one voxel of padding on the two inner axes: the rows of a buffer are then not a power of two
    # bytes apart, so a photon walking along y or x does not keep hitting the same cache sets
    acc = take_workspace((int(buffers), nx, ny + 1, nz + 1, 6))
    total = max(float(np.sum(np.max(rad, axis=1))) if P else 1.0, 1e-300)
    sr = 2.0 ** 58 / (16.0 * total)  # 16 = generous bound on one photon's length per voxel
    sd = sr / 3.0
    paths = np.full((P, record + 1, 3), np.nan) if record else np.zeros((1, 1, 3))
    recv = receiver_tuple() if receivers is None else receivers
    out = _new_results(P, paths)
    rad = np.ascontiguousarray(rad, dtype=np.float64)
    pre_trans = None
    if entry is not None and P:
        pre_trans = np.empty_like(rad)
        skipped_attenuation(grid.extinction, grid.lo, grid.ih, np.ascontiguousarray(entry, dtype=np.float64),
                            np.ascontiguousarray(pos, dtype=np.float64), pre_trans)
        rad = rad * pre_trans
    starts = PhotonStarts(np.ascontiguousarray(pos, dtype=np.float64), np.ascontiguousarray(dirs, dtype=np.float64),
                          rad)
    n_half, side = half_contrast(grid.field, float(outside_ior))
    control = _march_control(knobs, grid, record, n_half, side)
    dep = Deposits(acc.reshape(-1, 6), int(buffers), nx, ny, nz, acc.shape[2], acc.shape[3], sr, sd, 0, 1)
    if P:
        _march_kernel(grid, starts, locality_order(pos, grid), control, dep, out, recv)
    # the paper's stopping rule: iterate until fewer than stop_fraction * P photons are active
    truncated = _stopping_rule(grid, starts, control, dep, out, recv, knobs.stop_fraction)
    if P and recv.tris.shape[0]:
        ex = np.flatnonzero(out.status == EXITED).astype(np.int64)
        reach = 1e6 * (1.0 + float(np.abs(grid.lo).max() + np.abs(grid.hi).max()))
        exit_receivers(ex, out.exit_pos, out.exit_dir, recv, reach, out.hit_pos, out.hit_recv)
    if pre_trans is not None:
        out.hit_trans[:] *= pre_trans
    sums = np.empty((nx, ny, nz, 6))
    merge_buffers(acc, sr, sd, sums)
    give_workspace(acc)
    info = _photon_info(out, recv, truncated, control.max_steps, buffers)
    if record:
        info["paths"] = paths
    return sums, info


def trace_paths(grid, pos, dirs, knobs=None, max_points=100000):
    """The polylines followed by a few photons (for tests and figures); no deposition.

    Parameters
    ----------
    grid : MarchGrid
        The volume (:func:`march_grid`).
    pos, dirs : (P, 3) float64
        Photon start points and directions.
    knobs : MarchKnobs, optional
        As in :func:`march_photons` (``min_radiance`` and ``stop_fraction``
        are not read: no photon is absorbed or cut).
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
    knobs = march_knobs() if knobs is None else knobs
    nx, ny, nz = (int(s) for s in grid.field.shape[:3])
    max_steps = _step_limit(knobs, grid)
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    dirs = np.ascontiguousarray(dirs, dtype=np.float64)
    starts = PhotonStarts(pos, dirs, np.ones_like(pos))
    K = max(min(max_points, max_steps + 1), 1) - 1  # steps kept after the start point
    if K == 0:
        return [pos[p:p + 1].copy() for p in range(len(pos))]
    control = _march_control(knobs._replace(min_radiance=0.0), grid, K, float("inf"), 1.0)
    dep = Deposits(np.zeros((1, 6), np.int64), 1, nx, ny, nz, 1, 1, 1.0, 1.0, 1 << 62, 0)  # never deposits
    P = len(pos)
    out = _new_results(P, np.zeros((1, 1, 3)))
    recv = receiver_tuple()
    paths = []
    for p in range(len(pos)):
        path = np.empty((K + 1, 3))
        steps = _trace_one(p, grid, starts, control, dep, 0, out, path, recv)[0]
        paths.append(path[: min(steps, K) + 1].copy())
    return paths
