"""DOP853 on the ray equation: the field it reads, its right-hand side, one step, its error, its first step.

The graded-index reference (:mod:`refraction_ref.exact.grin`) integrates
``dx/ds = v / n(x)``, ``dv/ds = grad n(x)`` (Sun et al. 2008, §3, eqs. 2-3) in
the state ``y = (x, v)`` with scipy's DOP853
(``scipy.integrate.solve_ivp(method="DOP853")``): its tableau
(``scipy.integrate._ivp.dop853_coefficients``), its error norm (the 5th- and
3rd-order estimates combined, Hairer et al. II.10), its initial step (Hairer
et al. II.4) and its step controller (safety 0.9, factors 0.2 to 10, exponent
-1/8), the per-component scale ``atol + rtol max(|y|, |y_new|)``, written out
in Numba so that every ray runs on every thread without Python in the loop.
:func:`trace_rays_scipy` integrates the same rays with ``solve_ivp`` itself
(a terminal event at the box) and ``tests/exact/test_grin_reference.py``
checks that both agree.

The field is the one the volumetric method samples (:class:`GrinVolume`):
the packed float32 ``(n, dn/dx, dn/dy, dn/dz)`` of
:func:`~refraction_ref.volumetric.gradient.gradient_field`, read by
:func:`~refraction_ref.volumetric.grid.sample_field`, or for the tests the
closed-form Luneburg lens.

References
----------
.. [1] X. Sun, K. Zhou, E. Stollnitz, J. Shi, B. Guo, "Interactive
   Relighting of Dynamic Refractive Objects", ACM TOG 27(3), Article 35,
   2008: §3 eqs. 1-3 (the ray equation and its first-order form).
.. [2] E. Hairer, S. P. Norsett, G. Wanner, *Solving Ordinary Differential
   Equations I: Nonstiff Problems*, 2nd ed., §II.4 (initial step), §II.5 and
   §II.10 (DOP853 and its error estimate).
.. [3] R. K. Luneburg, *Mathematical Theory of Optics*, 1944 (the lens
   ``n = sqrt(2 - r^2 / R^2)``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..status import EXITED, LIMIT, LOST
from ..volumetric.grid import sample_field, volume_box

__all__ = ["RTOL", "ATOL", "MAX_STEP", "FIELD_SAMPLED", "FIELD_LUNEBURG", "GrinVolume", "GrinTolerances",
           "Dop853Tableau", "dop853_tableau", "GrinField", "grin_field", "sample_index", "ray_rhs", "dop853_step",
           "dop853_error_norm", "dop853_initial_step", "trace_rays_scipy"]

#: the converged tolerance (``benchmarks/results/grin_error_vs_time.md``, "Convergence of the reference"):
#: tightening it to 1e-12 moves no photon exit of the 64^3 Luneburg lens or GRIN blob by more than 3e-6 world
#: units (1e-4 voxel)
RTOL = 1e-10
#: absolute tolerance on positions (world units) and on v (index units)
ATOL = 1e-12
#: longest accepted step, in voxels of the smallest side: the polyline on which the level set,
#: extinction and receivers are evaluated (it never lengthens a step the tolerance asks)
MAX_STEP = 0.25

#: ``kind`` of the field: the method's sampled volume (:func:`~refraction_ref.volumetric.grid.sample_field`)
FIELD_SAMPLED = 0
#: ``kind`` of the field: the closed-form Luneburg lens ``n = sqrt(2 - r^2 / R^2)``, 1 outside (tests)
FIELD_LUNEBURG = 1


class GrinVolume(NamedTuple):
    """The medium the graded-index reference integrates through.

    Attributes
    ----------
    field : (nx, ny, nz, 4) float32
        n and its gradient at voxel centres
        (:func:`~refraction_ref.volumetric.gradient.gradient_field`), read as
        the method reads it (:func:`~refraction_ref.volumetric.grid.sample_field`).
        Only its shape (the voxels of ``max_step`` and ``s_max``) is read when ``analytic`` is given.
    bounds : (2, 3) array_like
        The volume box, world units.
    extinction : (nx, ny, nz, 3) array_like, optional
        kappa per voxel (per world unit): the optical depth is integrated.
    analytic : tuple, optional
        ``("luneburg", centre, R)``: integrate the closed-form lens instead of the volume (tests).
    """

    field: np.ndarray
    bounds: np.ndarray
    extinction: np.ndarray | None = None
    analytic: tuple | None = None


class GrinTolerances(NamedTuple):
    """DOP853's tolerances and the step cap (:data:`RTOL`, :data:`ATOL`, :data:`MAX_STEP` by default).

    Attributes
    ----------
    rtol, atol : float
        DOP853's relative and absolute tolerances (scipy's meaning).
    max_step : float
        Longest step, in voxels of the smallest side.
    """

    rtol: float = RTOL
    atol: float = ATOL
    max_step: float = MAX_STEP


try:  # scipy's own DOP853 tableau, so that the Numba integrator is scipy's method
    from scipy.integrate._ivp import dop853_coefficients as _dc
except ImportError:  # pragma: no cover - scipy moved it
    _dc = None


def dop853_tableau():
    """scipy's DOP853 tableau as :class:`Dop853Tableau` (float64, contiguous).

    Returns
    -------
    Dop853Tableau

    References
    ----------
    Hairer, Norsett, Wanner (1993), §II.5 (Dormand and Prince's 8(5,3) pair).
    """
    if _dc is None:  # pragma: no cover
        raise ImportError("scipy.integrate._ivp.dop853_coefficients is needed for the DOP853 tableau")
    ns = int(_dc.N_STAGES)
    return Dop853Tableau(np.ascontiguousarray(_dc.A[:ns, :ns], dtype=np.float64),
                         np.ascontiguousarray(_dc.B, np.float64), np.ascontiguousarray(_dc.C[:ns], np.float64),
                         np.ascontiguousarray(_dc.E3, np.float64), np.ascontiguousarray(_dc.E5, np.float64))


class Dop853Tableau(NamedTuple):
    """DOP853's tableau (scipy's arrays): 12 stages, B, C, and the two error estimators (13 entries)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    E3: np.ndarray
    E5: np.ndarray


class GrinField(NamedTuple):
    """What the right-hand side reads: the packed field (or a closed form), extinction, the box."""

    kind: int  # FIELD_SAMPLED or FIELD_LUNEBURG
    field: np.ndarray  # (nx, ny, nz, 4) float32: n and grad n (FIELD_SAMPLED)
    prm: np.ndarray  # (4,) float64: centre and radius (FIELD_LUNEBURG)
    ext: np.ndarray  # (nx, ny, nz, 3) float32 kappa; read when has_ext
    has_ext: int
    lo: np.ndarray
    hi: np.ndarray
    ih: np.ndarray


@nb.njit(cache=True)
def sample_index(fk, x, y, z):
    """``(n, dn/dx, dn/dy, dn/dz)`` at a world point: the method's trilinear field, or the closed-form lens.

    References
    ----------
    .. [1] Sun et al. 2008, §3 (the trilinear index field, eq. 3's gradient); docs/oracle.md, "Exact reference on
        volume scenes".
    """
    if fk.kind == 0:
        return sample_field(fk.field, fk.lo, fk.ih, x, y, z)
    p = fk.prm
    dx, dy, dz = x - p[0], y - p[1], z - p[2]
    R2 = p[3] * p[3]
    r2 = (dx * dx + dy * dy + dz * dz) / R2
    if r2 >= 1.0:
        return 1.0, 0.0, 0.0, 0.0
    n = math.sqrt(2.0 - r2)
    c = -1.0 / (R2 * n)  # grad sqrt(2 - r^2/R^2) = -(x - c) / (R^2 n)
    return n, c * dx, c * dy, c * dz


@nb.njit(cache=True)
def ray_rhs(fk, y, out):
    """``out = (v / n, grad n)`` at state ``y = (x, v)``; returns n (Sun et al. 2008, eqs. 2-3).

    References
    ----------
    .. [1] Sun et al. 2008, eqs. 2-3 (the ray equation d/ds (n dx/ds) = grad n as a first-order system).
    """
    n, gx, gy, gz = sample_index(fk, y[0], y[1], y[2])
    out[0] = y[3] / n
    out[1] = y[4] / n
    out[2] = y[5] / n
    out[3] = gx
    out[4] = gy
    out[5] = gz
    return n


@nb.njit(cache=True)
def dop853_step(fk, tab, y, f, h, K, tmp, ynew):
    """One DOP853 step of size h from (y, f = rhs(y)) into ``ynew``; K[12] = rhs(ynew). Returns n(ynew).

    scipy's ``rk_step``: stage s at ``y + h sum_j A[s, j] K[j]``, the solution ``y + h sum_j B[j] K[j]``.

    References
    ----------
    .. [1] E. Hairer, S. P. Norsett, G. Wanner, *Solving Ordinary Differential Equations I*, II.5 (Dormand-Prince
        8(5,3)); scipy.integrate.DOP853.
    """
    A, B = tab.A, tab.B
    for c in range(6):
        K[0, c] = f[c]
    for s in range(1, 12):
        for c in range(6):
            acc = 0.0
            for j in range(s):
                acc += K[j, c] * A[s, j]
            tmp[c] = y[c] + acc * h
        ray_rhs(fk, tmp, K[s])
    for c in range(6):
        acc = 0.0
        for j in range(12):
            acc += K[j, c] * B[j]
        ynew[c] = y[c] + h * acc
    return ray_rhs(fk, ynew, K[12])


@nb.njit(cache=True)
def dop853_error_norm(tab, K, h, y, ynew, rtol, atol):
    """scipy's ``DOP853._estimate_error_norm``: ``|h| e5^2 / sqrt((e5^2 + 0.01 e3^2) 6)`` in scaled RMS.

    References
    ----------
    .. [1] E. Hairer, S. P. Norsett, G. Wanner, *Solving Ordinary Differential Equations I*, II.10;
        scipy.integrate.DOP853's error estimate.
    """
    e5 = 0.0
    e3 = 0.0
    for c in range(6):
        sc = atol + max(abs(y[c]), abs(ynew[c])) * rtol
        a5 = 0.0
        a3 = 0.0
        for j in range(13):
            a5 += K[j, c] * tab.E5[j]
            a3 += K[j, c] * tab.E3[j]
        e5 += (a5 / sc) ** 2
        e3 += (a3 / sc) ** 2
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return abs(h) * e5 / math.sqrt((e5 + 0.01 * e3) * 6.0)


@nb.njit(cache=True)
def dop853_initial_step(fk, y0, f0, bound, max_step, rtol, atol, tmp, f1):
    """scipy's ``select_initial_step`` for an error estimator of order 7 (Hairer et al. II.4).

    References
    ----------
    .. [1] E. Hairer, S. P. Norsett, G. Wanner, *Solving Ordinary Differential Equations I*, II.4
        (the initial step); scipy.integrate's select_initial_step.
    """
    d0 = 0.0
    d1 = 0.0
    for c in range(6):
        sc = atol + abs(y0[c]) * rtol
        d0 += (y0[c] / sc) ** 2
        d1 += (f0[c] / sc) ** 2
    d0 = math.sqrt(d0 / 6.0)
    d1 = math.sqrt(d1 / 6.0)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, bound)
    for c in range(6):
        tmp[c] = y0[c] + h0 * f0[c]
    ray_rhs(fk, tmp, f1)
    d2 = 0.0
    for c in range(6):
        sc = atol + abs(y0[c]) * rtol
        d2 += ((f1[c] - f0[c]) / sc) ** 2
    d2 = math.sqrt(d2 / 6.0) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    return min(100.0 * h0, min(h1, min(bound, max_step)))


def grin_field(volume):
    """The :class:`GrinField` of a volume (its shape sets the voxels, also for a closed-form field) and its box.

    Parameters
    ----------
    volume : GrinVolume

    Returns
    -------
    GrinField, box
        The box: :class:`~refraction_ref.volumetric.grid.VolumeBox`.

    References
    ----------
    .. [1] Sun et al. 2008, §3 (the index volume); docs/oracle.md, "Exact reference on volume scenes".
    """
    field, bounds, extinction, analytic = volume
    shape = np.shape(field)
    box = volume_box(bounds, shape)
    if analytic is None:
        kind, prm = FIELD_SAMPLED, np.zeros(4)
        fld = np.ascontiguousarray(field, dtype=np.float32)
    else:
        name, centre, radius = analytic
        if name != "luneburg":
            raise ValueError(f"analytic field {name!r}; only 'luneburg' is known")
        kind = FIELD_LUNEBURG
        prm = np.array([*np.asarray(centre, np.float64).reshape(3), float(radius)])
        fld = np.zeros((2, 2, 2, 4), np.float32)  # not read
    if extinction is None:
        ext, has = np.zeros((1, 1, 1, 3), np.float32), 0
    else:
        ext = np.ascontiguousarray(extinction, dtype=np.float32)
        has = int(np.any(ext != 0))
    return GrinField(kind, fld, prm, ext, has, box.lo, box.hi, box.ih), box


def trace_rays_scipy(volume, pos, dirs, *, tolerances=GrinTolerances(), s_max=None):
    """The same rays by ``scipy.integrate.solve_ivp(method="DOP853")`` itself, for checking (slow: Python per step).

    A terminal event stops each ray where it leaves the box (the dense output's root, scipy's own). No
    step cap (``tolerances.max_step`` is not read), no receivers, no extinction.

    Parameters
    ----------
    volume, pos, dirs, tolerances, s_max
        As :func:`~refraction_ref.exact.grin.trace_rays`.

    Returns
    -------
    dict
        ``status`` (1 exited, 2 at ``s_max``, 4 solver failure), ``end_pos``, ``end_dir`` (R, 3), ``steps``
        (R,) (scipy's ``nfev``, right-hand-side evaluations), ``length`` (R,).

    References
    ----------
    scipy.integrate.solve_ivp; Hairer, Norsett, Wanner (1993), §II.10.
    """
    from scipy.integrate import solve_ivp

    fk, box = grin_field(volume._replace(extinction=None))
    if s_max is None:
        s_max = 8.0 * float(max(np.shape(volume.field)[:3])) * box.hmin
    pos = np.asarray(pos, np.float64).reshape(-1, 3)
    dirs = np.asarray(dirs, np.float64).reshape(-1, 3)
    R = len(pos)
    out = {"status": np.zeros(R, np.int8), "end_pos": np.full((R, 3), np.nan), "end_dir": np.full((R, 3), np.nan),
           "steps": np.zeros(R, np.int64), "length": np.zeros(R)}
    lo, hi = box.lo, box.hi

    def fun(s, y):
        o = np.empty(6)
        ray_rhs(fk, y, o)
        return o

    def leave(s, y):
        return float(min(np.min(y[:3] - lo), np.min(hi - y[:3])))

    leave.terminal = True
    leave.direction = -1
    for r in range(R):
        n0 = sample_index(fk, *pos[r])[0]
        y0 = np.concatenate([pos[r], n0 * dirs[r]])
        sol = solve_ivp(fun, (0.0, s_max), y0, method="DOP853", rtol=tolerances.rtol,
                        atol=tolerances.atol, events=leave)
        if sol.status == 1 and len(sol.t_events[0]):
            y = sol.y_events[0][0]
            out["status"][r] = EXITED
            out["length"][r] = sol.t_events[0][0]
        else:
            y = sol.y[:, -1]
            out["status"][r] = LIMIT if sol.status == 0 else LOST
            out["length"][r] = sol.t[-1]
        out["end_pos"][r] = y[:3]
        out["end_dir"][r] = y[3:] / np.linalg.norm(y[3:])
        out["steps"][r] = sol.nfev
    return out
