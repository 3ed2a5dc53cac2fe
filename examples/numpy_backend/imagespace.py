"""Clean-room NumPy backend of the image-space method (Chaudhari 2008).

Written from ``docs/oracle.md`` ("Porting rules: image-space", "Per-pixel
keys", "Stage buffers", "Conformance") and ``docs/backends.md`` alone, the
way a GPU port is structured: one function per pass (``rays``, ``geometry``,
``minmax``, ``voxelize``, ``peel``, ``reduce``, ``normals``, ``trace``,
``shade``; on scenes with lights and receivers the caustic stages of
``imagespace_caustics.py``), every pass vectorised over all pixels; the trace loops over
interface events and search iterations with all live pixels at once (one
"draw" per event, as a multi-pass shader would).

``run(golden_dir, out_dir)`` reads each image-space case's ``scene.json``
and ``geometry.npz`` (the placed triangles) from a golden suite and writes ``out_dir/<case>/result.npz`` with the final
keys and every stage buffer from ``rays`` to ``shade``, ready for
``refraction-ref check out_dir --golden golden_dir``. ``bugs=`` plants the
mistakes porters really make (``BUGS``), to show that ``check`` names the
pass to fix.

The only thing taken from the package is its public scene loader
(``refraction_ref.load_scene``, defaults filled in); the triangles come from
the golden suite's ``geometry.npz`` (``docs/backends.md``).

References
----------
P. Chaudhari, *Real-Time Multiple Refractions Through Deformable Objects*,
M.S. thesis, UMBC, 2008: §3.2 (rays), §3.3 (min-max and bitmask
voxelization), §3.4 (peeling), §3.5 (normals, eqs. 3.1-3.2), §3.6-3.7
(binary search, bounds, early termination), §3.8 (shading).
"""
from __future__ import annotations

import json
import os
from collections import namedtuple
from types import SimpleNamespace

import numpy as np

def _load_caustics():
    """The caustic passes (``imagespace_caustics.py`` beside this file), loaded by path."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "imagespace_caustics", os.path.join(os.path.dirname(os.path.abspath(__file__)), "imagespace_caustics.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


caustics_passes = _load_caustics()

MISSED, EXITED, LIMIT, TIR, LOST = 0, 1, 2, 3, 4

#: Planted bugs (``bugs=``): name -> what a porter got wrong.
BUGS = {
    "floor_slice": "voxelize: floor((d - zlo)/(zhi - zlo) (S - 1)) instead of rounding to the nearest slice",
    "y_flip": "rays: row 0 taken as the bottom of the image (y = (2 (i + 0.5)/H - 1) sy)",
    "half_pixel": "rays: pixel corners instead of centres (j, i instead of j + 0.5, i + 0.5)",
    "texture_y_flip": "trace: the layer textures read with v flipped (a bottom-left texture origin), row i reads row H - 1 - i",
    "ior_off": "trace: the object's index 0.5 % too large (1.005 ior)",
    "cull_back": "minmax/voxelize: back faces culled by the rasterizer (GPU default state)",
    "outward_normals": "normals: back layers' normals flipped to point out of the object (n_z < 0)",
    "forward_normals": "normals: one-sided (forward) differences j..j+delta, i-delta..i instead of central",
    "no_margin": "reduce: the search bound without the bound_margin constant",
    "path_length_ior": "trace: optical length (times ior) stored in path_length instead of the geometric one",
    "no_snap": "minmax/voxelize: the rasterizer samples the unsnapped triangle (no 1/256 pixel grid), as an "
               "analytic rasterizer or a ray caster does; not a bug: check admits it (the depth keys' slope term)",
    **caustics_passes.BUGS,
}

#: ``far`` is read only by the caustic march; ``ortho`` marks a directional light's view (orthographic)
Camera = namedtuple("Camera", "W H sx sy eye B near far ortho", defaults=(np.inf, False))
Knobs = namedtuple(
    "Knobs",
    "iterations layers slices bounds mip_size bound_margin blend filter peel_all slicing "
    "normals delta exit_threshold tir max_interfaces record",
)


# ----------------------------------------------------------------------------- camera
def camera(cam):
    """Camera scalars and view basis ("Camera scalars, frames and projections").

    References
    ----------
    Chaudhari 2008 §3.6 (projection); docs/oracle.md Conventions.
    """
    W, H = int(cam["width"]), int(cam["height"])
    sy = np.tan(np.radians(cam["fov_y"]) / 2.0)
    sx = np.tan(np.radians(cam["fov_y"]) / 2.0) * W / H
    eye = np.asarray(cam["eye"], np.float64)
    f = np.asarray(cam["target"], np.float64) - eye
    f = f / np.linalg.norm(f)
    r = np.cross(f, np.asarray(cam["up"], np.float64))
    r = r / np.linalg.norm(r)
    u = np.cross(r, f)
    return Camera(W, H, sx, sy, eye, np.stack([r, u, -f]), float(cam["near"]), float(cam["far"]))


def to_view(c, P):
    """World points (N, 3) -> view space; sums left to right, unfused (the last bit feeds every depth)."""
    B = c.B
    t = -c.eye @ B.T
    return P[:, 0:1] * B[:, 0] + P[:, 1:2] * B[:, 1] + P[:, 2:3] * B[:, 2] + t


def to_world(c, p, point=True):
    """View vectors (..., 3) -> world: ``x r + y u + z b`` (+ eye for points)."""
    B = c.B
    w = p[..., 0:1] * B[0] + p[..., 1:2] * B[1] + p[..., 2:3] * B[2]
    return w + c.eye if point else w


def unproject(c, col, row, d):
    """View point at depth d seen at continuous screen position (col, row); orthographic: no factor d."""
    if c.ortho:
        return (col * (2.0 / c.W) - 1.0) * c.sx, (1.0 - row * (2.0 / c.H)) * c.sy, -d
    return (col * (2.0 / c.W) - 1.0) * c.sx * d, (1.0 - row * (2.0 / c.H)) * c.sy * d, -d


def screen(c, P):
    """The trace's projection of view points (N, 3) -> (row, col); (-1, -1) behind the eye or off the image."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 if c.ortho else 1.0 / -P[:, 2]
        row = 0.5 * c.H - P[:, 1] * inv * (0.5 * c.H / c.sy)
        col = P[:, 0] * inv * (0.5 * c.W / c.sx) + 0.5 * c.W
    ok = (-P[:, 2] > 0) & (row >= 0) & (row < c.H) & (col >= 0) & (col < c.W)
    return np.where(ok, row, -1.0), np.where(ok, col, -1.0)


def knobs(scene_data):
    """The ``imagespace`` knobs this backend implements; refuses the others by name."""
    k = scene_data["imagespace"]
    unsupported = {"depth": "bitmask", "peeling": "separate", "endpoint": "probe"}
    for key, want in unsupported.items():
        if k[key] != want:
            raise NotImplementedError(
                f"imagespace.{key} = {k[key]!r} is not implemented by this example backend "
                f"(only {want!r}); set imagespace.{key} to {want!r}")
    if k.get("grid") is not None:
        raise NotImplementedError("imagespace.grid is not implemented by this example backend "
                                  "(the textures at the image's size); remove imagespace.grid")
    if k["normals"] not in ("central", "forward"):
        raise NotImplementedError(
            f"imagespace.normals = {k['normals']!r} is not implemented (use 'central' or 'forward')")
    return Knobs(int(k["iterations"]), int(k["layers"]), int(k["slices"]), k["bounds"],
                 int(k["mip_size"]), float(k["bound_margin"]), k["blend"], k["filter"],
                 bool(k["peel_all"]), k["slicing"], k["normals"], int(k["delta"]),
                 float(k["exit_threshold"]), bool(k["tir"]), int(k["max_interfaces"]),
                 int(k["record"]))


# ----------------------------------------------------------------------------- rays
def pass_rays(c, bugs=()):
    """``rays``: primary rays through the pixel centres (view-space ``v`` kept for the trace).

    References
    ----------
    Chaudhari 2008 §3.2.
    """
    W, H = c.W, c.H
    j = np.arange(W)[None, :]
    i = np.arange(H)[:, None]
    o = 0.0 if "half_pixel" in bugs else 0.5
    x = ((j + o) / W * 2.0 - 1.0) * c.sx + 0.0 * i
    if "y_flip" in bugs:
        y = ((i + o) / H * 2.0 - 1.0) * c.sy + 0.0 * j
    else:
        y = (1.0 - (i + o) / H * 2.0) * c.sy + 0.0 * j
    s = 1.0 / np.sqrt(x * x + y * y + 1.0)
    v = np.stack([x * s, y * s, -s], -1)
    ray_dir = to_world(c, v, point=False)
    ray_origin = np.broadcast_to(c.eye, ray_dir.shape).copy()
    return {"ray_origin": ray_origin, "ray_dir": ray_dir}, v


# ----------------------------------------------------------------------------- geometry
def pass_geometry(scene, case_dir):
    """``geometry``: merged world triangles (the case's ``geometry.npz``) and the shared material."""
    data = scene.data
    with np.load(os.path.join(case_dir, "geometry.npz")) as g:
        V, F = g["vertices"], g["faces"]
    mats = [o["material"] for o in data["objects"]]
    ior = float(mats[0]["ior"])
    absorption = np.asarray(mats[0]["absorption"], np.float64)
    return {"absorption": absorption}, (V, F, ior, float(data["outside_ior"]))


# ----------------------------------------------------------------------------- rasterizer
def _clip_near(c, V, F):
    """Sutherland-Hodgman against d = near, fanned; only called when a vertex is nearer than near."""
    near = c.near
    T = V[F]                                          # (F, 3, 3) view space
    keep = (-T[..., 2] - near) >= 0
    cnt = np.zeros(len(F), np.int64)
    out = np.full((len(F), 4, 3), np.nan)             # up to 4 output vertices per triangle
    for e in range(3):
        a, b = T[:, e], T[:, (e + 1) % 3]
        ka, kb = keep[:, e], keep[:, (e + 1) % 3]
        rows = np.nonzero(ka)[0]
        out[rows, cnt[rows]] = a[rows]
        cnt[rows] += 1
        ch = ka != kb
        rows = np.nonzero(ch)[0]
        da = -a[rows, 2] - near
        db = -b[rows, 2] - near
        s = da / (da - db)
        pt = a[rows] + s[:, None] * (b[rows] - a[rows])
        pt[:, 2] = -near
        out[rows, cnt[rows]] = pt
        cnt[rows] += 1
    tris, origin = [], []
    for k in (1, 2):                                  # fan from the first vertex
        rows = np.nonzero(cnt >= k + 2)[0]
        tris.append(np.stack([out[rows, 0], out[rows, k], out[rows, k + 1]], 1))
        origin.append(rows)
    T2 = np.concatenate(tris, 0)
    return T2.reshape(-1, 3), np.arange(len(T2) * 3).reshape(-1, 3), np.concatenate(origin)


def fragments(c, Vw, F, bugs=(), with_triangle=False):
    """Every fragment (pixel index, depth) of the GPU-style rasterizer: 1/256 snap, top-left rule, no culling.

    ``with_triangle=True`` also returns each fragment's triangle (its row in ``F``; a clipped
    triangle's pieces keep it). An orthographic view (``c.ortho``) snaps with d replaced by 1 and
    interpolates the depth linearly.

    ``bugs=("no_snap",)`` samples the unsnapped triangle (float64 vertices and edge functions, the same
    top-left rule): the depths of an analytic rasterizer, which ``check`` admits.

    References
    ----------
    Chaudhari 2008 §3.3; docs/oracle.md "Rasterization".
    """
    W, H, sx, sy = c.W, c.H, c.sx, c.sy
    V = to_view(c, Vw)
    origin = np.arange(len(F))
    if np.any(-V[:, 2] < c.near):
        V, F, origin = _clip_near(c, V, F)
    d = -V[:, 2]
    dp = np.ones_like(d) if c.ortho else d
    with np.errstate(divide="ignore", invalid="ignore"):
        col = (V[:, 0] / (dp * sx) * 0.5 + 0.5) * W
        row = (0.5 - V[:, 1] / (dp * sy) * 0.5) * H
        bad = (d <= 0) | ~(np.abs(col) < 2.0 ** 22) | ~(np.abs(row) < 2.0 ** 22)
        X = np.where(bad, 0.0, col * 256.0)
        Y = np.where(bad, 0.0, row * 256.0)
    if "no_snap" not in bugs:                         # the 1/256 sub-pixel grid; unsnapped: float64 vertices
        X, Y = np.rint(X).astype(np.int64), np.rint(Y).astype(np.int64)
    with np.errstate(divide="ignore"):
        D = d if c.ortho else 1.0 / d
    keep = ~bad[F].any(1)
    F, origin = F[keep], origin[keep]
    x0, x1, x2 = X[F].T
    y0, y1, y2 = Y[F].T
    d0, d1, d2 = D[F].T
    A = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
    if "cull_back" in bugs:
        # a GPU's default cull state: rows grow downwards, so a face counter-clockwise
        # from outside (front) has A < 0 here; the back faces (A > 0) are dropped
        A = np.where(A > 0, 0, A)
    fl = A < 0                                        # back faces kept: re-orient
    x1, x2 = np.where(fl, x2, x1), np.where(fl, x1, x2)
    y1, y2 = np.where(fl, y2, y1), np.where(fl, y1, y2)
    d1, d2 = np.where(fl, d2, d1), np.where(fl, d1, d2)
    A = np.abs(A)

    def first(a):                                     # first pixel centre >= a
        return np.maximum(-((128 - a) // 256), 0)

    def last(a, n):                                   # last pixel centre <= a
        return np.minimum((a - 128) // 256, n - 1)

    j0 = first(np.minimum(np.minimum(x0, x1), x2)).astype(np.int64)
    j1 = last(np.maximum(np.maximum(x0, x1), x2), W).astype(np.int64)
    i0 = first(np.minimum(np.minimum(y0, y1), y2)).astype(np.int64)
    i1 = last(np.maximum(np.maximum(y0, y1), y2), H).astype(np.int64)
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

    def own(ax, ay, bx, by):                          # top-left rule, rows growing downwards
        return (by - ay < 0) | ((by == ay) & (bx > ax))

    cov = (((w0 > 0) | ((w0 == 0) & own(a1, b1, a2, b2)))
           & ((w1 > 0) | ((w1 == 0) & own(a2, b2, a0, b0)))
           & ((w2 > 0) | ((w2 == 0) & own(a0, b0, a1, b1))))
    w0, w1, w2, t = w0[cov], w1[cov], w2[cov], t[cov]
    lin = (w0 * d0[t] + w1 * d1[t] + w2 * d2[t]) * (1.0 / A[t])
    depth = lin if c.ortho else 1.0 / lin
    if with_triangle:
        return i[cov] * W + j[cov], depth, origin[t]
    return i[cov] * W + j[cov], depth


# ----------------------------------------------------------------------------- minmax
def pass_minmax(c, pix, depth):
    """``minmax``: nearest and farthest fragment depth per pixel (§3.3)."""
    H, W = c.H, c.W
    zmin = np.full(H * W, np.inf)
    np.minimum.at(zmin, pix, depth)
    zmax = np.full(H * W, -np.inf)
    np.maximum.at(zmax, pix, depth)
    return {"zmin": zmin.reshape(H, W), "zmax": zmax.reshape(H, W)}


# ----------------------------------------------------------------------------- voxelize
def pass_voxelize(c, k, pix, depth, zmin, zmax, bugs=()):
    """``voxelize``: the per-pixel occupancy bitmask over S slices (§3.3)."""
    H, W, S = c.H, c.W, k.slices
    if k.slicing == "local":
        zlo, zhi = zmin.copy(), zmax.copy()
    else:
        cov = np.isfinite(zmin)
        gmin = zmin[cov].min() if cov.any() else np.inf
        gmax = zmax[cov].max() if cov.any() else -np.inf
        zlo, zhi = np.full((H, W), gmin), np.full((H, W), gmax)
    lo = zlo.ravel()[pix]
    rng = zhi.ravel()[pix] - lo
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (depth - lo) / rng * (S - 1)
        s = np.floor(x) if "floor_slice" in bugs else np.floor(x + 0.5)
    s = np.where(rng > 0, np.clip(s, 0, S - 1), 0).astype(np.int64)
    bits = np.zeros((H * W, S // 32), np.uint32)
    m = np.uint32(1) << (s % 32).astype(np.uint32)
    if k.blend == "add":
        np.add.at(bits, (pix, s // 32), m)            # 32-bit add per word: carries, wraps
    else:
        np.bitwise_or.at(bits, (pix, s // 32), m)
    return {"bits": bits.reshape(H, W, S // 32), "zlo": zlo, "zhi": zhi}


# ----------------------------------------------------------------------------- peel
def pass_peel(c, k, bits, zlo, zhi):
    """``peel``: the layered depth image from the bitmask (§3.4)."""
    H, W, S = c.H, c.W, k.slices
    K = bits.shape[2]
    b = np.unpackbits(np.ascontiguousarray(bits).astype("<u4").view(np.uint8).reshape(H, W, 4 * K),
                      axis=-1, bitorder="little").astype(bool)
    total = b.sum(-1)
    L = k.layers if k.peel_all else int(min(k.layers, total.max(initial=0)))
    rank = np.cumsum(b, -1) - 1
    ii, jj, ss = np.nonzero(b & (rank < L))
    ldi = np.full((L, H, W), np.inf, np.float32)
    ldi[rank[ii, jj, ss], ii, jj] = zlo[ii, jj] + ss * (1.0 / (S - 1)) * (zhi[ii, jj] - zlo[ii, jj])
    return {"ldi": ldi, "depth_complexity": total.astype(np.int16)}


# ----------------------------------------------------------------------------- reduce
def pass_reduce(c, k, ldi, zmin, zmax, bugs=()):
    """``reduce``: per-layer search bounds (MIP-level max/min plus a margin) (§3.7)."""
    H, W = c.H, c.W
    L = ldi.shape[0]
    f = 1 if k.bounds == "global" else max(1, -(-max(H, W) // k.mip_size))
    hb, wb = -(-H // f), -(-W // f)
    a = np.full((L, hb * f, wb * f), np.nan)
    a[:, :H, :W] = np.where(np.isfinite(ldi), ldi, np.nan)
    blk = a.reshape(L, hb, f, wb, f)
    ok = np.isfinite(blk)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (np.where(ok, blk, 0.0).sum(axis=(2, 4)) / ok.sum(axis=(2, 4))).reshape(L, hb * wb)
    hi = np.where(np.isnan(mean), -np.inf, mean).max(axis=1, initial=-np.inf)
    lo = np.where(np.isnan(mean), np.inf, mean).min(axis=1, initial=np.inf)
    if k.bounds == "mip" and "no_margin" not in bugs:
        gmax, gmin = zmax.max(initial=-np.inf), zmin.min(initial=np.inf)
        margin = k.bound_margin * (gmax - gmin) if np.isfinite(gmax) else 0.0
        hi[np.isfinite(hi)] += margin
        lo[np.isfinite(lo)] -= margin
    return {"bounds_hi": hi, "bounds_lo": lo}


# ----------------------------------------------------------------------------- normals
def _normals_central(c, layer, delta, forward=False):
    H, W = c.H, c.W
    dl_ = delta
    pad = np.full((H + 2 * dl_, W + 2 * dl_), np.inf)
    pad[dl_:-dl_, dl_:-dl_] = layer
    i, j = np.mgrid[0:H, 0:W].astype(np.float64)

    def side(nb, off):                                # an absent neighbour falls back to the centre
        ok = np.isfinite(nb)
        return np.where(ok, nb, layer), np.where(ok, off, 0)

    dr, oR = side(pad[dl_:-dl_, 2 * dl_:], dl_)
    du, oU = side(pad[:-2 * dl_, dl_:-dl_], -dl_)
    if forward:                                       # the planted bug: the centre as the other side
        dl, oL = layer, np.zeros_like(oR)
        dd, oD = layer, np.zeros_like(oU)
    else:
        dl, oL = side(pad[dl_:-dl_, :-2 * dl_], -dl_)
        dd, oD = side(pad[2 * dl_:, dl_:-dl_], dl_)
    xr = unproject(c, j + oR + 0.5, i + 0.5, dr)[0]
    xl = unproject(c, j + oL + 0.5, i + 0.5, dl)[0]
    yu = unproject(c, j + 0.5, i + oU + 0.5, du)[1]
    yd = unproject(c, j + 0.5, i + oD + 0.5, dd)[1]
    with np.errstate(invalid="ignore", divide="ignore"):
        gx = np.where((oR != oL) & (xr != xl), (dr - dl) / (xr - xl), 0.0)
        gy = np.where((oU != oD) & (yu != yd), (du - dd) / (yu - yd), 0.0)
    with np.errstate(invalid="ignore"):               # absent texels (inf - inf) become NaN below anyway
        s = 1.0 / np.sqrt(gx * gx + gy * gy + 1.0)
        n = np.stack([gx * s, gy * s, s], -1)
    n[~np.isfinite(layer)] = np.nan
    return n


def _normals_forward(c, layer):
    """Eq. 3.1 (knob ``normals = forward``): pixel units, a term 0 where the neighbour is absent."""
    pad = np.full((c.H + 2, c.W + 2), np.inf)
    pad[1:-1, 1:-1] = layer
    with np.errstate(invalid="ignore"):
        gx = pad[1:-1, 2:] - layer
        gy = pad[:-2, 1:-1] - layer
    gx = np.where(np.isfinite(gx), gx, 0.0)
    gy = np.where(np.isfinite(gy), gy, 0.0)
    s = 1.0 / np.sqrt(gx * gx + gy * gy + 1.0)
    n = np.stack([gx * s, gy * s, s], -1)
    n[~np.isfinite(layer)] = np.nan
    return n


def pass_normals(c, k, ldi, bugs=()):
    """``normals``: per-layer view-space unit normals from the depth images (§3.5, eqs. 3.1-3.2).

    n_z > 0 on every layer (the trace's Snell faces the normal to the ray).
    """
    out = np.full(ldi.shape + (3,), np.nan)
    for n in range(ldi.shape[0]):
        layer = ldi[n].astype(np.float64)
        if k.normals == "forward":
            out[n] = _normals_forward(c, layer)
        else:
            out[n] = _normals_central(c, layer, k.delta, forward="forward_normals" in bugs)
        if "outward_normals" in bugs and n % 2 == 1:  # back layers turned to face out of the object
            out[n] = -out[n]
    return {"normals": out}


# ----------------------------------------------------------------------------- trace helpers
def _sample(c, ldi64, t, r, col, bilinear):
    """Depth of layer t at screen (r, col) (``filter``); +inf off the image or where the texel lacks it."""
    H, W = c.H, c.W
    on = r >= 0.0
    ri = np.where(on, np.floor(r), 0).astype(np.int64)
    ci = np.where(on, np.floor(col), 0).astype(np.int64)
    near = np.where(on, ldi64[t, ri, ci], np.inf)
    if not bilinear:
        return near
    u, v = col - 0.5, r - 0.5
    j0 = np.floor(u).astype(np.int64)
    i0 = np.floor(v).astype(np.int64)
    fx, fy = u - j0, v - i0
    inb = (i0 >= 0) & (i0 + 1 < H) & (j0 >= 0) & (j0 + 1 < W) & on
    a0 = np.clip(i0, 0, H - 2)
    b0 = np.clip(j0, 0, W - 2)
    d00, d01 = ldi64[t, a0, b0], ldi64[t, a0, b0 + 1]
    d10, d11 = ldi64[t, a0 + 1, b0], ldi64[t, a0 + 1, b0 + 1]
    four = inb & np.isfinite(d00) & np.isfinite(d01) & np.isfinite(d10) & np.isfinite(d11)
    with np.errstate(invalid="ignore"):
        top = d00 + fx * (d01 - d00)
        bot = d10 + fx * (d11 - d10)
        lin = top + fy * (bot - top)
    return np.where(np.isfinite(near) & four, lin, near)


def _normal(c, nrm, ldi64, t, r, col, bilinear):
    """Normal of layer t at (r, col): the texel's, or the renormalised bilinear blend of four (sign-aligned)."""
    H, W = c.H, c.W
    ri = np.floor(r).astype(np.int64)
    ci = np.floor(col).astype(np.int64)
    nn = nrm[t, ri, ci]
    if not bilinear:
        return nn
    u, v = col - 0.5, r - 0.5
    j0 = np.floor(u).astype(np.int64)
    i0 = np.floor(v).astype(np.int64)
    fx, fy = (u - j0)[:, None], (v - i0)[:, None]
    inb = (i0 >= 0) & (i0 + 1 < H) & (j0 >= 0) & (j0 + 1 < W)
    a0 = np.clip(i0, 0, H - 2)
    b0 = np.clip(j0, 0, W - 2)
    four = inb.copy()
    for da in (0, 1):
        for db in (0, 1):
            four &= np.isfinite(ldi64[t, a0 + da, b0 + db])
    n00, n01 = nrm[t, a0, b0], nrm[t, a0, b0 + 1]
    n10, n11 = nrm[t, a0 + 1, b0], nrm[t, a0 + 1, b0 + 1]

    def align(m):
        dot = m[:, 0] * n00[:, 0] + m[:, 1] * n00[:, 1] + m[:, 2] * n00[:, 2]
        return np.where((dot < 0)[:, None], -m, m)

    with np.errstate(invalid="ignore", divide="ignore"):
        n01, n10, n11 = align(n01), align(n10), align(n11)
        top = n00 + fx * (n01 - n00)
        bot = n10 + fx * (n11 - n10)
        o = top + fy * (bot - top)
        q = o[:, 0] * o[:, 0] + o[:, 1] * o[:, 1] + o[:, 2] * o[:, 2]
        blend = np.where((q > 0)[:, None], o * (1.0 / np.sqrt(q))[:, None], n00)
    return np.where(four[:, None], blend, nn)


def _refract(v, n, eta):
    """Snell with TIR (one event per pixel): returns (unit direction, tir)."""
    c = -(v[:, 0] * n[:, 0] + v[:, 1] * n[:, 1] + v[:, 2] * n[:, 2])
    flip = c < 0.0
    n = np.where(flip[:, None], -n, n)                 # face the incident ray
    c = np.where(flip, -c, c)
    k = 1.0 - eta * eta * (1.0 - c * c)
    tir = k < 0.0
    with np.errstate(invalid="ignore"):
        wr = eta[:, None] * v + (eta * c - np.sqrt(k))[:, None] * n
    wm = v + (2.0 * c)[:, None] * n
    w = np.where(tir[:, None], wm, wr)
    w = w * (1.0 / np.sqrt(w[:, 0] * w[:, 0] + w[:, 1] * w[:, 1] + w[:, 2] * w[:, 2]))[:, None]
    return w, tir


# ----------------------------------------------------------------------------- trace
def pass_trace(c, k, v_view, ray_dir, ldi, total, zmax, zlo, zhi, bounds_hi, bounds_lo, nrm,
               ior, outside_ior, bugs=()):
    """``trace``: the multi-interface search, all pixels per event (§3.6-3.7).

    Each event refracts at the current interface with the filtered normal, then
    binary-searches the next layer between the point and the layer's bound
    (forward against ``bounds_hi``, backward against ``bounds_lo`` with ``tir``);
    the interface point is the thesis's R_n at the last probe's texel
    (``endpoint = probe``).

    References
    ----------
    Chaudhari 2008 §3.6 (binary search, eq. for E), §3.7 (bounds, early termination).
    """
    H, W, S = c.H, c.W, k.slices
    N = H * W
    L = ldi.shape[0]
    bil = k.filter == "bilinear"
    follow = k.tir
    if "ior_off" in bugs:
        ior = ior * 1.005
    ldi64 = ldi.astype(np.float64)
    with np.errstate(invalid="ignore"):
        thr = (zhi - zlo) * (k.exit_threshold / (S - 1))
    thr = np.where(np.isfinite(thr), thr, 0.0)
    tot = total.astype(np.int64)
    if "texture_y_flip" in bugs:                       # every texture the trace reads, read upside down
        ldi64, nrm, thr, tot, zmax = (a[..., ::-1, :, :] if a.ndim == 4 else a[..., ::-1, :]
                                      for a in (ldi64, nrm, thr, tot, zmax))
    bhi = np.concatenate([np.asarray(bounds_hi, np.float64), [-np.inf]])   # index L: no such layer
    blo = np.concatenate([np.asarray(bounds_lo, np.float64), [np.inf]])

    status = np.zeros(N, np.int8)
    interfaces = np.zeros(N, np.int16)
    plen_out = np.zeros(N)
    exit_pos = np.full((N, 3), np.nan)
    exit_dir = np.full((N, 3), np.nan)
    last_dir = np.full((N, 3), np.nan)
    K = k.record
    path_pos = np.full((N, K, 3), np.nan)
    path_dir = np.full((N, K, 3), np.nan)

    rd = ray_dir.reshape(N, 3)
    d0 = ldi64[0].ravel() if L else np.full(N, np.inf)
    missed = ~np.isfinite(d0)
    exit_dir[missed] = rd[missed]
    last_dir[missed] = rd[missed]

    # live state, compressed to the pixels still tracing
    pix = np.nonzero(~missed)[0]
    v = v_view.reshape(N, 3)[pix].copy()
    if c.ortho:                                        # a light's parallel photons start on layer 0
        q = np.stack(unproject(c, pix % W + 0.5, pix // W + 0.5, d0[pix]), -1)
    else:
        q = v * (d0[pix] / -v[:, 2])[:, None]          # first hit: the primary ray at layer 0's depth
    p = q.copy()
    t = np.zeros(len(pix), np.int64)
    ti, tj = pix // W, pix % W
    rq, cq = ti + 0.5, tj + 0.5
    g = np.full(len(pix), -1, np.int64)
    fwd = np.ones(len(pix), bool)
    events = np.zeros(len(pix), np.int64)
    nint = np.zeros(len(pix), np.int64)
    plen = np.zeros(len(pix))

    def finish(mask, code, pos=None, dirv=None, last=None):
        idx = pix[mask]
        status[idx] = code if np.ndim(code) == 0 else code[mask]
        interfaces[idx] = nint[mask]
        plen_out[idx] = plen[mask]
        if pos is not None:
            exit_pos[idx] = to_world(c, pos[mask])
            exit_dir[idx] = to_world(c, dirv[mask], point=False)
        last_dir[idx] = to_world(c, last[mask], point=False)

    while len(pix):
        with np.errstate(invalid="ignore"):
            seg = np.sqrt(((q - p) ** 2).sum(-1))
        plen = np.where(g % 2 == 0, plen + seg, plen)  # the segment p -> q ran inside
        p = q
        g2 = np.where(fwd, t, t - 1)
        n1 = np.where(g % 2 == 0, ior, outside_ior)
        n2 = np.where(g2 % 2 == 0, ior, outside_ior)
        nr = _normal(c, nrm, ldi64, t, rq, cq, True) if bil else nrm[t, ti, tj]
        w, tir = _refract(v, nr, n1 / n2)
        ev = events
        events = events + 1
        if K:
            rows = np.nonzero(ev < K)[0]
            path_pos[pix[rows], ev[rows]] = to_world(c, p[rows])
            path_dir[pix[rows], ev[rows]] = to_world(c, w[rows], point=False)
        done = np.zeros(len(pix), bool)
        # TIR the method does not follow: stop, keeping the incident direction
        m = tir & (not follow)
        finish(m, TIR, last=v)
        done |= m
        v = np.where(m[:, None], v, w)
        ref = ~tir
        g = np.where(ref & ~done, g2, g)
        nint = nint + (ref & ~done)
        m = ~done & ref & (g == -1)                    # back out through layer 0
        finish(m, EXITED, p, v, v)
        done |= m
        tt = np.minimum(t, max(L - 1, 0))
        early = fwd & ((t >= tot[ti, tj] - 1) | (zmax[ti, tj] - ldi64[tt, ti, tj] <= thr[ti, tj]))
        m = ~done & ref & early                        # early termination at the backmost depth (§3.7)
        finish(m, EXITED, p, v, v)
        done |= m
        m = ~done & (events >= k.max_interfaces)
        finish(m, np.where(tir, TIR, LIMIT).astype(np.int8), last=v)
        done |= m
        dd = -v[:, 2]
        outside = g % 2 != 0
        f_ = dd > 1e-9
        b_ = (dd < -1e-9) & follow
        m = ~done & ~f_ & ~b_                          # parallel to the screen or turned to the viewer
        ex = m & outside & (dd < 0.0)
        finish(ex, EXITED, p, v, v)
        finish(m & ~ex, LOST, last=v)
        done |= m
        fwd = f_
        t = np.where(f_, g + 1, g)
        m = ~done & f_ & (t >= k.layers)
        finish(m, LIMIT, last=v)
        done |= m
        tb = np.clip(t, 0, L)
        zb = np.where(f_, bhi[tb], blo[tb])
        pz = -p[:, 2]
        m = ~done & (~np.isfinite(zb) | (f_ & (zb <= pz)) | (~f_ & (zb >= pz)))
        finish(m & outside, EXITED, p, v, v)
        finish(m & ~outside, LOST, last=v)
        done |= m

        keep = ~done
        pix, v, p, t, g, fwd = pix[keep], v[keep], p[keep], t[keep], g[keep], fwd[keep]
        events, nint, plen, dd, zb = events[keep], nint[keep], plen[keep], dd[keep], zb[keep]
        outside = outside[keep]
        if not len(pix):
            break
        with np.errstate(invalid="ignore", divide="ignore"):
            E = p + ((zb - -p[:, 2]) / dd)[:, None] * v     # E = S + (Zmax - S_z)/v_z v
        a = np.zeros(len(pix))
        b = np.ones(len(pix))
        mm = np.ones(len(pix))
        for _ in range(k.iterations):                  # binary search (Oliveira and Brauwers 2007)
            mm = 0.5 * (a + b)
            P = p + mm[:, None] * (E - p)
            r, col = screen(c, P)
            ls = _sample(c, ldi64, t, r, col, bil)
            with np.errstate(invalid="ignore"):
                behind = np.isfinite(ls) & np.where(fwd, -P[:, 2] >= ls, -P[:, 2] <= ls)
            b = np.where(behind, mm, b)
            a = np.where(behind, a, mm)
        P = p + mm[:, None] * (E - p)                  # endpoint = probe: the last probe P_n
        rq, cq = screen(c, P)
        dq = _sample(c, ldi64, t, rq, cq, bil)
        m = ~np.isfinite(dq)
        finish(m & outside, EXITED, p, v, v)
        finish(m & ~outside, LOST, last=v)
        keep = ~m
        pix, v, p, t, g, fwd = pix[keep], v[keep], p[keep], t[keep], g[keep], fwd[keep]
        events, nint, plen = events[keep], nint[keep], plen[keep]
        rq, cq, dq = rq[keep], cq[keep], dq[keep]
        x, y, z = unproject(c, cq, rq, dq)             # R_n: the line of sight through P_n at the layer
        q = np.stack([x, y, z], -1)
        ti, tj = np.floor(rq).astype(np.int64), np.floor(cq).astype(np.int64)

    if "path_length_ior" in bugs:
        plen_out = plen_out * ior
    out = {
        "exit_pos": exit_pos.reshape(H, W, 3), "exit_dir": exit_dir.reshape(H, W, 3),
        "interfaces": interfaces.reshape(H, W), "path_length": plen_out.reshape(H, W),
        "status": status.reshape(H, W), "last_dir": last_dir.reshape(H, W, 3),
    }
    if K:
        out["path_pos"] = path_pos.reshape(H, W, K, 3)
        out["path_dir"] = path_dir.reshape(H, W, K, 3)
    return out


# ----------------------------------------------------------------------------- shade
def pass_shade(env, last_dir, path_length, absorption, ior):
    """``shade``: the environment along the last direction times Beer-Lambert (§3.8)."""
    if env["type"] == "constant":
        base = np.asarray(env["colors"][0], np.float64) * env["intensity"]
        image = np.broadcast_to(base, last_dir.shape).astype(np.float32)
        image = np.where(np.isnan(last_dir).any(-1, keepdims=True), np.float32(0), image)
    elif env["type"] == "checker":
        L_ = last_dir
        with np.errstate(invalid="ignore"):
            u = np.arctan2(L_[..., 0], -L_[..., 2]) / (2 * np.pi) + 0.5
            vv = np.arccos(np.clip(L_[..., 1], -1, 1)) / np.pi
        nan = np.isnan(u) | np.isnan(vv)
        tiles = env["tiles"]
        cu = np.floor(np.where(nan, 0, u) * tiles).astype(np.int64)
        cv = np.floor(np.where(nan, 0, vv) * (tiles / 2.0)).astype(np.int64)
        ci = (cu + cv) % 2
        image = (np.asarray(env["colors"], np.float64)[ci] * env["intensity"]).astype(np.float32)
        image[nan] = 0.0
    else:
        raise NotImplementedError(f"environment.type = {env['type']!r} is not implemented "
                                  "(this example shades 'checker' and 'constant')")
    if np.any(absorption > 0):
        image = (image * np.exp(-absorption * (path_length * ior)[..., None])).astype(np.float32)
    return {"image": image}


# ----------------------------------------------------------------------------- driver
def render_case(scene_path, bugs=()):
    """All passes ``rays`` .. ``shade`` for one scene; returns the result dict (golden key names)."""
    import refraction_ref as rr

    bugs = tuple(bugs)
    unknown = set(bugs) - set(BUGS)
    if unknown:
        raise ValueError(f"unknown planted bug(s) {sorted(unknown)}; known: {sorted(BUGS)}")
    scene = rr.load_scene(scene_path)
    data = scene.data
    k = knobs(data)
    c = camera(data["camera"])
    st = {}
    st["rays"], v_view = pass_rays(c, bugs)
    st["geometry"], (Vw, F, ior, outside_ior) = pass_geometry(scene, os.path.dirname(scene_path))
    pix, depth = fragments(c, Vw, F, bugs)
    st["minmax"] = pass_minmax(c, pix, depth)
    zmin, zmax = st["minmax"]["zmin"], st["minmax"]["zmax"]
    st["voxelize"] = pass_voxelize(c, k, pix, depth, zmin, zmax, bugs)
    vx = st["voxelize"]
    st["peel"] = pass_peel(c, k, vx["bits"], vx["zlo"], vx["zhi"])
    ldi, total = st["peel"]["ldi"], st["peel"]["depth_complexity"]
    st["reduce"] = pass_reduce(c, k, ldi, zmin, zmax, bugs)
    st["normals"] = pass_normals(c, k, ldi, bugs)
    st["trace"] = pass_trace(c, k, v_view, st["rays"]["ray_dir"], ldi, total, zmax, vx["zlo"],
                             vx["zhi"], st["reduce"]["bounds_hi"], st["reduce"]["bounds_lo"],
                             st["normals"]["normals"], ior, outside_ior, bugs)
    tr = st["trace"]
    st["shade"] = pass_shade(data["environment"], tr["last_dir"], tr["path_length"],
                             st["geometry"]["absorption"], ior)

    out = {f"stage.{s}.{b}": a for s, bufs in st.items() for b, a in bufs.items()}
    for key in ("ray_origin", "ray_dir"):
        out[key] = st["rays"][key]
    for key in ("exit_pos", "exit_dir", "interfaces", "path_length", "status"):
        out[key] = tr[key]
    out["hit"] = tr["status"] != MISSED
    out["depth_complexity"] = total
    caustics = bool(data.get("lights")) and bool(data.get("receivers"))
    # with caustics `image` is the full scene (caustic_final's): the refraction-only view is
    # `image_refraction`
    out["image_refraction" if caustics else "image"] = st["shade"]["image"]
    if caustics:
        before = set(st)
        final = caustics_passes.run_caustics(
            SimpleNamespace(**globals()), c, k, data, Vw, F, ior, outside_ior, st["geometry"]["absorption"], st,
            v_view, bugs)
        out.update({f"stage.{s}.{b}": a for s in st if s not in before for b, a in st[s].items()})
        out.update(final)
    return out


def imagespace_cases(golden_dir):
    """The image-space cases of a golden suite (``manifest.cases.<case>.method``)."""
    with open(os.path.join(golden_dir, "manifest.json")) as fh:
        man = json.load(fh)
    return sorted(n for n, cs in man["cases"].items() if cs.get("method") == "imagespace")


def run(golden_dir, out_dir, cases=None, bugs=()):
    """Write ``out_dir/<case>/result.npz`` for the suite's image-space cases (or ``cases``).

    Returns the list of cases written.
    """
    cases = imagespace_cases(golden_dir) if cases is None else list(cases)
    for case in cases:
        res = render_case(os.path.join(golden_dir, case, "scene.json"), bugs)
        os.makedirs(os.path.join(out_dir, case), exist_ok=True)
        np.savez(os.path.join(out_dir, case, "result.npz"), **res)
    return cases


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("golden")
    ap.add_argument("out")
    ap.add_argument("--cases", default=None)
    ap.add_argument("--bugs", default="")
    a = ap.parse_args()
    run(a.golden, a.out, a.cases.split(",") if a.cases else None,
        [b for b in a.bugs.split(",") if b])
