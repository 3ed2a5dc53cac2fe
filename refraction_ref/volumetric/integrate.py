"""One step along a curved light path: eqs. 4-5 (forward differences), or RK4 on eqs. 2-3.

A photon or viewing ray carries a position x and a "velocity" v = n dx/ds
(|v| = n); the ray equation ``d/ds (n dx/ds) = grad n`` (eqs. 1-3) is the
first-order system ``dx/ds = v / n``, ``dv/ds = grad n``. The paper steps it
by forward differences (eqs. 4-5, :func:`euler_step`); ``integrator =
'rk4'`` (beyond the paper) steps the same system by the classic fourth-order
Runge-Kutta scheme (:func:`rk4_step`). :func:`advance` picks one by the
integrator's code (:data:`~refraction_ref.volumetric.knobs.EULER`,
:data:`~refraction_ref.volumetric.knobs.RK4`).

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §3 (eqs. 1-3) and §4.4 (eqs. 4-5).
"""

from __future__ import annotations

import numba as nb

from .grid import sample_field

__all__ = ["euler_step", "rk4_step", "advance"]


@nb.njit(cache=True, inline="always")
def euler_step(p, v, g, ds):
    """Eqs. 4-5: ``x + ds v / n`` and ``v + ds grad n``, one forward-difference step.

    Parameters
    ----------
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
    Sun et al. (2008), §4.4, eqs. 4-5.
    """
    x, y, z = p
    vx, vy, vz = v
    n, gx, gy, gz = g
    s = ds / n
    return x + s * vx, y + s * vy, z + s * vz, vx + ds * gx, vy + ds * gy, vz + ds * gz


@nb.njit(cache=True, inline="always")
def rk4_step(field, lo, ih, p, v, g, ds):
    """The classic fourth-order Runge-Kutta step of eqs. 2-3 (beyond the paper).

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and its gradient, sampled at the inner stages.
    lo, ih : (3,) float64
        Lower corner and inverse voxel size of the volume.
    p, v, g, ds
        As for :func:`euler_step`.

    Returns
    -------
    tuple of 6 floats
        Position and velocity after the step (fourth-order accurate in ``ds``).

    References
    ----------
    Sun et al. (2008), §3, eqs. 2-3.
    """
    x, y, z = p
    vx, vy, vz = v
    n, gx, gy, gz = g
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


@nb.njit(cache=True)  # a call, not inlined: its callers would compile its body at every call site
def advance(field, lo, ih, integrator, p, v, g, ds):
    """One step of eqs. 4-5 (``integrator`` 0, :func:`euler_step`) or of RK4 (1, :func:`rk4_step`).

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and its gradient (RK4 samples it at the inner stages).
    lo, ih : (3,) float64
        Lower corner and inverse voxel size of the volume.
    integrator : int
        :data:`~refraction_ref.volumetric.knobs.EULER` (0) or
        :data:`~refraction_ref.volumetric.knobs.RK4` (1).
    p, v : 3-tuples of float
        Position and velocity ``n dx/ds``.
    g : 4-tuple of float
        ``(n, dn/dx, dn/dy, dn/dz)`` at ``p``, already sampled by the caller.
    ds : float
        Step length, world units.

    Returns
    -------
    tuple of 6 floats
        ``(x, y, z, vx, vy, vz)`` after the step.

    References
    ----------
    Sun et al. (2008), §4.4, eqs. 4-5; §3, eqs. 2-3.
    """
    if integrator == 0:
        return euler_step(p, v, g, ds)
    return rk4_step(field, lo, ih, p, v, g, ds)
