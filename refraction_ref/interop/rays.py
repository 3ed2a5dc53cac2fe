"""Rays through Mitsuba 3's intersector, refracted here: the parts the cross-checks share.

Mitsuba gives the hits (``scene.ray_intersect``, float32) and the shading
normals (``si.sh_frame.n``); Snell's law and total internal reflection are
applied here in float64 with the exact references' conventions (the shading
normal flipped to the geometric side, the geometric normal where the shading
normal sends the ray to the wrong side, :func:`cross_interface`). The paths
(:mod:`.paths`), the photons (:mod:`.caustics`) and the water
(:mod:`.water`) all go through these functions.

References
----------
.. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org.
.. [2] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
   ed., §8.2 (Snell's law, total internal reflection).
"""

from __future__ import annotations

import numpy as np

from ..meshes import bounds
from . import mitsuba as M

__all__ = ["points", "mitsuba_ray", "refract", "cross_interface", "merged_mesh", "ply_scene", "receiver_soup",
           "spawn_offset", "sensor_dict", "pixel_centre_rays", "map_coords"]


def points(v):
    """Mitsuba's (3, N) vector or point array as (N, 3) float64.

    Parameters
    ----------
    v : mitsuba.Point3f, mitsuba.Vector3f or mitsuba.Normal3f
        A vectorised Mitsuba 3-vector (or anything ``np.array`` reads as 3 x N).

    Returns
    -------
    (N, 3) float64 ndarray
    """
    return np.array(v, dtype=np.float64).reshape(3, -1).T


def mitsuba_ray(mi, origins, dirs):
    """A vectorised ``mi.Ray3f`` of (N, 3) origins and directions (rounded to float32).

    Parameters
    ----------
    mi : module
        The ``mitsuba`` module, a vectorised variant set.
    origins, dirs : (N, 3) array_like

    Returns
    -------
    mitsuba.Ray3f
    """
    o32 = np.asarray(origins, np.float32).T
    d32 = np.asarray(dirs, np.float32).T
    return mi.Ray3f(mi.Point3f(o32[0], o32[1], o32[2]), mi.Vector3f(d32[0], d32[1], d32[2]))


def refract(d, n, eta):
    """Snell / TIR of unit directions ``d`` at normals ``n`` (any side), relative index ``eta``, float64.

    Parameters
    ----------
    d : (N, 3) float64
        Unit directions of the incoming rays.
    n : (N, 3) float64
        Unit normals, on either side.
    eta : (N,) float64
        Relative index ``n1 / n2``.

    Returns
    -------
    out : (N, 3) float64
        The refracted direction, the mirror direction where ``tir``.
    tir : (N,) bool
        Total internal reflection.

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd ed., §8.2.
    """
    s = np.where(np.sum(d * n, axis=1) < 0, 1.0, -1.0)[:, None]
    nf = n * s  # facing the incoming ray
    ci = -np.sum(d * nf, axis=1)
    k = 1.0 - eta * eta * (1.0 - ci * ci)
    tir = k < 0
    t = eta[:, None] * d + (eta * ci - np.sqrt(np.maximum(k, 0.0)))[:, None] * nf
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    r = d + (2 * ci)[:, None] * nf
    return np.where(tir[:, None], r, t), tir


def cross_interface(d, sh, ng, eta):
    """One interface crossed with Mitsuba's shading normal ``sh``, as the exact tracer crosses it.

    Where the shading normal sends the refracted (or reflected) ray to the wrong
    side of the geometric normal ``ng``, the geometric normal is used instead;
    a non-finite result keeps the incoming direction and is reported ``lost``.

    Parameters
    ----------
    d : (N, 3) float64
        Unit directions of the incoming rays.
    sh, ng : (N, 3) float64
        Mitsuba's shading and geometric normals at the hits.
    eta : (N,) float64
        Relative index ``n1 / n2``.

    Returns
    -------
    out : (N, 3) float64
        The new directions.
    tir, lost : (N,) bool
        Total internal reflection; a non-finite result.

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd ed., §8.2.
    """
    sh = np.where((np.sum(sh * ng, axis=1) < 0)[:, None], -sh, sh)
    out, tir = refract(d, sh, eta)
    sn = np.sign(np.sum(out * ng, axis=1))
    sg = np.sign(np.sum(d * ng, axis=1))
    wrong = np.where(tir, sn == sg, sn != sg)
    if wrong.any():
        o2, t2 = refract(d[wrong], ng[wrong], eta[wrong])
        out[wrong], tir[wrong] = o2, t2
    lost = ~np.all(np.isfinite(out), axis=1)
    out[lost] = d[lost]
    return out, tir, lost


def merged_mesh(meshes):
    """Meshes as one: (vertices, faces, vertex normals or None, owner of each face).

    Parameters
    ----------
    meshes : list of dict
        ``vertices``, ``faces`` and ``normals`` (None: face normals) each
        (:func:`~refraction_ref.interop.mitsuba.object_meshes`).

    Returns
    -------
    vertices : (V, 3) ndarray
    faces : (F, 3) ndarray
    normals : (V, 3) ndarray or None
        None when any mesh has face normals.
    owner : (F,) int64
        The index of the mesh each face comes from.
    """
    vs, fs, ns, fo = [], [], [], []
    off = 0
    face_normals = any(m["normals"] is None for m in meshes)
    for k, m in enumerate(meshes):
        vs.append(m["vertices"])
        fs.append(m["faces"] + off)
        ns.append(m["normals"] if m["normals"] is not None else np.zeros_like(m["vertices"]))
        fo.append(np.full(len(m["faces"]), k, np.int64))
        off += len(m["vertices"])
    return (np.concatenate(vs), np.concatenate(fs), None if face_normals else np.concatenate(ns),
            np.concatenate(fo))


def ply_scene(mi, path, v, f, nrm):
    """A Mitsuba scene of one PLY written to ``path`` (``nrm`` per vertex, or None for face normals).

    Parameters
    ----------
    mi : module
        The ``mitsuba`` module, its variant set.
    path : str
        The PLY file to write.
    v, f : ndarray
        Vertices (V, 3) and faces (F, 3).
    nrm : (V, 3) ndarray or None
        Vertex normals; None for face normals.

    Returns
    -------
    mitsuba.Scene
    """
    M.write_ply(path, v, f, nrm)
    return mi.load_dict({"type": "scene", "all": {"type": "ply", "filename": path, "face_normals": nrm is None}})


def receiver_soup(v, f):
    """A receiver as a triangle soup with its face normals at every corner (flat shading in Mitsuba).

    Parameters
    ----------
    v : (V, 3) array_like
    f : (F, 3) array_like

    Returns
    -------
    dict
        ``vertices`` (3F, 3), ``faces`` (F, 3), ``normals`` (3F, 3).
    """
    tri = np.asarray(v, dtype=np.float64)[np.asarray(f)]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return {"vertices": tri.reshape(-1, 3), "faces": np.arange(3 * len(tri)).reshape(-1, 3),
            "normals": np.repeat(nrm, 3, axis=0)}


def spawn_offset(vertices):
    """How far a ray leaves a surface along its new direction: ``1e-5`` of the scene's size.

    The exact tracer's offset: ``1e-5`` times the larger of the vertices' bounding-box
    diagonal and their largest coordinate.

    Parameters
    ----------
    vertices : (V, 3) ndarray
        Every vertex the rays may meet.

    Returns
    -------
    offset : float
        World units.
    diagonal : float
        The bounding box's diagonal.
    """
    lo, hi = bounds(vertices)
    diagonal = float(np.linalg.norm(hi - lo))
    return 1e-5 * max(diagonal, float(np.abs(vertices).max())), diagonal


def sensor_dict(mi, cam):
    """Mitsuba's ``perspective`` sensor of our camera (``fov_axis`` y, a box filter, ``near_clip`` as exported).

    Parameters
    ----------
    mi : module
        The ``mitsuba`` module, its variant set.
    cam : Camera
        A perspective camera.

    Returns
    -------
    dict
        For ``mi.load_dict``.
    """
    return {"type": "perspective", "fov": float(cam.fov_y), "fov_axis": "y", "near_clip": M.NEAR_CLIP,
            "far_clip": 1e4,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(cam.eye), target=list(cam.target),
                                                       up=list(cam.up)),
            "film": {"type": "hdrfilm", "width": cam.width, "height": cam.height, "rfilter": {"type": "box"}}}


def pixel_centre_rays(mi, sensor, width, height):
    """The sensor's rays through every pixel centre, row by row (row 0 on top): one vectorised ``mi.Ray3f``.

    Parameters
    ----------
    mi : module
        The ``mitsuba`` module, a vectorised variant set.
    sensor : mitsuba.Sensor
    width, height : int
        The film's size in pixels.

    Returns
    -------
    mitsuba.Ray3f
        ``width * height`` rays.
    """
    idx = np.arange(height * width)
    pos = np.stack([(idx % width + 0.5) / width, (idx // width + 0.5) / height]).astype(np.float32)
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(pos[0], pos[1]), mi.Point2f(0.5, 0.5))
    return mi.Ray3f(ray)


def map_coords(p, frame, shape):
    """Points' (column, row) in a caustic map's frame ``(origin, u, v, V)``, in texels.

    Parameters
    ----------
    p : (N, 3) float64
        Points on the receiver.
    frame : (4, 3) float64
        Our ``caustic_frame_r``.
    shape : (Hc, Wc)
        The map's size.

    Returns
    -------
    col, row : (N,) float64
    """
    Hc, Wc = shape
    q = p - frame[0]
    return (q @ frame[1]) / (frame[1] @ frame[1]) * Wc, (q @ frame[2]) / (frame[2] @ frame[2]) * Hc
