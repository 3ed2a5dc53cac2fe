"""Illumination volumes: the refracted light beam below every water triangle (eq. 4-14).

The beam of water triangle ``F_j = (l, m, n)`` is bounded by the three refracted
rays ``IL_j = {T_l, T_m, T_n}`` leaving its vertices. It carries the flux that
the light pours through the triangle,

.. math:: \\Phi_j = E_\\perp A_w \\cos\\theta_i ,

``A_w cos(theta_i)`` being the triangle's area projected perpendicular to the
incident light (the numerator of eq. 4-18); absorption ``exp(-K d)`` (eq. 4-17)
is applied where the beam meets a plane. No Fresnel loss is applied, as in
eq. 4-18. A triangle seen from below by the light (a steep, folded wave) or
with zero area carries no flux; the water does not shadow itself.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.3 (eq. 4-14), §4.5 (eqs. 4-16 to 4-18).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..optics import refract3
from ..validation import SceneError
from .water import light_weight

__all__ = ["IlluminationVolumes", "illumination_volumes"]


class IlluminationVolumes(NamedTuple):
    """The beams of one light under every water triangle.

    Attributes
    ----------
    origins : (F, 3, 3) float64
        Water-triangle vertices, world space.
    dirs : (F, 3, 3) float64
        Unit refracted directions at those vertices.
    flux : (F,) float64
        ``E_perp * A_w * cos(theta_i)``, >= 0; zero for beams that do not exist.
    mean_dir : (F, 3) float64
        Unit mean of the three directions, the beam axis.
    """

    origins: np.ndarray
    dirs: np.ndarray
    flux: np.ndarray
    mean_dir: np.ndarray


class _Light(NamedTuple):
    """A light as the kernel takes it: directional (``point = False``: ``dir``) or point (``pos``)."""

    point: bool
    dir: np.ndarray  # (3,) unit direction of travel (directional)
    pos: np.ndarray  # (3,) position (point)
    weight: float  # mean radiance (:func:`~.water.light_weight`)


class _WaterArrays(NamedTuple):
    """The water mesh as the kernels take it."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray


class _VolumeArrays(NamedTuple):
    """The kernel's outputs: :class:`IlluminationVolumes`' arrays."""

    origins: np.ndarray
    dirs: np.ndarray
    flux: np.ndarray
    mean_dir: np.ndarray


@nb.njit(cache=True, inline="always")
def _incident(light, px, py, pz):
    """Unit incident direction at a point and the irradiance perpendicular to it
    (:func:`~.water.incident_directions`); ``light`` is read only, so its fields
    may be read inside a ``prange`` loop (numba#7135 drops stores, not loads)."""
    w = light.weight
    if not light.point:
        return light.dir[0], light.dir[1], light.dir[2], w
    dx = px - light.pos[0]
    dy = py - light.pos[1]
    dz = pz - light.pos[2]
    r2 = max(dx * dx + dy * dy + dz * dz, 1e-300)
    s = 1.0 / math.sqrt(r2)
    return dx * s, dy * s, dz * s, w / r2


@nb.njit(cache=True, parallel=True)
def _refract_vertices(mesh, light, eta, T, ok):
    """T_i at every water vertex (eq. 2-8) and whether light enters there."""
    V = mesh.vertices
    N = mesh.normals
    for i in nb.prange(V.shape[0]):
        ix, iy, iz, _ = _incident(light, V[i, 0], V[i, 1], V[i, 2])
        tx, ty, tz, tir = refract3(ix, iy, iz, N[i, 0], N[i, 1], N[i, 2], eta)
        T[i, 0] = tx
        T[i, 1] = ty
        T[i, 2] = tz
        facing = ix * N[i, 0] + iy * N[i, 1] + iz * N[i, 2] < 0.0
        ok[i] = facing and not tir and ty < 0.0


@nb.njit(cache=True, parallel=True)
def _volumes(mesh, light, T, ok, out):
    """Per water triangle: its vertices, their T_i, the flux E_perp A_w cos(theta_i) and the beam axis (eq. 4-14)."""
    V = mesh.vertices
    F = mesh.faces
    O = out.origins
    D = out.dirs
    flux = out.flux
    M = out.mean_dir
    for f in nb.prange(F.shape[0]):
        good = True
        mx = 0.0
        my = 0.0
        mz = 0.0
        cx = 0.0
        cy = 0.0
        cz = 0.0
        for k in range(3):
            v = F[f, k]
            for c in range(3):
                O[f, k, c] = V[v, c]
                D[f, k, c] = T[v, c]
            mx += T[v, 0]
            my += T[v, 1]
            mz += T[v, 2]
            cx += V[v, 0]
            cy += V[v, 1]
            cz += V[v, 2]
            good = good and ok[v]
        e1x = O[f, 1, 0] - O[f, 0, 0]
        e1y = O[f, 1, 1] - O[f, 0, 1]
        e1z = O[f, 1, 2] - O[f, 0, 2]
        e2x = O[f, 2, 0] - O[f, 0, 0]
        e2y = O[f, 2, 1] - O[f, 0, 1]
        e2z = O[f, 2, 2] - O[f, 0, 2]
        nx = e1y * e2z - e1z * e2y  # 2 A_w n
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        ix, iy, iz, e = _incident(light, cx / 3.0, cy / 3.0, cz / 3.0)
        proj = -(nx * ix + ny * iy + nz * iz) * 0.5  # A_w cos(theta_i), signed
        flux[f] = e * proj if (good and proj > 0.0) else 0.0
        ln = math.sqrt(mx * mx + my * my + mz * mz)
        if ln > 0.0:
            M[f, 0] = mx / ln
            M[f, 1] = my / ln
            M[f, 2] = mz / ln
        else:
            M[f, 0] = 0.0
            M[f, 1] = -1.0
            M[f, 2] = 0.0


def illumination_volumes(light, mesh, eta):
    """Build the illumination volume of every water triangle (eq. 4-14).

    Parameters
    ----------
    light : dict
        Directional or point light.
    mesh : WaterMesh
    eta : float
        ``outside_ior / water.ior``.

    Returns
    -------
    IlluminationVolumes

    References
    ----------
    Tipprasert (2006), eq. 2-8, eq. 4-14, eq. 4-18 (its numerator).
    """
    if light["type"] not in ("directional", "point"):
        raise SceneError(f"levelmap: light type {light['type']!r} is not supported; use 'directional' or 'point'")
    point = light["type"] == "point"
    d = np.asarray(light["direction"], dtype=np.float64)
    d = d / np.linalg.norm(d)
    pos = np.asarray(light["position"] if point else [0.0, 0.0, 0.0], dtype=np.float64)
    lt = _Light(point, d, pos, light_weight(light))
    m = _WaterArrays(np.ascontiguousarray(mesh.vertices, np.float64), np.ascontiguousarray(mesh.faces, np.int64),
              np.ascontiguousarray(mesh.normals, np.float64))
    nv, nf = len(m.vertices), len(m.faces)
    T = np.empty((nv, 3))
    ok = np.empty(nv, np.bool_)
    _refract_vertices(m, lt, float(eta), T, ok)
    out = _VolumeArrays(np.empty((nf, 3, 3)), np.empty((nf, 3, 3)), np.empty(nf), np.empty((nf, 3)))
    _volumes(m, lt, T, ok, out)
    return IlluminationVolumes(out.origins, out.dirs, out.flux, out.mean_dir)
