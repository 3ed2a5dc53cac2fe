"""Clean-room NumPy port of the volumetric method's receivers, caustic maps and viewing pass.

The ``receivers``, ``caustics`` and ``view`` passes of Sun et al. 2008 (Fig. 9, §4.5), written
from ``docs/oracle.md`` ("Porting rules: volumetric", the image-space ``receivers`` and ``splat``
rules they cite, Conventions) without the package's source; ``volumetric.py`` drives them. The
viewing pass runs every pixel at once, one loop over steps (a fragment shader's loop).

References
----------
X. Sun, K. Zhou, E. Stollnitz, J. Shi, B. Guo, *Interactive Relighting of Dynamic Refractive
Objects*, ACM TOG 27(3), 2008: Fig. 9 (receivers in the volume), §4.5 (viewing pass, eqs. 4-5
for the eye rays, Henyey-Greenstein phase function).
"""
from __future__ import annotations

import math

import numpy as np

RECEIVER_DEFAULTS = {"mesh": "plane", "fit": None, "size": [4.0, 4.0],
                     "albedo": [0.8, 0.8, 0.8], "name": None}
TRANSFORM_DEFAULTS = {"scale": 1.0, "rotate": [0.0, 0.0, 0.0], "translate": [0.0, 0.0, 0.0]}
CAMERA_DEFAULTS = {"eye": [0.0, 0.0, 2.6], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                   "fov_y": 30.0, "width": 512, "height": 512, "near": 0.1, "far": 10.0}
ENV_DEFAULTS = {"type": "checker", "tiles": 48, "colors": [[0.9, 0.9, 0.9], [0.1, 0.1, 0.1]],
                "path": None, "intensity": 1.0}


# ----------------------------------------------------------------------------------------------
# receivers (Fig. 9): the world triangles and the caustic-map frame
# ----------------------------------------------------------------------------------------------

def plane_triangles(rc):
    """A `plane` receiver's world triangles (2, 3, 3): vertices (-x,-z), (+x,-z), (+x,+z), (-x,+z),
    faces [0, 2, 1], [0, 3, 2]; placed by R = Rz Ry Rx * scale, then translate."""
    a, b = rc["size"] if rc.get("size") is not None else (4.0, 4.0)
    v = np.array([[-a / 2, 0, -b / 2], [a / 2, 0, -b / 2], [a / 2, 0, b / 2], [-a / 2, 0, b / 2]],
                 np.float64)
    t = dict(TRANSFORM_DEFAULTS, **(rc.get("transform") or {}))
    ax, ay, az = np.radians(np.asarray(t["rotate"], np.float64))
    Rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    Ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    Rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx * float(t["scale"])
    v = (v[:, 0:1] * R[:, 0] + v[:, 1:2] * R[:, 1] + v[:, 2:3] * R[:, 2]
         + np.asarray(t["translate"], np.float64))
    return v[np.array([[0, 2, 1], [0, 3, 2]])]


def face_normals(tris):
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def map_box(Vr, light):
    """Receiver r's map box (centre, U, V, W, w, h, d): the tight box of its world vertices in
    eq. 4-1's axes of the FIRST light."""
    c = (Vr.min(axis=0) + Vr.max(axis=0)) / 2.0
    T0 = (np.asarray(light["direction"], np.float64) if light["type"] == "directional"
          else c - np.asarray(light["position"], np.float64))
    T0 = T0 / np.linalg.norm(T0)
    V = -T0
    V = V / np.linalg.norm(V)
    N_ = np.array([0.0, 0.0, 1.0]) if abs(V[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    U = np.cross(V, N_)
    U /= np.linalg.norm(U)
    Wa = np.cross(U, V)
    Wa /= np.linalg.norm(Wa)
    R = np.stack([U, V, Wa])
    loc = Vr[:, 0:1] * R[:, 0] + Vr[:, 1:2] * R[:, 1] + Vr[:, 2:3] * R[:, 2]
    lo, hi = loc.min(axis=0), loc.max(axis=0)
    centre = ((lo + hi) / 2.0) @ R
    ext = np.maximum(hi - lo, 1e-6 * max(float((hi - lo).max()), 1e-12))
    return centre, U, V, Wa, ext[0], ext[1], ext[2]


def map_frame(box):
    centre, U, V, Wa, w, h, d = box
    return np.stack([centre - w / 2.0 * U - d / 2.0 * Wa + h / 2.0 * V, w * U, d * Wa, V])


def map_position(box, P, Hc, Wc):
    centre, U, V, Wa, w, h, d = box
    q = P - centre
    col = ((q[:, 0] * U[0] + q[:, 1] * U[1] + q[:, 2] * U[2]) / w + 0.5) * Wc
    row = ((q[:, 0] * Wa[0] + q[:, 1] * Wa[1] + q[:, 2] * Wa[2]) / d + 0.5) * Hc
    return col, row


def receivers(raw, lights, bugs=()):
    """Pass ``receivers``: (tris (T, 3, 3) merged in scene order, owner (T,), boxes, frames)."""
    tris, owner, boxes, frames = [], [], [], []
    for r, rc in enumerate(raw.get("receivers") or []):
        rc = dict(RECEIVER_DEFAULTS, **rc)
        t = plane_triangles(rc)
        tris.append(t)
        owner.append(np.full(len(t), r, np.int64))
        box = map_box(t.reshape(-1, 3), lights[0])
        boxes.append(box)
        frames.append(map_frame(box))
    if not tris:
        return np.zeros((0, 3, 3)), np.zeros(0, np.int64), [], []
    return np.concatenate(tris), np.concatenate(owner), boxes, frames


# ----------------------------------------------------------------------------------------------
# caustics (Fig. 9): bilinear splat of the photons that met material, no gathering
# ----------------------------------------------------------------------------------------------

def splat(col, row, val, Hc, Wc, bugs=()):
    """Bilinear splat, corners clamped to the map, photon order then corner order (float64)."""
    x = np.clip(col - 0.5, -1.0, Wc + 0.0)
    y = np.clip(row - 0.5, -1.0, Hc + 0.0)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y, val = x[ok], y[ok], val[ok]
    j0 = np.floor(x).astype(np.int64)
    i0 = np.floor(y).astype(np.int64)
    fx, fy = x - j0, y - i0
    out = np.zeros((Hc, Wc, val.shape[1]))
    ii, jj, ww = [], [], []
    for di, wy in ((0, 1.0 - fy), (1, fy)):
        for dj, wx in ((0, 1.0 - fx), (1, fx)):
            ii.append(np.clip(i0 + di, 0, Hc - 1))
            jj.append(np.clip(j0 + dj, 0, Wc - 1))
            ww.append(wy * wx)
    ii, jj, ww = (np.stack(a, 1).ravel() for a in (ii, jj, ww))
    np.add.at(out, (ii, jj), ww[:, None] * np.repeat(val, 4, axis=0))
    return out


def caustics(m, light_of, start_rad, lights, tris, owner, boxes, h2, Hc, Wc, bugs=()):
    """Pass ``caustics``: per receiver (caustic_map (Hc, Wc) float32, caustic_rgb (Hc, Wc, 3)
    float32). A photon with a receiver hit (status 5, or status 1 and a hit outside) that met
    material deposits E = flux |n . V| / A_texel, flux = max(start_radiance) h2 / max(radiance) T.
    """
    nrm = face_normals(tris)
    maps, rgbs = [], []
    hit = m["hit_tri"] >= 0
    if "caustics_unmet" not in bugs:
        hit = hit & m["met"]
    for r, box in enumerate(boxes):
        mono = np.zeros((Hc, Wc))
        rgb = np.zeros((Hc, Wc, 3))
        V = box[2]
        A = (box[4] / Wc) * (box[6] / Hc)
        for li, light in enumerate(lights):
            rad = np.broadcast_to(np.asarray(light.get("radiance", [1.0, 1.0, 1.0]), np.float64), (3,))
            if rad.max() <= 0:
                continue
            idx = np.flatnonzero(hit & (light_of == li))
            idx = idx[owner[m["hit_tri"][idx]] == r]
            if not len(idx):
                continue
            n = nrm[m["hit_tri"][idx]]
            cosv = np.abs(n[:, 0] * V[0] + n[:, 1] * V[1] + n[:, 2] * V[2])
            if "splat_no_cosine" in bugs:
                cosv = np.ones_like(cosv)
            flux = (start_rad[idx].max(axis=1) * h2 / rad.max())[:, None] * m["T"][idx]
            val = flux * (cosv / A)[:, None]
            col, row = map_position(box, m["hit_pos"][idx], Hc, Wc)
            s = splat(col, row, val, Hc, Wc, bugs)
            mono += (s[..., 0] + s[..., 1] + s[..., 2]) / 3.0
            rgb += s * rad
        maps.append(mono.astype(np.float32))
        rgbs.append(rgb.astype(np.float32))
    return maps, rgbs


# ----------------------------------------------------------------------------------------------
# view (§4.5)
# ----------------------------------------------------------------------------------------------

def camera_rays(cam):
    """ray_origin, ray_dir (H, W, 3) float64 world (Conventions, the image-space `rays` rule)."""
    cam = dict(CAMERA_DEFAULTS, **cam)
    W, H = int(cam["width"]), int(cam["height"])
    sy = np.tan(np.radians(cam["fov_y"]) / 2.0)
    sx = np.tan(np.radians(cam["fov_y"]) / 2.0) * W / H
    eye = np.asarray(cam["eye"], np.float64)
    f = np.asarray(cam["target"], np.float64) - eye
    f = f / np.linalg.norm(f)
    r = np.cross(f, cam["up"])
    r = r / np.linalg.norm(r)
    u = np.cross(r, f)
    B = np.stack([r, u, -f])
    j = np.arange(W)[None, :]
    i = np.arange(H)[:, None]
    x = ((j + 0.5) / W * 2.0 - 1.0) * sx + 0.0 * i
    y = (1.0 - (i + 0.5) / H * 2.0) * sy + 0.0 * j
    s = 1.0 / np.sqrt(x * x + y * y + 1.0)
    v = np.stack([x * s, y * s, -s], -1)
    d = v[..., 0:1] * B[0] + v[..., 1:2] * B[1] + v[..., 2:3] * B[2]
    return np.broadcast_to(eye, d.shape).copy(), d


def environment(D, env):
    """The environment (checker or constant) along directions D (M, 3) -> float32; NaN black."""
    e = dict(ENV_DEFAULTS, **(env or {}))
    colors = np.asarray(e["colors"], np.float64)
    if e["type"] == "constant":
        out = np.broadcast_to((colors[0] * e["intensity"]).astype(np.float32), D.shape).copy()
    elif e["type"] == "checker":
        tiles = e["tiles"]
        with np.errstate(invalid="ignore"):
            u = np.arctan2(D[:, 0], -D[:, 2]) / (2 * np.pi) + 0.5
            v = np.arccos(np.clip(D[:, 1], -1, 1)) / np.pi
            fu = np.floor(u * tiles)
            fv = np.floor(v * (tiles / 2.0))
        fu = np.where(np.isfinite(fu), fu, 0).astype(np.int64)
        fv = np.where(np.isfinite(fv), fv, 0).astype(np.int64)
        out = (colors[(fu + fv) % 2] * e["intensity"]).astype(np.float32)
    else:
        raise ValueError(f"environment.type = {e['type']!r}: this port covers checker and constant only")
    out[~np.all(np.isfinite(D), axis=1)] = 0.0
    return out


def phase(g, cos_t, bugs=()):
    """Henyey-Greenstein p(cos) with cos the photons' direction against the direction towards the
    camera; exactly 1 / (4 pi) for g = 0."""
    if "phase_sign" in bugs:
        g = -g
    if g == 0.0:
        return np.full(cos_t.shape, 1.0 / (4.0 * math.pi))
    d = 1.0 + g * g - 2.0 * g * cos_t
    return (1.0 - g * g) / (4.0 * math.pi * d * np.sqrt(d))


def view(ray_origin, ray_dir, field, vsmax, kappa, sigma, radiance, direction, lo, hi, n_half,
         side, vol, env, sample_field, voxel_of, clip, slab, bugs=()):
    """Pass ``view``: every pixel's curved viewing ray through the volume (Euler steps of length
    hmin; straight where ``view_step_max`` is inf), gathering the in-scattered radiance.

    Returns
    -------
    dict of hit (H, W) bool, exit_pos, exit_dir (H, W, 3) float64, status (H, W) int8,
    interfaces (H, W) int16, path_length (H, W) float64, image (H, W, 3) float32.
    """
    Hh, Ww = ray_dir.shape[:2]
    o = ray_origin.reshape(-1, 3)
    d = ray_dir.reshape(-1, 3)
    M = len(d)
    N = np.array(field.shape[:3])
    h = (hi - lo) / N
    ih = 1.0 / h
    hmin = float(h.min())
    g_ = float(vol["phase_g"])
    sigmaL = (radiance * sigma).astype(np.float32)
    lit = np.any(sigmaL != 0, axis=-1)
    kap = kappa.astype(np.float64)
    status = np.zeros(M, np.int8)
    hit = np.zeros(M, bool)
    inter = np.zeros(M, np.int16)
    plen = np.zeros(M)
    colour = np.zeros((M, 3))
    T = np.ones((M, 3))
    exit_pos = np.full((M, 3), np.nan)
    exit_dir = d.copy()
    w_env = d.copy()                       # the direction the environment is looked up along
    env_on = np.ones(M, bool)
    t_in, t_out = slab(o, d, lo, hi)
    enter = t_out > t_in
    act = np.flatnonzero(enter)
    x = np.zeros((M, 3))
    v = np.zeros((M, 3))
    inside = np.zeros(M, bool)
    x[act] = o[act] + t_in[act, None] * d[act]
    n0 = sample_field(field, x[act], lo, ih, N)[:, 0]
    v[act] = n0[:, None] * d[act]
    if "view_entry_voxel_n" in bugs:
        ce = voxel_of(x[act], lo, ih, N)
        n0v = field[ce[:, 0], ce[:, 1], ce[:, 2], 0].astype(np.float64)
        inside[act] = side * (n0v - n_half) > 0
    else:
        inside[act] = side * (n0 - n_half) > 0
    hit[act] = inside[act]
    ds = hmin
    max_steps = 4 * int(N.sum())
    for it in range(max_steps):
        if not len(act):
            break
        xa, va = x[act], v[act]
        c = voxel_of(xa, lo, ih, N)
        straight = np.isinf(vsmax[c[:, 0], c[:, 1], c[:, 2]])
        f = sample_field(field, xa, lo, ih, N)
        n = np.where(straight, field[c[:, 0], c[:, 1], c[:, 2], 0].astype(np.float64), f[:, 0])
        g = np.where(straight[:, None], 0.0, f[:, 1:])
        now = side * (n - n_half) > 0
        flip = now != inside[act]
        inter[act[flip]] += 1
        hit[act[flip]] = True
        inside[act] = now
        speed = np.sqrt(np.sum(va * va, axis=1))
        ok = speed > 1e-12
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            u = va / speed[:, None]
            x1 = np.where(straight[:, None], xa + ds * u, xa + (ds / n)[:, None] * va)
            v1 = np.where(straight[:, None], va, va + ds * g)
        s = clip(xa, x1, lo, hi)
        seg = np.where(straight, s * ds, s * np.sqrt(np.sum((x1 - xa) ** 2, axis=1)))
        ci = tuple(c.T)
        sl = lit[ci] & ok
        if np.any(sl):
            dirv = direction[ci][sl].astype(np.float64)
            ua = u[sl]
            cos_t = dirv[:, 0] * -ua[:, 0] + dirv[:, 1] * -ua[:, 1] + dirv[:, 2] * -ua[:, 2]
            p = phase(g_, cos_t, bugs)
            a_sl = act[sl]
            colour[a_sl] += T[a_sl] * sigmaL[ci][sl].astype(np.float64) * p[:, None] * seg[sl, None]
        kv = kap[ci]
        att = np.where(kv != 0, np.exp(-kv * seg[:, None]), 1.0)
        okv = act[ok]
        T[okv] *= att[ok]
        plen[act[ok & inside[act]]] += seg[ok & inside[act]]
        lost = act[~ok]
        status[lost] = 4
        exit_dir[lost] = np.nan
        env_on[lost] = False
        leave = ok & (s < 1.0)
        il = act[leave]
        ex = xa[leave] + s[leave, None] * (x1[leave] - xa[leave])
        wv = np.where((straight[leave] | (s[leave] == 0.0))[:, None], v1[leave],
                      va[leave] + (s[leave] * ds)[:, None] * g[leave])
        if "view_exit_full_step" in bugs:
            wv = v1[leave]
        wv = wv / np.sqrt(np.sum(wv * wv, axis=1))[:, None]
        met = hit[il]
        status[il] = np.where(met, 1, 0)
        exit_pos[il[met]] = ex[met]
        exit_dir[il[met]] = wv[met]
        w_env[il] = wv
        if "view_along_ray_dir" in bugs:
            w_env[il[~met]] = d[il[~met]]
        cont = ok & ~(s < 1.0)
        ic = act[cont]
        x[ic], v[ic] = x1[cont], v1[cont]
        act = ic
    status[act] = 2
    exit_dir[act] = np.nan
    env_on[act] = False
    if "view_drop_colour" in bugs:
        colour[(status == 2) | (status == 4)] = 0.0
    img = colour.copy()
    e = environment(w_env[env_on], env).astype(np.float64)
    img[env_on] = colour[env_on] + T[env_on] * e
    return {"hit": hit.reshape(Hh, Ww), "exit_pos": exit_pos.reshape(Hh, Ww, 3),
            "exit_dir": exit_dir.reshape(Hh, Ww, 3), "status": status.reshape(Hh, Ww),
            "interfaces": inter.reshape(Hh, Ww), "path_length": plen.reshape(Hh, Ww),
            "image": img.astype(np.float32).reshape(Hh, Ww, 3)}
