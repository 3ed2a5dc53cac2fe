"""Embree scenes, built in one place for every method that intersects real triangles.

The exact reference (:mod:`refraction_ref.exact`), the caustics' receiver
hits and shadow rays (:mod:`refraction_ref.caustics.receivers`) and the exact
water reference (:mod:`refraction_ref.levelmap.exact_water`) all ask Embree
(through embreex, float32) for the nearest triangle and then recompute the
hit in float64 on that triangle. Embree's BVH build is the costly part, so
triangle soups are cached by identity for the few scenes a render uses.
"""

from __future__ import annotations

import numpy as np

__all__ = ["embree_scene", "soup_scene"]

_SOUPS = {}


def embree_scene(vertices, faces):
    """An ``embreex`` scene of an indexed triangle mesh (float32 vertices, int32 faces)."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(vertices, dtype=np.float32), np.ascontiguousarray(faces, dtype=np.int32))
    return scene


def soup_scene(tris, cache=True):
    """An ``embreex`` scene of a triangle soup (T, 3, 3): primitive k is ``tris[k]``.

    With ``cache``, the scene is reused while the same array object is passed
    again (the receivers of one render, the objects' shadow test).
    """
    key = (id(tris), tris.shape)
    hit = _SOUPS.get(key) if cache else None
    if hit is not None and hit[0] is tris:
        return hit[1]
    v = np.ascontiguousarray(tris.reshape(-1, 3), dtype=np.float32)
    scene = embree_scene(v, np.arange(len(v), dtype=np.int32).reshape(-1, 3))
    if cache:
        if len(_SOUPS) >= 4:  # a few scenes per render: receivers, objects
            _SOUPS.pop(next(iter(_SOUPS)))
        _SOUPS[key] = (tris, scene)
    return scene
