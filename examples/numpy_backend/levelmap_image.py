"""The level map's ``image`` pass: the camera's view through the water and directly (clean room).

Written from ``docs/oracle.md`` ("Porting rules: level map", ``image``; the
Level map Outputs table; "Stage buffers" for ``view_status`` and the
``water_*`` / ``receiver_pos`` buffers) and the camera rules of "Porting
rules: image-space" (``rays``, "Rasterization"), without the package's
source. ``levelmap.py`` calls :func:`image_pass` after ``casting``.

Two ways of finding the receiver point, as the contract has them:
``image_direct`` **rasterizes** the receivers with the camera's GPU-style
rasterizer (the image-space example's, reused), ``image`` **ray-casts**:
each eye ray against the water mesh, refracted there with the renormalised
Phong normal, then against every receiver triangle. The ray caster is a
two-level one, as a GPU port would build it: triangles grouped in Morton
order into clusters of 32, clusters into super-clusters of 32, each with
its bounding box; the (ray, box) pairs of each level slab-tested at once,
then Möller-Trumbore on the surviving (ray, triangle) pairs only.

References
----------
N. Tipprasert 2006, §4.6 (eq. 4-19, ``I_o = I_c I_d + I_a``), eq. 2-8
(Snell at the water); P. Chaudhari 2008 §3.2 (primary rays), §3.3
(rasterization).
"""

import importlib.util
import os

import numpy as np

#: view codes (Stage buffers, `image`'s `view_status`)
VIEW_MISSED, VIEW_THROUGH, VIEW_LOST, VIEW_DIRECT, VIEW_TIR = 0, 1, 2, 3, 4

#: Planted bugs of this pass (merged into ``levelmap.BUGS``).
BUGS = {
    "rounded_lookup": "image: the caustic-map texel rounded (rint(row), rint(col)) instead of floored",
    "half_texel_lookup": "image: the lookup half a texel off the other way (floor(col - 0.5), texel "
                         "centres taken at integer coordinates)",
    "swapped_lookup": "image: the map read as map[col, row] (u and v swapped)",
    "v_flip_lookup": "image: the map read with its rows flipped (a bottom-left texture origin)",
    "unnormalised_water_normal": "image: the interpolated Phong normal at the water not renormalised",
    "absorb_direct": "image: exp(-K |Q - eye|) applied to status-3 pixels (receivers seen directly)",
    "water_rectangle": "image: 'missed the water' tested against the flat rectangle |x| <= sx/2, "
                       "|z| <= sz/2 at the mean height instead of the mesh",
    "view_inverted_eta": "image: the eye ray refracted with water.ior / outside_ior",
    "ambient_unweighted": "image: eq. 4-19 as albedo I_c + ambient (I_a not scaled by the albedo)",
    "direct_raycast": "image_direct ray-cast from the eye instead of rasterized",
}

CLUSTER = 32        # triangles per cluster of the ray caster's two-level structure
BARY_EPS = 1e-12    # Möller-Trumbore's inclusive barycentric bounds (oracle, `image`)


def _load_imagespace():
    """The image-space example (camera, primary rays, the camera's rasterizer), loaded by path."""
    spec = importlib.util.spec_from_file_location(
        "example_imagespace_for_levelmap",
        os.path.join(os.path.dirname(os.path.abspath(__file__)), "imagespace.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


_imagespace = None


def _cam():
    global _imagespace
    if _imagespace is None:
        _imagespace = _load_imagespace()
    return _imagespace


CAMERA_DEFAULTS = {"eye": [0, 0, 2.6], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y": 30,
                   "width": 512, "height": 512, "near": 0.1, "far": 10}


# ----------------------------------------------------------------------------
# the ray caster: Morton clusters, slab test, Möller-Trumbore (float64)
# ----------------------------------------------------------------------------


def _morton(c):
    """Morton codes (10 bits per axis) of points ``c`` (N, 3) in their bounding cube.

    One scale for all axes: a per-axis one would stretch the water's few
    centimetres of waves over as many bits as its metres of extent, and
    group triangles by height instead of by place.
    """
    lo = c.min(axis=0)
    span = max(float(np.max(c.max(axis=0) - lo)), 1e-300)
    q = np.clip(((c - lo) / span * 1023).astype(np.int64), 0, 1023)
    code = np.zeros(len(c), dtype=np.int64)
    for bit in range(10):
        for a in range(3):
            code |= ((q[:, a] >> bit) & 1) << (3 * bit + a)
    return code


def _boxes(tris, ids):
    """Bounding boxes of groups of triangles (``ids`` (n, k), -1 for padding), padded by 1e-9 of the span."""
    t = tris[np.maximum(ids, 0)]                                   # (n, k, 3, 3)
    real = (ids >= 0)[..., None, None]
    lo = np.where(real, t, np.inf).min(axis=(1, 2))
    hi = np.where(real, t, -np.inf).max(axis=(1, 2))
    span = np.max(tris.max(axis=(0, 1)) - tris.min(axis=(0, 1)))
    return lo - 1e-9 * span, hi + 1e-9 * span


def _pad(ids, k):
    """``ids`` split into rows of k, the last row padded with -1."""
    n = -(-len(ids) // k)
    return np.concatenate([ids, np.full(n * k - len(ids), -1)]).reshape(n, k)


def build(tris, groups=None):
    """The caster's two-level structure over triangles (T, 3, 3).

    Triangles sorted in Morton order of their centroids into clusters of
    ``CLUSTER``, clusters into super-clusters of ``CLUSTER``, each with its
    bounding box; ``groups`` (T,) (the receiver of each triangle) keeps
    clusters within one group, so a big floor triangle does not widen a
    cluster of small sphere triangles.
    """
    groups = np.zeros(len(tris), dtype=np.int64) if groups is None else groups
    code = _morton(tris.mean(axis=1))
    leaves = []
    for gid in np.unique(groups):
        idx = np.flatnonzero(groups == gid)
        leaves.append(_pad(idx[np.argsort(code[idx], kind="stable")], CLUSTER))
    leaves = np.concatenate(leaves)
    lo, hi = _boxes(tris, leaves)
    supers = _pad(np.arange(len(leaves)), CLUSTER)
    slo = np.where((supers >= 0)[..., None], lo[np.maximum(supers, 0)], np.inf).min(axis=1)
    shi = np.where((supers >= 0)[..., None], hi[np.maximum(supers, 0)], -np.inf).max(axis=1)
    return {"tris": tris, "leaves": leaves, "lo": lo, "hi": hi, "supers": supers, "slo": slo, "shi": shi}


def _slab(o, d, lo, hi, tmin):
    """Ray-box overlap of paired rays and boxes (all (n, 3)); a zero direction component is handled."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0 = (lo - o) * inv
        t1 = (hi - o) * inv
    par = d == 0
    inside = (o >= lo) & (o <= hi)
    tn = np.where(par, np.where(inside, -np.inf, np.inf), np.minimum(t0, t1)).max(axis=1)
    tf = np.where(par, np.where(inside, np.inf, -np.inf), np.maximum(t0, t1)).min(axis=1)
    return (tn <= tf) & (tf >= tmin)


def _expand(ray, node, children):
    """(ray, child) pairs of (ray, node) pairs, padding dropped."""
    k = children.shape[1]
    ray = np.repeat(ray, k)
    child = children[np.repeat(node, k), np.tile(np.arange(k), len(node))]
    keep = child >= 0
    return ray[keep], child[keep]


def first_hit(O, D, acc, tmin=0.0, chunk=16384):
    """Nearest triangle hit of each ray (origins ``O``, directions ``D``, (N, 3)).

    Returns ``t`` (inf where none), barycentrics ``u`` (vertex b), ``v``
    (vertex c) and the triangle index ``face`` (-1 where none). Ties in t
    go to the lower triangle index.

    References
    ----------
    Möller and Trumbore 1997, float64, the barycentrics inclusive within
    1e-12 (docs/oracle.md, Porting rules: level map, `image`).
    """
    N = len(O)
    t_out = np.full(N, np.inf)
    u_out = np.full(N, np.nan)
    v_out = np.full(N, np.nan)
    f_out = np.full(N, -1, dtype=np.int64)
    tris = acc["tris"]
    S = len(acc["supers"])
    for s in range(0, N, chunk):
        o, d = O[s:s + chunk], D[s:s + chunk]
        n = len(o)
        ray, node = np.repeat(np.arange(n), S), np.tile(np.arange(S), n)
        hit = _slab(o[ray], d[ray], acc["slo"][node], acc["shi"][node], tmin)
        ray, node = _expand(ray[hit], node[hit], acc["supers"])
        hit = _slab(o[ray], d[ray], acc["lo"][node], acc["hi"][node], tmin)
        ray, face = _expand(ray[hit], node[hit], acc["leaves"])
        tri = tris[face]
        oo, dd = o[ray], d[ray]
        e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        p = np.cross(dd, e2)
        det = np.sum(e1 * p, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv_det = 1.0 / det
            tv = oo - tri[:, 0]
            u = np.sum(tv * p, axis=1) * inv_det
            qv = np.cross(tv, e1)
            v = np.sum(dd * qv, axis=1) * inv_det
            t = np.sum(e2 * qv, axis=1) * inv_det
        hit = ((det != 0) & (u >= -BARY_EPS) & (v >= -BARY_EPS) & (u + v <= 1.0 + BARY_EPS)
               & (t >= tmin) & np.isfinite(t))
        ray, face, t, u, v = ray[hit], face[hit], t[hit], u[hit], v[hit]
        order = np.lexsort((face, t, ray))
        first = np.ones(order.size, dtype=bool)
        first[1:] = ray[order][1:] != ray[order][:-1]
        k = order[first]
        t_out[s + ray[k]] = t[k]
        u_out[s + ray[k]] = u[k]
        v_out[s + ray[k]] = v[k]
        f_out[s + ray[k]] = face[k]
    return t_out, u_out, v_out, f_out


def _refract(I, N, eta):
    """Snell in vector form, the normal turned to face I (`water`'s eq. 2-8); NaN and ``tir`` where k < 0."""
    c = -(I[..., 0] * N[..., 0] + I[..., 1] * N[..., 1] + I[..., 2] * N[..., 2])
    flip = c < 0
    N = np.where(flip[..., None], -N, N)
    c = np.where(flip, -c, c)
    k = 1.0 - eta * eta * (1.0 - c * c)
    with np.errstate(invalid="ignore"):
        T = eta * I + (eta * c - np.sqrt(k))[..., None] * N
        T = T / np.linalg.norm(T, axis=-1, keepdims=True)
    return np.where((k < 0)[..., None], np.nan, T), k < 0


# ----------------------------------------------------------------------------
# eq. 4-19: the shading of a receiver point
# ----------------------------------------------------------------------------


def lookup(Q, box, Hc, Wc, bugs=()):
    """Texel (i, j) of light 0's caustic map that holds world points ``Q`` (floor, clipped to the map)."""
    c, U, V, W, (w, h, d) = box
    q = Q - c
    col = ((q[:, 0] * U[0] + q[:, 1] * U[1] + q[:, 2] * U[2]) / w + 0.5) * Wc
    row = ((q[:, 0] * W[0] + q[:, 1] * W[1] + q[:, 2] * W[2]) / d + 0.5) * Hc
    if "rounded_lookup" in bugs:          # planted: the nearest texel corner, half a texel off
        col, row = np.rint(col), np.rint(row)
    elif "half_texel_lookup" in bugs:     # planted: texel centres at integers
        col, row = col - 0.5, row - 0.5
    j = np.clip(np.floor(col), 0, Wc - 1).astype(np.int64)
    i = np.clip(np.floor(row), 0, Hc - 1).astype(np.int64)
    if "swapped_lookup" in bugs:          # planted: u and v swapped (square maps only)
        i, j = j, i
    if "v_flip_lookup" in bugs:           # planted: a bottom-left texture origin
        i = Hc - 1 - i
    return i, j


def shade(Q, rec, dist, cmaps, boxes, albedos, ambient, K, bugs=()):
    """Eq. 4-19 at points ``Q`` (N, 3) of receivers ``rec`` (N,): float32 RGB (N, 3).

    ``albedo (I_c + ambient) exp(-K dist)``, ``I_c`` the float64 value of
    the receiver's cast map at its floored texel in light 0's box; no
    exponential where ``dist`` is 0 or K is 0.
    """
    out = np.zeros((len(Q), 3), dtype=np.float64)
    for r in np.unique(rec):
        m = rec == r
        cmap = cmaps[r]
        Hc, Wc = cmap.shape
        i, j = lookup(Q[m], boxes[r], Hc, Wc, bugs)
        Ic = cmap[i, j].astype(np.float64)
        tr = np.exp(-K * dist[m]) if K > 0 else np.ones(int(m.sum()))
        a = albedos[r][None, :]
        if "ambient_unweighted" in bugs:  # planted: the notebook's I_c I_d + ambient
            out[m] = (a * Ic[:, None] + ambient) * tr[:, None]
        else:
            out[m] = a * (Ic + ambient)[:, None] * tr[:, None]
    return out.astype(np.float32)


# ----------------------------------------------------------------------------
# the pass
# ----------------------------------------------------------------------------


def image_pass(scene, wat, recs, boxes, cmaps, eta, K, ambient, bugs=()):
    """Pass `image`: ``image``, ``image_direct``, their masks and the view buffers.

    Parameters
    ----------
    scene : dict
        The scene (its ``camera`` block, defaults filled here).
    wat : dict
        `water`'s buffers of light 0: ``vertices``, ``normals`` (the analytic
        vertex normals) and ``faces``.
    recs : list of (vertices, faces, P0, albedo)
        The placed receivers, in ``receivers`` order.
    boxes : list of (5, 3)
        ``box_r_0`` per receiver (light 0's box: the cast map's frame).
    cmaps : list of (Hc, Wc) float32
        ``caustic_map_r`` per receiver (after casting).
    eta, K, ambient : float
        ``outside_ior / water.ior``, ``water.absorption``, ``caustics.ambient``.

    Returns
    -------
    dict
        Buffer name -> array (the `image` stage's buffers).

    References
    ----------
    Tipprasert 2006 §4.6, eq. 4-19; eq. 2-8 at the water.
    """
    isp = _cam()
    camd = dict(CAMERA_DEFAULTS, **(scene.get("camera") or {}))
    cam = isp.camera(camd)
    H, W = cam.H, cam.W
    rays, _ = isp.pass_rays(cam)
    D = rays["ray_dir"].reshape(-1, 3)
    eye = cam.eye
    O = np.broadcast_to(eye, D.shape).copy()
    albedos = [a for _, _, _, a in recs]
    rtris = np.concatenate([v[f] for v, f, _, _ in recs])
    owner = np.concatenate([np.full(len(f), k) for k, (_, f, _, _) in enumerate(recs)])
    racc = build(rtris, owner)

    # --- image_direct: the camera's rasterizer, nearest fragment, ties to the earlier receiver
    if "direct_raycast" in bugs:
        t, _, _, face = first_hit(O, D, racc)
        has_d = face >= 0
        Qd = O + np.where(has_d, t, 0.0)[:, None] * D
        rd = np.where(has_d, owner[np.maximum(face, 0)], 0)
    else:
        pix_all, dep_all, rec_all, tri_all = [], [], [], []
        for r, (v, f, _, _) in enumerate(recs):
            pix, dep, tri = isp.fragments(cam, v, f, tuple(b for b in bugs if b == "no_snap"),
                                          with_triangle=True)
            pix_all.append(pix)
            dep_all.append(dep)
            rec_all.append(np.full(len(pix), r))
            tri_all.append(tri)
        pix, dep = np.concatenate(pix_all), np.concatenate(dep_all)
        rr_, tri = np.concatenate(rec_all), np.concatenate(tri_all)
        order = np.lexsort((tri, rr_, dep, pix))
        first = np.ones(order.size, dtype=bool)
        first[1:] = pix[order][1:] != pix[order][:-1]
        k = order[first]
        depth = np.full(H * W, np.nan)
        depth[pix[k]] = dep[k]
        rd = np.zeros(H * W, dtype=np.int64)
        rd[pix[k]] = rr_[k]
        has_d = np.isfinite(depth)
        fwd = -cam.B[2]                                # unit view direction f
        Dz = D[:, 0] * fwd[0] + D[:, 1] * fwd[1] + D[:, 2] * fwd[2]
        Qd = eye + D * (np.where(has_d, depth, 0.0) / Dz)[:, None]
    img_d = np.zeros((H * W, 3), dtype=np.float32)
    img_d[has_d] = shade(Qd[has_d], rd[has_d], np.zeros(int(has_d.sum())), cmaps, boxes, albedos,
                         ambient, K, bugs)

    # --- image: the eye rays at the water mesh
    verts, normals, wf = wat["vertices"], wat["normals"], wat["faces"]
    wtris = verts[wf]
    tw, uw, vw, fw = first_hit(O, D, build(wtris))
    hit_w = fw >= 0
    flat = np.zeros(H * W, dtype=bool)
    if "water_rectangle" in bugs:       # planted: the flat rectangle decides who meets the water
        sx, sz = (float(x) for x in scene["water"].get("size", [4, 4]))
        hgt = float(scene["water"].get("height", 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            tp = (hgt - O[:, 1]) / D[:, 1]
        X = O + tp[:, None] * D
        on = (tp >= 0) & (np.abs(X[:, 0]) <= sx / 2) & (np.abs(X[:, 2]) <= sz / 2)
        flat = on & ~hit_w                # admitted by the rectangle, missed by the mesh: the flat point
        tw = np.where(flat, tp, tw)
        hit_w = on
    status = np.full(H * W, VIEW_DIRECT, dtype=np.int8)
    P = np.full((H * W, 3), np.nan)
    Tdir = np.full((H * W, 3), np.nan)
    a, b, c = (wf[np.maximum(fw, 0), k] for k in range(3))
    uu, vv = np.where(hit_w, uw, 0.0), np.where(hit_w, vw, 0.0)
    n = ((1 - uu - vv)[:, None] * normals[a] + uu[:, None] * normals[b] + vv[:, None] * normals[c])
    n[flat] = (0.0, 1.0, 0.0)
    if "unnormalised_water_normal" not in bugs:
        n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    eta_v = 1.0 / eta if "view_inverted_eta" in bugs else eta
    T, tir = _refract(D, n, eta_v)     # with the planted bug: the short normal bends T
    Pw = O + np.where(hit_w, tw, 0.0)[:, None] * D
    P[hit_w] = Pw[hit_w]
    status[hit_w & tir] = VIEW_TIR
    thr = hit_w & ~tir
    status[thr] = VIEW_THROUGH
    Tdir[thr] = T[thr]

    # --- image: the receivers, from P along T (status 1) or from the eye along D (status 3)
    go = (status == VIEW_THROUGH) | (status == VIEW_DIRECT)
    Og = np.where((status == VIEW_THROUGH)[:, None], P, O)[go]
    Dg = np.where((status == VIEW_THROUGH)[:, None], Tdir, D)[go]
    t2, _, _, f2 = first_hit(Og, Dg, racc)
    met = f2 >= 0
    tri = rtris[np.maximum(f2, 0)]
    m = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):      # the hit recomputed on the triangle's plane
        tp = np.sum((tri[:, 0] - Og) * m, axis=1) / np.sum(Dg * m, axis=1)
    tp = np.where(np.isfinite(tp), tp, t2)
    Qg = Og + np.where(met, tp, 0.0)[:, None] * Dg
    idx = np.flatnonzero(go)
    Q = np.full((H * W, 3), np.nan)
    Q[idx[met]] = Qg[met]
    rec = np.zeros(H * W, dtype=np.int64)
    rec[idx[met]] = owner[f2[met]]
    was_through = status == VIEW_THROUGH
    lost = np.zeros(H * W, dtype=bool)
    lost[idx[~met]] = True
    status[lost & was_through] = VIEW_LOST
    status[lost & ~was_through] = VIEW_MISSED
    length = np.full(H * W, np.nan)
    sel1 = status == VIEW_THROUGH
    sel3 = status == VIEW_DIRECT
    length[sel1] = np.linalg.norm(Q[sel1] - P[sel1], axis=-1)
    length[sel3] = 0.0
    dist = np.where(sel1, length, 0.0)
    if "absorb_direct" in bugs:          # planted: the direct view absorbed along the eye ray
        dist = np.where(sel3, np.linalg.norm(Q - eye, axis=-1), dist)
    shown = sel1 | sel3
    img = np.zeros((H * W, 3), dtype=np.float32)
    img[shown] = shade(Q[shown], rec[shown], dist[shown], cmaps, boxes, albedos, ambient, K, bugs)
    return {
        "image": img.reshape(H, W, 3),
        "object_mask": shown.reshape(H, W),
        "image_direct": img_d.reshape(H, W, 3),
        "object_mask_direct": has_d.reshape(H, W),
        "view_status": status.reshape(H, W),
        "water_pos": P.reshape(H, W, 3),
        "water_dir": Tdir.reshape(H, W, 3),
        "receiver_pos": Q.reshape(H, W, 3),
        "water_length": length.reshape(H, W),
    }
