"""Lights, once for every method: validation, directions at points, light cameras.

A scene light is ``{"type": "directional", "direction": [x, y, z]}`` (the
direction its rays travel; unit irradiance perpendicular to it per unit
``radiance``) or ``{"type": "point", "position": [x, y, z]}`` (unit
intensity per unit ``radiance``). :func:`validate_lights` checks them once
for every method (water scenes add: the light must shine into the water
from above); :func:`light_direction_at` gives the direction of travel and
the distance fall-off at world points (the caustic final pass, the shadow
test); :func:`light_camera` fits a light's photon texture to the objects
(Chaudhari 2008, §4.1: orthographic for a directional light, perspective
for a point light).

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §2.3.2, §4.1.
.. [2] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, 2006, §4.3.
"""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .validation import SceneError, show

__all__ = ["LIGHT_TYPES", "validate_lights", "light_camera", "light_direction_at"]

LIGHT_TYPES = ("directional", "point")
_MARGIN = 1.02  # the window is 2 % wider than the bounding sphere


def validate_lights(data):
    """Check every light of a merged scene; raise :class:`SceneError` naming the key.

    For a scene with ``water``, a directional light must travel downwards
    (negative y) and a point light must sit above the highest crest.

    Parameters
    ----------
    data : dict
        The merged scene dictionary (``lights`` list, optional ``water``
        block with ``height`` and ``waves``).

    Returns
    -------
    dict
        ``data`` itself, unchanged.

    Raises
    ------
    SceneError
        An unknown type, a zero direction, a missing position, a negative or
        non-finite radiance, or a light that cannot reach the water from above.
    """
    from .validation import check_number, check_vector

    w = data.get("water")
    top = None
    if w is not None:  # the water block's own checks run later: its numbers are checked here before use
        waves = w["waves"] if isinstance(w.get("waves"), list) else []
        top = float(check_number(w["height"], "water.height")) + sum(
            abs(float(check_number(x["amplitude"], f"water.waves[{k}].amplitude")))
            for k, x in enumerate(waves) if isinstance(x, dict) and "amplitude" in x)
    if not isinstance(data["lights"], list):
        raise SceneError("scene: 'lights' must be a list of lights")
    for k, lt in enumerate(data["lights"] or []):
        if not isinstance(lt["type"], str) or lt["type"] not in LIGHT_TYPES:
            raise SceneError(f"scene: 'lights[{k}].type' is {show(lt['type'])}; use \"directional\" or \"point\"")
        # every key the light holds is checked whether or not its kind reads it: a junk 'position' on a
        # directional light (or 'direction' on a point light) is a typo the user should hear about
        d = check_vector(lt["direction"], 3, f"lights[{k}].direction")
        if lt["position"] is not None:
            check_vector(lt["position"], 3, f"lights[{k}].position")
        if lt["type"] == "directional":
            if not np.linalg.norm(d) > 0:
                raise SceneError(f"scene: 'lights[{k}].direction' is zero; give the direction the light travels")
            if top is not None and d[1] >= 0:
                raise SceneError(f"scene: 'lights[{k}].direction' is {show(lt['direction'])}: the light comes from "
                                 "below the horizon (or along it) and never enters the water from above; "
                                 "give the direction a negative y component")
        else:
            if lt["position"] is None:
                raise SceneError(f"scene: 'lights[{k}]' is a point light without 'position'; give [x, y, z], e.g. "
                             f"--set 'lights.{k}.position=[0, 3, 0]'")
            pos = check_vector(lt["position"], 3, f"lights[{k}].position")
            if top is not None and pos[1] <= top:
                raise SceneError(f"scene: 'lights[{k}].position' y = {pos[1]} is not above the water "
                                 f"(its crests reach y = {top}); raise the light above the water")
        rad = check_vector(lt["radiance"], 3, f"lights[{k}].radiance")
        if np.any(rad < 0):
            raise SceneError(f"scene: 'lights[{k}].radiance' is {show(lt['radiance'])}; it must be >= 0")
        check_number(float(rad.max()), f"lights[{k}].radiance")
    return data


def _bounding_sphere(vertices):
    v = np.asarray(vertices, dtype=np.float64)
    c = (v.min(axis=0) + v.max(axis=0)) / 2.0
    r = float(np.sqrt(((v - c) ** 2).sum(axis=1).max()))
    return c, max(r, 1e-9)


def _up_for(d):
    """An up hint not parallel to ``d``: world +y unless ``d`` is nearly vertical, then +z."""
    return (0.0, 0.0, 1.0) if abs(d[1]) > 0.9 else (0.0, 1.0, 0.0)


def light_camera(light, vertices, photons):
    """The camera of a light's photon texture, fitted to the objects.

    Parameters
    ----------
    light : dict
        A scene light (``directional`` with ``direction``, or ``point`` with
        ``position``).
    vertices : (V, 3) array_like
        World-space vertices of every refractive object.
    photons : int
        Texels per side of the photon texture.

    Returns
    -------
    Camera
        Orthographic (directional light) or perspective (point light),
        ``photons`` x ``photons`` texels.

    Raises
    ------
    SceneError
        A point light inside the objects' bounding sphere.
    """
    c, r = _bounding_sphere(vertices)
    n = int(photons)
    if light["type"] == "directional":
        d = np.asarray(light["direction"], dtype=np.float64)
        d = d / np.linalg.norm(d)
        eye = c - d * (1.1 * r)
        return Camera(tuple(eye), tuple(c), _up_for(d), 1.0, n, n, 0.05 * r, 2.2 * r,
                      projection="orthographic", ortho_height=2.0 * r * _MARGIN)
    pos = np.asarray(light["position"], dtype=np.float64)
    dist = float(np.linalg.norm(c - pos))
    if dist <= r * 1.05:
        raise SceneError(f"caustics: the point light at {pos.tolist()} lies inside the refractive objects' "
                         f"bounding sphere (centre {np.round(c, 4).tolist()}, radius {r:.4g}); the light's "
                         "photon texture needs it outside. Move the light away from the objects")
    d = (c - pos) / dist
    half = np.arcsin(min(r * _MARGIN / dist, 0.999))
    return Camera(tuple(pos), tuple(c), _up_for(d), float(np.degrees(2.0 * half)), n, n,
                  max(dist - 1.05 * r, 1e-4 * dist), dist + 1.05 * r)


def light_direction_at(light, points):
    """Unit directions the light travels at world points (..., 3), and the distance factor.

    Parameters
    ----------
    light : dict
        A scene light: ``directional`` with ``direction`` or ``point`` with
        ``position``.
    points : (..., 3) array_like
        World-space points.

    Returns
    -------
    L : (..., 3) ndarray
        Direction of travel of the light's rays.
    falloff : (...) ndarray
        1 for a directional light, ``1 / r^2`` for a point light.
    """
    p = np.asarray(points, dtype=np.float64)
    if light["type"] == "directional":
        d = np.asarray(light["direction"], dtype=np.float64)
        d = d / np.linalg.norm(d)
        return np.broadcast_to(d, p.shape), np.ones(p.shape[:-1])
    v = p - np.asarray(light["position"], dtype=np.float64)
    r2 = np.maximum((v * v).sum(axis=-1), 1e-300)
    return v / np.sqrt(r2)[..., None], 1.0 / r2
