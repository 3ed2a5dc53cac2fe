"""Exact multi-interface Snell tracer through the actual triangles.

This is the ground-truth oracle for the image-space approximations of
Chaudhari (2008): every ray is intersected with the real triangle mesh
(Embree for the search, float64 Möller–Trumbore for the hit itself) and
refracted by Snell's law at *every* interface it crosses, with total internal
reflection, until it leaves the scene or a bounce limit is reached.

Snell's law, total internal reflection and Beer–Lambert absorption are *not*
implemented here; they come from :mod:`refraction_ref.optics` so that the
oracle and the approximations share one implementation of each law.

References
----------
.. [1] T. Whitted, "An Improved Illumination Model for Shaded Display",
   *Communications of the ACM* 23(6), 343–349, 1980 (recursive ray tracing
   with refraction at every interface).
.. [2] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
   ed., §8.2 (Snell's law, total internal reflection).
.. [3] T. Möller, B. Trumbore, "Fast, Minimum Storage Ray/Triangle
   Intersection", *Journal of Graphics Tools* 2(1), 21–28, 1997.
.. [4] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008 (the image-space method this module is
   the reference for; absorption model of §3.8).
"""

from __future__ import annotations

import numpy as np

from . import optics
from .embree import embree_scene
from .status import EXITED, LIMIT, LOST, MISSED, TIR

__all__ = [
    "trace_exact",
    "area_weighted_vertex_normals",
    "STATUS_MISSED",
    "STATUS_EXITED",
    "STATUS_BOUNCE_LIMIT",
    "STATUS_BOUNCE_LIMIT_TIR",
    "STATUS_LOST",
]

# the historical names of this module, aliases of :mod:`refraction_ref.status`
STATUS_MISSED = MISSED
STATUS_EXITED = EXITED
STATUS_BOUNCE_LIMIT = LIMIT
STATUS_BOUNCE_LIMIT_TIR = TIR
STATUS_LOST = LOST

_CHUNK = 65536
_OUTSIDE = -1  # medium index of the surrounding medium
_ACTIVE = -1  # status value of a ray still being traced (internal)


def area_weighted_vertex_normals(vertices, faces):
    """Area-weighted unit vertex normals of a triangle mesh.

    Each vertex normal is the normalised sum of the (unnormalised) face
    normals ``(v1 - v0) x (v2 - v0)`` of the faces that use it, i.e. the sum
    of unit face normals weighted by twice the face area.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Counter-clockwise (outward) triangles.

    Returns
    -------
    (V, 3) ndarray of float64
        Unit normals; all-zero rows for vertices used by no face of non-zero
        area (the tracer then falls back to the face normal).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    vn = np.zeros_like(v)
    for c in range(3):
        for j in range(3):
            vn[:, c] += np.bincount(f[:, j], weights=fn[:, c], minlength=len(v))
    norm = np.linalg.norm(vn, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        vn = np.where(norm > 0, vn / np.where(norm > 0, norm, 1.0), 0.0)
    return vn


def _validate(vertices, faces, face_object, object_ior, object_absorption,
              origins, dirs, vertex_normals, outside_ior, max_bounces, normals_name="vertex_normals"):
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("vertices contain non-finite values (NaN or inf)")
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {f.shape}")
    if f.shape[0] == 0:
        raise ValueError("faces is empty")
    if not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be integers, got dtype {f.dtype}")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"faces index out of range [0, {len(v)})")
    f = f.astype(np.int64)
    fo = np.asarray(face_object)
    if fo.shape != (len(f),):
        raise ValueError(f"face_object must have shape ({len(f)},), got {fo.shape}")
    if not np.issubdtype(fo.dtype, np.integer):
        raise ValueError(f"face_object must be integers, got dtype {fo.dtype}")
    ior = np.asarray(object_ior, dtype=np.float64)
    if ior.ndim != 1 or len(ior) == 0:
        raise ValueError(f"object_ior must have shape (K,), got {ior.shape}")
    k = len(ior)
    if fo.min() < 0 or fo.max() >= k:
        raise ValueError(f"face_object values must lie in [0, {k}) (K = len(object_ior))")
    fo = fo.astype(np.int64)
    if not np.all(np.isfinite(ior)) or np.any(ior <= 0):
        raise ValueError("object_ior must be finite and > 0")
    ab = np.asarray(object_absorption, dtype=np.float64)
    if ab.shape != (k, 3):
        raise ValueError(f"object_absorption must have shape ({k}, 3), got {ab.shape}")
    if not np.all(np.isfinite(ab)) or np.any(ab < 0):
        raise ValueError("object_absorption must be finite and >= 0")
    if not (np.isfinite(outside_ior) and outside_ior > 0):
        raise ValueError(f"outside_ior must be finite and > 0, got {outside_ior}")
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(dirs, dtype=np.float64)
    if o.ndim != 2 or o.shape[1] != 3:
        raise ValueError(f"origins must have shape (N, 3), got {o.shape}")
    if d.shape != o.shape:
        raise ValueError(f"dirs must have the shape of origins {o.shape}, got {d.shape}")
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))):
        raise ValueError("origins and dirs must be finite")
    if len(d) and np.max(np.abs(np.linalg.norm(d, axis=1) - 1.0)) > 1e-6:
        raise ValueError("dirs must be unit vectors (|d| - 1 > 1e-6)")
    if vertex_normals is not None:
        vn = np.asarray(vertex_normals, dtype=np.float64)
        if vn.shape != v.shape and vn.shape != (len(f), 3, 3):
            raise ValueError(f"{normals_name} must have shape {v.shape} (per vertex) or {(len(f), 3, 3)} "
                             f"(per corner), got {vn.shape}")
        if not np.all(np.isfinite(vn)):
            raise ValueError(f"{normals_name} contain non-finite values")
    else:
        vn = None
    if int(max_bounces) != max_bounces or not (0 <= max_bounces <= np.iinfo(np.int16).max):
        raise ValueError(f"max_bounces must be an integer in [0, 32767], got {max_bounces}")
    return v, f, fo, ior, ab, o, d, vn


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _unit(a):
    n = np.linalg.norm(a, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return a / n


def trace_exact(vertices, faces, face_object, object_ior, object_absorption,
                origins, dirs, *, vertex_normals=None, smooth=True,
                outside_ior=1.0, max_bounces=64, progress=False,
                epsilon=None, chunk_size=_CHUNK, record=0, normals=None) -> dict:
    """Trace rays through a triangle scene, refracting at every interface.

    Each ray is intersected with the real triangles: Embree (float32) finds
    the nearest triangle, then the hit distance and barycentrics are
    recomputed in float64 with Möller–Trumbore [3]_ on that triangle. At each
    hit the ray is refracted with :func:`refraction_ref.optics.refract`
    (Snell's law [1]_ [2]_); under total internal reflection (TIR) it takes
    the mirror direction and stays in the same medium. This is the exact
    reference for the image-space method of Chaudhari (2008) [4]_.

    Inside/outside is decided by the geometric facing of the hit triangle
    (outward, counter-clockwise winding is assumed): ``dot(d, Ng) < 0``
    means the ray enters object ``face_object[f]`` (index goes from the
    current medium to ``object_ior[k]``); ``> 0`` means it leaves (index goes
    to ``outside_ior``). A per-ray current-medium index is kept; rays start
    in the outside medium. Objects are assumed not to be nested.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        World-space vertex positions (float64 is used throughout).
    faces : (F, 3) array_like of int
        Outward-wound triangles of all objects.
    face_object : (F,) array_like of int
        Object index in ``[0, K)`` of each face.
    object_ior : (K,) array_like of float
        Index of refraction of each object, > 0.
    object_absorption : (K, 3) array_like of float
        Absorption coefficient per colour channel of each object, >= 0.
    origins, dirs : (N, 3) array_like of float
        Ray origins (outside every object) and unit directions.
    vertex_normals : (V, 3) or (F, 3, 3) array_like of float, optional
        Shading normals, per vertex or per corner (row ``[f, k]`` belongs to
        vertex ``faces[f, k]``; e.g. the crease normals of
        :func:`refraction_ref.meshes.corner_normals`, which let a vertex on a
        sharp edge carry one normal per side). Default: area-weighted vertex
        normals (:func:`area_weighted_vertex_normals`). Only used when
        ``smooth``. A zero normal (interpolated) means "use the face normal".
    normals : (V, 3) or (F, 3, 3) array_like of float, optional
        The same as ``vertex_normals`` under the name the exact reference's
        ``geometry`` stage gives its buffer (``ctx.buf["geometry"]["normals"]``,
        passed with ``smooth=ctx.buf["geometry"]["smooth"]``); give one of
        the two.
    smooth : bool, default True
        Refract with barycentrically interpolated shading normals (``True``)
        or with the face normals (``False``). The shading normal is flipped
        to the geometric normal's side when they disagree; if it would send
        the refracted / reflected ray to the wrong side of the triangle the
        face normal is used for that event instead (keeps the medium
        bookkeeping consistent with the geometry).
    outside_ior : float, default 1.0
        Index of the surrounding medium.
    max_bounces : int, default 64
        Maximum number of surface events (refractions + TIR reflections).
        After that many events one more intersection query decides whether
        the ray exits (status 1) or is stopped (status 2 / 3).
    progress : bool, default False
        Show a tqdm progress bar over bounces.
    epsilon : float, optional
        Origin offset used to avoid self-intersection in the float32 Embree
        query (along the new direction and along the face normal, to the
        side the ray leaves to). Default ``1e-5 * scale`` with ``scale`` the
        larger of the bounding-box diagonal and the largest absolute
        coordinate. Distances and hit points are *not* affected by it: they
        are recomputed in float64 from the un-offset surface point.
    chunk_size : int, default 65536
        Rays per Embree call.
    record : int, default 0
        Keep the first ``record`` events of every path in ``path_pos`` and
        ``path_dir``; 0 records nothing (and adds no keys).

    Returns
    -------
    dict of ndarray, N rows each
        ``hit`` (bool)
            The first ray hit a triangle.
        ``status`` (int8)
            :mod:`refraction_ref.status`: 0 ``MISSED``, 1 ``EXITED``, 2
            ``LIMIT`` (stopped at the bounce limit), 3 ``TIR`` (stopped at
            the bounce limit with TIR as last event), 4 ``LOST``
            (non-finite direction; should not happen).
        ``exit_pos`` (N, 3)
            Last surface point, where the ray left (NaN unless status 1).
        ``exit_dir`` (N, 3)
            Direction after the last event (status 1), ``dirs`` (status 0),
            NaN otherwise.
        ``last_dir`` (N, 3)
            Direction at the end of tracing (the one before the failure for
            status 4).
        ``hit_pos`` (N, 3), ``first_face`` (N,) int64
            First hit point (NaN on miss) and face (-1 on miss).
        ``first_normal`` (N, 3), ``first_dir`` (N, 3)
            Shading normal actually used at the first hit (outward, i.e. on
            the geometric normal's side) and the direction right after the
            first event (NaN on miss); for checking Snell's law.
        ``interfaces`` (int16)
            Number of refractions (interface crossings); TIR not counted.
        ``bounces`` (int16)
            Number of surface events (refractions + TIR reflections).
        ``path_length`` (float64)
            Geometric length travelled inside objects.
        ``transmittance`` (N, 3)
            Product over segments inside object ``k`` of
            ``exp(-absorption_k * length * ior_k)``
            (:func:`refraction_ref.optics.beer_lambert`).
        ``leaked`` (bool)
            The ray escaped to infinity while its medium was an object (an
            open or inconsistently wound mesh); its status is still 1.
        ``path_pos`` (N, K, 3), ``path_dir`` (N, K, 3)
            Only with ``record=K > 0``. Row ``k`` is the ``k``-th surface
            event (``k < bounces``): the float64 hit point on the triangle
            (row 0 is ``hit_pos``, unless ``max_bounces=0``: no events) and
            the unit direction after the event, refracted or, under TIR,
            reflected (row 0 is ``first_dir``).
            A lost event keeps its point with a NaN direction. Rows past
            the path's events are NaN (all rows of a missed ray; a hit
            beyond the bounce limit is not an event and not recorded). For
            an exited ray with at most ``K`` events the last row is
            ``exit_pos`` and ``exit_dir``, bit for bit.

    Raises
    ------
    ValueError
        On malformed input: wrong shapes, non-finite vertices, ``ior <= 0``,
        negative absorption, face indices out of range, non-unit directions.

    Notes
    -----
    Deterministic: identical inputs give bit-identical outputs (Embree's
    BVH build and traversal are deterministic and all float64 work is
    element-wise).

    References
    ----------
    .. [1] T. Whitted, "An Improved Illumination Model for Shaded Display",
       Commun. ACM 23(6), 1980.
    .. [2] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*,
       3rd ed., §8.2.
    .. [3] T. Möller, B. Trumbore, "Fast, Minimum Storage Ray/Triangle
       Intersection", J. Graphics Tools 2(1), 1997.
    .. [4] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008.
    """
    if normals is not None and vertex_normals is not None:
        raise ValueError("give the shading normals as normals or as vertex_normals, not both")
    name = "normals" if normals is not None else "vertex_normals"
    v, f, fo, ior, ab, o, d, vn = _validate(
        vertices, faces, face_object, object_ior, object_absorption,
        origins, dirs, vertex_normals if normals is None else normals, outside_ior, max_bounces, name)
    max_bounces = int(max_bounces)
    chunk_size = int(chunk_size)
    if chunk_size < 1:
        raise ValueError("chunk_size must be >= 1")
    if smooth and vn is None:
        vn = area_weighted_vertex_normals(v, f)
    per_corner = vn is not None and vn.ndim == 3
    if epsilon is None:
        lo, hi = v.min(axis=0), v.max(axis=0)
        scale = max(float(np.linalg.norm(hi - lo)), float(np.abs(v).max()), 1e-30)
        epsilon = 1e-5 * scale
    epsilon = float(epsilon)
    if not (np.isfinite(epsilon) and epsilon >= 0):
        raise ValueError("epsilon must be finite and >= 0")
    if int(record) != record or record < 0:
        raise ValueError(f"record must be an integer >= 0, got {record!r}")
    record = int(record)

    n = len(o)
    nan3 = np.full((n, 3), np.nan)
    pos = o.copy()
    dirn = d.copy()
    side = np.zeros((n, 3))  # unit face normal on the side the ray leaves to
    medium = np.full(n, _OUTSIDE, dtype=np.int64)
    status = np.full(n, _ACTIVE, dtype=np.int8)
    last_tir = np.zeros(n, dtype=bool)
    interfaces = np.zeros(n, dtype=np.int16)
    bounces = np.zeros(n, dtype=np.int16)
    path_length = np.zeros(n)
    trans = np.ones((n, 3))
    exit_pos = nan3.copy()
    exit_dir = nan3.copy()
    last_dir = d.copy()
    hit_pos = nan3.copy()
    first_face = np.full(n, -1, dtype=np.int64)
    first_normal = nan3.copy()
    first_dir = nan3.copy()
    leaked = np.zeros(n, dtype=bool)
    if record:
        path_pos = np.full((n, record, 3), np.nan)
        path_dir = np.full((n, record, 3), np.nan)
    # index of refraction of each medium; the outside medium is the last entry
    med_ior = np.append(ior, float(outside_ior))

    tri = v[f]  # (F, 3, 3) float64
    e1_all = tri[:, 1] - tri[:, 0]
    e2_all = tri[:, 2] - tri[:, 0]
    ng_all = _unit(np.cross(e1_all, e2_all))

    if n == 0:
        scene = None
    else:
        scene = embree_scene(v, f)

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=max_bounces + 1, desc="trace_exact", unit="bounce")

    for bounce in range(max_bounces + 1):
        active = np.flatnonzero(status == _ACTIVE)
        if bar is not None:
            bar.set_postfix(active=len(active))
        if len(active) == 0:
            break
        for c0 in range(0, len(active), chunk_size):
            idx = active[c0:c0 + chunk_size]
            p = pos[idx]
            dd = dirn[idx]
            if bounce == 0:
                org = p
            else:
                org = p + epsilon * (dd + side[idx])
            res = scene.run(np.ascontiguousarray(org, dtype=np.float32),
                            np.ascontiguousarray(dd, dtype=np.float32), output=1)
            prim = np.asarray(res["primID"], dtype=np.int64)
            miss = prim < 0

            # --- rays with no further hit -----------------------------------
            mi = idx[miss]
            if bounce == 0:
                status[mi] = MISSED
                exit_dir[mi] = d[mi]
            else:
                status[mi] = EXITED
                exit_pos[mi] = pos[mi]
                exit_dir[mi] = dirn[mi]
                leaked[mi] = medium[mi] != _OUTSIDE
            last_dir[mi] = dirn[mi]

            hm = ~miss
            hi_ = idx[hm]
            if len(hi_) == 0:
                continue
            # --- float64 Möller–Trumbore on the triangle Embree found --------
            fi = prim[hm]
            p = p[hm]
            dd = dd[hm]
            v0 = tri[fi, 0]
            e1 = e1_all[fi]
            e2 = e2_all[fi]
            pvec = np.cross(dd, e2)
            det = _dot(e1, pvec)
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = 1.0 / det
                tvec = p - v0
                u = _dot(tvec, pvec) * inv
                qvec = np.cross(tvec, e1)
                w2 = _dot(dd, qvec) * inv
                t = _dot(e2, qvec) * inv
            bad = ~np.isfinite(t) | (t <= 0.0)
            if np.any(bad):  # parallel / degenerate: trust Embree's distance
                tf = np.asarray(res["tfar"], dtype=np.float64)[hm]
                h = org[hm] + tf[:, None] * dd if bounce else p + tf[:, None] * dd
                t_fb = _dot(h - p, dd)
                t = np.where(bad, t_fb, t)
                # barycentrics of the Embree point
                u = np.where(bad, np.asarray(res["u"], dtype=np.float64)[hm], u)
                w2 = np.where(bad, np.asarray(res["v"], dtype=np.float64)[hm], w2)
            x = p + t[:, None] * dd
            if bounce == 0:
                hit_pos[hi_] = x
                first_face[hi_] = fi
            if bounce == max_bounces:  # budget spent, and there is a further hit
                status[hi_] = np.where(last_tir[hi_], TIR, LIMIT).astype(np.int8)
                last_dir[hi_] = dirn[hi_]
                continue

            # --- absorption / path length on the segment just travelled -----
            med = medium[hi_]
            inside = med != _OUTSIDE
            if np.any(inside):
                ii = hi_[inside]
                k = med[inside]
                seg = t[inside]
                path_length[ii] += seg
                trans[ii] *= optics.beer_lambert(ab[k], seg, ior[k])

            # --- normals ----------------------------------------------------
            ng = ng_all[fi]
            cos_g = _dot(dd, ng)
            entering = cos_g < 0.0
            if smooth:
                b1 = np.clip(u, 0.0, 1.0)
                b2 = np.clip(w2, 0.0, 1.0)
                b0 = np.clip(1.0 - u - w2, 0.0, 1.0)
                s = b0 + b1 + b2
                s = np.where(s > 0, s, 1.0)
                if per_corner:  # the same sum, the corner normals of face fi
                    cn = vn[fi]
                    ns = (b0[:, None] * cn[:, 0] + b1[:, None] * cn[:, 1]
                          + b2[:, None] * cn[:, 2]) / s[:, None]
                else:
                    tf_ = f[fi]
                    ns = (b0[:, None] * vn[tf_[:, 0]] + b1[:, None] * vn[tf_[:, 1]]
                          + b2[:, None] * vn[tf_[:, 2]]) / s[:, None]
                ns = _unit(ns)
                okn = np.all(np.isfinite(ns), axis=1)
                ns = np.where(okn[:, None], ns, ng)
                flip = _dot(ns, ng) < 0.0
                ns[flip] = -ns[flip]
            else:
                ns = ng

            # --- Snell (optics.refract) --------------------------------------
            obj = fo[fi]
            n1 = med_ior[med]  # med == -1 indexes the outside entry
            n2 = np.where(entering, ior[obj], float(outside_ior))
            eta = n1 / n2
            newd, tir = optics.refract(dd, ns, eta)
            if smooth:
                # transmitted rays must keep the sign of d.Ng, reflected ones flip it
                cos_new = _dot(newd, ng)
                wrong = np.where(tir, np.sign(cos_new) == np.sign(cos_g),
                                 np.sign(cos_new) != np.sign(cos_g))
                if np.any(wrong):
                    nd2, tir2 = optics.refract(dd[wrong], ng[wrong], eta[wrong])
                    newd[wrong] = nd2
                    tir[wrong] = tir2
                    ns[wrong] = ng[wrong]

            lost = ~np.all(np.isfinite(newd), axis=1)
            newd = np.where(lost[:, None], dd, newd)  # keep previous dir for lost rays
            if bounce < record:  # every active ray has had `bounce` events: this is row `bounce`
                path_pos[hi_, bounce] = x
                path_dir[hi_, bounce] = np.where(lost[:, None], np.nan, newd)

            # --- bookkeeping ------------------------------------------------
            if bounce == 0:
                first_normal[hi_] = ns
                first_dir[hi_] = newd
            crossed = ~tir & ~lost
            medium[hi_] = np.where(crossed, np.where(entering, obj, _OUTSIDE), med)
            interfaces[hi_] += crossed.astype(np.int16)
            bounces[hi_] += 1
            last_tir[hi_] = tir
            pos[hi_] = x
            dirn[hi_] = newd
            last_dir[hi_] = newd
            side[hi_] = ng * np.where(_dot(newd, ng) >= 0.0, 1.0, -1.0)[:, None]
            if np.any(lost):
                status[hi_[lost]] = LOST
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()

    assert not np.any(status == _ACTIVE)
    out = {
        "hit": status != MISSED,
        "status": status,
        "exit_pos": exit_pos,
        "exit_dir": exit_dir,
        "last_dir": last_dir,
        "hit_pos": hit_pos,
        "first_face": first_face,
        "first_normal": first_normal,
        "first_dir": first_dir,
        "interfaces": interfaces,
        "bounces": bounces,
        "path_length": path_length,
        "transmittance": trans,
        "leaked": leaked,
    }
    if record:
        out["path_pos"] = path_pos
        out["path_dir"] = path_dir
    return out
