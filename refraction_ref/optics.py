"""Geometric optics shared by every method: Snell, total internal reflection,
Fresnel and Beer-Lambert.

The scalar kernels (``refract3``, ``reflect3``, ``fresnel_dielectric``) are
Numba functions that the per-pixel and per-photon kernels of all three
methods call; the array functions (``refract``, ``reflect``, ``fresnel``,
``beer_lambert``) apply the very same kernels to arrays, so there is exactly
one implementation of each law.

Conventions: ``d`` is the unit incident direction, ``n`` a unit surface
normal on either side of the surface (it is flipped internally so that it
faces the incident ray), ``eta = n1 / n2`` the ratio of the index on the
incident side to the index on the transmitted side.

References
----------
.. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
   ed., §8.2 (Snell's law, Fresnel reflectance for dielectrics).
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.8 (absorption
   :math:`I = I_0 e^{-\\alpha l \\eta}`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .vec3 import readonly

__all__ = [
    "refract3",
    "reflect3",
    "fresnel_dielectric",
    "refract",
    "reflect",
    "fresnel",
    "beer_lambert",
]


@nb.njit(cache=True, inline="always")
def refract3(dx, dy, dz, nx, ny, nz, eta):
    """Refract one direction by Snell's law.

    Parameters
    ----------
    dx, dy, dz : float
        Unit incident direction.
    nx, ny, nz : float
        Unit normal, either orientation.
    eta : float
        Ratio n1 / n2 of the incident to the transmitted index.

    Returns
    -------
    tx, ty, tz : float
        Unit transmitted direction; the mirror direction when ``tir``.
    tir : bool
        True when ``sin(theta_t) > 1`` (total internal reflection).

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
       ed., §8.2.3 (specular transmission: Snell's law in vector form).
    .. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §3.6 (Snell's law at each interface).
    """
    c = -(dx * nx + dy * ny + dz * nz)
    if c < 0.0:  # make the normal face the incident ray
        nx, ny, nz, c = -nx, -ny, -nz, -c
    k = 1.0 - eta * eta * (1.0 - c * c)
    if k < 0.0:
        rx = dx + 2.0 * c * nx
        ry = dy + 2.0 * c * ny
        rz = dz + 2.0 * c * nz
        s = 1.0 / math.sqrt(rx * rx + ry * ry + rz * rz)
        return rx * s, ry * s, rz * s, True
    a = eta * c - math.sqrt(k)
    tx = eta * dx + a * nx
    ty = eta * dy + a * ny
    tz = eta * dz + a * nz
    s = 1.0 / math.sqrt(tx * tx + ty * ty + tz * tz)
    return tx * s, ty * s, tz * s, False


@nb.njit(cache=True, inline="always")
def reflect3(dx, dy, dz, nx, ny, nz):
    """Mirror direction of ``d`` about the plane with normal ``n``.

    Parameters
    ----------
    dx, dy, dz : float
        Incident direction (unit length for a unit result).
    nx, ny, nz : float
        Unit surface normal, either orientation (the sign cancels).

    Returns
    -------
    rx, ry, rz : float
        Reflected direction ``d - 2 (d . n) n``.

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
       ed., §8.2.2 (specular reflection).
    """
    c = dx * nx + dy * ny + dz * nz
    return dx - 2.0 * c * nx, dy - 2.0 * c * ny, dz - 2.0 * c * nz


@nb.njit(cache=True, inline="always")
def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance of a dielectric interface.

    Parameters
    ----------
    cos_i : float
        Cosine of the incidence angle (sign ignored).
    eta : float
        n1 / n2.

    Returns
    -------
    float
        Reflectance in [0, 1]; 1 under total internal reflection.

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
       ed., §8.2.1 (Fresnel reflectance of dielectrics).
    """
    cos_i = min(abs(cos_i), 1.0)
    sin2_t = eta * eta * (1.0 - cos_i * cos_i)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin2_t)
    # r = (n1 cos_i - n2 cos_t) / (...) with n1/n2 = eta
    r_par = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    r_perp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (r_par * r_par + r_perp * r_perp)


@nb.njit(cache=True, parallel=True)
def _refract_many(d, n, eta, out, tir):
    for i in nb.prange(d.shape[0]):
        tx, ty, tz, t = refract3(d[i, 0], d[i, 1], d[i, 2], n[i, 0], n[i, 1], n[i, 2], eta[i])
        out[i, 0] = tx
        out[i, 1] = ty
        out[i, 2] = tz
        tir[i] = t


@nb.njit(cache=True, parallel=True)
def _fresnel_many(cos_i, eta, out):
    for i in nb.prange(cos_i.shape[0]):
        out[i] = fresnel_dielectric(cos_i[i], eta[i])


def _as_vectors(a):
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a.reshape(-1, 3)


def refract(d, n, eta):
    """Refract directions by Snell's law (array version of :func:`refract3`).

    Parameters
    ----------
    d : (..., 3) array_like
        Unit incident directions.
    n : (..., 3) array_like
        Unit normals (either orientation).
    eta : float or (...) array_like
        n1 / n2 per direction.

    Returns
    -------
    t : (..., 3) ndarray
        Unit transmitted directions (mirror directions where ``tir``).
    tir : (...) ndarray of bool
        Total internal reflection.

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
       ed., §8.2.3 (specular transmission: Snell's law in vector form).
    """
    d = np.asarray(d, dtype=np.float64)
    shape = d.shape[:-1]
    dd = _as_vectors(d)
    nn = _as_vectors(np.broadcast_to(np.asarray(n, dtype=np.float64), d.shape))
    ee = np.ascontiguousarray(np.broadcast_to(np.asarray(eta, dtype=np.float64), shape)).reshape(-1)
    out = np.empty_like(dd)
    tir = np.empty(dd.shape[0], dtype=np.bool_)
    _refract_many(readonly(dd), readonly(nn), readonly(ee), out, tir)  # one signature (vec3.readonly)
    return out.reshape(d.shape), tir.reshape(shape)


def reflect(d, n):
    """Mirror directions ``d - 2 (d . n) n`` for unit normals ``n``.

    Parameters
    ----------
    d : (..., 3) array_like
        Incident directions.
    n : (..., 3) array_like
        Unit normals, broadcast against ``d``; either orientation.

    Returns
    -------
    (..., 3) float64 ndarray
        Reflected directions.

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
       ed., §8.2.2 (specular reflection).
    """
    d = np.asarray(d, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    return d - 2.0 * np.sum(d * n, axis=-1, keepdims=True) * n


def fresnel(cos_i, eta):
    """Unpolarised Fresnel reflectance (array version of :func:`fresnel_dielectric`).

    Parameters
    ----------
    cos_i : array_like
        Cosine of the incidence angle per direction (sign ignored), any shape.
    eta : float or array_like
        Index ratio n1 / n2 (incident over transmitted side), broadcast to
        ``cos_i.shape``.

    Returns
    -------
    float64 ndarray
        Reflectance in [0, 1] with the shape of ``cos_i``; 1 under total
        internal reflection.

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
       ed., §8.2.1 (Fresnel reflectance of dielectrics).
    """
    cos_i = np.asarray(cos_i, dtype=np.float64)
    c = np.ascontiguousarray(cos_i).reshape(-1)
    e = np.ascontiguousarray(np.broadcast_to(np.asarray(eta, dtype=np.float64), cos_i.shape)).reshape(-1)
    out = np.empty_like(c)
    _fresnel_many(readonly(c), readonly(e), out)  # one signature (vec3.readonly)
    return out.reshape(cos_i.shape)


def beer_lambert(absorption, length, ior=1.0):
    """Transmittance after travelling ``length`` through an absorbing medium.

    Implements :math:`I / I_0 = \\exp(-\\alpha\\, l\\, \\eta)` with the optical
    path length ``l * eta`` of Chaudhari (2008), §3.8.

    Parameters
    ----------
    absorption : (3,) array_like
        Absorption coefficient per colour channel, >= 0.
    length : array_like
        Geometric length inside the medium.
    ior : float
        Index of refraction of the medium (``eta``).

    Returns
    -------
    ndarray
        Transmittance with shape ``length.shape + (3,)``.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §3.8 (absorption
       :math:`I = I_0 e^{-\\alpha l \\eta}`).
    """
    a = np.asarray(absorption, dtype=np.float64)
    length = np.asarray(length, dtype=np.float64)
    return np.exp(-a * (length * ior)[..., None])
