"""Clean-room NumPy port of the volumetric method (Sun et al. 2008), ``voxelize`` to ``march``.

Written from ``docs/oracle.md`` ("Porting rules: volumetric", "Volumetric",
"Stage buffers") and ``docs/backends.md`` alone, without the package's
source, the way a GPU port is structured: one function per pass, every pass
vectorised over voxels, texels or photons (the march loops over steps with
all active photons at once, as a compute shader dispatch per step would).

``run(golden_dir, out_dir)`` reads each volumetric case's ``scene.json``
from a golden suite and writes ``out_dir/<case>/result.npz`` with the
golden key names, shapes and dtypes, ready for ``refraction-ref check``.
``bugs=`` plants mistakes that porters really make (``BUGS``), to show that
``check`` names the pass that holds them.

References
----------
X. Sun, K. Zhou, E. Stollnitz, J. Shi, B. Guo, *Interactive Relighting of
Dynamic Refractive Objects*, ACM TOG 27(3), 2008: §4.1 (voxelize), §3 eq. 3
(gradient), §4.2 and §5.3 (octree), §4.3 (photons), §4.4 eqs. 4-6 (march).
"""
from __future__ import annotations

import json
import math
import os

import numpy as np

#: Planted porter's bugs, by flag: what it does and the pass it should name.
BUGS = {
    "forward_gradient": ("gradient: forward differences (n[i+1] - n[i]) / h instead of central", "gradient"),
    "eps_swap": ("octree: the level labelled by eps and the step by eps2 (eps and eps' swapped)", "octree"),
    "half_voxel": ("march: voxel centres taken at lo + i h (off by half a voxel) in the trilinear lookup",
                   "march"),
    "step_ds_max": ("march: the step clamped to [ds_min, ds_max] (the knob) instead of the voxel's step_max",
                    "march"),
    "window_flip": ("photons: texture row 0 at -e2 (the window flipped vertically)", "photons"),
    "no_nudge": ("march: no 1e-4-voxel nudge past the node boundary", "march"),
}

#: The `volumetric` knob block's defaults (docs/oracle.md, knob table).
VOL_DEFAULTS = {
    "resolution": 128, "photons": 1024, "ds_min": 1.0, "ds_max": 8.0, "eps": 0.005, "eps2": 0.02,
    "integrator": "euler", "phase_g": 0.0, "scattering": 0.2, "absorption": 0.0, "supersample": 4,
    "blur": 9, "padding": 6, "bounds": None, "max_steps": 0, "min_radiance": 0.001,
    "stop_fraction": 0.001, "stiff": 0.25, "stepping": "paper", "proxy": "inflated", "proxy_inflate": 6.0,
}
LIGHT_DEFAULTS = {"type": "directional", "direction": [0.0, -1.0, 0.0], "position": None,
                  "radiance": [1.0, 1.0, 1.0]}


# ----------------------------------------------------------------------------------------------
# scene
# ----------------------------------------------------------------------------------------------

def read_scene(path):
    """The scene JSON with the keys this port reads resolved to their documented defaults.

    Returns
    -------
    dict with ``raw`` (the JSON), ``dir`` (the scene's folder), ``vol`` (the knobs), ``lights``,
    ``outside_ior``.
    """
    with open(path) as f:
        raw = json.load(f)
    vol = dict(VOL_DEFAULTS)
    vol.update(raw.get("volumetric") or {})
    if raw.get("receivers"):
        raise ValueError(f"{path}: this port covers scenes without receivers only")
    if vol["integrator"] != "euler" or vol["stepping"] != "paper":
        raise ValueError(f"{path}: this port covers integrator=euler, stepping=paper only "
                         f"(got {vol['integrator']!r}, {vol['stepping']!r})")
    lights = [dict(LIGHT_DEFAULTS, **l) for l in raw.get("lights", [dict(LIGHT_DEFAULTS)])]
    return {"raw": raw, "dir": os.path.dirname(os.path.abspath(path)), "vol": vol, "lights": lights,
            "outside_ior": float(raw.get("outside_ior", 1.0))}


def _rgb(x):
    a = np.asarray(x, np.float64)
    return np.broadcast_to(a, (3,)).copy() if a.ndim == 0 else a


# ----------------------------------------------------------------------------------------------
# voxelize (§4.1)
# ----------------------------------------------------------------------------------------------

def _raster_columns(P, F, lo, h, N, r, S):
    """Fragments of an orthographic rasterization of triangles onto the columns along axis r.

    The level map's rasterizer (1/256 snap, top-left fill rule, linear depth), columns
    ``(p, q) = ((r + 1) % 3, (r + 2) % 3)`` at ``S`` times the voxel resolution.

    Returns
    -------
    (j, i, depth, sign): column index along p, along q, fragment depth (world coordinate on r),
    +1 where the triangle faces -r (the ray along +r enters), -1 otherwise.
    """
    p, q = (r + 1) % 3, (r + 2) % 3
    X = np.rint((P[:, p] - lo[p]) / (h[p] / S) * 256.0).astype(np.int64)
    Y = np.rint((P[:, q] - lo[q]) / (h[q] / S) * 256.0).astype(np.int64)
    Z = P[:, r]
    x0, x1, x2 = X[F].T
    y0, y1, y2 = Y[F].T
    z0, z1, z2 = Z[F].T
    A = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
    fl = A < 0
    x1, x2 = np.where(fl, x2, x1), np.where(fl, x1, x2)
    y1, y2 = np.where(fl, y2, y1), np.where(fl, y1, y2)
    z1, z2 = np.where(fl, z2, z1), np.where(fl, z1, z2)
    sign = np.where(fl, 1, -1)
    A = np.abs(A)

    def first(a):
        return np.maximum(-((128 - a) // 256), 0)

    def last(a, n):
        return np.minimum((a - 128) // 256, n - 1)

    n_p, n_q = S * int(N[p]), S * int(N[q])
    j0 = first(np.minimum(np.minimum(x0, x1), x2))
    j1 = last(np.maximum(np.maximum(x0, x1), x2), n_p)
    i0 = first(np.minimum(np.minimum(y0, y1), y2))
    i1 = last(np.maximum(np.maximum(y0, y1), y2), n_q)
    nj = np.maximum(j1 - j0 + 1, 0)
    n = np.where(A > 0, np.maximum(i1 - i0 + 1, 0) * nj, 0)
    t = np.repeat(np.arange(len(F)), n)
    k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    i = i0[t] + k // nj[t]
    j = j0[t] + k % nj[t]
    px, py = 256 * j + 128, 256 * i + 128
    a0, a1, a2, b0, b1, b2 = x0[t], x1[t], x2[t], y0[t], y1[t], y2[t]
    w0 = (a2 - a1) * (py - b1) - (b2 - b1) * (px - a1)
    w1 = (a0 - a2) * (py - b2) - (b0 - b2) * (px - a2)
    w2 = (a1 - a0) * (py - b0) - (b1 - b0) * (px - a0)

    def bias(ax, ay, bx, by):                      # top-left: 0 for an owning edge, else -1
        return np.where((by - ay < 0) | ((by == ay) & (bx > ax)), 0, -1)

    cov = ((w0 + bias(a1, b1, a2, b2) >= 0) & (w1 + bias(a2, b2, a0, b0) >= 0)
           & (w2 + bias(a0, b0, a1, b1) >= 0))
    w0, w1, w2, t = w0[cov], w1[cov], w2[cov], t[cov]
    depth = (w0 * z0[t] + w1 * z1[t] + w2 * z2[t]) * (1.0 / A[t])
    return j[cov], i[cov], depth, sign[t]


def _winding_votes(P, F, lo, h, N, S, closed):
    """Inside flags at the S-supersampled sample grid (N*S per axis) by winding numbers.

    closed: inside where the +z winding number from -inf is non-zero; otherwise six votes (x, y,
    z from -inf and from +inf), inside with at least 4.
    """
    M = [int(v) * S for v in N]
    votes = np.zeros(M, np.uint8)
    for r in ((2,) if closed else (0, 1, 2)):
        p, q = (r + 1) % 3, (r + 2) % 3
        j, i, depth, sign = _raster_columns(P, F, lo, h, N, r, S)
        zs = lo[r] + (np.arange(M[r]) + 0.5) * h[r] / S
        m = np.searchsorted(zs, depth, side="right")       # first sample with depth < z
        delta = np.zeros((M[p], M[q], M[r] + 1), np.int32)
        np.add.at(delta, (j, i, m), sign)
        wind = np.cumsum(delta, axis=2)                      # winding from -inf at each sample
        total = wind[:, :, -1:]
        wind = wind[:, :, :-1]
        inside = (wind != 0).astype(np.uint8)
        if not closed:
            inside = inside + ((wind - total) != 0)
        # reorder (p, q, r) -> (x, y, z)
        order = np.argsort([p, q, r])
        votes += np.transpose(inside, order)
    return votes >= 1 if closed else votes >= 4


def _object_closed(V, F):
    import trimesh
    m = trimesh.Trimesh(V, F, process=False)
    m.merge_vertices()
    if m.is_watertight:
        return True
    m.fill_holes()
    return bool(m.is_watertight)


def _gauss_blur(a, blur):
    from scipy.ndimage import correlate1d
    r = blur // 2
    x = np.arange(-r, r + 1, dtype=np.float64)
    sigma = blur / 6.0
    w = np.exp(-x * x / (2.0 * sigma * sigma))
    w = w / w.sum()
    for ax in range(3):
        a = correlate1d(a, w, axis=ax, mode="nearest")
    return a


def scene_objects(sc):
    """World-space triangles per object, from the case's ``geometry.npz`` (``docs/backends.md``:
    the placed triangles merged in object order, ``face_object`` naming each one's object), as a
    list of (V, F, ior, absorption)."""
    with np.load(os.path.join(sc["dir"], "geometry.npz")) as g:
        V, F, owner = g["vertices"], g["faces"], g["face_object"]
    out = []
    for k, o in enumerate(sc["raw"].get("objects", [])):
        Fk = F[owner == k]
        used, Fk = np.unique(Fk, return_inverse=True)   # the object's own vertices, in their order
        mat = o.get("material", {})
        out.append((V[used], Fk.reshape(-1, 3).astype(np.int64),
                    float(mat.get("ior", 1.5)), _rgb(mat.get("absorption", [0.0, 0.0, 0.0]))))
    return out


def voxelize(sc, bugs=()):
    """Pass ``voxelize``: the index volume, its box, and the objects' absorption per voxel.

    Returns
    -------
    ior (nx, ny, nz) float64, lo (3,), hi (3,), absorb (nx, ny, nz, 3) float64 (object absorption
    weighted by coverage; zeros for `volume` input), objs (the placed meshes; [] for volume input).

    References
    ----------
    Sun 2008 §4.1 (slicing, supersampled boundary voxels, Gaussian blur).
    """
    raw, vol = sc["raw"], sc["vol"]
    if raw.get("volume"):
        v = raw["volume"]
        ior = v["ior"]
        ior = np.load(os.path.join(sc["dir"], ior)) if isinstance(ior, str) else np.asarray(ior)
        ior = np.asarray(ior, np.float64)
        b = np.asarray(v["bounds"], np.float64)
        return ior, b[0], b[1], np.zeros(ior.shape + (3,)), []
    objs = scene_objects(sc)
    N = int(vol["resolution"])
    allv = np.concatenate([o[0] for o in objs])
    if vol["bounds"] is not None:
        b = np.asarray(vol["bounds"], np.float64)
        lo, hi = b[0], b[1]
    else:
        vmin, vmax = allv.min(0), allv.max(0)
        c = (vmin + vmax) / 2.0
        ext = float(np.max(vmax - vmin)) or 1.0
        half = (ext / 2.0) * N / (N - 2 * int(vol["padding"]) - 1)
        lo, hi = c - half, c + half
    Ns = np.array([N, N, N])
    h = (hi - lo) / Ns
    S = int(vol["supersample"])
    out = sc["outside_ior"]
    ior = np.full((N, N, N), out, np.float64)
    absorb = np.zeros((N, N, N, 3))
    for V, F, n_k, a_k in objs:
        closed = _object_closed(V, F)
        centre = _winding_votes(V, F, lo, h, Ns, 1, closed)
        cov = centre.astype(np.float64)
        if S > 1:
            from scipy.ndimage import maximum_filter, minimum_filter
            mixed = (maximum_filter(centre, size=3, mode="nearest")
                     != minimum_filter(centre, size=3, mode="nearest"))
            sub = _winding_votes(V, F, lo, h, Ns, S, closed)
            frac = sub.reshape(N, S, N, S, N, S).mean(axis=(1, 3, 5))
            cov = np.where(mixed, frac, cov)
        ior = ior + cov * (n_k - out)
        absorb = absorb + cov[..., None] * a_k
    blur = int(vol["blur"])
    if blur > 1:
        ior = _gauss_blur(ior, blur)
        absorb = np.stack([_gauss_blur(absorb[..., c], blur) for c in range(3)], -1)
    return ior, lo, hi, absorb, objs


# ----------------------------------------------------------------------------------------------
# gradient (§3, eq. 3)
# ----------------------------------------------------------------------------------------------

def gradient(ior, lo, hi, bugs=()):
    """Pass ``gradient``: ``field`` (nx, ny, nz, 4) float32 = (n, dn/dx, dn/dy, dn/dz).

    Central differences inside, one-sided on the faces, in float64, rounded once.

    References
    ----------
    Sun 2008 §3, eq. 3 (the ray equation needs grad n).
    """
    h = (hi - lo) / np.array(ior.shape)
    out = np.empty(ior.shape + (4,), np.float64)
    out[..., 0] = ior
    for ax in range(3):
        n = ior.shape[ax]
        i = np.arange(n)
        if "forward_gradient" in bugs:
            i0, i1 = np.minimum(i, n - 2), np.minimum(i + 1, n - 1)
        else:
            i0, i1 = np.maximum(i - 1, 0), np.minimum(i + 1, n - 1)
        d = (np.take(ior, i1, axis=ax) - np.take(ior, i0, axis=ax))
        shape = [1, 1, 1]
        shape[ax] = n
        out[..., 1 + ax] = d / ((i1 - i0) * h[ax]).reshape(shape)
    return out.astype(np.float32)


# ----------------------------------------------------------------------------------------------
# octree (§4.2, §5.3)
# ----------------------------------------------------------------------------------------------

def _pyramid(mn, mx):
    K = max(1, int(math.ceil(math.log2(max(mn.shape)))))
    levels = [(mn, mx)]
    for _ in range(K):
        a, b = levels[-1]
        s = a.shape
        pad = [(0, (-d) % 2) for d in s]
        a = np.pad(a, pad, mode="edge")    # an edge copy changes neither min nor max
        b = np.pad(b, pad, mode="edge")
        a = a.reshape(a.shape[0] // 2, 2, a.shape[1] // 2, 2, a.shape[2] // 2, 2).min(axis=(1, 3, 5))
        b = b.reshape(b.shape[0] // 2, 2, b.shape[1] // 2, 2, b.shape[2] // 2, 2).max(axis=(1, 3, 5))
        levels.append((a, b))
    return levels


def _leaves(levels, eps, eps2, ds_max, shape):
    K = len(levels) - 1
    level = np.full(shape, -1, np.int8)
    smax = np.full(shape, ds_max, np.float32)
    I, J, Kk = np.meshgrid(*[np.arange(s) for s in shape], indexing="ij")
    for L in range(K, -1, -1):
        a, b = levels[L]
        rng = (b - a)[I >> L, J >> L, Kk >> L]
        new = (level < 0) & (rng < eps2)
        level[new] = L
        smax[new] = np.where(rng[new] < eps, np.inf, ds_max)
    level[level < 0] = 0
    return level, smax


def octree(ior, vol, bugs=()):
    """Pass ``octree``: ``level`` int8, ``step_max`` and ``view_step_max`` float32 (voxels).

    A min/max pyramid; the coarsest node whose range is below eps' is the leaf (its level), and
    its step is unbounded when the range is also below eps, else ``ds_max``. ``stepping = paper``:
    level-0 ranges are single voxels; ``view_step_max`` always uses 26-neighbour-dilated ranges.

    References
    ----------
    Sun 2008 §4.2 (Fig. 4), §5.3 (epsilon, epsilon').
    """
    from scipy.ndimage import maximum_filter, minimum_filter
    eps, eps2, ds_max = float(vol["eps"]), float(vol["eps2"]), float(vol["ds_max"])
    if "eps_swap" in bugs:
        eps, eps2 = eps2, eps
    level, smax = _leaves(_pyramid(ior, ior), eps, eps2, ds_max, ior.shape)
    dl = _pyramid(minimum_filter(ior, size=3, mode="nearest"), maximum_filter(ior, size=3, mode="nearest"))
    _, vsmax = _leaves(dl, eps, eps2, ds_max, ior.shape)
    return level, smax, vsmax


# ----------------------------------------------------------------------------------------------
# photons (§4.3)
# ----------------------------------------------------------------------------------------------

def _slab(org, d, blo, bhi):
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (blo - org) / d
        t1 = (bhi - org) / d
    t_in = np.maximum(np.max(np.minimum(t0, t1), axis=1), 0.0)
    t_out = np.min(np.maximum(t0, t1), axis=1)
    return t_in, t_out


def _corners(lo, hi):
    return np.array([[(lo, hi)[a][0], (lo, hi)[b][1], (lo, hi)[c][2]]
                     for a in (0, 1) for b in (0, 1) for c in (0, 1)])


def light_texels(light, lo, hi, N, M, bugs=()):
    """Texel ray origins, directions and start radiance of one light's photon texture, and its
    grid (e1, e2, u0, du, v0, dv, M) for ``_first_hits``."""
    rad = _rgb(light["radiance"])
    h = (hi - lo) / N
    h2 = (h[0] * h[1] * h[2]) ** (2.0 / 3.0)
    C = _corners(lo, hi)
    if light["type"] != "directional":
        raise NotImplementedError("point lights: not ported (no volumetric golden case uses one)")
    d = np.asarray(light["direction"], np.float64)
    d = d / np.linalg.norm(d)
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(d, a)
    e1 = e1 / np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    ac, cc = C @ e1, C @ e2
    ca, cm = (ac.min() + ac.max()) / 2.0, (cc.min() + cc.max()) / 2.0
    side = max(np.ptp(ac), np.ptp(cc)) * (1.0 + 1e-9)
    dmin = (C @ d).min() - 1.0
    s = (np.arange(M) + 0.5) / M - 0.5
    rr, q = np.divmod(np.arange(M * M), M)
    row_sign = 1.0 if "window_flip" in bugs else -1.0
    org = ((ca + s[q] * side)[:, None] * e1 + (cm + row_sign * s[rr] * side)[:, None] * e2
           + dmin * d)
    L = rad * (side / M) ** 2 / h2
    grid = (e1, e2, ca + s[0] * side, side / M, cm + row_sign * s[0] * side, row_sign * side / M, M)
    return org, np.broadcast_to(d, org.shape).copy(), np.broadcast_to(L, org.shape).copy(), grid


def _inflated_proxy(objs, hmin, inflate):
    """Each object's mesh welded by position, wound outwards, and moved out along its vertex
    normals by ``inflate * hmin / max(c, 0.5)``."""
    Vs, Fs, base = [], [], 0
    for V, F, _, _ in objs:
        uq, inv = np.unique(V, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        Fw = inv[F]
        Fw = Fw[(Fw[:, 0] != Fw[:, 1]) & (Fw[:, 1] != Fw[:, 2]) & (Fw[:, 0] != Fw[:, 2])]
        fn = np.cross(uq[Fw[:, 1]] - uq[Fw[:, 0]], uq[Fw[:, 2]] - uq[Fw[:, 0]])
        # wound outwards: signed volume positive
        vol6 = np.sum(np.einsum("ij,ij->i", uq[Fw[:, 0]], fn))
        if vol6 < 0:
            Fw = Fw[:, [0, 2, 1]]
            fn = -fn
        vn = np.zeros_like(uq)
        for c in range(3):
            np.add.at(vn, Fw[:, c], fn)
        ln = np.linalg.norm(vn, axis=1)
        vn = vn / np.where(ln > 0, ln, 1.0)[:, None]
        fl = np.linalg.norm(fn, axis=1)
        fu = fn / np.where(fl > 0, fl, 1.0)[:, None]
        cmin = np.full(len(uq), np.inf)
        for c in range(3):
            np.minimum.at(cmin, Fw[:, c], np.einsum("ij,ij->i", vn[Fw[:, c]], fu))
        disp = inflate * hmin / np.maximum(cmin, 0.5)
        Vs.append(uq + vn * disp[:, None])
        Fs.append(Fw + base)
        base += len(uq)
    return np.concatenate(Vs), np.concatenate(Fs)


def _first_hits(org, d, V, F, grid):
    """Nearest hit of a light's parallel texel rays ``org + t d`` on triangles (Moller-Trumbore,
    two-sided), every (triangle, texel) pair of the triangle's footprint at once.

    grid = (e1, e2, u0, du, v0, dv, M): texel (rr, q) has ``org . e1 = u0 + q du`` and
    ``org . e2 = v0 + rr dv``.

    Returns
    -------
    t (T,) float64, inf where no hit; front (T,) bool: the hit face's normal opposes d (ties in t
    go to the lower triangle index).
    """
    e1g, e2g, u0, du, v0, dv, M = grid
    T = len(org)
    v0_, v1_, v2_ = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    q = (np.stack([v0_ @ e1g, v1_ @ e1g, v2_ @ e1g], 1) - u0) / du
    r = (np.stack([v0_ @ e2g, v1_ @ e2g, v2_ @ e2g], 1) - v0) / dv
    q0 = np.clip(np.ceil(q.min(1) - 1e-6), 0, M).astype(np.int64)
    q1 = np.clip(np.floor(q.max(1) + 1e-6), -1, M - 1).astype(np.int64)
    r0 = np.clip(np.ceil(r.min(1) - 1e-6), 0, M).astype(np.int64)
    r1 = np.clip(np.floor(r.max(1) + 1e-6), -1, M - 1).astype(np.int64)
    nq = np.maximum(q1 - q0 + 1, 0)
    n = nq * np.maximum(r1 - r0 + 1, 0)
    tri = np.repeat(np.arange(len(F)), n)
    k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    tex = (r0[tri] + k // nq[tri]) * M + q0[tri] + k % nq[tri]
    e1, e2 = v1_ - v0_, v2_ - v0_
    pvec = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, pvec)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det[tri]
        tvec = org[tex] - v0_[tri]
        uu = np.einsum("ij,ij->i", tvec, pvec[tri]) * inv
        qv = np.cross(tvec, e1[tri])
        vv = (qv @ d) * inv
        t = np.einsum("ij,ij->i", qv, e2[tri]) * inv
        ok = (det[tri] != 0) & (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & (t > 0)
    tri, tex, t = tri[ok], tex[ok], t[ok]
    o = np.lexsort((tri, t, tex))
    tri, tex, t = tri[o], tex[o], t[o]
    firsts = np.ones(len(tex), bool)
    firsts[1:] = tex[1:] != tex[:-1]
    best = np.full(T, np.inf)
    front = np.zeros(T, bool)
    best[tex[firsts]] = t[firsts]
    front[tex[firsts]] = (np.cross(e1, e2)[tri[firsts]] @ d) < 0
    return best, front


def photons(sc, ior, lo, hi, objs, bugs=()):
    """Pass ``photons``: ``start_pos``, ``start_dir``, ``start_radiance`` (P, 3) float64.

    One photon per texel of each light's square orthographic texture whose ray meets the proxy
    (``proxy = inflated``) or the box (``proxy = box``), lights in scene order, texels row-major.

    References
    ----------
    Sun 2008 §4.3 (photon generation from a light's texture, proxy geometry).
    """
    vol = sc["vol"]
    M = int(vol["photons"])
    N = np.array(ior.shape)
    h = (hi - lo) / N
    hmin = float(h.min())
    pos, dirs, rads = [], [], []
    for light in sc["lights"]:
        org, d, L, grid = light_texels(light, lo, hi, N, M, bugs)
        t_box, t_out_box = _slab(org, d, lo, hi)
        hit_box = t_out_box > t_box
        if vol["proxy"] == "box":
            t, keep = t_box, hit_box
        elif not objs:
            g = float(vol["proxy_inflate"])
            idx = np.nonzero(np.abs(ior - sc["outside_ior"]) >= 1e-6)
            if len(idx[0]) == 0:
                keep = np.zeros(len(org), bool)
                t = t_box
            else:
                first = np.array([i.min() for i in idx], np.float64)
                last = np.array([i.max() for i in idx], np.float64)
                blo = np.maximum(lo + (first - g) * h, lo)
                bhi = np.minimum(lo + (last + 1 + g) * h, hi)
                t, t_out = _slab(org, d, blo, bhi)
                keep = t_out > t
        else:
            Vp, Fp = _inflated_proxy(objs, hmin, float(vol["proxy_inflate"]))
            th, front = _first_hits(org, d[0], Vp, Fp, grid)
            keep = np.isfinite(th) & hit_box & (th <= t_out_box)
            use_box = (~front) | (th < t_box)
            t = np.where(use_box, t_box, th)
        p = np.clip(org + t[:, None] * d, lo, hi)
        pos.append(p[keep])
        dirs.append(d[keep])
        rads.append(L[keep])
    return np.concatenate(pos), np.concatenate(dirs), np.concatenate(rads)


# ----------------------------------------------------------------------------------------------
# march (§4.4, eqs. 4-6)
# ----------------------------------------------------------------------------------------------

def _voxel_of(x, lo, h, N):
    with np.errstate(invalid="ignore"):
        c = np.floor((x - lo) / h)
    c = np.where(np.isnan(c), 0, c)
    return np.clip(c, 0, N - 1).astype(np.int64)


def sample_field(field, x, lo, h, N, bugs=()):
    """Trilinear lookup of ``field`` at world points x (P, 3) -> (P, 4) float64.

    Values clamp at the outer voxel centres; weights wx wy wz; float32 values, float64 sums.
    """
    with np.errstate(invalid="ignore"):
        u = (x - lo) / h - (0.0 if "half_voxel" in bugs else 0.5)
        low = (u < 0) | np.isnan(u)
        high = u >= N - 1
        cell = np.where(low, 0, np.where(high, N - 2, np.floor(np.where(low | high, 0, u))))
        fr = np.where(low, 0.0, np.where(high, 1.0, u - cell))
    cell = cell.astype(np.int64)
    out = np.zeros((len(x), field.shape[-1]))
    for dx in (0, 1):
        wx = fr[:, 0] if dx else 1.0 - fr[:, 0]
        for dy in (0, 1):
            wy = fr[:, 1] if dy else 1.0 - fr[:, 1]
            for dz in (0, 1):
                wz = fr[:, 2] if dz else 1.0 - fr[:, 2]
                val = field[cell[:, 0] + dx, cell[:, 1] + dy, cell[:, 2] + dz].astype(np.float64)
                out += (wx * wy * wz)[:, None] * val
    return out


def _axis_distance(x, u, lo, h, N, L):
    U = (x - lo) / h
    c = np.where(U > 0, np.floor(np.where(U > 0, U, 0)), 0).astype(np.int64)
    b0 = (c >> L[:, None]) << L[:, None]
    size = np.left_shift(1, L)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        up = (np.minimum(b0 + size, N) - U) * h / u
        dn = (b0 - U) * h / u
    return np.where(u == 0, np.inf, np.where(u > 0, up, dn))


def extinction(sc, ior, absorb):
    """kappa (nx, ny, nz, 3) float32: the medium's scattering + absorption (+ objects' absorption
    weighted by coverage), or ``volume.extinction``."""
    v = sc["raw"].get("volume") or {}
    if v.get("extinction") is not None:
        e = v["extinction"]
        e = np.load(os.path.join(sc["dir"], e)) if isinstance(e, str) else np.asarray(e, np.float64)
        if e.ndim <= 1:
            e = np.broadcast_to(_rgb(e), ior.shape + (3,))
        elif e.ndim == 3:
            e = np.repeat(e[..., None], 3, -1)
        return np.asarray(e, np.float32)
    vol = sc["vol"]
    k = _rgb(vol["scattering"]) + _rgb(vol["absorption"]) + absorb
    return np.broadcast_to(k, ior.shape + (3,)).astype(np.float32)


def segment_voxels(p0, p1, N):
    """The voxels each segment p0 -> p1 (voxel coordinates, (S, 3)) crosses, as a 3D DDA visits
    them, all segments at once: the crossings of the integer planes on each axis, sorted per
    segment, give the intervals; each interval's voxel is the floor of its midpoint.

    Returns
    -------
    seg (K,) segment index, vox (K, 3) int64, t0, t1 (K,) segment parameters where it enters and
    leaves that voxel; voxels outside the grid are dropped (the walk stops at the grid's edge).
    """
    S = len(p0)
    d = p1 - p0
    f0, f1 = np.floor(p0), np.floor(p1)
    segs, ts = [np.arange(S)], [np.zeros(S)]
    for a in range(3):
        lo_a = np.minimum(f0[:, a], f1[:, a])
        n = np.abs(f1[:, a] - f0[:, a]).astype(np.int64)
        sid = np.repeat(np.arange(S), n)
        k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        plane = lo_a[sid] + 1 + k
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (plane - p0[sid, a]) / d[sid, a]
        segs.append(sid)
        ts.append(np.clip(t, 0.0, 1.0))
    segs.append(np.arange(S))
    ts.append(np.ones(S))
    sid = np.concatenate(segs)
    t = np.concatenate(ts)
    o = np.lexsort((t, sid))
    sid, t = sid[o], t[o]
    same = sid[1:] == sid[:-1]
    a0, a1, sg = t[:-1][same], t[1:][same], sid[:-1][same]
    keep = a1 > a0
    a0, a1, sg = a0[keep], a1[keep], sg[keep]
    mid = p0[sg] + ((a0 + a1) / 2.0)[:, None] * d[sg]
    vox = np.floor(mid).astype(np.int64)
    ok = np.all((vox >= 0) & (vox < N), axis=1)
    return sg[ok], vox[ok], a0[ok], a1[ok]


def deposit(rad_acc, dir_acc, x, e, L, L1, lo, h, N):
    """Add segments x -> e of radiance L -> L1 to the accumulators (Sun 2008 §4.4): each crossed
    voxel gets ``(L + (L1 - L) (t0 + t1) / 2) (t1 - t0) lv`` (lv the length in voxels) and its
    direction sums ``dir * sum(that)``."""
    p0, p1 = (x - lo) / h, (e - lo) / h
    lv = np.sqrt(np.sum((p1 - p0) ** 2, axis=1))
    seg = np.sqrt(np.sum((e - x) ** 2, axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        dr = (e - x) / seg[:, None]
    sg, vox, t0, t1 = segment_voxels(p0, p1, N)
    w = (L[sg] + (L1[sg] - L[sg]) * ((t0 + t1) / 2.0)[:, None]) * ((t1 - t0) * lv[sg])[:, None]
    flat = (vox[:, 0] * N[1] + vox[:, 1]) * N[2] + vox[:, 2]
    for c in range(3):
        rad_acc[:, c] += np.bincount(flat, w[:, c], minlength=len(rad_acc))
        dir_acc[:, c] += np.bincount(flat, dr[sg, c] * w.sum(axis=1), minlength=len(dir_acc))


def skipped_attenuation(start_pos, start_dir, kappa, lo, hi):
    """exp(-sum kappa_voxel length_in_voxel) over the part of each texel ray inside the box that a
    proxy start skipped (entry -> start), (P, 3)."""
    N = np.array(kappa.shape[:3])
    h = (hi - lo) / N
    t_in, t_out = _slab(start_pos, -start_dir, lo, hi)
    t = np.where(np.isfinite(t_out), np.maximum(t_out, 0.0), 0.0)
    entry = start_pos - t[:, None] * start_dir
    p0, p1 = (entry - lo) / h, (start_pos - lo) / h
    sg, vox, t0, t1 = segment_voxels(p0, p1, N)
    length = np.sqrt(np.sum((start_pos - entry) ** 2, axis=1))
    tau = np.zeros((len(start_pos), 3))
    k = kappa[vox[:, 0], vox[:, 1], vox[:, 2]].astype(np.float64)
    for c in range(3):
        tau[:, c] = np.bincount(sg, k[:, c] * (t1 - t0) * length[sg], minlength=len(start_pos))
    return np.exp(-tau)


def march(field, level, step_max, kappa, start_pos, start_dir, start_rad, lo, hi, vol,
          bugs=(), record=None, deposit_steps=None):
    """Pass ``march``: adaptive photon marching, all photons vectorised, one loop over steps.

    Returns
    -------
    dict of ``exit_pos``, ``exit_dir`` (P, 3) float64 (NaN unless status 1), ``photon_status``
    (P,) int8, ``steps`` (P,) int64 (before the stopping rule), ``paths`` (len(record), 257, 3)
    when ``record`` (photon indices) is given; with ``deposit_steps`` (the stopping rule's cut, or
    a step count no photon reaches) also ``rad_acc``, ``dir_acc`` (nx*ny*nz, 3) float64: the
    deposits of every photon's first ``deposit_steps`` steps.

    References
    ----------
    Sun 2008 §4.4, eqs. 4-5 (x += ds/n v, v += ds grad n), eq. 6 (attenuation), §5.3 (the
    octree's step bound).
    """
    N = np.array(field.shape[:3])
    h = (hi - lo) / N
    hmin = float(h.min())
    ds_min = float(vol["ds_min"])
    max_steps = int(vol["max_steps"]) or int(math.ceil(8 * N.max() / ds_min)) + 16
    P = len(start_pos)
    x = start_pos.copy()
    n0 = sample_field(field, x, lo, h, N, bugs)[:, 0]
    v = n0[:, None] * start_dir
    L = start_rad * skipped_attenuation(start_pos, start_dir, kappa, lo, hi)
    L_start_max = L.max(axis=1)
    if deposit_steps is not None:
        rad_acc = np.zeros((int(np.prod(N)), 3))
        dir_acc = np.zeros((int(np.prod(N)), 3))
    status = np.zeros(P, np.int8)
    steps = np.zeros(P, np.int64)
    exit_pos = np.full((P, 3), np.nan)
    exit_dir = np.full((P, 3), np.nan)
    active = np.arange(P)
    paths = None
    if record is not None:
        paths = np.full((len(record), 257, 3), np.nan)
        paths[:, 0] = start_pos[record]
        slot = np.full(P, -1)
        slot[record] = np.arange(len(record))
    for it in range(max_steps):
        if len(active) == 0:
            break
        xa, va = x[active], v[active]
        c = _voxel_of(xa, lo, h, N)
        cap = step_max[c[:, 0], c[:, 1], c[:, 2]].astype(np.float64)
        Lv = level[c[:, 0], c[:, 1], c[:, 2]].astype(np.int64)
        f = sample_field(field, xa, lo, h, N, bugs)
        n, g = f[:, 0], f[:, 1:]
        speed = np.sqrt(np.sum(va * va, axis=1))
        ok = (speed > 1e-12 * n) & (n > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = va / speed[:, None]
            dist = _axis_distance(xa, u, lo, h, N, Lv)
        ds = np.maximum(np.min(dist, axis=1), 0.0)
        if "no_nudge" not in bugs:
            ds = ds + 1e-4 * hmin
        hi_cap = float(vol["ds_max"]) if "step_ds_max" in bugs else cap
        ds = np.minimum(np.maximum(ds, ds_min * hmin), hi_cap * hmin)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            x1 = xa + (ds / n)[:, None] * va
            v1 = va + ds[:, None] * g
        ok &= np.all(np.isfinite(x1), axis=1) & np.all(np.isfinite(v1), axis=1)
        # clip to the box
        s = np.ones(len(active))
        with np.errstate(divide="ignore", invalid="ignore"):
            for a in range(3):
                up = (x1[:, a] > hi[a]) & (x1[:, a] > xa[:, a])
                dn = (x1[:, a] < lo[a]) & (x1[:, a] < xa[:, a])
                s = np.where(up, np.minimum(s, (hi[a] - xa[:, a]) / (x1[:, a] - xa[:, a])), s)
                s = np.where(dn, np.minimum(s, (lo[a] - xa[:, a]) / (x1[:, a] - xa[:, a])), s)
        s = np.maximum(s, 0.0)
        e = xa + s[:, None] * (x1 - xa)
        seg = np.sqrt(np.sum((e - xa) ** 2, axis=1))
        L1 = L[active] * np.exp(-kappa[c[:, 0], c[:, 1], c[:, 2]].astype(np.float64) * seg[:, None])
        lost = active[~ok]
        status[lost] = 4
        go = ok
        idx = active[go]
        steps[idx] += 1
        if deposit_steps is not None and it < deposit_steps:
            deposit(rad_acc, dir_acc, xa[go], e[go], L[idx], L1[go], lo, h, N)
        if paths is not None and it < 256:
            sl = slot[idx]
            m = sl >= 0
            paths[sl[m], it + 1] = e[go][m]
        out = go & (s < 1.0)
        io = active[out]
        status[io] = 1
        exit_pos[io] = e[out]
        vd = np.where((s[out] == 0.0)[:, None], v1[out], va[out] + (s[out] * ds[out])[:, None] * g[out])
        exit_dir[io] = vd / np.linalg.norm(vd, axis=1)[:, None]
        cont = go & ~(s < 1.0)
        ic = active[cont]
        x[ic], v[ic], L[ic] = x1[cont], v1[cont], L1[cont]
        absorbed = L1[cont].max(axis=1) < float(vol["min_radiance"]) * L_start_max[ic]
        status[ic[absorbed]] = 3
        active = ic[~absorbed]
    status[active] = 2
    out = {"exit_pos": exit_pos, "exit_dir": exit_dir, "photon_status": status, "steps": steps,
           "paths": paths}
    if deposit_steps is not None:
        out["rad_acc"], out["dir_acc"] = rad_acc, dir_acc
    return out


def stop_cut(steps, vol):
    """The stopping rule's cut (``stop_fraction``): the step count beyond which photons are cut;
    None when the rule is off."""
    f = float(vol["stop_fraction"])
    if f > 0 and len(steps):
        k = int(math.ceil(f * len(steps))) - 1
        return int(np.sort(steps)[::-1][max(k, 0)])
    return None


def stopping_rule(m, vol):
    """The ensemble stopping rule (``stop_fraction``): photons with more than ``cut`` steps are
    cut there (status 2, exit rows NaN). Returns the total step count (int64)."""
    steps = m["steps"].copy()
    f = float(vol["stop_fraction"])
    P = len(steps)
    if f > 0 and P:
        k = int(math.ceil(f * P)) - 1
        cut = np.sort(steps)[::-1][max(k, 0)]
        over = steps > cut
        m["photon_status"][over] = 2
        m["exit_pos"][over] = np.nan
        m["exit_dir"][over] = np.nan
        steps[over] = cut
    m["steps"] = steps
    return np.int64(steps.sum())


def smooth(rad_acc, dir_acc, shape):
    """Pass ``smooth``: the deposits filtered by [1/4, 1/2, 1/4] along x, y, z (edges clamped);
    ``radiance`` float32 and ``direction`` float32 (unit, zero where no photon passed)."""
    from scipy.ndimage import correlate1d
    w = np.array([0.25, 0.5, 0.25])
    r = rad_acc.reshape(shape + (3,))
    d = dir_acc.reshape(shape + (3,))
    for ax in range(3):
        r = correlate1d(r, w, axis=ax, mode="nearest")
        d = correlate1d(d, w, axis=ax, mode="nearest")
    n = np.sqrt(np.sum(d * d, axis=-1, keepdims=True))
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(n > 0, d / n, 0.0)
    return r.astype(np.float32), d.astype(np.float32)


def path_index(P):
    """The inspection sample of ``photon_paths``: 64 evenly spaced photon indices."""
    if P <= 64:
        return np.arange(P, dtype=np.int64)
    return np.unique(np.round(np.linspace(0, P - 1, 64)).astype(np.int64))


# ----------------------------------------------------------------------------------------------
# driver
# ----------------------------------------------------------------------------------------------

def render_case(scene_path, bugs=()):
    """Every pass from ``voxelize`` to ``march`` on one scene -> dict of golden-named arrays."""
    unknown = set(bugs) - set(BUGS)
    if unknown:
        raise ValueError(f"unknown bug flag(s) {sorted(unknown)}; known: {sorted(BUGS)}")
    sc = read_scene(scene_path)
    vol = sc["vol"]
    ior, lo, hi, absorb, objs = voxelize(sc, bugs)
    field = gradient(ior, lo, hi, bugs)
    level, smax, vsmax = octree(ior, vol, bugs)
    sp, sd, srad = photons(sc, ior, lo, hi, objs, bugs)
    kappa = extinction(sc, ior, absorb)
    rec = path_index(len(sp))
    m = march(field, level, smax, kappa, sp, sd, srad, lo, hi, vol, bugs, record=rec)
    total = stopping_rule(m, vol)
    # the deposits of the steps the stopping rule keeps: the march again, depositing the first
    # `cut` steps (photons are independent, so the second march retraces the first)
    cut = stop_cut(march(field, level, smax, kappa, sp, sd, srad, lo, hi, vol, bugs)["steps"], vol)
    dm = march(field, level, smax, kappa, sp, sd, srad, lo, hi, vol, bugs,
               deposit_steps=cut if cut is not None else 1 << 62)
    radiance, direction = smooth(dm["rad_acc"], dm["dir_acc"], ior.shape)
    return {
        "ior": ior, "volume_bounds": np.stack([lo, hi]),
        "stage.voxelize.ior_volume": ior,
        "stage.gradient.field": field,
        "stage.octree.level": level, "stage.octree.step_max": smax, "stage.octree.view_step_max": vsmax,
        "stage.photons.start_pos": sp, "stage.photons.start_dir": sd, "stage.photons.start_radiance": srad,
        "stage.march.exit_pos": m["exit_pos"], "stage.march.exit_dir": m["exit_dir"],
        "stage.march.photon_status": m["photon_status"],
        # no receivers in this port: no photon meets one
        "stage.march.hit_pos": np.full((len(sp), 3), np.nan),
        "stage.march.hit_receiver": np.full(len(sp), -1, np.int32),
        "photon_exit_pos": m["exit_pos"], "photon_exit_dir": m["exit_dir"],
        "photon_status": m["photon_status"], "photon_steps": total,
        "stage.photon_paths.paths": m["paths"], "stage.photon_paths.path_index": rec,
        "stage.smooth.radiance": radiance, "stage.smooth.direction": direction,
        "radiance": radiance, "direction": direction,
    }


def volumetric_cases(golden_dir):
    """Names of the golden suite's volumetric cases (from its manifest)."""
    with open(os.path.join(golden_dir, "manifest.json")) as f:
        man = json.load(f)
    cases = man.get("cases", {})
    return sorted(c for c, v in cases.items() if v.get("method") == "volumetric")


def run(golden_dir, out_dir, cases=None, bugs=()):
    """Write ``out_dir/<case>/result.npz`` for each volumetric case of a golden suite.

    Parameters
    ----------
    golden_dir : a suite made by ``refraction-ref golden build``
    out_dir : the candidate folder for ``refraction-ref check``
    cases : case names (default: every volumetric case in the manifest)
    bugs : planted bug flags (``BUGS``)
    """
    cases = list(cases) if cases is not None else volumetric_cases(golden_dir)
    for case in cases:
        res = render_case(os.path.join(golden_dir, case, "scene.json"), bugs)
        os.makedirs(os.path.join(out_dir, case), exist_ok=True)
        np.savez(os.path.join(out_dir, case, "result.npz"), **res)
    return cases


def main(argv=None):
    """``python volumetric.py GOLDEN CAND [--cases A,B] [--bug NAME ...]``."""
    import argparse
    ap = argparse.ArgumentParser(description="clean-room NumPy volumetric backend (Sun 2008)")
    ap.add_argument("golden")
    ap.add_argument("out")
    ap.add_argument("--cases", default=None, help="comma list (default: every volumetric case)")
    ap.add_argument("--bug", action="append", default=[], choices=sorted(BUGS))
    a = ap.parse_args(argv)
    done = run(a.golden, a.out, a.cases.split(",") if a.cases else None, tuple(a.bug))
    print(f"wrote {len(done)} case(s) to {a.out}: {', '.join(done)}")


if __name__ == "__main__":
    main()
