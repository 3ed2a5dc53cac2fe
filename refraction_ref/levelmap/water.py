"""The water surface: a height field of summed sine waves, meshed, with analytic
normals, and the light refracted at every water vertex (eq. 2-8).

Height ``h(x, z) = height + sum_k a_k sin(2 pi / lambda_k (d_k . (x, z)) + phi_k)``
with each direction ``d_k`` normalised; a flat surface is zero waves. The
surface is centred on the origin in x and z, ``size = [sx, sz]``, meshed as
``resolution x resolution`` quads split into two triangles each.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §2.6 (Snell's law, eqs. 2-7 and 2-8), §4.3.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..validation import SceneError

__all__ = ["WaterMesh", "wave_height", "wave_gradient", "surface_normals", "water_mesh", "incident_directions",
           "light_weight"]


class WaterMesh(NamedTuple):
    """A triangulated water surface.

    Attributes
    ----------
    vertices : (V, 3) float64, world space
    faces : (F, 3) int64, counter-clockwise seen from above (face normals +y)
    normals : (V, 3) float64, unit analytic normals of the height field
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray


def _waves(water):
    out = []
    for w in water.get("waves") or []:
        d = np.asarray(w["direction"], dtype=np.float64)
        d = d / np.linalg.norm(d)
        out.append((float(w["amplitude"]), 2.0 * np.pi / float(w["wavelength"]), d, float(w["phase"])))
    return out


def wave_height(water, x, z):
    """Surface height ``h(x, z)`` (world y) of the water block.

    Parameters
    ----------
    water : dict
        The resolved ``water`` block (``height`` and ``waves``: amplitude,
        wavelength, direction, phase).
    x, z : array_like
        World coordinates, broadcast together.

    Returns
    -------
    ndarray of float64
        Height ``h(x, z)``, world units, of the broadcast shape.

    References
    ----------
    Tipprasert (2006), §4.3 (the water surface whose triangles cast the
    illumination volumes).
    """
    x = np.asarray(x, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    h = np.full(np.broadcast(x, z).shape, float(water["height"]))
    for a, k, d, ph in _waves(water):
        h = h + a * np.sin(k * (d[0] * x + d[1] * z) + ph)
    return h


def wave_gradient(water, x, z):
    """Analytic partial derivatives ``(dh/dx, dh/dz)`` of the height field.

    Parameters
    ----------
    water : dict
        The resolved ``water`` block.
    x, z : array_like
        World coordinates, broadcast together.

    Returns
    -------
    hx, hz : ndarray of float64
        ``dh/dx`` and ``dh/dz`` of the broadcast shape.

    References
    ----------
    Tipprasert (2006), §4.3.
    """
    x = np.asarray(x, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    shape = np.broadcast(x, z).shape
    hx = np.zeros(shape)
    hz = np.zeros(shape)
    for a, k, d, ph in _waves(water):
        c = a * k * np.cos(k * (d[0] * x + d[1] * z) + ph)
        hx = hx + c * d[0]
        hz = hz + c * d[1]
    return hx, hz


def surface_normals(water, x, z):
    """Unit upward normals ``(-h_x, 1, -h_z) / |.|`` of the height field.

    Parameters
    ----------
    water, x, z : dict, array_like, array_like
        As for :func:`wave_gradient`, whose derivatives give the normals.

    Returns
    -------
    (..., 3) float64
        Unit normals, ``y`` up.

    References
    ----------
    Tipprasert (2006), §2.6 (normals for Snell's law) and §4.3.
    """
    hx, hz = wave_gradient(water, x, z)
    n = np.stack([-hx, np.ones_like(hx), -hz], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def water_mesh(water):
    """Mesh the water block: ``resolution x resolution`` quads, two triangles each.

    Parameters
    ----------
    water : dict
        The resolved ``water`` block (``resolution``, ``size``, ``height``,
        ``waves``).

    Returns
    -------
    WaterMesh
        ``(resolution + 1)**2`` vertices displaced by the waves, their
        analytic normals, and ``2 resolution**2`` faces.

    References
    ----------
    Tipprasert (2006), §4.3 (water triangles and their illumination volumes).
    """
    n = int(water["resolution"])
    sx, sz = (float(s) for s in water["size"])
    xs = np.linspace(-sx / 2.0, sx / 2.0, n + 1)
    zs = np.linspace(-sz / 2.0, sz / 2.0, n + 1)
    Z, X = np.meshgrid(zs, xs, indexing="ij")  # vertex (i, j): z = zs[i], x = xs[j]
    Y = wave_height(water, X, Z)
    v = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    nrm = surface_normals(water, X, Z).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v00 = (i * (n + 1) + j).ravel()
    v01 = v00 + 1
    v10 = v00 + (n + 1)
    v11 = v10 + 1
    f = np.concatenate([np.stack([v00, v10, v01], axis=1), np.stack([v10, v11, v01], axis=1)])
    return WaterMesh(v, f.astype(np.int64), nrm)


def light_weight(light):
    """Scalar strength of a light: the mean of its RGB ``radiance``.

    A directional light of weight 1 delivers unit irradiance measured
    perpendicular to its direction; a point light of weight ``I`` delivers
    ``I / r**2`` at distance ``r``.

    Parameters
    ----------
    light : dict
        A scene light (its ``radiance``, RGB).

    Returns
    -------
    float
        Mean of the three channels.

    References
    ----------
    Tipprasert (2006), §4.5 (incident intensity ``I_i`` of eq. 4-18).
    """
    return float(np.mean(np.asarray(light["radiance"], dtype=np.float64)))


def incident_directions(light, points):
    """Unit incident light directions at ``points`` (N, 3) and the irradiance
    perpendicular to them (N,), for a directional or a point light.

    Parameters
    ----------
    light : dict
        A scene light, ``'directional'`` (``direction``) or ``'point'``
        (``position``), with its ``radiance``.
    points : (N, 3) array_like
        World points (the water vertices).

    Returns
    -------
    dirs : (N, 3) float64
        Unit directions from the light towards the points.
    irradiance : (N,) float64
        :func:`light_weight`, divided by the squared distance for a point light.

    Raises
    ------
    SceneError
        For another light type.

    References
    ----------
    Tipprasert (2006), §4.3 and §4.5 (``I_i`` and ``theta_i`` of eq. 4-18).
    """
    points = np.asarray(points, dtype=np.float64)
    w = light_weight(light)
    if light["type"] == "directional":
        d = np.asarray(light["direction"], dtype=np.float64)
        d = d / np.linalg.norm(d)
        return np.broadcast_to(d, points.shape).copy(), np.full(len(points), w)
    if light["type"] == "point":
        p = np.asarray(light["position"], dtype=np.float64)
        d = points - p
        r2 = np.einsum("ij,ij->i", d, d)
        r2 = np.maximum(r2, 1e-300)
        return d / np.sqrt(r2)[:, None], w / r2
    raise SceneError(f"levelmap: light type {light['type']!r} is not supported; use 'directional' or 'point'")
