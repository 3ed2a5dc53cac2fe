"""The final pass: receivers lit directly (with a shadow test) and by the caustics (Chaudhari 2008, §4.1).

A receiver point ``p`` with face normal ``n`` (turned towards the ray that
sees it) and albedo ``rho`` has the colour

.. math:: c = \\rho \\Big(\\sum_l L_l \\big(\\max(0, -n \\cdot \\omega_l)\\, f_l(p)\\, V_l(p)
              + E_{c,l}(p)\\big)\\Big)

with ``L_l`` the light's radiance (RGB), ``omega_l`` the direction its
rays travel, ``f_l = 1`` (directional) or ``1 / r^2`` (point), ``V_l`` the
visibility of the light past the refractive objects (the shadow test) and
``E_c`` the caustic irradiance looked up (bilinearly) in the receiver's
caustic map (``caustic_rgb_r``, which already holds ``L_l``). There is no
ambient term: light that passed through an object reaches the receiver
only as caustics, so at IOR 1 the caustics exactly replace the shadow.

Shadow tests: the image-space method reads the light's min-depth image
(the first pass of §3.3 in the light's view doubles as a shadow map); the
exact reference casts a ray to the light through the real triangles.

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §4.1.
.. [2] L. Williams, "Casting Curved Shadows on Curved Surfaces", SIGGRAPH
   1978 (shadow maps).
"""

from __future__ import annotations

import numpy as np

from ..embree import run_chunks, soup_scene
from ..lights import light_direction_at
from .receivers import map_position, occluded

__all__ = ["sample_bilinear", "shade_points", "shadow_map_visibility", "exact_visibility"]


def sample_bilinear(E, col, row):
    """Bilinear look-up of a map (Hc, Wc, C) at continuous texel positions, clamped at the border."""
    Hc, Wc = E.shape[:2]
    x = np.clip(np.asarray(col, dtype=np.float64) - 0.5, 0.0, Wc - 1.0)
    y = np.clip(np.asarray(row, dtype=np.float64) - 0.5, 0.0, Hc - 1.0)
    x = np.nan_to_num(x)
    y = np.nan_to_num(y)
    j0 = np.minimum(np.floor(x).astype(np.int64), Wc - 1)
    i0 = np.minimum(np.floor(y).astype(np.int64), Hc - 1)
    j1 = np.minimum(j0 + 1, Wc - 1)
    i1 = np.minimum(i0 + 1, Hc - 1)
    fx = (x - j0)[:, None]
    fy = (y - i0)[:, None]
    return ((1 - fy) * ((1 - fx) * E[i0, j0] + fx * E[i0, j1])
            + fy * ((1 - fx) * E[i1, j0] + fx * E[i1, j1]))


def shadow_map_visibility(lcam, zmin, points, bias):
    """Visibility of a light at world points from its min-depth image (1 lit, 0 shadowed).

    Points outside the light's window are lit (the window covers the objects).
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return np.ones(0)
    col, row, d = lcam.to_screen(lcam.world_to_view(p))
    H, W = zmin.shape
    inside = np.isfinite(col) & np.isfinite(row) & (col >= 0) & (col < W) & (row >= 0) & (row < H) & (d > 0)
    i = np.where(inside, np.floor(np.nan_to_num(row)), 0).astype(np.int64).clip(0, H - 1)
    j = np.where(inside, np.floor(np.nan_to_num(col)), 0).astype(np.int64).clip(0, W - 1)
    z = zmin[i, j]
    shadow = inside & np.isfinite(z) & (d > z + bias)
    return (~shadow).astype(np.float64)


def exact_visibility(obj_tris, light, points, normals, chunk=1 << 15):
    """Visibility of a light at world points past the refractive triangles (Embree shadow rays).

    The points are tested in fixed chunks of ``chunk`` on ``numba.get_num_threads()``
    threads (:func:`refraction_ref.embree.run_chunks`); every ray is tested on its own,
    so the result does not depend on the chunks or the threads.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0 or len(obj_tris) == 0:
        return np.ones(len(p))
    L, _ = light_direction_at(light, p)
    to_light = -np.asarray(L)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    side = np.where(np.einsum("ij,ij->i", n, to_light) >= 0, 1.0, -1.0)[:, None]
    scale = max(float(np.abs(obj_tris).max()), 1.0)
    o = p + 1e-6 * scale * (to_light + side * n)
    tmax = None
    if light["type"] == "point":
        tmax = np.linalg.norm(np.asarray(light["position"], dtype=np.float64) - o, axis=1)
    soup_scene(obj_tris)  # built (and cached) once, before the threads query it
    hit = np.empty(len(p), dtype=bool)

    def one(a, b):
        hit[a:b] = occluded(obj_tris, o[a:b], to_light[a:b], None if tmax is None else tmax[a:b])

    run_chunks(one, len(p), chunk)
    return (~hit).astype(np.float64)


def shade_points(rs, lights, maps_rgb, points, faces, ray_dirs, visibility):
    """Colour of receiver points (see the module docstring).

    Parameters
    ----------
    rs : ReceiverSet
    lights : list of dict
    maps_rgb : list of (Hc, Wc, 3) arrays
        Caustic irradiance per receiver, radiance included.
    points : (M, 3) float64
        World points on the receivers.
    faces : (M,) int64
        Receiver triangle of each point.
    ray_dirs : (M, 3) float64
        Direction of the ray that sees each point (the normal is turned to face it).
    visibility : callable
        ``visibility(l, points, normals) -> (M,)`` in [0, 1] for light ``l``.

    Returns
    -------
    (M, 3) float64
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    M = len(P)
    out = np.zeros((M, 3))
    if M == 0:
        return out
    faces = np.asarray(faces, dtype=np.int64)
    n = rs.normals[faces].copy()
    flip = np.einsum("ij,ij->i", n, np.asarray(ray_dirs, dtype=np.float64).reshape(-1, 3)) > 0
    n[flip] = -n[flip]
    owner = rs.owner[faces]
    light_sum = np.zeros((M, 3))
    for l, lt in enumerate(lights):
        L, fall = light_direction_at(lt, P)
        cos = np.maximum(0.0, -np.einsum("ij,ij->i", n, L))
        lit = cos > 0
        v = np.zeros(M)
        if lit.any():
            v[lit] = visibility(l, P[lit], n[lit])
        light_sum += np.asarray(lt["radiance"], dtype=np.float64)[None, :] * (cos * fall * v)[:, None]
    for r in range(len(rs.boxes)):
        sel = owner == r
        if sel.any():
            col, row = map_position(rs, r, P[sel])
            light_sum[sel] += sample_bilinear(maps_rgb[r], col, row)
    return rs.albedo[owner] * light_sum
