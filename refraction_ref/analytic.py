"""Closed-form references for refraction through simple shapes.

Used by the tests of every method (exact tracer and image-space
approximations): the two-interface refraction of rays through a homogeneous
sphere, the icosphere mesh that approximates that sphere, and the paths
through a Luneburg lens (the graded-index reference,
:mod:`refraction_ref.exact.grin`).

References
----------
.. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
   ed., §3.2.2 (ray–sphere intersection) and §8.2 (Snell's law).
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008.
"""

from __future__ import annotations

import numpy as np

from . import optics

__all__ = ["sphere_refraction", "icosphere_mesh", "luneburg_lens"]


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def sphere_refraction(origins, dirs, center, radius, ior, outside_ior=1.0):
    """Refract rays through a homogeneous sphere (two interfaces).

    Each ray is intersected with the sphere, refracted at the entry point
    (index ``outside_ior -> ior``), travels along the straight chord and is
    refracted again at the exit point (``ior -> outside_ior``). Both
    refractions use :func:`refraction_ref.optics.refract`.

    Total internal reflection cannot occur at the exit when ``ior >=
    outside_ior``: the chord and the two radii to its end points form an
    isosceles triangle, so the angle of incidence at the exit equals the
    refraction angle at the entry, ``theta_t``, and Snell's law at the exit
    gives ``sin(theta_out) = (ior / outside_ior) sin(theta_t) =
    sin(theta_in) <= 1``. (When ``ior < outside_ior``, e.g. an air bubble in
    glass, TIR can only happen at the *entry*; such rays are reflected there:
    ``tir`` is True, ``exit_pos = entry_pos``, ``exit_dir`` the mirror
    direction and ``path_length = 0``.)

    Parameters
    ----------
    origins, dirs : (N, 3) array_like of float
        Ray origins (must lie outside the sphere; rays starting inside are
        reported as misses) and unit directions.
    center : (3,) array_like of float
        Sphere centre.
    radius : float
        Sphere radius, > 0.
    ior : float
        Index of refraction of the sphere.
    outside_ior : float, default 1.0
        Index of the surrounding medium.

    Returns
    -------
    dict of ndarray
        ``hit`` (N,) bool; ``entry_pos``, ``exit_pos``, ``exit_dir`` (N, 3)
        and ``path_length`` (N,) (chord length inside the sphere), NaN for
        misses; ``tir`` (N,) bool (entry TIR, only if ``ior < outside_ior``).

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
       ed., §3.2.2 (ray-sphere intersection) and §8.2 (Snell's law).
    """
    o = np.atleast_2d(np.asarray(origins, dtype=np.float64))
    d = np.atleast_2d(np.asarray(dirs, dtype=np.float64))
    c = np.asarray(center, dtype=np.float64).reshape(3)
    if o.shape != d.shape or o.shape[-1] != 3:
        raise ValueError(f"origins and dirs must both be (N, 3), got {o.shape}, {d.shape}")
    if not radius > 0 or not ior > 0 or not outside_ior > 0:
        raise ValueError("radius, ior and outside_ior must be > 0")
    r = float(radius)
    n = len(o)

    oc = o - c
    b = _dot(d, oc)
    cc = _dot(oc, oc) - r * r
    disc = b * b - cc
    hit = (disc >= 0.0) & (cc > 0.0) & (b < 0.0)  # outside and heading towards it
    sq = np.sqrt(np.where(hit, disc, 0.0))
    t1 = -b - sq

    nan3 = np.full((n, 3), np.nan)
    entry = np.where(hit[:, None], o + t1[:, None] * d, np.nan)
    n1 = (entry - c) / r
    t_in, tir = optics.refract(np.where(hit[:, None], d, 0.0),
                               np.where(hit[:, None], n1, 0.0),
                               float(outside_ior) / float(ior))
    tir = tir & hit
    # second root of |entry + s t_in - c|^2 = r^2 (|entry - c| = r): s = -2 t_in.(entry - c)
    chord = np.where(hit & ~tir, -2.0 * _dot(t_in, entry - c), np.nan)
    chord = np.where(hit & tir, 0.0, chord)
    chord = np.maximum(chord, 0.0)  # grazing rays: round-off may give -0
    exit_pos = np.where(hit[:, None], entry + chord[:, None] * t_in, np.nan)
    n2 = (exit_pos - c) / r
    t_out, tir2 = optics.refract(np.where(hit[:, None], t_in, 0.0),
                                 np.where(hit[:, None], n2, 0.0),
                                 float(ior) / float(outside_ior))
    exit_dir = np.where(tir[:, None], t_in, t_out)
    exit_dir = np.where(hit[:, None], exit_dir, nan3)
    exit_pos = np.where(tir[:, None], entry, exit_pos)
    return {
        "hit": hit,
        "entry_pos": entry,
        "exit_pos": exit_pos,
        "exit_dir": exit_dir,
        "path_length": np.where(hit, chord, np.nan),
        "tir": tir,
    }


def icosphere_mesh(subdivisions=5, radius=0.5):
    """Icosphere triangle mesh centred at the origin.

    Parameters
    ----------
    subdivisions : int, default 5
        Subdivision level (20 * 4**subdivisions faces; 20,480 for 5).
    radius : float, default 0.5
        Radius of the circumscribed sphere (unit diameter by default); all
        vertices lie on it, the faces lie slightly inside.

    Returns
    -------
    vertices : (V, 3) ndarray of float64
    faces : (F, 3) ndarray of int64
        Outward (counter-clockwise) winding.

    References
    ----------
    .. [1] trimesh, ``trimesh.creation.icosphere`` (subdivided icosahedron,
       vertices projected onto the sphere).
    """
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=float(radius))
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def luneburg_lens(origins, dirs, center, radius):
    """Closed-form paths through a Luneburg lens ``n = sqrt(2 - r^2 / R^2)`` (index 1 outside).

    With ``v = n dx/ds`` and the parameter ``tau`` (``dx/dtau = v``), the ray
    equation ``d/ds (n dx/ds) = grad n`` becomes ``d^2 x / dtau^2 = grad(n^2
    / 2) = -(x - c) / R^2``: a harmonic oscillator. A ray that meets the lens
    at ``P`` (where ``n = 1``) along the unit ``d`` follows ``x - c = (P - c)
    cos(tau / R) + R d sin(tau / R)``, which meets the sphere again at
    ``tau = pi R / 2``: every ray leaves at ``c + R d``, the point of the lens
    facing its direction, along ``(c - P) / R`` (parallel rays focus on the
    far side; Luneburg 1944).

    Parameters
    ----------
    origins, dirs : (N, 3) array_like of float
        Ray origins outside the lens and unit directions.
    center : (3,) array_like of float
        Lens centre.
    radius : float
        Lens radius, > 0.

    Returns
    -------
    dict of ndarray
        ``hit`` (N,) bool (the ray meets the lens); ``entry_pos``, ``exit_pos``
        and ``exit_dir`` (N, 3), NaN for misses.

    References
    ----------
    .. [1] R. K. Luneburg, *Mathematical Theory of Optics*, Brown University,
       1944, §28 (the lens focusing a parallel beam on its surface).
    .. [2] M. Born, E. Wolf, *Principles of Optics*, 7th ed., §3.2.1 (the ray
       equation) and §4.2 (the Maxwell fish-eye and Luneburg lenses).
    """
    o = np.atleast_2d(np.asarray(origins, dtype=np.float64))
    d = np.atleast_2d(np.asarray(dirs, dtype=np.float64))
    c = np.asarray(center, dtype=np.float64).reshape(3)
    if o.shape != d.shape or o.shape[-1] != 3:
        raise ValueError(f"origins and dirs must both be (N, 3), got {o.shape}, {d.shape}")
    if not radius > 0:
        raise ValueError("radius must be > 0")
    r = float(radius)
    oc = o - c
    b = _dot(d, oc)
    cc = _dot(oc, oc) - r * r
    disc = b * b - cc
    hit = (disc >= 0.0) & (cc >= 0.0) & (b < 0.0)
    t1 = -b - np.sqrt(np.where(hit, disc, 0.0))
    entry = np.where(hit[:, None], o + t1[:, None] * d, np.nan)
    exit_pos = np.where(hit[:, None], c + r * d, np.nan)
    exit_dir = np.where(hit[:, None], (c - entry) / r, np.nan)
    return {"hit": hit, "entry_pos": entry, "exit_pos": exit_pos, "exit_dir": exit_dir}
