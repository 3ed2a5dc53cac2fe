"""A converged reference for graded-index volumes: the ray equation by an adaptive 8th-order solver.

The volumetric method (Sun et al. 2008) marches photons and viewing rays
through an index volume with fixed-form steps (eqs. 4-5, or RK4) whose
length the octree sets (§4.2, §4.4, §5.3). This module integrates the *same*
ray equation through the *same* continuous field with Dormand and Prince's
explicit Runge-Kutta method of order 8 (DOP853) and adaptive steps, tightened
until the answer stops moving, so that what differs from the method is the
integration alone.

The equation
------------
With ``v = n dx/ds`` (s the arc length) the ray equation
``d/ds (n dx/ds) = grad n`` (Sun et al. 2008, §3, eq. 1; Born and Wolf
§3.2, eq. 3.2(2)) is the first-order system (eqs. 2-3)::

    dx/ds = v / n(x),      dv/ds = grad n(x)

integrated in the state ``y = (x, v)`` (6 components) over the parameter s.

The field
---------
Exactly the one the method samples: the packed float32 array
``(n, dn/dx, dn/dy, dn/dz)`` of
:func:`~refraction_ref.volumetric.gradient.gradient_field` (n at voxel
centres, its gradient by central differences, one-sided on the faces;
eq. 3) read at any point by
:func:`~refraction_ref.volumetric.grid.sample_field`: trilinear between
voxel centres, clamped to the outermost centres. The gradient is thus the
interpolated central difference, not the derivative of the interpolated n
(that one jumps at every voxel face, and the method never uses it), so
``|v| = n`` is not an exact invariant of this system; the drift is
reported (``drift``), as the march reports its own.

The solver
----------
scipy's DOP853 (``scipy.integrate.solve_ivp(method="DOP853")``) written out
in Numba (:mod:`refraction_ref.exact.dop853`: its tableau, error norm,
initial step and the right-hand side), so that every ray runs on every
thread without Python in the loop; this module holds scipy's step controller
(safety 0.9, factors 0.2 to 10, exponent -1/8), the events and the paths.
:func:`trace_rays_scipy` integrates the same rays with ``solve_ivp`` itself
(a terminal event at the box) and ``tests/exact/test_grin_reference.py``
checks that both agree. Steps are also
capped at ``max_step`` voxels, so that the polyline of accepted steps
resolves what is evaluated along the path (the material level set,
extinction voxel by voxel, receivers).

Entry and exit rules (the method's, :mod:`refraction_ref.volumetric`)
---------------------------------------------------------------------
* Photons start where the method's ``photons`` stage puts them (on the
  volume box, or on the proxy), with ``v = n(x0) d``; a photon that starts
  on a proxy carries the transmittance of the straight segment it skipped
  (the march's ``entry`` rule, eq. 6).
* Viewing rays enter the box by the method's slab test
  (:func:`~refraction_ref.volumetric.view.box_entry_one`), with ``v = n d``.
* A path ends where it leaves the box: the step that crosses a face is
  redone to the crossing (a bracketed root of the distance to the box on the
  step's own 8th-order map ``h -> y(s + h)``), the exit point is put on the
  face, and the exit direction is ``v / |v|`` there (no refraction at the
  box: the index is continuous there, as for the method).
* A step whose chord meets a receiver triangle (the march's
  ``segment_receiver``) is redone to the curved path's crossing of the
  triangle's plane; a photon that leaves the box goes on straight to the
  first receiver outside it (the march's ``exit_receivers``).
* "Met refractive material" (the photons' ``touched``, the viewing ray's
  ``hit``) and the viewing ray's ``interfaces`` and ``path_length`` are the
  method's half-contrast level set
  (:func:`~refraction_ref.volumetric.grid.half_contrast`), tested at every
  accepted step's end (the start included); ``path_length`` splits a step
  that crosses the level linearly in n.
* Transmittance: ``exp(-integral of kappa)`` along the chords of the accepted
  steps, voxel by voxel (kappa is constant per voxel, as the method holds it;
  the march applies the kappa of a step's first voxel to the whole step).
* Stops: ``LIMIT`` at the method's path budget in length (photons
  ``8 max(shape)`` voxels, viewing rays ``4 (nx + ny + nz)`` voxels: the
  march's and the viewing pass's step limits at one voxel a step); ``LOST``
  where ``|v|`` collapses (photons below ``1e-12 n``, viewing rays below
  ``1e-12``, as the method), ``n <= 0``, a non-finite state, or a step below
  scipy's minimum. No ``min_radiance`` cut and no stopping rule: every path
  runs to its end.

References
----------
.. [1] X. Sun, K. Zhou, E. Stollnitz, J. Shi, B. Guo, "Interactive
   Relighting of Dynamic Refractive Objects", ACM TOG 27(3), Article 35,
   2008: §3 eqs. 1-3 (the ray equation and its first-order form), §4.3
   (photon entry), §4.4 eqs. 4-6 (the march this reference converges), §4.5
   (viewing rays), §5.3 (the step tolerances).
.. [2] M. Born, E. Wolf, *Principles of Optics*, 7th ed., §3.2.1 (the ray
   equation d/ds (n dr/ds) = grad n).
.. [3] E. Hairer, S. P. Norsett, G. Wanner, *Solving Ordinary Differential
   Equations I: Nonstiff Problems*, 2nd ed., §II.4 (initial step), §II.5 and
   §II.10 (DOP853 and its error estimate).
.. [4] R. K. Luneburg, *Mathematical Theory of Optics*, 1944 (the lens
   ``n = sqrt(2 - r^2 / R^2)`` checked in the tests).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..status import EXITED, LIMIT, LOST, MISSED
from ..volumetric.extinction import optical_depth, skipped_attenuation
from ..volumetric.grid import half_contrast, volume_box
from ..volumetric.receivers import exit_receivers, receiver_tuple, segment_receiver
from ..volumetric.view import box_entry_one
from .dop853 import (ATOL, FIELD_LUNEBURG, FIELD_SAMPLED, MAX_STEP, RTOL, GrinTolerances, GrinVolume,
                     dop853_error_norm, dop853_initial_step, dop853_step, dop853_tableau, grin_field, ray_rhs,
                     sample_index, trace_rays_scipy)

__all__ = ["trace_rays", "trace_photons", "trace_view", "trace_rays_scipy", "tolerance_sweep", "GrinVolume",
           "GrinTolerances", "RTOL", "ATOL", "MAX_STEP", "RECEIVED", "FIELD_SAMPLED", "FIELD_LUNEBURG"]

#: a photon stopped on a receiver inside the volume (the march's ``PHOTON_RECEIVED``)
RECEIVED = 5


class GrinSettings(NamedTuple):
    """Tolerances, the step cap and budget, the material level set and the lost rule (the kernels' scalars)."""

    rtol: float
    atol: float
    max_step: float  # world units
    s_max: float  # path budget, world units
    n_half: float
    side: float
    lost_rel: int  # 1: |v| <= 1e-12 n is lost (photons); 0: |v| <= 1e-12 (viewing rays)


class GrinPaths(NamedTuple):
    """Per-ray results (:func:`trace_rays`, Returns)."""

    status: np.ndarray  # (R,) int8
    end_pos: np.ndarray  # (R, 3)
    end_dir: np.ndarray  # (R, 3)
    hit_tri: np.ndarray  # (R,) int32
    tau: np.ndarray  # (R, 3) optical depth
    met: np.ndarray  # (R,) bool
    crossings: np.ndarray  # (R,) int32
    path_length: np.ndarray  # (R,)
    length: np.ndarray  # (R,) parameter s at the end
    steps: np.ndarray  # (R,) int32 accepted steps
    rejected: np.ndarray  # (R,) int32 rejected steps
    drift: np.ndarray  # (R,) max ||v| - n| / n


# --------------------------------------------------------------------- events
@nb.njit(cache=True)
def _box_excess(lo, hi, y):
    """How far the point y[:3] lies outside the box (<= 0 inside), the largest over the faces."""
    e = -np.inf
    for a in range(3):
        e = max(e, max(y[a] - hi[a], lo[a] - y[a]))
    return e


class GrinScratch(NamedTuple):
    """One ray's scratch: the stages of the root-finding steps, two states, the receiver plane."""

    K: np.ndarray  # (13, 6)
    tmp: np.ndarray  # (6,)
    yt: np.ndarray  # (6,)
    plane: np.ndarray  # (8,): the triangle's normal (0:3), the sign making the start side negative (4), a vertex (5:8)


@nb.njit(cache=True)
def _event_value(mode, fk, tab, y, f, h, w):
    """The event function after a step h from y: box excess (mode 1) or signed plane distance (mode 2)."""
    yt, plane = w.yt, w.plane
    dop853_step(fk, tab, y, f, h, w.K, w.tmp, yt)
    if mode == 1:
        return _box_excess(fk.lo, fk.hi, yt)
    return plane[4] * ((yt[0] - plane[5]) * plane[0] + (yt[1] - plane[6]) * plane[1] + (yt[2] - plane[7]) * plane[2])


@nb.njit(cache=True)
def _root(mode, fk, tab, y, f, bracket, w):
    """The step in ``bracket = (ha, ga, hb, gb)`` where the event function crosses 0 (ga <= 0 < gb): Illinois
    regula falsi. Returns a step whose end has event value >= 0 (at or just past the crossing), within a few
    ulp of it."""
    ha, ga, hb, gb = bracket
    side = 0
    for _ in range(200):
        if hb - ha <= 4e-16 * hb or gb == 0.0:
            break
        hc = (ha * gb - hb * ga) / (gb - ga)
        if not (hc > ha and hc < hb):
            hc = 0.5 * (ha + hb)
            if not (hc > ha and hc < hb):
                break
        gc = _event_value(mode, fk, tab, y, f, hc, w)
        if gc >= 0.0:
            hb, gb = hc, gc
            if side == 1:
                ga *= 0.5
            side = 1
        else:
            ha, ga = hc, gc
            if side == -1:
                gb *= 0.5
            side = -1
    return hb


# --------------------------------------------------------------------- one ray
@nb.njit(cache=True)
def _accepted_step(fk, tab, cfg, y, f, s, h_abs, K, tmp, ynew):
    """One accepted DOP853 step from (s, y) by scipy's controller (``RungeKutta._step_impl``), into ``ynew``.

    Returns ``(ok, h, h_next, n(ynew), rejected steps)``; ``ok`` False when the step fell below scipy's
    minimum (``10 ulp(s)``).
    """
    rtol, atol = cfg.rtol, cfg.atol
    min_step = 10.0 * abs(np.nextafter(s, np.inf) - s)
    if h_abs > cfg.max_step:
        h_abs = cfg.max_step
    elif h_abs < min_step:
        h_abs = min_step
    rejected = False
    rej = 0
    while True:
        if h_abs < min_step:
            return False, 0.0, 0.0, 0.0, rej
        s_new = s + h_abs
        if s_new > cfg.s_max:
            s_new = cfg.s_max
        h = s_new - s
        h_abs = abs(h)
        n1 = dop853_step(fk, tab, y, f, h, K, tmp, ynew)
        en = dop853_error_norm(tab, K, h, y, ynew, rtol, atol)
        if en < 1.0:
            factor = 10.0 if en == 0.0 else min(10.0, 0.9 * en ** (-1.0 / 8.0))
            if rejected:
                factor = min(1.0, factor)
            return True, h, h_abs * factor, n1, rej
        h_abs *= max(0.2, 0.9 * en ** (-1.0 / 8.0))
        rejected = True
        rej += 1


@nb.njit(cache=True)
def _events(fk, tab, recv, y, f, h, ynew, n1, w):
    """The box face, then a receiver, on the accepted step y -> ynew (step h): the step cut at the first one.

    ``ynew`` is replaced by the state at the event. Returns ``(event, h_end, n(ynew), receiver triangle)``:
    event 0 none, 1 the box face (``ynew`` put on the face), 2 a receiver triangle (the curved path's
    crossing of its plane).
    """
    lo, hi, plane = fk.lo, fk.hi, w.plane
    ev = 0
    h_end = h
    hit_q = -1
    ex = _box_excess(lo, hi, ynew)
    if ex > 0.0:
        g0 = min(_box_excess(lo, hi, y), 0.0)
        h_end = _root(1, fk, tab, y, f, (0.0, g0, h, ex), w)
        n1 = dop853_step(fk, tab, y, f, h_end, w.K, w.tmp, ynew)
        # put the point on the face it crossed (the root leaves it within a few ulp past it)
        best = -1
        bex = -np.inf
        for a in range(3):
            e = max(ynew[a] - hi[a], lo[a] - ynew[a])
            if e > bex:
                bex = e
                best = a
        ynew[best] = hi[best] if ynew[best] - hi[best] >= lo[best] - ynew[best] else lo[best]
        for a in range(3):
            ynew[a] = min(max(ynew[a], lo[a]), hi[a])
        ev = 1
    if recv.tris.shape[0] > 0:
        th, q = segment_receiver(recv, y[0], y[1], y[2], ynew[0] - y[0], ynew[1] - y[1], ynew[2] - y[2], 1.0)
        if q >= 0:
            t = recv.tris
            e1x, e1y, e1z = t[q, 1, 0] - t[q, 0, 0], t[q, 1, 1] - t[q, 0, 1], t[q, 1, 2] - t[q, 0, 2]
            e2x, e2y, e2z = t[q, 2, 0] - t[q, 0, 0], t[q, 2, 1] - t[q, 0, 1], t[q, 2, 2] - t[q, 0, 2]
            plane[0] = e1y * e2z - e1z * e2y
            plane[1] = e1z * e2x - e1x * e2z
            plane[2] = e1x * e2y - e1y * e2x
            plane[5], plane[6], plane[7] = t[q, 0, 0], t[q, 0, 1], t[q, 0, 2]
            da = (y[0] - plane[5]) * plane[0] + (y[1] - plane[6]) * plane[1] + (y[2] - plane[7]) * plane[2]
            db = (ynew[0] - plane[5]) * plane[0] + (ynew[1] - plane[6]) * plane[1] + (ynew[2] - plane[7]) * plane[2]
            plane[4] = -1.0 if da > 0.0 or (da == 0.0 and db < 0.0) else 1.0
            ga, gb = plane[4] * da, plane[4] * db
            if gb > 0.0 and ga <= 0.0:
                h_end = _root(2, fk, tab, y, f, (0.0, ga, h_end, gb), w)
                n1 = dop853_step(fk, tab, y, f, h_end, w.K, w.tmp, ynew)
            ev = 2
            hit_q = q
    return ev, h_end, n1, hit_q


@nb.njit(cache=True)
def _trace_one(r, fk, tab, cfg, recv, x0, d0, out):
    """Integrate ray r from x0 along d0 (unit) to its end; fills row r of ``out``."""
    y = np.empty(6)
    f = np.empty(6)
    ynew = np.empty(6)
    tmp = np.empty(6)
    K = np.empty((13, 6))
    w = GrinScratch(np.empty((13, 6)), np.empty(6), np.empty(6), np.zeros(8))
    n_half, side = cfg.n_half, cfg.side
    n0 = sample_index(fk, x0[0], x0[1], x0[2])[0]
    for c in range(3):
        y[c] = x0[c]
        y[3 + c] = n0 * d0[c]
    n = ray_rhs(fk, y, f)
    a_prev = side * (n - n_half)
    inside = a_prev > 0.0
    met = inside
    crossings = 0
    path_length = 0.0
    tau_r, tau_g, tau_b = 0.0, 0.0, 0.0
    drift = 0.0
    s = 0.0
    steps = 0
    rej = 0
    status = LIMIT
    hit_q = -1
    h_abs = dop853_initial_step(fk, y, f, cfg.s_max, cfg.max_step, cfg.rtol, cfg.atol, tmp, ynew)
    while True:
        if not (s < cfg.s_max):
            status = LIMIT
            break
        ok, h, h_next, n1, nrej = _accepted_step(fk, tab, cfg, y, f, s, h_abs, K, tmp, ynew)
        rej += nrej
        finite = True
        for c in range(6):
            if not math.isfinite(ynew[c]):
                finite = False
        if not ok or not finite or not (n1 > 0.0):
            status = LOST
            break
        ev, h_end, n1, hit_q = _events(fk, tab, recv, y, f, h, ynew, n1, w)
        # along the chord y -> ynew: extinction, the material level set, drift
        cx, cy, cz = ynew[0] - y[0], ynew[1] - y[1], ynew[2] - y[2]
        chord = math.sqrt(cx * cx + cy * cy + cz * cz)
        if fk.has_ext:
            dr, dg, db_ = optical_depth(fk.ext, fk.lo, fk.ih, (y[0], y[1], y[2]), (ynew[0], ynew[1], ynew[2]))
            tau_r += dr
            tau_g += dg
            tau_b += db_
        a1 = side * (n1 - n_half)
        if a_prev > 0.0 and a1 > 0.0:
            path_length += chord
        elif a_prev > 0.0:
            path_length += chord * a_prev / (a_prev - a1)
        elif a1 > 0.0:
            path_length += chord * a1 / (a1 - a_prev)
        now = a1 > 0.0
        if now != inside:
            crossings += 1
            inside = now
            met = True
        a_prev = a1
        vn = math.sqrt(ynew[3] * ynew[3] + ynew[4] * ynew[4] + ynew[5] * ynew[5])
        dr_ = abs(vn - n1) / n1
        if dr_ > drift:
            drift = dr_
        s += h_end
        steps += 1
        for c in range(6):
            y[c] = ynew[c]
        if ev == 1:
            status = EXITED
            break
        if ev == 2:
            status = RECEIVED
            break
        if (cfg.lost_rel and not (vn > 1e-12 * n1)) or (not cfg.lost_rel and not (vn > 1e-12)):
            status = LOST
            break
        for c in range(6):  # FSAL: the last stage is rhs(ynew)
            f[c] = K[12, c]
        n = n1
        h_abs = h_next
    vn = math.sqrt(y[3] * y[3] + y[4] * y[4] + y[5] * y[5])
    for c in range(3):
        out.end_pos[r, c] = y[c]
        out.end_dir[r, c] = y[3 + c] / vn if vn > 0.0 else np.nan
    out.status[r] = status
    out.hit_tri[r] = hit_q
    out.tau[r, 0] = tau_r
    out.tau[r, 1] = tau_g
    out.tau[r, 2] = tau_b
    out.met[r] = met
    out.crossings[r] = crossings
    out.path_length[r] = path_length
    out.length[r] = s
    out.steps[r] = steps
    out.rejected[r] = rej
    out.drift[r] = drift


@nb.njit(cache=True, parallel=True)
def _trace_kernel(fk, tab, cfg, recv, pos, dirs, out):
    for r in nb.prange(pos.shape[0]):
        _trace_one(r, fk, tab, cfg, recv, pos[r], dirs[r], out)



# --------------------------------------------------------------------- Python API
def trace_rays(volume, pos, dirs, *, tolerances=GrinTolerances(), s_max=None, receivers=None, level=None,
               lost_relative=True):
    """Integrate the ray equation from points in the volume box until each ray leaves it (the core).

    Parameters
    ----------
    volume : GrinVolume
        The field, the box, extinction (kappa per voxel, per world unit: the optical depth is
        integrated) or the closed-form lens (:class:`~refraction_ref.exact.dop853.GrinVolume`).
    pos : (R, 3) array_like
        Start points, inside the box or on its faces.
    dirs : (R, 3) array_like
        Unit start directions; the start state is ``v = n(pos) dirs``.
    tolerances : GrinTolerances
        DOP853's ``rtol``, ``atol`` and the step cap ``max_step`` in voxels of the smallest side
        (:data:`RTOL`, :data:`ATOL`, :data:`MAX_STEP` by default).
    s_max : float, optional
        Path budget in world units (default: ``8 max(shape)`` voxels).
    receivers : tuple, optional
        :func:`~refraction_ref.volumetric.receivers.receiver_tuple`: a path stops on them (status 5).
    level : (float, float), optional
        ``(n_half, side)``, the half-contrast level set
        (:func:`~refraction_ref.volumetric.grid.half_contrast`); default ``(inf, 1)``: none.
    lost_relative : bool
        ``|v| <= 1e-12 n`` is lost (photons); False: ``|v| <= 1e-12`` (viewing rays).

    Returns
    -------
    dict
        ``status`` (R,) int8 (1 exited, 2 limit, 4 lost, 5 received), ``end_pos``, ``end_dir`` (R, 3)
        (where and in which direction the path ended: the exit on the face, the receiver hit, or the last
        state), ``hit_tri`` (R,) (receiver triangle, an index into ``receivers.tris``; -1 none), ``tau``
        (R, 3) optical depth, ``met`` (R,) bool (beyond ``n_half`` somewhere), ``crossings`` (R,),
        ``path_length`` (R,) (length beyond ``n_half``), ``length`` (R,) (parameter s at the end),
        ``steps``, ``rejected`` (R,) solver steps, ``drift`` (R,) ``max ||v| - n| / n``, ``evals`` (R,)
        right-hand-side evaluations (12 per step tried and 12 per root-finding iteration not counted:
        a lower bound).

    References
    ----------
    Sun et al. (2008), §3 eqs. 1-3; Hairer, Norsett, Wanner (1993), §II.4-II.10 (DOP853).
    """
    fk, box = grin_field(volume)
    pos = np.ascontiguousarray(np.asarray(pos, dtype=np.float64).reshape(-1, 3))
    dirs = np.ascontiguousarray(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
    R = len(pos)
    if s_max is None:
        s_max = 8.0 * float(max(np.shape(volume.field)[:3])) * box.hmin
    n_half, side = (np.inf, 1.0) if level is None else level
    settings = GrinSettings(float(tolerances.rtol), float(tolerances.atol), float(tolerances.max_step) * box.hmin,
                            float(s_max), float(n_half), float(side), 1 if lost_relative else 0)
    recv = receiver_tuple() if receivers is None else receivers
    out = GrinPaths(np.zeros(R, np.int8), np.full((R, 3), np.nan), np.full((R, 3), np.nan),
                    np.full(R, -1, np.int32), np.zeros((R, 3)), np.zeros(R, np.bool_), np.zeros(R, np.int32),
                    np.zeros(R), np.zeros(R), np.zeros(R, np.int32), np.zeros(R, np.int32), np.zeros(R))
    if R:
        _trace_kernel(fk, dop853_tableau(), settings, recv, pos, dirs, out)
    res = {"status": out.status, "end_pos": out.end_pos, "end_dir": out.end_dir, "hit_tri": out.hit_tri,
           "tau": out.tau, "met": out.met, "crossings": out.crossings, "path_length": out.path_length,
           "length": out.length, "steps": out.steps, "rejected": out.rejected, "drift": out.drift}
    res["evals"] = 12 * (out.steps.astype(np.int64) + out.rejected)
    return res


def trace_photons(volume, pos, dirs, *, receivers=None, outside_ior=1.0, entry=None, tolerances=GrinTolerances()):
    """Converged photon paths from the method's photon starts: exits, receiver hits, transmittance.

    Parameters
    ----------
    volume : GrinVolume
        The method's packed field (:func:`~refraction_ref.volumetric.gradient.gradient_field`), its box
        and kappa per voxel (the march's).
    pos, dirs : (P, 3) float64
        The ``photons`` stage's start points and unit directions
        (:func:`~refraction_ref.volumetric.photons.generate_photons`).
    receivers : tuple, optional
        :func:`~refraction_ref.volumetric.receivers.receiver_tuple` of the scene's receivers.
    outside_ior : float
        The index outside the objects (the material level set, :func:`~refraction_ref.volumetric.grid.half_contrast`).
    entry : (P, 3) float64, optional
        Where each photon's texel ray entered the volume when it starts on a proxy: its transmittance
        starts with the straight segment skipped (the march's rule, eq. 6).
    tolerances : GrinTolerances
        As :func:`trace_rays`.

    Returns
    -------
    dict
        The keys of :func:`~refraction_ref.volumetric.march.march_photons`' photon dict that a caustic
        deposit and a comparison read: ``exit_pos``, ``exit_dir`` (P, 3; NaN unless exited), ``status``
        (P,) int8 (1 exited, 2 limit, 4 lost, 5 received; the march's codes), ``touched`` (P,) bool,
        ``hit_pos`` (P, 3), ``hit_tri`` (P,) int64, ``hit_receiver`` (P,) int32, ``hit_trans`` (P, 3)
        (transmittance at the receiver or at the exit), plus ``steps``, ``rejected``, ``evals``,
        ``drift`` per photon and ``total_steps``.

    References
    ----------
    Sun et al. (2008), §4.3 (photon starts), §4.4 eqs. 4-6 (the march this converges), §6.2.2 Fig. 9
    (receivers).
    """
    field, bounds, extinction, analytic = volume
    level = half_contrast(field, float(outside_ior)) if analytic is None else (np.inf, 1.0)
    pos = np.ascontiguousarray(pos, dtype=np.float64).reshape(-1, 3)
    dirs = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
    P = len(pos)
    recv = receiver_tuple() if receivers is None else receivers
    res = trace_rays(volume, pos, dirs, tolerances=tolerances, receivers=recv, level=level, lost_relative=True)
    st = res["status"]
    trans = np.exp(-res["tau"])
    if entry is not None and P and extinction is not None:
        box = volume_box(bounds, field.shape)
        pre = np.empty((P, 3))
        skipped_attenuation(np.ascontiguousarray(extinction, dtype=np.float32), box.lo, box.ih,
                             np.ascontiguousarray(entry, dtype=np.float64), pos, pre)
        trans = trans * pre
    ex = st == EXITED
    exit_pos = np.where(ex[:, None], res["end_pos"], np.nan)
    exit_dir = np.where(ex[:, None], res["end_dir"], np.nan)
    hit_pos = np.full((P, 3), np.nan)
    hit_tri = res["hit_tri"].astype(np.int32)
    rc = st == RECEIVED
    hit_pos[rc] = res["end_pos"][rc]
    if P and recv.tris.shape[0]:
        box = volume_box(bounds, field.shape)
        sel = np.flatnonzero(ex).astype(np.int64)
        reach = 1e6 * (1.0 + float(np.abs(box.lo).max() + np.abs(box.hi).max()))
        exit_receivers(sel, exit_pos, exit_dir, recv, reach, hit_pos, hit_tri)
    hit_trans = np.where((ex | rc)[:, None], trans, np.nan)
    tri = hit_tri.astype(np.int64)
    hit_receiver = np.where(tri >= 0, np.searchsorted(recv.start, tri, side="right") - 1, -1).astype(np.int32)
    return {"exit_pos": exit_pos, "exit_dir": exit_dir, "status": st, "touched": res["met"], "hit_pos": hit_pos,
            "hit_tri": tri, "hit_receiver": hit_receiver, "hit_trans": hit_trans, "steps": res["steps"],
            "rejected": res["rejected"], "evals": res["evals"], "drift": res["drift"],
            "total_steps": int(res["steps"].sum(dtype=np.int64)),
            "drift_max": float(res["drift"].max()) if P else 0.0}


def trace_view(volume, origins, dirs, *, outside_ior=1.0, n_range=None, tolerances=GrinTolerances()):
    """Converged viewing rays: each primary ray through the volume box, the viewing pass's per-pixel keys.

    Parameters
    ----------
    volume : GrinVolume
        The method's packed field, its box and kappa per voxel (``transmittance`` along the path).
    origins, dirs : (R, 3) float64
        Primary rays (:meth:`~refraction_ref.camera.Camera.primary_rays`).
    outside_ior : float
    n_range : (float, float), optional
        Minimum and maximum of the index, as the viewing pass takes them (default: the field's).
    tolerances : GrinTolerances
        As :func:`trace_rays`; the path budget is the viewing pass's, ``4 (nx + ny + nz)`` voxels.

    Returns
    -------
    dict
        As :func:`~refraction_ref.volumetric.view.view_volume`: ``exit_pos``, ``exit_dir`` (R, 3; NaN
        where stopped, ``exit_pos`` NaN and ``exit_dir = dirs`` where status 0), ``last_dir`` (R, 3: the
        direction at the box exit for every ray that left it, bent or not; the primary direction for a
        ray that missed the box; NaN where stopped), ``hit``, ``interfaces``, ``path_length``,
        ``status`` (0 missed, 1 exited, 2 limit, 4 lost), ``transmittance`` (R, 3); and ``steps``,
        ``evals``, ``drift`` per ray.

    References
    ----------
    Sun et al. (2008), §4.5 (viewing rays), eqs. 2-3 and 6.
    """
    field, bounds, _, analytic = volume
    org = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
    R = len(org)
    box = volume_box(bounds, field.shape)
    if analytic is not None:
        n_half, side = np.inf, 1.0
    else:
        if n_range is None:
            nmin, nmax = float(field[..., 0].min()), float(field[..., 0].max())
        else:
            nmin, nmax = float(np.float32(n_range[0])), float(np.float32(n_range[1]))
        far = nmax if abs(nmax - outside_ior) >= abs(nmin - outside_ior) else nmin
        side = 1.0 if far >= outside_ior else -1.0
        n_half = 0.5 * (outside_ior + far) if far != outside_ior else np.inf * side
    t_in = np.array([box_entry_one(box.lo, box.hi, *org[r], *d[r]) for r in range(R)]) if R else np.zeros(0)
    inb = np.isfinite(t_in)
    idx = np.flatnonzero(inb)
    start = org[idx] + t_in[idx, None] * d[idx]
    nx, ny, nz = field.shape[:3]
    res = trace_rays(volume, start, d[idx], tolerances=tolerances, s_max=4.0 * (nx + ny + nz) * box.hmin,
                     level=(n_half, side), lost_relative=False)
    status = np.full(R, MISSED, np.int8)
    hit = np.zeros(R, np.bool_)
    inter = np.zeros(R, np.int16)
    path_length = np.zeros(R)
    trans = np.ones((R, 3))
    exit_pos = np.full((R, 3), np.nan)
    exit_dir = d.copy()
    last_dir = d.copy()
    steps = np.zeros(R, np.int32)
    drift = np.zeros(R)
    st = res["status"]
    met = res["met"]
    status[idx] = np.where((st == EXITED) & ~met, MISSED, st)
    hit[idx] = met
    inter[idx] = res["crossings"].astype(np.int16)
    path_length[idx] = res["path_length"]
    trans[idx] = np.exp(-res["tau"])
    steps[idx] = res["steps"]
    drift[idx] = res["drift"]
    out_ok = st == EXITED
    ep = np.where(out_ok[:, None], res["end_pos"], np.nan)
    ed = np.where(out_ok[:, None], res["end_dir"], np.nan)
    last_dir[idx] = ed
    exit_pos[idx] = np.where((out_ok & met)[:, None], ep, np.nan)
    exit_dir[idx] = np.where((out_ok & met)[:, None], ed, np.where(out_ok[:, None], d[idx], np.nan))
    evals = np.zeros(R, np.int64)
    evals[idx] = res["evals"]
    return {"exit_pos": exit_pos, "exit_dir": exit_dir, "last_dir": last_dir, "hit": hit, "interfaces": inter,
            "path_length": path_length, "status": status, "transmittance": trans, "steps": steps, "evals": evals,
            "drift": drift}


def tolerance_sweep(volume, pos, dirs, rtols=(1e-6, 1e-8, 1e-10, 1e-12), atol_ratio=1e-2, max_step=MAX_STEP,
                    **kw):
    """How far the exits move as the tolerance tightens: the convergence table of the reference.

    Parameters
    ----------
    volume, pos, dirs
        As :func:`trace_rays`.
    rtols : sequence of float
        Relative tolerances, loosest first; ``atol = atol_ratio * rtol``.
    atol_ratio : float
    max_step : float
        The step cap in voxels (:class:`GrinTolerances`), the same at every tolerance.
    **kw
        Passed to :func:`trace_rays` (``s_max``, ``receivers``, ...).

    Returns
    -------
    list of dict
        Per tolerance: ``rtol``, ``atol``, ``steps`` (mean accepted steps per ray), ``seconds``, and against
        the next tighter one (None for the tightest) ``dpos_max``, ``dpos_p99`` (world units) and
        ``ddir_max`` (radians) over the rays that exited at both, ``status_changed`` (count).

    References
    ----------
    Hairer, Norsett, Wanner (1993), §II.4 (tolerance proportionality).
    """
    import time

    runs = []
    for rt in rtols:
        t0 = time.perf_counter()
        r = trace_rays(volume, pos, dirs, tolerances=GrinTolerances(rt, atol_ratio * rt, max_step), **kw)
        runs.append((rt, time.perf_counter() - t0, r))
    rows = []
    for i, (rt, sec, r) in enumerate(runs):
        row = {"rtol": rt, "atol": atol_ratio * rt, "steps": float(np.mean(r["steps"])) if len(r["steps"]) else 0.0,
               "seconds": sec, "dpos_max": None, "dpos_p99": None, "ddir_max": None, "status_changed": None}
        if i + 1 < len(runs):
            q = runs[i + 1][2]
            both = (r["status"] == EXITED) & (q["status"] == EXITED)
            dp = np.linalg.norm(r["end_pos"][both] - q["end_pos"][both], axis=1)
            cosang = np.clip(np.sum(r["end_dir"][both] * q["end_dir"][both], axis=1), -1, 1)
            dd = np.arccos(cosang)
            row.update(dpos_max=float(dp.max()) if len(dp) else 0.0,
                       dpos_p99=float(np.percentile(dp, 99)) if len(dp) else 0.0,
                       ddir_max=float(dd.max()) if len(dd) else 0.0,
                       status_changed=int(np.count_nonzero(r["status"] != q["status"])))
        rows.append(row)
    return rows
