"""Diffuse receivers, once for every method: their triangles, caustic-map frames and hits (Chaudhari 2008, §4.1).

Triangles
    A scene's ``receivers`` (a floor, a pool's walls) take light: caustics
    from the image-space, volumetric and exact methods (Chaudhari 2008,
    §4.1; Sun et al. 2008, §6.2.2) and water caustics (Tipprasert 2006,
    ch. 4). :func:`receiver_soup` places every receiver's mesh
    (``fit``/``size`` then ``transform``, as objects) and merges them into
    one triangle soup (:class:`Receivers`); :func:`receiver_set` adds each
    receiver's caustic-map box (:class:`ReceiverSet`). The level map's own
    reference boxes, planes and position maps
    (:mod:`refraction_ref.levelmap.planes`, :mod:`refraction_ref.levelmap.maps`)
    are not receivers: they are the level-map method's reference planes
    (Tipprasert 2006, eqs. 4-1 to 4-13) laid over this same soup, one box
    per (receiver, light), where the caustic map of the other methods is one
    box per receiver aligned with the first light.
Frames
    Receiver ``r``'s caustic map lies on the face (nearest the light) of the
    **tight** box of its vertices in axes aligned with the first light's
    direction at the receiver: the level map's axes (eq. 4-1,
    :func:`~refraction_ref.caustics.boxes.box_axes`), not the level map's
    box (:func:`~refraction_ref.caustics.boxes.reference_box` with
    ``placement="tight"``; ``caustics.placement`` places only the
    level map's boxes), framed by
    :func:`~refraction_ref.caustics.boxes.frame_of`: ``caustic_frame_r``
    is (origin, u, v, normal) and texel (a, b) holds the irradiance on the
    first surface of the receiver seen from the light through
    ``origin + (b + .5)/Wc u + (a + .5)/Hc v``. A floor lit from straight
    above gets the floor rectangle itself.
Hits
    Where rays meet the receivers (:func:`receiver_hits`): the eye-space
    march in the camera's depth image of the receivers (:func:`eye_buffers`;
    :mod:`~refraction_ref.caustics.eyespace`, Krüger et al. 2006) or Embree
    on their triangles (:mod:`~refraction_ref.caustics.exact_hits`).

References
----------
.. [1] J. Krüger, K. Bürger, R. Westermann, "Interactive Screen-Space
   Accurate Photon Tracing on GPUs", EGSR 2006.
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §4.1.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..meshes import object_mesh
from ..raster import clip_near, rasterize
from ..validation import SceneError
from .boxes import frame_of, reference_box, to_map
from .exact_hits import hit_exact
from .eyespace import march_eyespace

__all__ = ["Receivers", "receiver_soup", "ReceiverSet", "receiver_set", "eye_buffers", "map_position",
           "ReceiverHitMode", "receiver_hits"]


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
    """All receiver triangles of a scene (:class:`Receivers`), for every method.

    Parameters
    ----------
    scene : Scene
        A loaded scene; its ``receivers`` are placed as objects are
        (``fit``/``size``, then ``transform``).
    method : str
        The method that needs receivers, named in the error.

    Returns
    -------
    Receivers
        The triangle soup, owners, unit face normals, albedo and each
        receiver's vertices.

    Raises
    ------
    SceneError
        When the scene has no receivers (naming ``method``, which needs them).

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    .. [2] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
       with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
       University, 2006, §4.2 (the receivers of the level map).
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


class ReceiverSet(NamedTuple):
    """Every receiver triangle, with each receiver's caustic-map box.

    Attributes
    ----------
    tris : (T, 3, 3) float64 world vertices
    owner : (T,) int64 receiver index
    normals : (T, 3) float64 unit face normals
    albedo : (R, 3) float64
    boxes : list of Box, one per receiver
    """

    tris: np.ndarray
    owner: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray
    boxes: list

    def frame(self, r):
        """``caustic_frame_r`` (4, 3): origin, u, v, normal (docs/oracle.md).

        Parameters
        ----------
        r : int
            The receiver.

        Returns
        -------
        (4, 3) float64
        """
        return frame_of(self.boxes[r])


def receiver_set(scene, light, size):
    """Receiver triangles of a scene and their map boxes, aligned with ``light``.

    Parameters
    ----------
    scene : Scene
    light : dict
        The first light: its direction at each receiver's centre orients the box.
    size : int
        Texels per side of each caustic map (``caustics.map_size``).

    Returns
    -------
    ReceiverSet
        The soup of :func:`receiver_soup` with one caustic-map box per receiver.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    soup = receiver_soup(scene, "caustics")
    boxes = []
    for v in soup.vertices:
        centre = (v.min(axis=0) + v.max(axis=0)) / 2.0
        if light["type"] == "directional":
            T0 = np.asarray(light["direction"], dtype=np.float64)
        else:
            T0 = centre - np.asarray(light["position"], dtype=np.float64)
            if not np.linalg.norm(T0) > 0:
                T0 = np.array([0.0, -1.0, 0.0])
        boxes.append(reference_box(v, T0 / np.linalg.norm(T0), int(size), "tight"))
    return ReceiverSet(soup.tris, soup.owner, soup.normals, soup.albedo, boxes)


def map_position(rs, r, points):
    """Continuous (col, row) of world points in receiver ``r``'s caustic map.

    :func:`~refraction_ref.levelmap.planes.to_map`'s col and row, operation for operation
    (``q = p - centre``, ``col = (q.U / w + 0.5) Wc``, ``row = (q.W / d + 0.5) Hc``, the dot
    products in :func:`~refraction_ref.vec3.dot`'s order), in a kernel parallel over the points.

    Parameters
    ----------
    rs : ReceiverSet
    r : int
        The receiver.
    points : (N, 3) array_like
        World points.

    Returns
    -------
    col, row : (N,) float64
        Map positions (texel centres at ``+0.5``).

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    box = rs.boxes[r]
    p = np.asarray(points, dtype=np.float64)
    if p.ndim < 1 or p.shape[-1] != 3:
        q = to_map(box, points)
        return q[..., 0], q[..., 1]
    flat = np.ascontiguousarray(p).reshape(-1, 3)
    Hc, Wc = box.size
    frame = np.array([box.center, box.U, box.W, [box.w, box.d, 0.0]], dtype=np.float64)
    col, row = np.empty(len(flat)), np.empty(len(flat))
    _map_position_kernel(flat, frame, float(Hc), float(Wc), col, row)
    return col.reshape(p.shape[:-1]), row.reshape(p.shape[:-1])


@nb.njit(cache=True, parallel=True)
def _map_position_kernel(p, frame, Hc, Wc, col, row):
    cx, cy, cz = frame[0, 0], frame[0, 1], frame[0, 2]
    ux, uy, uz = frame[1, 0], frame[1, 1], frame[1, 2]
    wx, wy, wz = frame[2, 0], frame[2, 1], frame[2, 2]
    bw, bd = frame[3, 0], frame[3, 1]
    for k0 in nb.prange(p.shape[0]):
        k = np.int64(k0)
        qx = p[k, 0] - cx
        qy = p[k, 1] - cy
        qz = p[k, 2] - cz
        col[k] = ((qx * ux + qy * uy + qz * uz) / bw + 0.5) * Wc
        row[k] = ((qx * wx + qy * wy + qz * wz) / bd + 0.5) * Hc


def eye_buffers(rs, cam):
    """The receivers' depth image from the camera and the triangle seen at each pixel.

    Parameters
    ----------
    rs : ReceiverSet
    cam : Camera
        The eye camera.

    Returns
    -------
    depth : (H, W) float64
        Nearest receiver depth, ``+inf`` where none.
    tri : (H, W) int64
        Index into ``rs.tris``, ``-1`` where none.

    References
    ----------
    Chaudhari 2008, §4.1 (the receivers the eye sees); Krüger et al. 2006 (the depth the march reads).
    """
    tv = cam.world_to_view(rs.tris)
    d = -tv[..., 2]
    cross = d.min(axis=1) < cam.near
    if not cross.any():
        return rasterize(tv, cam, "nearest", clip=False)
    # clip the triangles crossing the near plane, remembering where each piece came from
    parts, src = [], []
    for t in range(len(tv)):
        if not cross[t]:
            parts.append(tv[t:t + 1])
            src.append(np.array([t]))
        else:
            c = clip_near(tv[t:t + 1], cam.near)
            parts.append(c)
            src.append(np.full(len(c), t))
    tv2 = np.concatenate(parts)
    src = np.concatenate(src).astype(np.int64)
    if len(tv2) == 0:  # every receiver behind the camera
        return np.full(cam.shape, np.inf), np.full(cam.shape, -1, np.int64)
    depth, ids = rasterize(tv2, cam, "nearest", clip=False)
    return depth, np.where(ids >= 0, src[np.maximum(ids, 0)], -1)


class ReceiverHitMode(NamedTuple):
    """How rays meet the receivers (the ``receiver_hit`` pass, §4.1).

    Attributes
    ----------
    mode : str
        ``"eyespace"`` (march in the camera's depth image, Krüger et al. 2006) or ``"exact"`` (Embree).
    cam : Camera or None
        The eye camera (eye-space mode).
    eyebuf : (depth, tri) or None
        :func:`eye_buffers` (eye-space mode).
    """

    mode: str
    cam: object = None
    eyebuf: tuple | None = None


def receiver_hits(rs, origins, dirs, mode, cam=None, eyebuf=None, view=None):
    """Where world rays meet the receivers: eye-space march or Embree.

    Parameters
    ----------
    rs : ReceiverSet
    origins, dirs : (N, 3) array_like
        World rays.
    mode : str
        ``"eyespace"`` (march in ``eyebuf``, Krüger et al. 2006) or ``"exact"`` (Embree).
    cam : Camera, optional
        The eye camera (eye-space mode).
    eyebuf : (depth, tri), optional
        :func:`eye_buffers` (eye-space mode).
    view : (origins, dirs) in the camera's view space, optional
        ``cam.world_to_view(origins)`` and ``cam.dir_world_to_view(dirs)`` (eye-space mode), when the
        caller computed them already (with their operations, so the same bits).

    Returns
    -------
    points : (N, 3) float64
        Hit points (NaN where none).
    face : (N,) int64
        Receiver triangle hit, ``-1`` where none.

    References
    ----------
    Chaudhari 2008, §4.1 (photons to their receivers); Krüger et al. 2006 (``march``).
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    if mode == "exact":
        t, face = hit_exact(rs.tris, o, d)
    else:
        ov, dv = (cam.world_to_view(o), cam.dir_world_to_view(d)) if view is None else view
        t, pix = march_eyespace(ov, dv, eyebuf[0], cam)
        face = np.empty(len(o), np.int64)  # the triangle seen at the hit's pixel, -1 none
        _pixel_face_kernel(pix, np.ascontiguousarray(eyebuf[1], dtype=np.int64), face)
    P = np.empty(o.shape)
    face_out = np.empty(len(o), np.int64)
    if len(o):  # P = o + t[:, None] * d; face where t is finite, else -1: on every thread
        _hit_points_kernel(np.ascontiguousarray(o), np.ascontiguousarray(t, dtype=np.float64),
                           np.ascontiguousarray(d), np.ascontiguousarray(face, dtype=np.int64), P, face_out)
    return P, face_out


@nb.njit(cache=True, parallel=True)
def _pixel_face_kernel(pix, tri, face):
    for k0 in nb.prange(pix.shape[0]):
        k = np.int64(k0)
        face[k] = tri[pix[k, 0], pix[k, 1]] if pix[k, 0] >= 0 else -1


@nb.njit(cache=True, parallel=True)
def _hit_points_kernel(o, t, d, face, P, face_out):
    for k0 in nb.prange(o.shape[0]):
        k = np.int64(k0)
        for c in range(3):
            P[k, c] = o[k, c] + t[k] * d[k, c]
        face_out[k] = face[k] if (math.isfinite(t[k]) and face[k] >= 0) else -1
