"""Diffuse receivers, once for every method: their triangles, owners, normals and albedo.

A scene's ``receivers`` (a floor, a pool's walls) take light: caustics from
the image-space and exact methods (Chaudhari 2008, §4.1) and water caustics
(Tipprasert 2006, ch. 4). :func:`receiver_soup` places every receiver's
mesh (``fit``/``size`` then ``transform``, as objects) and merges them into
one triangle soup; each method lays its own caustic-map boxes over it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .meshes import object_mesh
from .validation import SceneError

__all__ = ["Receivers", "receiver_soup"]


class Receivers(NamedTuple):
    """Every receiver triangle of a scene in one soup.

    Attributes
    ----------
    tris : (T, 3, 3) float64 world vertices
    owner : (T,) int64 receiver index
    normals : (T, 3) float64 unit face normals (zero for zero-area faces)
    albedo : (R, 3) float64
    vertices : list of (V_r, 3) per receiver (for the bounding boxes)
    """

    tris: np.ndarray
    owner: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray
    vertices: list


def receiver_soup(scene, method="scene"):
    """All receiver triangles of a scene (:class:`Receivers`).

    Raises
    ------
    SceneError
        When the scene has no receivers (naming ``method``, which needs them).
    """
    tris, owner, alb, verts = [], [], [], []
    for k, rc in enumerate(scene.data["receivers"] or []):
        try:
            v, f = object_mesh(rc, scene.base_dir)
        except SceneError as e:
            raise SceneError(f"receivers[{k}].mesh: {e}") from None
        tris.append(v[f])
        owner.append(np.full(len(f), k, np.int64))
        alb.append(np.asarray(rc["albedo"], dtype=np.float64))
        verts.append(v)
    if not tris:
        raise SceneError(f"{method}: the scene has no receivers; add at least one entry to 'receivers' "
                         "(e.g. a pool floor: {\"mesh\": \"plane\", \"size\": [4, 4]})")
    t = np.concatenate(tris)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)
    return Receivers(t, np.concatenate(owner), n, np.stack(alb), verts)
