"""docs/oracle.md's porting rules for the level map's `casting` and `image` passes, run as written.

The functions below are the NumPy lines of "Porting rules: level map (Tipprasert 2006)", sections
`casting` and `image` (the docs show them; keep the two in step). They start from the oracle's
upstream stage buffers (`water`, `planes`, `level_map`, `caustics`, `casting`) and the receivers'
triangles, and must reproduce the oracle's `casting` and `image` buffers on small scenes: two lights
of different radiance, and a TIR scene (`outside_ior > water.ior`) whose eye rays are partly
totally reflected at the water.
"""

from __future__ import annotations

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref.levelmap.pipeline import receivers_of
from refraction_ref.scene import load_scene


# --------------------------------------------------------------------- the documented rules
def camera_rays(cam):
    """Primary rays (oracle: "Camera scalars" and `rays`): eye, unit directions (H, W, 3), the view basis."""
    W, H = cam["width"], cam["height"]
    sy = np.tan(np.radians(cam["fov_y"]) / 2.0)
    sx = sy * W / H
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
    D = v[..., 0:1] * B[0] + v[..., 1:2] * B[1] + v[..., 2:3] * B[2]
    return eye, D, B, (sx, sy)


def fragments(Vw, F, cam):
    """(pixel index i*W + j, view depth) of every fragment: the image-space porting rules' rasterizer
    (perspective, 1/256 snap, top-left rule; no vertex lies in front of the near plane here)."""
    eye, _, B, (sx, sy) = camera_rays(cam)
    W, H = cam["width"], cam["height"]
    t = -eye @ B.T
    V = Vw[:, 0:1] * B[:, 0] + Vw[:, 1:2] * B[:, 1] + Vw[:, 2:3] * B[:, 2] + t
    d = -V[:, 2]
    assert (d >= cam["near"]).all(), "near clipping is not ported here"
    X = np.rint((V[:, 0] / (d * sx) * 0.5 + 0.5) * W * 256.0).astype(np.int64)
    Y = np.rint((0.5 - V[:, 1] / (d * sy) * 0.5) * H * 256.0).astype(np.int64)
    D = 1.0 / d
    x0, x1, x2 = X[F].T
    y0, y1, y2 = Y[F].T
    d0, d1, d2 = D[F].T
    A = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
    fl = A < 0
    x1, x2 = np.where(fl, x2, x1), np.where(fl, x1, x2)
    y1, y2 = np.where(fl, y2, y1), np.where(fl, y1, y2)
    d1, d2 = np.where(fl, d2, d1), np.where(fl, d1, d2)
    A = np.abs(A)

    def first(a):
        return np.maximum(-((128 - a) // 256), 0)

    def last(a, n):
        return np.minimum((a - 128) // 256, n - 1)

    j0 = first(np.minimum(np.minimum(x0, x1), x2))
    j1 = last(np.maximum(np.maximum(x0, x1), x2), W)
    i0 = first(np.minimum(np.minimum(y0, y1), y2))
    i1 = last(np.maximum(np.maximum(y0, y1), y2), H)
    nj = np.maximum(j1 - j0 + 1, 0)
    n = np.where(A > 0, np.maximum(i1 - i0 + 1, 0) * nj, 0)
    tt = np.repeat(np.arange(len(F)), n)
    k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    i = i0[tt] + k // nj[tt]
    j = j0[tt] + k % nj[tt]
    px, py = 256 * j + 128, 256 * i + 128
    a0, a1, a2, b0, b1, b2 = x0[tt], x1[tt], x2[tt], y0[tt], y1[tt], y2[tt]
    w0 = (a2 - a1) * (py - b1) - (b2 - b1) * (px - a1)
    w1 = (a0 - a2) * (py - b2) - (b0 - b2) * (px - a2)
    w2 = (a1 - a0) * (py - b0) - (b1 - b0) * (px - a0)

    def own(ax, ay, bx, by):
        return (by - ay < 0) | ((by == ay) & (bx > ax))

    cov = (((w0 > 0) | ((w0 == 0) & own(a1, b1, a2, b2))) & ((w1 > 0) | ((w1 == 0) & own(a2, b2, a0, b0)))
           & ((w2 > 0) | ((w2 == 0) & own(a0, b0, a1, b1))))
    w0, w1, w2, tt = w0[cov], w1[cov], w2[cov], tt[cov]
    depth = 1.0 / ((w0 * d0[tt] + w1 * d1[tt] + w2 * d2[tt]) * (1.0 / A[tt]))
    return i[cov] * W + j[cov], depth


def first_hit(O, D, tris, chunk=256):
    """Nearest float64 Moller-Trumbore hit of each ray on triangles (T, 3, 3): t (inf on a miss), u, v, face.

    Edges inclusive (barycentrics within 1e-12), t >= 0; u weighs vertex 1, v vertex 2; of equal t, the
    lower face. Only pairs whose ray passes within a triangle's bounding sphere are tested (a receiver
    sphere has 20k triangles): the test itself is the same per pair, so the hits are those of all pairs.
    """
    n = len(O)
    t_best = np.full(n, np.inf)
    u_best = np.zeros(n)
    v_best = np.zeros(n)
    f_best = np.full(n, -1, np.int64)
    a = tris[:, 0]
    e1 = tris[:, 1] - a
    e2 = tris[:, 2] - a
    ctr = tris.mean(1)
    rad = np.sqrt(((tris - ctr[:, None]) ** 2).sum(-1).max(1))
    cc = np.sum(ctr * ctr, -1)
    for s in range(0, n, chunk):
        o, d = O[s:s + chunk], D[s:s + chunk]
        # ray-to-centre distances by matrix products; the margin covers their rounding (a cull only)
        dd = np.sum(d * d, -1)[:, None]
        tc = d @ ctr.T - np.sum(o * d, -1)[:, None]                      # (C - o) . d
        oc2 = cc[None] - 2.0 * (o @ ctr.T) + np.sum(o * o, -1)[:, None]  # |C - o|^2
        r = rad[None] + 1e-6 * (1.0 + np.sqrt(cc)[None] + np.sqrt(np.sum(o * o, -1))[:, None])
        near = (oc2 * dd - tc * tc <= r * r * dd) & (tc >= -r * np.sqrt(dd))
        ri, fi = np.nonzero(near)
        if not len(ri):
            continue
        dp, op = d[ri], o[ri]
        p = np.cross(dp, e2[fi])
        det = np.sum(e1[fi] * p, -1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = op - a[fi]
            u = np.sum(tv * p, -1) * inv
            q = np.cross(tv, e1[fi])
            v = np.sum(dp * q, -1) * inv
            t = np.sum(e2[fi] * q, -1) * inv
        ok = (det != 0.0) & (u >= -1e-12) & (v >= -1e-12) & (u + v <= 1.0 + 1e-12) & (t >= 0.0)
        ri, fi, t, u, v = ri[ok], fi[ok], t[ok], u[ok], v[ok]
        order = np.lexsort((fi, t, ri))                               # per ray: nearest, then lowest face
        ri, fi, t, u, v = ri[order], fi[order], t[order], u[order], v[order]
        first = np.r_[True, ri[1:] != ri[:-1]]
        k = s + ri[first]
        t_best[k], u_best[k], v_best[k], f_best[k] = t[first], u[first], v[first], fi[first]
    return t_best, u_best, v_best, f_best


def water_faces(n):
    """The water grid's faces (oracle, `water`): all (v00, v10, v01) first, then all (v10, v11, v01)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v00 = (i * (n + 1) + j).ravel()
    v10, v01 = v00 + n + 1, v00 + 1
    return np.concatenate([np.stack([v00, v10, v01], 1), np.stack([v10, v10 + 1, v01], 1)])


def refract(I, N, eta):
    """Snell in vector form, the normal turned to face I (oracle, `water`); (T, tir)."""
    c = -np.sum(I * N, -1)
    N = np.where((c < 0)[:, None], -N, N)
    c = np.abs(c)
    k = 1.0 - eta * eta * (1.0 - c * c)
    T = eta * I + (eta * c - np.sqrt(np.maximum(k, 0.0)))[:, None] * N
    return T / np.linalg.norm(T, axis=-1, keepdims=True), k < 0.0


def lookup_shade(Q, r, dist, box, cmap, albedo, ambient, K, bugs=()):
    """Eq. 4-19 at receiver points Q of receiver r: albedo (I_c + ambient) exp(-K dist), float32.

    box: stage.planes.box_r_0 (the first light's); cmap: caustic_map_r; map texel floor(row), floor(col),
    clamped to the map; dist the distance in water (0 for a receiver seen directly, no absorption).
    """
    c, U, _, W, (w, _, d) = box
    Hc, Wc = cmap.shape
    q = Q - c
    col = ((q[:, 0] * U[0] + q[:, 1] * U[1] + q[:, 2] * U[2]) / w + 0.5) * Wc
    row = ((q[:, 0] * W[0] + q[:, 1] * W[1] + q[:, 2] * W[2]) / d + 0.5) * Hc
    snap = np.rint if "round_lookup" in bugs else np.floor  # the bug a test plants: rounding, half a texel off
    j = np.clip(snap(col), 0, Wc - 1).astype(np.int64)
    i = np.clip(snap(row), 0, Hc - 1).astype(np.int64)
    e = cmap[i, j].astype(np.float64)
    tr = np.exp(-K * dist) if K > 0 else np.ones_like(dist)
    return (albedo[r][None, :] * (e + ambient)[:, None] * tr[:, None]).astype(np.float32)


def port_image(data, g, tris, owner, bugs=()):
    """The `image` stage's buffers from the upstream buffers g (stage.* keys) and the receivers' triangles.

    data: the resolved scene (``load_scene(path).data``); bugs: mistakes planted by the tests
    (``round_lookup``, ``unnormalised_normal``).
    """
    cam, water = data["camera"], data["water"]
    H, Wd = cam["height"], cam["width"]
    eta = float(data["outside_ior"]) / float(water["ior"])
    K = float(water["absorption"])
    ambient = float(data["caustics"]["ambient"])
    albedo = np.array([np.asarray(rc["albedo"], np.float64) for rc in data["receivers"]])
    R = len(data["receivers"])
    boxes = [g[f"stage.planes.box_{r}_0"] for r in range(R)]
    maps = [g[f"stage.casting.caustic_map_{r}"] for r in range(R)]
    eye, D, B, _ = camera_rays(cam)
    D = D.reshape(-1, 3)
    O = np.broadcast_to(eye, D.shape)
    out = {}

    # image_direct: rasterized (the 1/256 snap), nearest fragment per receiver, ties to the earlier receiver
    best = np.full(H * Wd, np.inf)
    who = np.full(H * Wd, -1)
    for r in range(R):
        t_r = tris[owner == r]
        pix, depth = fragments(t_r.reshape(-1, 3), np.arange(3 * len(t_r)).reshape(-1, 3), cam)
        d_r = np.full(H * Wd, np.inf)
        np.minimum.at(d_r, pix, depth)
        closer = d_r < best
        best[closer], who[closer] = d_r[closer], r
    img = np.zeros((H * Wd, 3), np.float32)
    for r in range(R):
        s = who == r
        Q = eye + D[s] * (best[s] / (D[s] @ -B[2]))[:, None]
        img[s] = lookup_shade(Q, r, np.zeros(s.sum()), boxes[r], maps[r], albedo, ambient, 0.0)
    out["image_direct"] = img.reshape(H, Wd, 3)
    out["object_mask_direct"] = (who >= 0).reshape(H, Wd)

    # image: eye rays ray-cast against the water mesh, refracted with the renormalised Phong normal
    Vw, Nw = g["stage.water.water_vertices"], g["stage.water.water_normals"]
    F = water_faces(int(water["resolution"]))
    t, u, v, f = first_hit(O, D, Vw[F])
    met = np.isfinite(t)
    status = np.full(len(D), 3, np.int8)                     # VIEW_DIRECT until the water is met
    P = np.full_like(D, np.nan)
    T = np.full_like(D, np.nan)
    P[met] = O[met] + t[met, None] * D[met]
    a, b, c = F[f[met]].T
    n = (1 - u[met] - v[met])[:, None] * Nw[a] + u[met, None] * Nw[b] + v[met, None] * Nw[c]
    if "unnormalised_normal" not in bugs:
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
    T_met, tir = refract(D[met], n, eta)
    status[met] = np.where(tir, 4, 1)
    T[met] = np.where(tir[:, None], np.nan, T_met)
    # then the receivers: from the water along T (status 1), from the eye along D (status 3); no visibility test
    go = (status == 1) | (status == 3)
    O2 = np.where((status == 1)[:, None], P, O)[go]
    D2 = np.where((status == 1)[:, None], T, D)[go]
    t2, _, _, f2 = first_hit(O2, D2, tris)
    hit = np.isfinite(t2)
    Q = np.full_like(D, np.nan)
    Q[np.flatnonzero(go)[hit]] = O2[hit] + t2[hit, None] * D2[hit]
    rid = np.full(len(D), -1)
    rid[np.flatnonzero(go)[hit]] = owner[f2[hit]]
    status[np.flatnonzero(go)[~hit]] = np.where(status[go][~hit] == 1, 2, 0)   # lost, missed
    length = np.full(len(D), np.nan)
    length[status == 1] = np.linalg.norm(Q[status == 1] - P[status == 1], axis=-1)
    length[status == 3] = 0.0
    img = np.zeros((len(D), 3), np.float32)
    for r in range(R):
        s = rid == r
        img[s] = lookup_shade(Q[s], r, length[s], boxes[r], maps[r], albedo, ambient, K, bugs)
    P[(status == 0) | (status == 3)] = np.nan
    out.update(image=img.reshape(H, Wd, 3), object_mask=((status == 1) | (status == 3)).reshape(H, Wd),
               view_status=status.reshape(H, Wd), water_pos=P.reshape(H, Wd, 3), water_dir=T.reshape(H, Wd, 3),
               receiver_pos=Q.reshape(H, Wd, 3), water_length=length.reshape(H, Wd))
    return out


def port_casting(g, r, L):
    """caustic_map_r of the `casting` stage: each light's map (radiance already in its flux) added once."""
    out = g[f"stage.caustics.caustic_map_{r}_0"].astype(np.float64).copy()
    c0, U0, V0, W0, (w0, _, d0) = g[f"stage.planes.box_{r}_0"]
    Hc, Wc = out.shape
    pos0 = g[f"stage.level_map.position_{r}_0"]
    own0 = g[f"stage.level_map.diffuse_{r}_0"].any(-1)
    ii, jj = np.nonzero(own0 & np.isfinite(pos0))
    zeta = pos0[ii, jj]
    p = (c0 + (((jj + 0.5) / Wc - 0.5) * w0)[:, None] * U0 + (((ii + 0.5) / Hc - 0.5) * d0)[:, None] * W0
         - zeta[:, None] * V0)
    n = g[f"stage.level_map.normal_{r}_0"][ii, jj]
    ts0 = max(w0 / Wc, d0 / Hc)
    for l in range(1, L):
        cl, Ul, Vl, Wl, (wl, _, dl) = g[f"stage.planes.box_{r}_{l}"]
        q = p - cl
        col = ((q[:, 0] * Ul[0] + q[:, 1] * Ul[1] + q[:, 2] * Ul[2]) / wl + 0.5) * Wc
        row = ((q[:, 0] * Wl[0] + q[:, 1] * Wl[1] + q[:, 2] * Wl[2]) / dl + 0.5) * Hc
        z = -(q[:, 0] * Vl[0] + q[:, 1] * Vl[1] + q[:, 2] * Vl[2])
        a, b = np.floor(row).astype(np.int64), np.floor(col).astype(np.int64)
        inside = (a >= 0) & (a < Hc) & (b >= 0) & (b < Wc)
        a, b = np.where(inside, a, 0), np.where(inside, b, 0)
        own_l = g[f"stage.level_map.diffuse_{r}_{l}"].any(-1)
        tol = 2 * max(max(wl / Wc, dl / Hc), ts0) / np.maximum(np.abs(n @ Vl), 0.05)
        agree = inside & own_l[a, b] & (np.abs(g[f"stage.level_map.position_{r}_{l}"][a, b] - z) <= tol)
        out[ii[agree], jj[agree]] += g[f"stage.caustics.caustic_map_{r}_{l}"][a[agree], b[agree]]
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)


# --------------------------------------------------------------------- the rules against the oracle
SMALL = {"camera.width": 40, "camera.height": 32, "caustics.map_size": 48, "water.resolution": 12,
         "levelmap.planes": 12}


def _small(case, **more):
    """A catalogue case at test size, rendered by the oracle with every stage kept."""
    from refraction_ref.golden.build import catalogue

    scene = load_scene(catalogue([case])[0]["scene"], {**SMALL, **more})
    res = rr.render(scene, "levelmap", keep="stages")
    g = {k: res[k] for k in res.arrays if k.startswith("stage.")}
    return scene, g


@pytest.fixture(scope="module")
def two_lights():
    return _small("lm_two_lights")


@pytest.fixture(scope="module")
def tir():
    return _small("lm_tir")


def _assert_image(scene, g):
    rec = receivers_of(scene)
    mine = port_image(scene.data, g, rec.tris, rec.owner)
    for key in ("view_status", "object_mask", "object_mask_direct"):
        np.testing.assert_array_equal(mine[key], g[f"stage.image.{key}"], err_msg=key)
    for key in ("image", "image_direct"):  # float32 colours: the rules give the oracle's bits
        np.testing.assert_array_equal(mine[key], g[f"stage.image.{key}"], err_msg=key)
    for key in ("water_pos", "water_dir", "receiver_pos", "water_length"):  # NaN where the oracle has NaN
        np.testing.assert_allclose(mine[key], g[f"stage.image.{key}"], rtol=0, atol=1e-9, err_msg=key)
    return mine


def test_casting_adds_each_light_once(two_lights):
    scene, g = two_lights
    lights = scene.data["lights"]
    assert len(lights) == 2 and np.mean(lights[0]["radiance"]) != np.mean(lights[1]["radiance"]) != 1.0
    for r in range(len(scene.data["receivers"])):
        np.testing.assert_array_equal(port_casting(g, r, 2), g[f"stage.casting.caustic_map_{r}"])
    # light 1 really is cast: the floor gains light where light 0's map alone has less
    floor0 = g["stage.caustics.caustic_map_0_0"].astype(np.float32)
    gained = g["stage.casting.caustic_map_0"] > floor0 + 1e-6
    assert gained.mean() > 0.3
    # the porter's bug: weighting each map by its light's radiance again (the flux already holds it) moves the map
    twice = dict(g)
    for l, lt in enumerate(lights):
        for r in range(len(scene.data["receivers"])):
            twice[f"stage.caustics.caustic_map_{r}_{l}"] = g[f"stage.caustics.caustic_map_{r}_{l}"] * np.mean(
                lt["radiance"])
    wrong = port_casting(twice, 0, 2)
    good = g["stage.casting.caustic_map_0"]
    assert np.abs(wrong - good).sum() > 0.2 * np.abs(good).sum()


def test_image_rules_reproduce_the_oracle_with_two_lights(two_lights):
    mine = _assert_image(*two_lights)
    st = mine["view_status"]
    assert (st == 1).any() and (st == 3).any() and not (st == 4).any()


def test_image_rules_reproduce_the_oracle_under_tir(tir):
    scene, g = tir
    assert scene.data["outside_ior"] > scene.data["water"]["ior"]
    mine = _assert_image(scene, g)
    st = mine["view_status"]
    assert (st == 4).sum() > 0.2 * st.size and (st == 1).any()
    # a totally reflected ray is black, keeps its water point, and has no refracted direction
    assert not mine["image"][st == 4].any()
    assert np.isfinite(mine["water_pos"][st == 4]).all() and np.isnan(mine["water_dir"][st == 4]).all()


def test_a_rounded_lookup_or_an_unnormalised_normal_breaks_the_image(two_lights):
    """The rules that matter: floor (not round) at the map lookup, the Phong normal renormalised."""
    scene, g = two_lights
    rec = receivers_of(scene)
    good = port_image(scene.data, g, rec.tris, rec.owner)
    rounded = port_image(scene.data, g, rec.tris, rec.owner, bugs=("round_lookup",))
    assert (np.abs(rounded["image"] - good["image"]) > 1e-3).any(-1).mean() > 0.05
    bent = port_image(scene.data, g, rec.tris, rec.owner, bugs=("unnormalised_normal",))
    assert np.nanmax(np.abs(bent["water_dir"] - good["water_dir"])) > 1e-4
