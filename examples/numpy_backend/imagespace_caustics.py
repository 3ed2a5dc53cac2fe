"""Clean-room NumPy port of the image-space caustic stages (Chaudhari 2008 §4.1).

Written from ``docs/oracle.md`` ("Caustic stages (§4.1)" under "Porting rules:
image-space", "Caustics on receivers", "Stage buffers") alone, one function per
pass, in the order ``check`` judges them: ``receivers``, ``receiver_depth``,
``photon_trace``, ``receiver_hit``, ``splat``, ``gather``, ``caustic_final``.
The light's view reuses the eye passes of ``imagespace.py`` (``base``, the
module passed in) on an N x N orthographic or perspective camera; the
eye-space march runs every photon at once, one sample index per step (a
line primitive's fragments, all lines in one draw).

References
----------
P. Chaudhari, *Real-Time Multiple Refractions Through Deformable Objects*,
M.S. thesis, UMBC, 2008, §4.1 (caustics mapping after Shah et al. 2007, the
eye-space photon search of Krüger et al. 2006, the photon gathering of Wyman
and Davis 2006); L. Williams 1978 (the shadow map).
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np

#: Planted caustic bugs (merged into ``imagespace.BUGS``).
BUGS = {
    "splat_no_cosine": "splat: the irradiance flux / A_texel without the receiver's |n . V|",
    "flux_no_texel_area": "photon_trace/splat: a photon's flux is only its transmittance, not times the "
                          "light texel's area on the window",
    "gather_sigma": "gather: sigma = g / 6 (the window read as six sigma wide) instead of (g - 1) / 6",
    "gather_zero_pad": "gather: zero padding at the map's borders instead of mirroring",
    "splat_nearest": "splat: all of a photon's energy into its nearest texel instead of four bilinear corners",
    "shadow_texel_off": "caustic_final: the shadow map read one light texel off (row floor(row) + 1)",
    "no_shadow": "caustic_final: no shadow test (every receiver point lit directly)",
    "exact_hit": "receiver_hit: the exact ray-triangle hit instead of the eye-space march",
    "march_round": "receiver_hit: the march's nearest texel by rounding (rint) instead of floor",
    "plane_other_diagonal": "receivers: the plane split along the other diagonal (faces [0, 1, 3], [1, 2, 3])",
    "light_mean_centre": "photon_trace: the light camera's bounding sphere centred on the vertices' mean",
    "map_transposed": "receivers/splat: map rows along u and columns along v",
    "hit_face_at_hit": "receiver_hit: hit_face the triangle of the texel under hit_pos instead of the texel "
                       "where the crossing was detected",
    "light_cull_back": "photon_trace: the light's view rasterized with back faces culled (a GPU's default state)",
    "final_nearest_lookup": "caustic_final: the caustic map read at the nearest texel (point sampling) "
                            "instead of bilinearly",
}

LightCam = namedtuple("LightCam", "cam far N")
Box = namedtuple("Box", "centre U V Wa w h d")


# ----------------------------------------------------------------------------- light camera
def light_camera(base, vertices, light, N, bugs=()):
    """The light's camera fitted to the objects' bounding sphere ("The light's camera").

    Returns ``(LightCam, camera_l)``, ``camera_l`` the (6, 3) buffer ``stage.photon_trace.camera_l``.

    References
    ----------
    Chaudhari 2008 §4.1 (render the objects from the light); docs/oracle.md Conventions.
    """
    V = np.asarray(vertices, np.float64)
    c = V.mean(axis=0) if "light_mean_centre" in bugs else (V.min(axis=0) + V.max(axis=0)) / 2.0
    r = max(float(np.sqrt(((V - c) ** 2).sum(axis=1).max())), 1e-9)
    if light["type"] == "directional":
        d = np.asarray(light["direction"], np.float64)
        d = d / np.linalg.norm(d)
        eye = c - d * (1.1 * r)
        sy = 2.0 * r * 1.02 / 2.0
        sx = sy * N / N
        near, far, ortho = 0.05 * r, 2.2 * r, True
    else:
        eye = np.asarray(light["position"], np.float64)
        dist = float(np.linalg.norm(c - eye))
        if dist <= 1.05 * r:
            raise ValueError("lights[].position lies inside the objects' bounding sphere; "
                             "move the point light farther from the objects")
        d = (c - eye) / dist
        fov = float(np.degrees(2.0 * np.arcsin(min(r * 1.02 / dist, 0.999))))
        sy = float(np.tan(np.radians(fov) / 2.0))
        sx = float(sy * N / N)
        near, far, ortho = max(dist - 1.05 * r, 1e-4 * dist), dist + 1.05 * r, False
    up = np.array([0.0, 0.0, 1.0]) if abs(d[1]) > 0.9 else np.array([0.0, 1.0, 0.0])
    f = c - eye
    f = f / np.linalg.norm(f)
    rt = np.cross(f, up)
    rt = rt / np.linalg.norm(rt)
    LB = np.stack([rt, np.cross(rt, f), -f])
    cam = base.Camera(N, N, sx, sy, eye, LB, near, far, ortho)
    buf = np.stack([eye, LB[0], LB[1], LB[2], [sx, sy, 1.0 if ortho else 0.0], [near, far, float(N)]])
    return LightCam(cam, far, N), buf


# ----------------------------------------------------------------------------- receivers
def plane_triangles(rc, bugs=()):
    """A ``plane`` receiver's world triangles (2, 3, 3): ``fit`` is not supported, ``transform`` is."""
    if rc["mesh"] != "plane":
        raise NotImplementedError(f"receivers[].mesh = {rc['mesh']!r} is not implemented by this example "
                                  "(only the built-in 'plane')")
    if rc.get("fit") is not None:
        raise NotImplementedError("receivers[].fit is not implemented by this example; remove it")
    a, b = rc["size"]
    v = np.array([[-a / 2, 0, -b / 2], [a / 2, 0, -b / 2], [a / 2, 0, b / 2], [-a / 2, 0, b / 2]], np.float64)
    t = rc["transform"]
    ax, ay, az = np.radians(np.asarray(t["rotate"], np.float64))
    Rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    Ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    Rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx * float(t["scale"])
    v = v[:, 0:1] * R[:, 0] + v[:, 1:2] * R[:, 1] + v[:, 2:3] * R[:, 2] + np.asarray(t["translate"], np.float64)
    faces = [[0, 1, 3], [1, 2, 3]] if "plane_other_diagonal" in bugs else [[0, 2, 1], [0, 3, 2]]
    return v[np.array(faces)]


def face_normals(tris):
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def map_box(Vr, light):
    """Receiver r's map box: the tight box of its vertices in eq. 4-1's axes for the first light."""
    c = (Vr.min(axis=0) + Vr.max(axis=0)) / 2.0
    T0 = np.asarray(light["direction"], np.float64) if light["type"] == "directional" \
        else c - np.asarray(light["position"], np.float64)
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
    return Box(centre, U, V, Wa, ext[0], ext[1], ext[2])


def map_position(box, P, Hc, Wc, bugs=()):
    """Continuous (col, row) of world points P (M, 3) in the map: column along u, row along v."""
    q = P - box.centre
    U, Wa = box.U, box.Wa
    col = ((q[:, 0] * U[0] + q[:, 1] * U[1] + q[:, 2] * U[2]) / box.w + 0.5) * Wc
    row = ((q[:, 0] * Wa[0] + q[:, 1] * Wa[1] + q[:, 2] * Wa[2]) / box.d + 0.5) * Hc
    if "map_transposed" in bugs:
        return row, col
    return col, row


def pass_receivers(data, bugs=()):
    """``receivers``: the receivers' triangle soup, owners, unit normals, albedos and map boxes/frames."""
    tris, owner = [], []
    for r, rc in enumerate(data["receivers"]):
        t = plane_triangles(rc, bugs)
        tris.append(t)
        owner.append(np.full(len(t), r, np.int64))
    tris = np.concatenate(tris, 0)
    owner = np.concatenate(owner)
    boxes, frames = [], {}
    for r in range(len(data["receivers"])):
        Vr = tris[owner == r].reshape(-1, 3)
        box = map_box(Vr, data["lights"][0])
        boxes.append(box)
        frames[f"frame_{r}"] = np.stack([box.centre - box.w / 2.0 * box.U - box.d / 2.0 * box.Wa
                                         + box.h / 2.0 * box.V, box.w * box.U, box.d * box.Wa, box.V])
    albedo = np.asarray([rc["albedo"] for rc in data["receivers"]], np.float64)
    soup = dict(tris=tris, owner=owner, normals=face_normals(tris), albedo=albedo, boxes=boxes)
    return frames, soup


# ----------------------------------------------------------------------------- receiver_depth
def pass_receiver_depth(base, c, tris):
    """``receiver_depth``: the receivers rasterized from the eye, nearest fragment, ties to the lower index."""
    Vw = tris.reshape(-1, 3)
    F = np.arange(len(Vw)).reshape(-1, 3)
    pix, d, tri = base.fragments(c, Vw, F, with_triangle=True)
    depth = np.full(c.H * c.W, np.inf)
    triangle = np.full(c.H * c.W, -1, np.int64)
    o = np.lexsort((tri, d, pix))                     # per pixel: nearest, then the lower triangle
    pix, d, tri = pix[o], d[o], tri[o]
    first = np.ones(len(pix), bool)
    first[1:] = pix[1:] != pix[:-1]
    depth[pix[first]] = d[first]
    triangle[pix[first]] = tri[first]
    return {"depth": depth.reshape(c.H, c.W), "triangle": triangle.reshape(c.H, c.W)}


# ----------------------------------------------------------------------------- photon_trace
def pass_photon_trace(base, lc, k, Vw, F, ior, outside_ior, absorption, bugs=()):
    """``photon_trace``: the eye passes in the light's view, one photon per texel; the exiting photons' flux.

    Returns the stage buffers (without the light suffix) and the light pass's ``zmin`` (the shadow map).

    References
    ----------
    Chaudhari 2008 §4.1 (Shah et al. 2007's photons through every layer); §3.8 (Beer-Lambert).
    """
    c = lc.cam
    N = lc.N
    pix, depth = base.fragments(c, Vw, F, ("cull_back",) if "light_cull_back" in bugs else ())
    mm = base.pass_minmax(c, pix, depth)
    vx = base.pass_voxelize(c, k, pix, depth, mm["zmin"], mm["zmax"])
    pe = base.pass_peel(c, k, vx["bits"], vx["zlo"], vx["zhi"])
    rd = base.pass_reduce(c, k, pe["ldi"], mm["zmin"], mm["zmax"])
    nr = base.pass_normals(c, k, pe["ldi"])
    if c.ortho:
        v = np.broadcast_to(np.array([0.0, 0.0, -1.0]), (N, N, 3)).copy()
    else:
        _, v = base.pass_rays(c)
    ray_dir = base.to_world(c, v, point=False)
    tr = base.pass_trace(c, k._replace(record=0), v, ray_dir, pe["ldi"], pe["depth_complexity"], mm["zmax"],
                         vx["zlo"], vx["zhi"], rd["bounds_hi"], rd["bounds_lo"], nr["normals"], ior,
                         outside_ior)
    st = tr["status"].ravel()
    keep = np.flatnonzero(st == 1)                     # texel order, row-major
    i, j = np.divmod(keep, N)
    a = (2.0 * c.sx / N) * (2.0 * c.sy / N)
    if "flux_no_texel_area" in bugs:
        a = 1.0
    if c.ortho:
        f0 = np.full(len(i), a)
    else:
        x = ((j + 0.5) / N * 2.0 - 1.0) * c.sx
        y = (1.0 - (i + 0.5) / N * 2.0) * c.sy
        f0 = a / (1.0 + x * x + y * y) ** 1.5
    flux = f0[:, None] * np.exp(-np.asarray(absorption) * (tr["path_length"].ravel()[keep] * ior)[:, None])
    out = {"ldi": pe["ldi"], "exit_pos": tr["exit_pos"].reshape(-1, 3)[keep],
           "exit_dir": tr["exit_dir"].reshape(-1, 3)[keep]}
    return out, flux, mm["zmin"]


# ----------------------------------------------------------------------------- receiver_hit
def _clip(a0, a1, t0, t1):
    """Keep the t of [t0, t1] where a0 + a1 t <= 0 (every ray at once)."""
    zero = a1 == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        tc = -a0 / a1
    t0n = np.where(zero, np.where(a0 > 0.0, 1.0, t0), np.where(a1 > 0.0, t0, np.maximum(t0, tc)))
    t1n = np.where(zero, np.where(a0 > 0.0, 0.0, t1), np.where(a1 > 0.0, np.minimum(t1, tc), t1))
    return t0n, t1n


def _project(c, x, y, z):
    inv = 1.0 / -z
    return 0.5 * c.H - y * inv * (0.5 * c.H / c.sy), x * inv * (0.5 * c.W / c.sx) + 0.5 * c.W


def _exact_hits(exit_pos, exit_dir, tris):
    """The planted ``exact_hit``: the nearest ray-triangle hit (Möller-Trumbore), seen by the eye or not."""
    P = len(exit_pos)
    best = np.full(P, np.inf)
    face = np.full(P, -1, np.int64)
    for k, T in enumerate(tris):
        e1, e2 = T[1] - T[0], T[2] - T[0]
        h = np.cross(exit_dir, e2)
        a = h @ e1
        with np.errstate(divide="ignore", invalid="ignore"):
            f = 1.0 / a
            s = exit_pos - T[0]
            u = f * (s * h).sum(1)
            q = np.cross(s, e1)
            v = f * (exit_dir * q).sum(1)
            t = f * (q @ e2)
        ok = (np.abs(a) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9) & (t < best)
        best = np.where(ok, t, best)
        face = np.where(ok, k, face)
    hit = exit_pos + np.where(np.isfinite(best), best, np.nan)[:, None] * exit_dir
    return hit, face


def receiver_hits(c, exit_pos, exit_dir, depth, triangle, bugs=()):
    """The eye-space march of every ray (exit_pos, exit_dir) against the receivers' depth image.

    Returns ``(hit_pos, hit_face)``: NaN / -1 where the march is lost or never crosses.

    References
    ----------
    Chaudhari 2008 §4.1 (Krüger et al. 2006: the photons as lines in eye space, resolved against the
    depth image of the surroundings); docs/oracle.md ``receiver_hit`` steps 1-5.
    """
    M = len(exit_pos)
    o = base_to_view(c, exit_pos)
    B = c.B
    v = exit_dir[:, 0:1] * B[:, 0] + exit_dir[:, 1:2] * B[:, 1] + exit_dir[:, 2:3] * B[:, 2] + 0.0
    ox, oy, oz = o.T
    dx, dy, dz = v.T
    sx, sy, near, far = c.sx, c.sy, c.near, c.far
    t0, t1 = np.zeros(M), np.full(M, 1e30)
    t0, t1 = _clip(near + oz, dz, t0, t1)
    t0, t1 = _clip(-oz - far, -dz, t0, t1)
    t0, t1 = _clip(ox + sx * oz, dx + sx * dz, t0, t1)
    t0, t1 = _clip(-ox + sx * oz, -dx + sx * dz, t0, t1)
    t0, t1 = _clip(oy + sy * oz, dy + sy * dz, t0, t1)
    t0, t1 = _clip(-oy + sy * oz, -dy + sy * dz, t0, t1)
    live = (t1 > t0) & (t1 < 1e29)
    t_hit = np.full(M, np.nan)
    hi = np.full(M, -1, np.int64)
    hj = np.full(M, -1, np.int64)
    idx = np.flatnonzero(live)
    ox, oy, oz, dx, dy, dz, t0, t1 = (a[idx] for a in (ox, oy, oz, dx, dy, dz, t0, t1))
    with np.errstate(divide="ignore", invalid="ignore"):
        r0, c0 = _project(c, ox + t0 * dx, oy + t0 * dy, oz + t0 * dz)
        dA = -(oz + t0 * dz)
        r1, c1 = _project(c, ox + t1 * dx, oy + t1 * dy, oz + t1 * dz)
        dB = -(oz + t1 * dz)
    n = np.minimum(np.maximum(np.ceil(np.maximum(np.abs(c1 - c0), np.abs(r1 - r0))).astype(np.int64) + 1, 2),
                   1 << 16)
    gap_prev = np.full(len(idx), -np.inf)
    t_prev = t0.copy()
    rd_prev = dA.copy()
    act = np.ones(len(idx), bool)
    m = 0
    while act.any():
        a = np.flatnonzero(act)
        u = m / n[a]
        s = (u / dB[a]) / ((1.0 - u) / dA[a] + u / dB[a])
        t = t0[a] + s * (t1[a] - t0[a])
        px, py, pz = ox[a] + t * dx[a], oy[a] + t * dy[a], oz[a] + t * dz[a]
        row, col = _project(c, px, py, pz)
        rd = -pz
        fr = np.rint(row) if "march_round" in bugs else np.floor(row)
        fc = np.rint(col) if "march_round" in bugs else np.floor(col)
        i = np.clip(fr, 0, c.H - 1).astype(np.int64)
        j = np.clip(fc, 0, c.W - 1).astype(np.int64)
        sd = depth[i, j]
        fin = np.isfinite(sd)
        with np.errstate(invalid="ignore"):
            gap = np.where(fin, rd - sd, -np.inf)
            hit = (gap >= 0.0) & (gap_prev[a] < 0.0) & (gap <= np.abs(rd - rd_prev[a]) + 0.01 * sd)
            gp = gap_prev[a]
            f = np.where(np.isfinite(gp), -gp / (gap - gp), 1.0)
        h = a[hit]
        t_hit[idx[h]] = t_prev[h] + f[hit] * (t[hit] - t_prev[h])
        hi[idx[h]], hj[idx[h]] = i[hit], j[hit]
        gap_prev[a], t_prev[a], rd_prev[a] = gap, t, rd
        act[h] = False
        m += 1
        act &= m <= n
    face = np.where(hi >= 0, triangle[np.maximum(hi, 0), np.maximum(hj, 0)], -1)
    face = np.where(np.isfinite(t_hit), face, -1)
    hit_pos = exit_pos + t_hit[:, None] * exit_dir
    if "hit_face_at_hit" in bugs:                      # the texel under the resolved point instead
        ok = face >= 0
        row, col = _project(c, *base_to_view(c, hit_pos[ok]).T)
        face[ok] = triangle[np.clip(np.floor(row), 0, c.H - 1).astype(np.int64),
                            np.clip(np.floor(col), 0, c.W - 1).astype(np.int64)]
    return hit_pos, face


def base_to_view(c, P):
    t = -c.eye @ c.B.T
    B = c.B
    return P[:, 0:1] * B[:, 0] + P[:, 1:2] * B[:, 1] + P[:, 2:3] * B[:, 2] + t


def pass_receiver_hit(c, exit_pos, exit_dir, depth, triangle, tris, bugs=()):
    """``receiver_hit``: where the eye-space march meets each exiting photon with the receivers."""
    if "exact_hit" in bugs:
        return _exact_hits(exit_pos, exit_dir, tris)
    return receiver_hits(c, exit_pos, exit_dir, depth, triangle, bugs)


# ----------------------------------------------------------------------------- splat
def splat(col, row, val, Hc, Wc, bugs=()):
    """Bilinear splat of ``val`` (M, 3) at continuous map positions, corners clamped to the map, in order."""
    x = np.clip(col - 0.5, -1.0, Wc + 0.0)
    y = np.clip(row - 0.5, -1.0, Hc + 0.0)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y, val = x[ok], y[ok], val[ok]
    out = np.zeros((Hc, Wc, val.shape[1]))
    if "splat_nearest" in bugs:
        i = np.clip(np.floor(y + 0.5), 0, Hc - 1).astype(np.int64)
        j = np.clip(np.floor(x + 0.5), 0, Wc - 1).astype(np.int64)
        np.add.at(out, (i, j), val)
        return out
    j0 = np.floor(x).astype(np.int64)
    i0 = np.floor(y).astype(np.int64)
    fx, fy = x - j0, y - i0
    ii, jj, ww = [], [], []
    for di, wy in ((0, 1.0 - fy), (1, fy)):
        for dj, wx in ((0, 1.0 - fx), (1, fx)):
            ii.append(np.clip(i0 + di, 0, Hc - 1))
            jj.append(np.clip(j0 + dj, 0, Wc - 1))
            ww.append(wy * wx)
    ii, jj, ww = (np.stack(a, 1).ravel() for a in (ii, jj, ww))       # photon-major, then corner
    np.add.at(out, (ii, jj), ww[:, None] * np.repeat(val, 4, axis=0))
    return out


def pass_splat(hit_pos, hit_face, flux, r, box, soup, Hc, Wc, bugs=()):
    """``splat``: one light's photons on receiver r, E = flux |n . V| / A_texel, bilinear (Hc, Wc, 3) float64.

    References
    ----------
    Chaudhari 2008 §4.1 (caustics mapping, Shah et al. 2007); §2.3.2.
    """
    owner, normals = soup["owner"], soup["normals"]
    idx = np.flatnonzero((hit_face >= 0) & (owner[np.maximum(hit_face, 0)] == r))
    n, V = normals[hit_face[idx]], box.V
    cosv = np.abs(n[:, 0] * V[0] + n[:, 1] * V[1] + n[:, 2] * V[2])
    if "splat_no_cosine" in bugs:
        cosv = np.ones_like(cosv)
    val = flux[idx] * (cosv / ((box.w / Wc) * (box.d / Hc)))[:, None]
    col, row = map_position(box, hit_pos[idx], Hc, Wc, bugs)
    return splat(col, row, val, Hc, Wc, bugs)


# ----------------------------------------------------------------------------- gather
def gather(E, g, bugs=()):
    """``gather``: separable Gaussian over g x g texels, rows (u) first, mirrored at the borders.

    References
    ----------
    Chaudhari 2008 §4.1 (photon gathering of Wyman and Davis 2006, a 7 x 7 window).
    """
    r = g // 2
    if r == 0:
        return E.copy()
    x = np.arange(-r, r + 1, dtype=np.float64)
    sigma = g / 6.0 if "gather_sigma" in bugs else (g - 1) / 6.0
    w = np.exp(-0.5 * (x / sigma) ** 2)
    w = w / w.sum()
    if min(E.shape[:2]) - 1 < r:
        if min(E.shape[:2]) - 1 <= 0:
            return E.copy()
        r2 = min(E.shape[:2]) - 1
        w = w[r - r2:r + r2 + 1]
        w = w / w.sum()
        r = r2
    mirror = "gather_zero_pad" not in bugs

    def fold(a):                                       # along axis 0, every output texel at once
        N_ = a.shape[0]
        i = np.arange(N_)
        out = np.zeros_like(a)
        for t in range(-r, r + 1):
            srcs = (i - t, -1 - i - t, 2 * N_ - 1 - i - t) if mirror else (i - t,)
            for src in srcs:
                ok = (src >= 0) & (src < N_)
                term = w[t + r] * a[np.clip(src, 0, N_ - 1)]
                out = out + np.where(ok.reshape((-1,) + (1,) * (a.ndim - 1)), term, 0.0)
        return out

    return fold(fold(E.transpose(1, 0, 2)).transpose(1, 0, 2))


# ----------------------------------------------------------------------------- caustic_final
def environment(base, env, D):
    """The environment along directions D (M, 3), float32; NaN directions black."""
    img = base.pass_shade(env, D, np.zeros(len(D)), np.zeros(3), 1.0)["image"]
    img = np.asarray(img, np.float32).copy()
    img[~np.all(np.isfinite(D), axis=1)] = 0.0
    return img


def shadow_vis(P, lc, lzmin, bugs=()):
    """The shadow-map test of receiver points P against light l's ``zmin``: 1 lit, 0 shadowed (Williams 1978)."""
    c = lc.cam
    N = lc.N
    LB, leye = c.B, c.eye
    pv = P[:, 0:1] * LB[:, 0] + P[:, 1:2] * LB[:, 1] + P[:, 2:3] * LB[:, 2] + (-leye @ LB.T)
    dl = -pv[:, 2]
    s = np.ones_like(dl) if c.ortho else dl
    with np.errstate(divide="ignore", invalid="ignore"):
        col = (pv[:, 0] / (s * c.sx) * 0.5 + 0.5) * N
        row = (0.5 - pv[:, 1] / (s * c.sy) * 0.5) * N
    if "no_shadow" in bugs:
        return np.ones(len(P))
    return np.where(_shadow_margin(col, row, dl, lc, lzmin, bugs) > 0, 0.0, 1.0)


def _shadow_margin(col, row, dl, lc, lzmin, bugs=()):
    """``dl - (zmin + bias)`` at the nearest texel of (col, row); -inf where no depth is compared."""
    c, N = lc.cam, lc.N
    inside = np.isfinite(col) & np.isfinite(row) & (col >= 0) & (col < N) & (row >= 0) & (row < N) & (dl > 0)
    off = 1 if "shadow_texel_off" in bugs else 0
    i = np.clip(np.floor(np.where(inside, row, 0)).astype(np.int64) + off, 0, N - 1)
    j = np.clip(np.floor(np.where(inside, col, 0)).astype(np.int64), 0, N - 1)
    z = lzmin[i, j]
    bias = 1e-3 * (lc.far - c.near) + 2.0 * (2.0 * c.sy / N)
    with np.errstate(invalid="ignore"):
        return np.where(inside & np.isfinite(z), dl - (z + bias), -np.inf)


def shadow_buffers(P, lc, lzmin, bugs=()):
    """``stage.caustic_final.shadow_l`` codes (1 lit, 2 in shadow) and ``shadow_margin_l`` at receiver points P.

    The margin is 0 where moving the point's texel position by 5e-3 texel along an axis changes the verdict
    (docs/oracle.md, caustic_final: a texel-edge tie).
    """
    c, N = lc.cam, lc.N
    LB, leye = c.B, c.eye
    pv = P[:, 0:1] * LB[:, 0] + P[:, 1:2] * LB[:, 1] + P[:, 2:3] * LB[:, 2] + (-leye @ LB.T)
    dl = -pv[:, 2]
    s = np.ones_like(dl) if c.ortho else dl
    with np.errstate(divide="ignore", invalid="ignore"):
        col = (pv[:, 0] / (s * c.sx) * 0.5 + 0.5) * N
        row = (0.5 - pv[:, 1] / (s * c.sy) * 0.5) * N
    m = _shadow_margin(col, row, dl, lc, lzmin, bugs)
    if "no_shadow" in bugs:
        return np.ones(len(P), np.uint8), np.full(len(P), -np.inf)
    code = np.where(m > 0, 2, 1).astype(np.uint8)
    for dc, dr in ((5e-3, 0.0), (-5e-3, 0.0), (0.0, 5e-3), (0.0, -5e-3)):
        m = np.where((_shadow_margin(col + dc, row + dr, dl, lc, lzmin, bugs) > 0) != (m > 0), 0.0, m)
    return code, m


def shade_receiver(P, face, dirs, soup, lights, vis, rgb, Hc, Wc, bugs=()):
    """Colour of receiver points P on triangles ``face`` seen along ``dirs``: direct (shadow-tested) + caustics."""
    n = soup["normals"][face].copy()
    n[(n[:, 0] * dirs[:, 0] + n[:, 2] * dirs[:, 2]) + n[:, 1] * dirs[:, 1] > 0] *= -1.0
    acc = np.zeros((len(P), 3))
    for l, lt in enumerate(lights):
        if lt["type"] == "directional":
            L = np.asarray(lt["direction"], np.float64)
            L = np.broadcast_to(L / np.linalg.norm(L), P.shape)
            fall = np.ones(len(P))
        else:
            q = P - np.asarray(lt["position"], np.float64)
            r2 = np.maximum((q * q).sum(axis=-1), 1e-300)
            L = q / np.sqrt(r2)[:, None]
            fall = 1.0 / r2
        cos = -((n[:, 0] * L[:, 0] + n[:, 2] * L[:, 2]) + n[:, 1] * L[:, 1])
        cos = np.where((cos > 0) | np.isnan(cos), cos, 0.0)
        v = np.zeros(len(P))
        lit = cos > 0
        v[lit] = vis[l](P[lit])
        acc += np.asarray(lt["radiance"], np.float64) * (cos * fall * v)[:, None]
    own = soup["owner"][face]
    for r, box in enumerate(soup["boxes"]):
        sel = own == r
        col, row = map_position(box, P[sel], Hc, Wc, bugs)
        x = np.nan_to_num(np.clip(col - 0.5, 0.0, Wc - 1.0))
        y = np.nan_to_num(np.clip(row - 0.5, 0.0, Hc - 1.0))
        j0 = np.minimum(np.floor(x).astype(np.int64), Wc - 1)
        i0 = np.minimum(np.floor(y).astype(np.int64), Hc - 1)
        j1, i1 = np.minimum(j0 + 1, Wc - 1), np.minimum(i0 + 1, Hc - 1)
        fx, fy = (x - j0)[:, None], (y - i0)[:, None]
        if "final_nearest_lookup" in bugs:             # point sampling: the texel under the point
            fx, fy = np.round(fx), np.round(fy)
        E = rgb[r]
        acc[sel] += (1 - fy) * ((1 - fx) * E[i0, j0] + fx * E[i0, j1]) + fy * ((1 - fx) * E[i1, j0] + fx * E[i1, j1])
    return soup["albedo"][own] * acc


def pass_caustic_final(base, c, k, data, zfront, rdepth, rtri, ray_dir, v_view, tr, shade_pts, ior,
                       outside_ior, absorption, shadow_maps, bugs=()):
    """``caustic_final``: receivers lit directly and by the maps, seen directly or through the object.

    ``image_caustics`` sends the multi-layer trace's exit rays through the march; ``image_caustics_single``
    refracts once at the front surface (the thesis's final pass).

    References
    ----------
    Chaudhari 2008 §4.1 ("single surface refraction for the final rendering pass"), §3.8.
    """
    H, W = c.H, c.W
    env = data["environment"]
    rd = ray_dir.reshape(-1, 3)
    obj = np.isfinite(zfront)
    rec = np.isfinite(rdepth) & (rdepth < np.where(obj, zfront, np.inf))
    obj = (obj & ~rec).ravel()
    rec = rec.ravel()
    base_img = np.zeros((H * W, 3))
    ri = np.flatnonzero(rec)
    dr = rd[ri]
    f = -c.B[2]
    P = c.eye + dr * (rdepth.ravel()[ri] / (dr[:, 0] * f[0] + dr[:, 1] * f[1] + dr[:, 2] * f[2]))[:, None]
    base_img[ri] = shade_pts(P, rtri.ravel()[ri], dr)
    shadow = {}
    for l, (lc, lz) in enumerate(shadow_maps):        # every receiver pixel, facing the light or not
        code, m = np.zeros(H * W, np.uint8), np.full(H * W, np.nan)
        code[ri], m[ri] = shadow_buffers(P, lc, lz, bugs)
        shadow[f"shadow_{l}"] = code.reshape(H, W)
        shadow[f"shadow_margin_{l}"] = m.reshape(H, W).astype(np.float32)
    bg = ~rec & ~obj
    base_img[bg] = environment(base, env, rd[bg])

    def colour(o, d):
        Ph, face = receiver_hits(c, o, d, rdepth, rtri)
        out = np.zeros((len(o), 3))
        hit = face >= 0
        out[hit] = shade_pts(Ph[hit], face[hit], d[hit])
        out[~hit] = environment(base, env, d[~hit])
        return out

    full, single = base_img.copy(), base_img.copy()
    st = tr["status"].ravel()
    oi = np.flatnonzero(obj)
    xi = np.flatnonzero(obj & (st == 1))
    si = np.flatnonzero(obj & (st != 1))
    full[xi] = colour(tr["exit_pos"].reshape(-1, 3)[xi], tr["exit_dir"].reshape(-1, 3)[xi])
    full[si] = environment(base, env, tr["last_dir"].reshape(-1, 3)[si])
    full[oi] *= np.exp(-absorption * (tr["path_length"].ravel()[oi] * ior)[:, None])
    # the thesis's final pass: one refraction at the front surface, normal from zfront
    if k.normals == "forward":
        n = base._normals_forward(c, zfront).reshape(-1, 3)[oi]
    else:
        n = base._normals_central(c, zfront, k.delta).reshape(-1, 3)[oi]
    v = v_view.reshape(-1, 3)[oi]
    i, j = np.divmod(oi, W)
    x = ((j + 0.5) / W * 2.0 - 1.0) * c.sx
    y = (1.0 - (i + 0.5) / H * 2.0) * c.sy
    eta = outside_ior / ior
    cc = -(v[:, 0] * n[:, 0] + v[:, 1] * n[:, 1] + v[:, 2] * n[:, 2])
    n = np.where((cc < 0)[:, None], -n, n)
    cc = np.abs(cc)
    kk = 1.0 - eta * eta * (1.0 - cc * cc)
    with np.errstate(invalid="ignore"):
        w = np.where((kk < 0.0)[:, None], v + 2.0 * cc[:, None] * n,
                     eta * v + (eta * cc - np.sqrt(np.maximum(kk, 0.0)))[:, None] * n)
        w = w * (1.0 / np.sqrt(w[:, 0] * w[:, 0] + w[:, 1] * w[:, 1] + w[:, 2] * w[:, 2]))[:, None]
    w = np.where(np.all(np.isfinite(w), axis=1)[:, None], w, v)
    zf = zfront.ravel()[oi]
    single[oi] = colour(base.to_world(c, np.stack([x * zf, y * zf, -zf], -1)),
                        base.to_world(c, w, point=False) + 0.0)
    return {"image_caustics": full.reshape(H, W, 3).astype(np.float32),
            "image_caustics_single": single.reshape(H, W, 3).astype(np.float32), **shadow}


# ----------------------------------------------------------------------------- driver
def run_caustics(base, c, k, data, Vw, F, ior, outside_ior, absorption, st, v_view, bugs=()):
    """Every caustic stage after ``shade``; adds ``st[stage]`` dicts and returns the final caustic keys."""
    Hc = Wc = int(data["caustics"]["map_size"])
    g = int(data["caustics"]["gather"])
    N = int(data["imagespace"]["photons"])
    lights = data["lights"]
    st["receivers"], soup = pass_receivers(data, bugs)
    st["receiver_depth"] = pass_receiver_depth(base, c, soup["tris"])
    rdepth, rtri = st["receiver_depth"]["depth"], st["receiver_depth"]["triangle"]
    R = len(data["receivers"])
    pt, rh, lcs, zmins = {}, {}, [], []
    splat_sum = [np.zeros((Hc, Wc)) for _ in range(R)]
    cmap = [np.zeros((Hc, Wc)) for _ in range(R)]
    rgb = [np.zeros((Hc, Wc, 3)) for _ in range(R)]
    for l, lt in enumerate(lights):
        lc, buf = light_camera(base, Vw, lt, N, bugs)
        bufs, flux, lzmin = pass_photon_trace(base, lc, k, Vw, F, ior, outside_ior, absorption, bugs)
        lcs.append(lc)
        zmins.append(lzmin)
        pt[f"camera_{l}"] = buf
        for b in ("ldi", "exit_pos", "exit_dir"):
            pt[f"{b}_{l}"] = bufs[b]
        hp, hf = pass_receiver_hit(c, bufs["exit_pos"], bufs["exit_dir"], rdepth, rtri, soup["tris"], bugs)
        rh[f"hit_pos_{l}"], rh[f"hit_face_{l}"] = hp, hf
        for r in range(R):
            E = pass_splat(hp, hf, flux, r, soup["boxes"][r], soup, Hc, Wc, bugs)
            splat_sum[r] += (E[..., 0] + E[..., 1] + E[..., 2]) / 3.0
            m = gather(E, g, bugs)
            cmap[r] += (m[..., 0] + m[..., 1] + m[..., 2]) / 3.0
            rgb[r] += m * np.asarray(lt["radiance"], np.float64)
    st["photon_trace"] = pt
    st["receiver_hit"] = rh
    st["splat"] = {f"splat_{r}": splat_sum[r].astype(np.float32) for r in range(R)}
    rgb = [np.where(np.isfinite(a), a, 0.0) for a in rgb]
    cmap = [np.where(np.isfinite(a), a, 0.0) for a in cmap]
    ga = {}
    for r in range(R):
        ga[f"caustic_map_{r}"] = cmap[r].astype(np.float32)
        ga[f"caustic_frame_{r}"] = st["receivers"][f"frame_{r}"]
        ga[f"caustic_rgb_{r}"] = rgb[r].astype(np.float32)
    st["gather"] = ga
    vis = [(lambda P, lc=lc, z=z: shadow_vis(P, lc, z, bugs)) for lc, z in zip(lcs, zmins)]

    def shade_pts(P, face, dirs):
        return shade_receiver(P, face, dirs, soup, lights, vis, rgb, Hc, Wc, bugs)

    st["caustic_final"] = pass_caustic_final(base, c, k, data, st["minmax"]["zmin"], rdepth, rtri,
                                             st["rays"]["ray_dir"], v_view, st["trace"], shade_pts, ior,
                                             outside_ior, absorption, list(zip(lcs, zmins)), bugs)
    out = dict(ga)
    out.update({k_: v for k_, v in st["caustic_final"].items() if k_.startswith("image_caustics")})
    out["image"] = out["image_caustics"]
    return out
