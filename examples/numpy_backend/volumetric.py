"""Clean-room NumPy port of the volumetric method (Sun et al. 2008), ``voxelize`` to ``view``.

Written from ``docs/oracle.md`` ("Porting rules: volumetric", "Volumetric",
"Stage buffers") and ``docs/backends.md`` alone, without the package's
source, the way a GPU port is structured: one function per pass, every pass
vectorised over voxels, texels or photons (the march loops over steps with
all active photons at once, as a compute shader dispatch per step would). The
receivers, caustic maps and viewing pass are in ``volumetric_view.py``.

``run(golden_dir, out_dir)`` reads each volumetric case's ``scene.json``
from a golden suite and writes ``out_dir/<case>/result.npz`` with the
golden key names, shapes and dtypes, ready for ``refraction-ref check``.
``bugs=`` plants mistakes that porters really make (``BUGS``), to show that
``check`` names the pass that holds them.

References
----------
X. Sun, K. Zhou, E. Stollnitz, J. Shi, B. Guo, *Interactive Relighting of
Dynamic Refractive Objects*, ACM TOG 27(3), 2008: §4.1 (voxelize), §3 eq. 3
(gradient), §4.2 and §5.3 (octree), §4.3 (photons), §4.4 eqs. 4-6 (march), Fig. 9
(receivers), §4.5 (view).
"""
from __future__ import annotations

import json
import math
import os

import numpy as np

try:                                   # the sibling helper module, loaded by path or as a script
    import volumetric_view as vv
except ImportError:
    import importlib.util as _ilu
    _spec = _ilu.spec_from_file_location(
        "volumetric_view", os.path.join(os.path.dirname(os.path.abspath(__file__)), "volumetric_view.py"))
    vv = _ilu.module_from_spec(_spec)
    _spec.loader.exec_module(vv)

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
    "deposit_no_length": ("march: a deposit not scaled by its segment length (in voxels)", "march"),
    "no_extinction": ("march: no extinction along the photon's steps (eq. 6 left out)", "march"),
    "exit_dir_full_step": ("march: the photon's exit direction from the full step's v1, not the "
                           "step redone over the part inside the box", "march"),
    "no_receivers": ("march: receivers inside the volume ignored (photons pass through them)", "march"),
    "caustics_unmet": ("caustics: photons splatted whether or not they met refractive material",
                       "caustics"),
    "splat_no_cosine": ("caustics: the splat without |n . V|", "caustics"),
    "no_skip_attenuation": ("march: a proxy start without the extinction of the skipped segment",
                            "march"),
    "no_outside_hits": ("march: photons leaving the volume not continued to the receivers below it",
                        "march"),
    "kappa_float64": ("march/view: kappa kept in float64 (0.2, not float32's 0.20000000298)",
                      "none: inside every tolerance"),
    "view_entry_voxel_n": ("view: the inside flag at the box entry from the entry voxel's own n, "
                           "not the sampled n", "view"),
    "phase_sign": ("view: Henyey-Greenstein with the sign of g flipped", "view"),
    "view_along_ray_dir": ("view: status-0 pixels shaded along the written ray_dir/exit_dir, not the "
                           "bent direction at the box exit", "view"),
    "view_exit_full_step": ("view: the viewing ray's exit direction from the full step's v1", "view"),
    "view_drop_colour": ("view: the radiance gathered before a stop (status 2, 4) dropped", "view"),
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
    for r in raw.get("receivers") or []:
        if r.get("mesh", "plane") != "plane" or r.get("fit") is not None:
            raise ValueError(f"{path}: this port covers built-in `plane` receivers without `fit` only")
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
    """Slab test, half-open per axis: IEEE division; a NaN t0 (the ray in a lower face's plane)
    spans (-inf, inf), a NaN t1 propagates (the ray misses). Returns (t_in, t_out); the ray meets
    the box when t_out > t_in."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0 = (blo - org) * inv
        t1 = (bhi - org) * inv
    lo_t = np.where(np.isnan(t0), -np.inf, np.minimum(t0, t1))
    hi_t = np.where(np.isnan(t0), np.inf, np.maximum(t0, t1))
    t_in = np.maximum(lo_t.max(axis=1), 0.0)
    t_out = hi_t.min(axis=1)
    return t_in, t_out


def _corners(lo, hi):
    return np.array([[(lo, hi)[a][0], (lo, hi)[b][1], (lo, hi)[c][2]]
                     for a in (0, 1) for b in (0, 1) for c in (0, 1)])


def _point_texels(light, rad, h2, C, lo, hi, M):
    """A point light's texel rays: a square perspective camera at the light looking at the box
    centre (up +y, +x when |f_y| >= 0.9) whose window just covers the box's corners; the start
    radiance ``radiance domega / h2``, ``domega = (2 sx / M)(2 sy / M) cos^3``."""
    eye = np.asarray(light["position"], np.float64)
    f = (lo + hi) / 2.0 - eye
    f = f / np.linalg.norm(f)
    up = np.array([0.0, 1.0, 0.0]) if abs(f[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    r = np.cross(f, up)
    r = r / np.linalg.norm(r)
    u = np.cross(r, f)
    B = np.stack([r, u, -f])
    t = -eye @ B.T
    pv = C[:, 0:1] * B[:, 0] + C[:, 1:2] * B[:, 1] + C[:, 2:3] * B[:, 2] + t
    depth = -pv[:, 2]
    tt = (1.0 + 1e-9) * float(np.max(np.maximum(np.abs(pv[:, 0]), np.abs(pv[:, 1])) / depth))
    fov = np.degrees(2.0 * np.arctan(tt))
    sy = np.tan(np.radians(fov) / 2.0)
    sx = sy * M / M
    j = np.arange(M)[None, :]
    i = np.arange(M)[:, None]
    x = ((j + 0.5) / M * 2.0 - 1.0) * sx + 0.0 * i
    y = (1.0 - (i + 0.5) / M * 2.0) * sy + 0.0 * j
    sc_ = 1.0 / np.sqrt(x * x + y * y + 1.0)
    v = np.stack([x * sc_, y * sc_, -sc_], -1).reshape(-1, 3)
    d = v[:, 0:1] * B[0] + v[:, 1:2] * B[1] + v[:, 2:3] * B[2]
    domega = (2.0 * sx / M) * (2.0 * sy / M) * sc_.reshape(-1) ** 3
    L = rad[None, :] * (domega / h2)[:, None]
    return np.broadcast_to(eye, d.shape).copy(), d, L, None


def light_texels(light, lo, hi, N, M, bugs=()):
    """Texel ray origins, directions and start radiance of one light's photon texture, and its
    grid (e1, e2, u0, du, v0, dv, M) for ``_first_hits``."""
    rad = _rgb(light["radiance"])
    h = (hi - lo) / N
    h2 = (h[0] * h[1] * h[2]) ** (2.0 / 3.0)
    C = _corners(lo, hi)
    if light["type"] != "directional":
        return _point_texels(light, rad, h2, C, lo, hi, M)
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
    pos, dirs, rads, lids = [], [], [], []
    for li, light in enumerate(sc["lights"]):
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
            if grid is None:
                raise NotImplementedError("point lights on meshes (proxy = inflated): not ported; "
                                          "set volumetric.proxy = box or use volume input")
            Vp, Fp = _inflated_proxy(objs, hmin, float(vol["proxy_inflate"]))
            th, front = _first_hits(org, d[0], Vp, Fp, grid)
            keep = np.isfinite(th) & hit_box & (th <= t_out_box)
            use_box = (~front) | (th < t_box)
            t = np.where(use_box, t_box, th)
        p = np.clip(org + t[:, None] * d, lo, hi)
        pos.append(p[keep])
        dirs.append(d[keep])
        rads.append(L[keep])
        lids.append(np.full(int(keep.sum()), li, np.int64))
    return np.concatenate(pos), np.concatenate(dirs), np.concatenate(rads), np.concatenate(lids)


# ----------------------------------------------------------------------------------------------
# march (§4.4, eqs. 4-6)
# ----------------------------------------------------------------------------------------------

def _vcoord(x, lo, ih):
    """Voxel coordinates U = (x - lo) * ih (a product with the reciprocal, as the oracle)."""
    return (x - lo) * ih


def _voxel_of(x, lo, ih, N):
    with np.errstate(invalid="ignore"):
        U = _vcoord(x, lo, ih)
        c = np.floor(np.where(U > 0, U, 0.0))
    c = np.where(np.isnan(c), 0, c)
    return np.clip(c, 0, N - 1).astype(np.int64)


def sample_field(field, x, lo, ih, N, bugs=()):
    """Trilinear lookup of ``field`` at world points x (P, 3) -> (P, 4) float64.

    Values clamp at the outer voxel centres; weights wx wy wz; float32 values, float64 sums.
    """
    with np.errstate(invalid="ignore"):
        u = _vcoord(x, lo, ih) - (0.0 if "half_voxel" in bugs else 0.5)
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


def _axis_distance(x, u, lo, h, ih, N, L):
    U = _vcoord(x, lo, ih)
    c = np.where(U > 0, np.floor(np.where(U > 0, U, 0)), 0).astype(np.int64)
    b0 = (c >> L[:, None]) << L[:, None]
    size = np.left_shift(1, L)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        up = (np.minimum(b0 + size, N) - U) * h / u
        dn = (b0 - U) * h / u
    return np.where(u == 0, np.inf, np.where(u > 0, up, dn))


def extinction(sc, ior, absorb, bugs=()):
    """kappa (nx, ny, nz, 3) float32: ``volume.extinction`` rounded to float32, or the medium's
    ``float32(float64(float32(scattering)) + absorption)`` (+ float32 object absorption x
    coverage)."""
    v = sc["raw"].get("volume") or {}
    if v.get("extinction") is not None:
        e = v["extinction"]
        e = np.load(os.path.join(sc["dir"], e)) if isinstance(e, str) else np.asarray(e, np.float64)
        if e.ndim <= 1:
            e = np.broadcast_to(_rgb(e), ior.shape + (3,))
        elif e.ndim == 3:
            e = np.repeat(e[..., None], 3, -1)
        return np.ascontiguousarray(e, np.float32)
    vol = sc["vol"]
    k = (_rgb(vol["scattering"]).astype(np.float32).astype(np.float64)
         + _rgb(vol["absorption"])).astype(np.float32)
    if "kappa_float64" in bugs:
        return np.broadcast_to(_rgb(vol["scattering"]) + _rgb(vol["absorption"]) + absorb,
                               ior.shape + (3,)).astype(np.float64)
    k = np.broadcast_to(k, ior.shape + (3,)).astype(np.float32)
    if np.any(absorb):
        k = (k + absorb.astype(np.float32)).astype(np.float32)
    return k


def scattering(sc, shape):
    """sigma (nx, ny, nz, 3) float32 for the viewing pass: ``volume.scattering`` or the knob."""
    v = sc["raw"].get("volume") or {}
    s = v.get("scattering")
    if s is None:
        s = sc["vol"]["scattering"]
    s = np.load(os.path.join(sc["dir"], s)) if isinstance(s, str) else np.asarray(s, np.float64)
    if s.ndim <= 1:
        s = np.broadcast_to(_rgb(s), shape + (3,))
    elif s.ndim == 3:
        s = np.repeat(s[..., None], 3, -1)
    return np.ascontiguousarray(s, np.float32)


def dda_walk(x, e, lo, ih, N, clamp=False):
    """The voxels each segment x -> e (world, (S, 3)) crosses, by a 3D DDA (Amanatides-Woo) in
    voxel coordinates from the voxel of x, every segment at once (one loop over the walk).

    Returns
    -------
    seg (K,), vox (K, 3) int64, t0, t1 (K,) the segment parameters where it enters and leaves the
    voxel, lv (S,) the segment's length in voxels. The walk stops at the segment's end or the
    grid's edge (``clamp``: walks on past it, its voxels clamped to the grid); intervals of zero
    length are left out.
    """
    S = len(x)
    u0 = _vcoord(x, lo, ih)
    du = _vcoord(e, lo, ih) - u0
    lv = np.sqrt(np.sum(du * du, axis=1))
    with np.errstate(invalid="ignore"):
        v = np.clip(np.floor(np.where(u0 > 0, u0, 0.0)), 0, N - 1).astype(np.int64)
    step = np.where(du > 0, 1, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        tmax = np.where(du != 0, (v + (du > 0) - u0) / du, np.inf)
        tdel = np.where(du != 0, np.abs(1.0 / du), np.inf)
    t = np.zeros(S)
    act = np.arange(S)
    segs, voxs, t0s, t1s = [], [], [], []
    while len(act):
        tm = tmax[act]
        tn = np.minimum(tm.min(axis=1), 1.0)
        pos = tn - t[act] > 0
        segs.append(act[pos])
        voxs.append(np.clip(v[act[pos]], 0, N - 1))
        t0s.append(t[act[pos]]); t1s.append(tn[pos])
        go = tn < 1.0
        a = np.argmin(tm, axis=1)                     # ties: x before y before z
        ai, aa = act[go], a[go]
        v[ai, aa] += step[ai, aa]
        tmax[ai, aa] += tdel[ai, aa]
        inside = (v[ai, aa] >= 0) & (v[ai, aa] < N[aa]) if not clamp else np.ones(len(ai), bool)
        t[ai] = tn[go]
        act = ai[inside]
    if not segs:
        return (np.zeros(0, np.int64), np.zeros((0, 3), np.int64), np.zeros(0), np.zeros(0), lv)
    return np.concatenate(segs), np.concatenate(voxs), np.concatenate(t0s), np.concatenate(t1s), lv


class Deposits:
    """The photons' deposits as 64-bit fixed point (RGB in multiples of q, direction sums in
    multiples of 3 q, each share truncated towards zero), so sums are exact and order-free."""

    def __init__(self, nvox, L_start):
        self.q = 16.0 * float(np.sum(L_start.max(axis=1))) / 2.0 ** 58
        self.rgb = np.zeros((nvox, 3), np.int64)
        self.dirs = np.zeros((nvox, 3), np.int64)

    def add(self, x, e, L, L1, lo, ih, N, bugs=()):
        """Deposit the segments x -> e of radiance L -> L1 (Sun 2008 §4.4, eq. 6)."""
        if len(x) == 0 or self.q <= 0:
            return
        seg = np.sqrt(np.sum((e - x) ** 2, axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            dr = np.where((seg > 0)[:, None], (e - x) / seg[:, None], 0.0)   # a zero step adds nothing
        sg, vox, t0, t1, lv = dda_walk(x, e, lo, ih, N)
        length = np.ones_like(lv) if "deposit_no_length" in bugs else lv
        rgb = (L[sg] + (L1[sg] - L[sg]) * ((t0 + t1) / 2.0)[:, None]) * ((t1 - t0) * length[sg])[:, None]
        ds = dr[sg] * rgb.sum(axis=1)[:, None]
        flat = (vox[:, 0] * N[1] + vox[:, 1]) * N[2] + vox[:, 2]
        np.add.at(self.rgb, flat, np.trunc(rgb / self.q).astype(np.int64))
        np.add.at(self.dirs, flat, np.trunc(ds / (3.0 * self.q)).astype(np.int64))

    def sums(self):
        """(rgb, direction sums) float64 (nvox, 3)."""
        return self.rgb.astype(np.float64) * self.q, self.dirs.astype(np.float64) * (3.0 * self.q)


def skipped_attenuation(start_pos, start_dir, kappa, lo, hi):
    """exp(-sum kappa_voxel length_in_voxel) over the part of each texel ray inside the box that a
    proxy start skipped (entry -> start), the walk clamped to the grid, (P, 3)."""
    N = np.array(kappa.shape[:3])
    ih = 1.0 / ((hi - lo) / N)
    t_in, t_out = _slab(start_pos, -start_dir, lo, hi)
    t = np.where(np.isfinite(t_out), np.maximum(t_out, 0.0), 0.0)
    entry = start_pos - t[:, None] * start_dir
    sg, vox, t0, t1, _ = dda_walk(entry, start_pos, lo, ih, N, clamp=True)
    length = np.sqrt(np.sum((start_pos - entry) ** 2, axis=1))
    tau = np.zeros((len(start_pos), 3))
    k = kappa[vox[:, 0], vox[:, 1], vox[:, 2]].astype(np.float64)
    for c in range(3):
        tau[:, c] = np.bincount(sg, k[:, c] * (t1 - t0) * length[sg], minlength=len(start_pos))
    return np.exp(-tau)


def material_level(field, outside):
    """(n_half, side): the half-contrast level of the index and the side material lies on."""
    n = field[..., 0]
    hi_, lo_ = float(n.max()), float(n.min())
    far = hi_ if abs(hi_ - outside) >= abs(lo_ - outside) else lo_
    return outside + (far - outside) / 2.0, float(np.sign(far - outside))


def clip_box(x, x1, lo, hi):
    """The part s in [0, 1] of each step x -> x1 inside the box (axes moving out of it)."""
    s = np.ones(len(x))
    with np.errstate(divide="ignore", invalid="ignore"):
        for a in range(3):
            up = (x1[:, a] > hi[a]) & (x1[:, a] > x[:, a])
            dn = (x1[:, a] < lo[a]) & (x1[:, a] < x[:, a])
            s = np.where(up, np.minimum(s, (hi[a] - x[:, a]) / (x1[:, a] - x[:, a])), s)
            s = np.where(dn, np.minimum(s, (lo[a] - x[:, a]) / (x1[:, a] - x[:, a])), s)
    return np.maximum(s, 0.0)


def _dot(a, b):
    """Row-wise a . b as x x' + y y' + z z' (no BLAS, no fused multiply-add)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _ray_tris(o, D, tris, tmax):
    """Nearest hit of rays o + t D, t in (0, tmax], on triangles (T, 3, 3): two-sided
    Moller-Trumbore, triangles in order, a later one only when strictly nearer.
    Returns (t, tri): inf / -1 where none."""
    best = np.full(len(o), np.inf)
    tri = np.full(len(o), -1, np.int64)
    for k in range(len(tris)):
        v0, v1, v2 = tris[k]
        e1, e2 = v1 - v0, v2 - v0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            pv = np.cross(D, e2)
            det = _dot(pv, e1)
            inv = 1.0 / det
            tv = o - v0
            u = _dot(tv, pv) * inv
            qv = np.cross(tv, e1)
            w = _dot(D, qv) * inv
            t = _dot(qv, e2) * inv
            ok = ((det != 0) & np.isfinite(det) & (u >= 0) & (u <= 1) & (w >= 0) & (u + w <= 1)
                  & (t > 0) & (t <= tmax) & (t < best))
        best = np.where(ok, t, best)
        tri = np.where(ok, k, tri)
    return best, tri


def march(field, level, step_max, kappa, start_pos, start_dir, start_rad, lo, hi, vol, outside,
          bugs=(), record=None, deposit_cap=None, tris=None):
    """Pass ``march``: adaptive photon marching, all photons vectorised, one loop over steps.

    Returns
    -------
    dict of ``exit_pos``, ``exit_dir`` (P, 3) float64 (NaN unless status 1), ``photon_status``
    (P,) int8, ``steps`` (P,) int64 (before the stopping rule), ``hit_pos`` (P, 3), ``hit_tri``
    (P,) (the receiver triangle met inside the volume, -1 where none), ``T`` (P, 3) the
    transmittance at the end (``T_skip`` included), ``met`` (P,) bool (met refractive material),
    ``paths`` (len(record), 257, 3) when ``record`` is given; with ``deposit_cap`` (a step count)
    the march stops there and returns ``deposits`` (``Deposits``) of every step taken.

    References
    ----------
    Sun 2008 §4.4, eqs. 4-5 (x += ds/n v, v += ds grad n), eq. 6 (attenuation), §5.3 (the
    octree's step bound); Fig. 9 (receivers inside the volume).
    """
    N = np.array(field.shape[:3])
    h = (hi - lo) / N
    ih = 1.0 / h
    hmin = float(h.min())
    ds_min = float(vol["ds_min"])
    max_steps = int(vol["max_steps"]) or int(math.ceil(8 * N.max() / ds_min)) + 16
    if deposit_cap is not None:
        max_steps = min(max_steps, int(deposit_cap))
    P = len(start_pos)
    n_half, side = material_level(field, outside)
    x = start_pos.copy()
    n0 = sample_field(field, x, lo, ih, N, bugs)[:, 0]
    v = n0[:, None] * start_dir
    T = (np.ones_like(start_rad) if "no_skip_attenuation" in bugs
         else skipped_attenuation(start_pos, start_dir, kappa, lo, hi))
    L = start_rad * T
    L_start_max = L.max(axis=1)
    dep = Deposits(int(np.prod(N)), L) if deposit_cap is not None else None
    status = np.zeros(P, np.int8)
    steps = np.zeros(P, np.int64)
    met = np.zeros(P, bool)
    exit_pos = np.full((P, 3), np.nan)
    exit_dir = np.full((P, 3), np.nan)
    hit_pos = np.full((P, 3), np.nan)
    hit_tri = np.full(P, -1, np.int64)
    active = np.arange(P)
    paths = None
    if record is not None:
        paths = np.full((len(record), 257, 3), np.nan)
        paths[:, 0] = start_pos[record]
        slot = np.full(P, -1)
        slot[record] = np.arange(len(record))
    kap = kappa.astype(np.float64)
    for it in range(max_steps):
        if len(active) == 0:
            break
        xa, va = x[active], v[active]
        c = _voxel_of(xa, lo, ih, N)
        cap = step_max[c[:, 0], c[:, 1], c[:, 2]].astype(np.float64)
        Lv = level[c[:, 0], c[:, 1], c[:, 2]].astype(np.int64)
        f = sample_field(field, xa, lo, ih, N, bugs)
        n, g = f[:, 0], f[:, 1:]
        met[active] |= side * (n - n_half) > 0
        speed = np.sqrt(np.sum(va * va, axis=1))
        ok = (speed > 1e-12 * n) & (n > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = va * (1.0 / speed)[:, None]
            dist = _axis_distance(xa, u, lo, h, ih, N, Lv)
        ds = np.maximum(np.min(dist, axis=1), 0.0)
        if "no_nudge" not in bugs:
            ds = ds + 1e-4 * hmin
        hi_cap = float(vol["ds_max"]) if "step_ds_max" in bugs else cap
        ds = np.minimum(np.maximum(ds, ds_min * hmin), hi_cap * hmin)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            x1 = xa + (ds / n)[:, None] * va
            v1 = va + ds[:, None] * g
        ok &= np.all(np.isfinite(x1), axis=1) & np.all(np.isfinite(v1), axis=1)
        s = clip_box(xa, x1, lo, hi)
        rt = np.full(len(active), -1, np.int64)
        if tris is not None and len(tris) and "no_receivers" not in bugs:
            th, rt = _ray_tris(xa, x1 - xa, tris, s)
            rt = np.where(ok, rt, -1)
            s = np.where(rt >= 0, th, s)
        e = xa + s[:, None] * (x1 - xa)
        seg = np.sqrt(np.sum((e - xa) ** 2, axis=1))
        kv = kap[c[:, 0], c[:, 1], c[:, 2]]
        att = np.ones_like(kv) if "no_extinction" in bugs else np.exp(-kv * seg[:, None])
        L1 = L[active] * att
        T1 = T[active] * att
        status[active[~ok]] = 4
        go = ok
        idx = active[go]
        steps[idx] += 1
        if dep is not None:
            dep.add(xa[go], e[go], L[idx], L1[go], lo, ih, N, bugs)
        if paths is not None and it < 256:
            sl = slot[idx]
            m = sl >= 0
            paths[sl[m], it + 1] = e[go][m]
        hitm = go & (rt >= 0)
        ih_ = active[hitm]
        status[ih_] = 5
        hit_pos[ih_] = e[hitm]
        hit_tri[ih_] = rt[hitm]
        T[ih_] = T1[hitm]
        out = go & (rt < 0) & (s < 1.0)
        io = active[out]
        status[io] = 1
        exit_pos[io] = e[out]
        T[io] = T1[out]
        if "exit_dir_full_step" in bugs:
            vd = v1[out]
        else:
            vd = np.where((s[out] == 0.0)[:, None], v1[out],
                          va[out] + (s[out] * ds[out])[:, None] * g[out])
        exit_dir[io] = vd / np.sqrt(np.sum(vd * vd, axis=1))[:, None]
        cont = go & (rt < 0) & ~(s < 1.0)
        ic = active[cont]
        x[ic], v[ic], L[ic], T[ic] = x1[cont], v1[cont], L1[cont], T1[cont]
        absorbed = L1[cont].max(axis=1) < float(vol["min_radiance"]) * L_start_max[ic]
        status[ic[absorbed]] = 3
        active = ic[~absorbed]
    status[active] = 2
    return {"exit_pos": exit_pos, "exit_dir": exit_dir, "photon_status": status, "steps": steps,
            "hit_pos": hit_pos, "hit_tri": hit_tri, "T": T, "met": met, "paths": paths,
            "deposits": dep}


def outside_hits(m, tris, lo, hi, bugs=()):
    """Status-1 photons go on straight from their exit to the first receiver outside the box:
    fills ``hit_pos`` and ``hit_tri`` of those that meet one (status stays 1)."""
    if tris is None or not len(tris) or "no_outside_hits" in bugs:
        return
    io = np.flatnonzero(m["photon_status"] == 1)
    if not len(io):
        return
    tmax = 1e6 * (1.0 + float(np.max(np.abs(lo))) + float(np.max(np.abs(hi))))
    o, D = m["exit_pos"][io], m["exit_dir"][io]
    t, k = _ray_tris(o, D, tris, tmax)
    hm = k >= 0
    m["hit_pos"][io[hm]] = o[hm] + t[hm, None] * D[hm]
    m["hit_tri"][io[hm]] = k[hm]


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
        m["hit_pos"][over] = np.nan
        m["hit_tri"][over] = -1
        steps[over] = cut
    m["steps"] = steps
    return np.int64(steps.sum())


def smooth(rad_acc, dir_acc, shape):
    """Pass ``smooth``: the deposits filtered by [1/4, 1/2, 1/4] along x, then y, then z (edges
    clamped) in float64 on the six sums, rounded once; ``radiance`` float32 and ``direction``
    float32 (unit, zero where no photon passed)."""
    a = np.concatenate([rad_acc, dir_acc], axis=1).reshape(shape + (6,))
    for ax in range(3):
        m = np.moveaxis(a, ax, 0)
        prev = np.concatenate([m[:1], m[:-1]])
        nxt = np.concatenate([m[1:], m[-1:]])
        a = np.moveaxis(m * 0.5 + (prev + nxt) * 0.25, 0, ax)
    r, d = a[..., :3], a[..., 3:]
    n = np.sqrt(d[..., 0:1] ** 2 + d[..., 1:2] ** 2 + d[..., 2:3] ** 2)
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
    """Every pass from ``voxelize`` to ``view`` on one scene -> dict of golden-named arrays."""
    unknown = set(bugs) - set(BUGS)
    if unknown:
        raise ValueError(f"unknown bug flag(s) {sorted(unknown)}; known: {sorted(BUGS)}")
    sc = read_scene(scene_path)
    vol, raw = sc["vol"], sc["raw"]
    ior, lo, hi, absorb, objs = voxelize(sc, bugs)
    field = gradient(ior, lo, hi, bugs)
    level, smax, vsmax = octree(ior, vol, bugs)
    sp, sd, srad, light_of = photons(sc, ior, lo, hi, objs, bugs)
    kappa = extinction(sc, ior, absorb, bugs)
    N = np.array(ior.shape)
    h = (hi - lo) / N
    has_caustics = bool(raw.get("receivers")) and bool(sc["lights"])
    tris, owner, boxes, frames = (vv.receivers(raw, sc["lights"], bugs) if has_caustics
                                  else (None, None, [], []))
    rec = path_index(len(sp))
    args = (field, level, smax, kappa, sp, sd, srad, lo, hi, vol, sc["outside_ior"])
    m = march(*args, bugs, record=rec, tris=tris)
    cut = stop_cut(m["steps"], vol)
    total = stopping_rule(m, vol)
    outside_hits(m, tris, lo, hi, bugs)
    # the deposits of the steps the stopping rule keeps: the march again, stopped at the cut
    # (photons are independent, so the second march retraces the first)
    dm = march(*args, bugs, tris=tris, deposit_cap=cut if cut is not None else 1 << 62)
    rad_sum, dir_sum = dm["deposits"].sums()
    radiance, direction = smooth(rad_sum, dir_sum, ior.shape)
    hit_receiver = np.where(m["hit_tri"] >= 0, owner[np.maximum(m["hit_tri"], 0)] if has_caustics
                            else -1, -1).astype(np.int32)
    out = {
        "ior": ior, "volume_bounds": np.stack([lo, hi]),
        "stage.voxelize.ior_volume": ior,
        "stage.gradient.field": field,
        "stage.octree.level": level, "stage.octree.step_max": smax, "stage.octree.view_step_max": vsmax,
        "stage.photons.start_pos": sp, "stage.photons.start_dir": sd, "stage.photons.start_radiance": srad,
        "stage.march.exit_pos": m["exit_pos"], "stage.march.exit_dir": m["exit_dir"],
        "stage.march.photon_status": m["photon_status"],
        "stage.march.hit_pos": m["hit_pos"], "stage.march.hit_receiver": hit_receiver,
        "stage.march.deposit": rad_sum.reshape(ior.shape + (3,)).astype(np.float32),
        "photon_exit_pos": m["exit_pos"], "photon_exit_dir": m["exit_dir"],
        "photon_status": m["photon_status"], "photon_steps": total,
        "stage.photon_paths.paths": m["paths"], "stage.photon_paths.path_index": rec,
        "stage.smooth.radiance": radiance, "stage.smooth.direction": direction,
        "radiance": radiance, "direction": direction,
    }
    if has_caustics:
        Hc = Wc = int((raw.get("caustics") or {}).get("map_size", 512))
        h2 = float((h[0] * h[1] * h[2]) ** (2.0 / 3.0))
        maps, rgbs = vv.caustics(m, light_of, srad, sc["lights"], tris, owner, boxes, h2, Hc, Wc,
                                 bugs)
        for r, fr in enumerate(frames):
            out[f"stage.receivers.frame_{r}"] = fr
            for pre in ("", "stage.caustics."):
                out[f"{pre}caustic_frame_{r}"] = fr
                out[f"{pre}caustic_map_{r}"] = maps[r]
                out[f"{pre}caustic_rgb_{r}"] = rgbs[r]
    # view (§4.5)
    ro, rd = vv.camera_rays(raw.get("camera") or {})
    n_half, side = material_level(field, sc["outside_ior"])
    sigma = scattering(sc, ior.shape)
    vw = vv.view(ro, rd, field, vsmax, kappa, sigma, radiance, direction, lo, hi, n_half, side, vol,
                 raw.get("environment"), sample_field, _voxel_of, clip_box, _slab, bugs)
    out.update({"ray_origin": ro, "ray_dir": rd})
    for k in ("hit", "exit_pos", "exit_dir", "status", "image"):
        out[k] = vw[k]
        out[f"stage.view.{k}"] = vw[k]
    out["interfaces"], out["path_length"] = vw["interfaces"], vw["path_length"]
    return out


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
