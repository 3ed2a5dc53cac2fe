"""The final pass's fused kernels against the NumPy code they replaced, on 1 and 2 threads.

``shade_points`` with a :class:`~refraction_ref.caustics.shade.ShadowMaps` visibility colours every
point in one kernel (the facing normal, each light's cosine, shadow-map test and direct term, the
caustic map's look-up, the albedo); ``shadow_map_test`` writes the shadow buffers' verdict and
margin in one pass. Both must give the bits of the NumPy expressions (``shade_points_numpy``,
``shadow_map_margin_numpy`` of ``test_caustics_parallel``) whatever the lights, receivers and
threads.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_caustics_parallel import SCENE, shade_points_numpy, shadow_map_margin_numpy

import refraction_ref as rr
from refraction_ref.camera import Camera
from refraction_ref.caustics import shade
from refraction_ref.caustics.shadow import ShadowMaps, shadow_map_test, shadow_map_visibility, view_affine
from refraction_ref.caustics.receivers import receiver_set


def _light_cam(ortho, size=32):
    return Camera.from_dict({"eye": [0.3, 3.0, 0.2], "target": [0, 0, 0], "up": [0, 0, 1], "fov_y": 40,
                             "width": size, "height": size, "near": 0.1, "far": 10, "ortho": ortho,
                             **({"ortho_height": 3.0} if ortho else {})})


def _case(lights, n_receivers=2, seed=11, M=6000):
    with open(SCENE) as f:
        raw = json.load(f)
    raw["lights"] = lights
    rcv = [{"mesh": "plane", "size": [4, 4], "transform": {"translate": [0, -0.5, 0]}, "albedo": [0.8, 0.6, 0.4]},
           {"mesh": "plane", "size": [2, 2], "transform": {"translate": [0, 0.3, -1.0], "rotate": [90, 0, 0]}}]
    raw["receivers"] = rcv[:n_receivers]
    sc = rr.load_scene(raw)
    rs = receiver_set(sc, sc.data["lights"][0], 32)
    rng = np.random.default_rng(seed)
    faces = rng.integers(0, len(rs.tris), M)
    b = rng.dirichlet([1, 1, 1], M)
    P = np.einsum("ij,ijk->ik", b, rs.tris[faces])
    P[::701] = np.nan  # NaN cosines and map positions
    d = rng.normal(size=(M, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    maps = [rng.random(box.size + (3,)) for box in rs.boxes]
    return sc, rs, P, faces, d, maps, rng


@pytest.mark.parametrize("lights, n_receivers, shadowed", [
    ([{"type": "directional", "direction": [0.2, -1.0, -0.1], "radiance": [1, 0.5, 0.25]}], 1, [True]),
    ([{"type": "directional", "direction": [0.2, -1.0, -0.1], "radiance": [1, 0.5, 0.25]},
      {"type": "point", "position": [0.5, 1.5, 0.3], "radiance": [2.0, 2.0, 1.0]}], 2, [True, False]),
    ([{"type": "point", "position": [0.5, 1.5, 0.3], "radiance": [2.0, 2.0, 1.0]},
      {"type": "directional", "direction": [-0.3, -1.0, 0.2], "radiance": [0.5, 1, 1]}], 2, [True, True]),
])
def test_fused_shade_points_equals_numpy(on_one_and_two_threads, lights, n_receivers, shadowed):
    sc, rs, P, faces, d, maps, rng = _case(lights, n_receivers)
    shadow = []
    for l, s in enumerate(shadowed):
        if not s:
            shadow.append(None)
            continue
        zmin = rng.uniform(2.5, 3.8, (32, 32))
        zmin[rng.random((32, 32)) < 0.2] = np.inf
        shadow.append((_light_cam(l % 2 == 1), zmin, 0.01))
    vis = ShadowMaps(shadow)
    assert shade.shade_points_fuses(rs, sc.data["lights"], maps, vis)  # the fused kernel runs
    want = shade_points_numpy(rs, sc.data["lights"], maps, P, faces, d, vis)
    # the generic path (any callable) gives the same bits too
    generic = shade.shade_points(rs, sc.data["lights"], maps, P, faces, d, lambda l, p, n: vis(l, p, n))
    a, b = on_one_and_two_threads(lambda: shade.shade_points(rs, sc.data["lights"], maps, P, faces, d, vis))
    for got in (a, b, generic):
        assert np.array_equal(got, want, equal_nan=True)
    assert np.nanstd(want) > 0
    # some points are shadowed, some lit, some face away from a light
    v0 = vis(0, P, None)
    assert 0 < np.nansum(v0 == 0) < len(P)


@pytest.mark.parametrize("ortho", [False, True])
def test_shadow_map_test_equals_numpy(on_one_and_two_threads, ortho):
    rng = np.random.default_rng(41)
    lcam = _light_cam(ortho)
    zmin = rng.uniform(2.5, 3.5, (32, 32))
    zmin[rng.random((32, 32)) < 0.2] = np.inf
    p = rng.uniform(-1.5, 1.5, (4000, 3))
    p[::500] = np.nan
    p[1::500] = [0.3, 5.0, 0.2]  # behind the light
    K = 9000
    idx = rng.permutation(K)[:len(p)]
    for tie in (0.0, 5e-3, 0.3):
        code_w = np.zeros(K, np.uint8)
        margin_w = np.full(K, np.nan, np.float32)
        code_w[idx] = np.where(shadow_map_visibility(lcam, zmin, p, 0.01) > 0, 1, 2)
        margin_w[idx] = shadow_map_margin_numpy(lcam, zmin, p, 0.01, tie)
        assert (code_w == 2).sum() > 100 and (code_w == 1).sum() > 100

        def run():
            code = np.zeros(K, np.uint8)
            margin = np.full(K, np.nan, np.float32)
            shadow_map_test(lcam, zmin, p, 0.01, tie, idx, code, margin)
            return code, margin

        for code, margin in on_one_and_two_threads(run):
            assert np.array_equal(code, code_w)
            assert np.array_equal(margin, margin_w, equal_nan=True)


def _final_rays_numpy(cam, zfront, exit_pos, exit_dir, xi, oi, method, delta, eta):
    """The final pass's rays as _final_imagespace built them before its kernel: the exit rays, then
    the front surface's refracted rays (whole-image normals and directions, refract, front points)."""
    from refraction_ref.imagespace.normals import layer_normals
    from refraction_ref.optics import refract

    H, W = cam.shape
    o_full = exit_pos.reshape(-1, 3)[xi]
    d_full = exit_dir.reshape(-1, 3)[xi]
    nrm = layer_normals(np.where(np.isfinite(zfront), zfront, np.inf), cam, method, delta)
    dv = cam.primary_rays_view().reshape(-1, 3)[oi]
    t, _ = refract(dv, nrm.reshape(-1, 3)[oi], eta)
    t = np.where(np.all(np.isfinite(t), axis=1)[:, None], t, dv)
    ii, jj = oi // W, oi % W
    x = ((jj + 0.5) / W * 2.0 - 1.0) * float(cam.sx)
    y = (1.0 - (ii + 0.5) / H * 2.0) * float(cam.sy)
    dfront = zfront.reshape(-1)[oi]
    pv = np.stack([x, y, -dfront], axis=1) if cam.ortho else np.stack([x * dfront, y * dfront, -dfront], axis=1)
    return (np.concatenate([o_full, cam.view_to_world(pv)]), np.concatenate([d_full, cam.dir_view_to_world(t)]))


@pytest.mark.parametrize("ortho", [False, True])
@pytest.mark.parametrize("method, delta", [("central", 1), ("central", 2), ("forward", 1), ("mesh3x3", 1),
                                           ("cross", 1)])
def test_final_rays_kernel_equals_numpy(on_one_and_two_threads, ortho, method, delta):
    from refraction_ref.imagespace import caustics as ic
    from refraction_ref.imagespace.normals import NORMAL_METHODS, no_lut

    rng = np.random.default_rng(23)
    cam = _light_cam(ortho, 40)
    H, W = cam.shape
    yy, xx = np.mgrid[0:H, 0:W]
    zfront = 3.0 - 0.4 * np.exp(-((xx - 20) ** 2 + (yy - 18) ** 2) / 90.0) + 0.01 * rng.random((H, W))
    zfront[(xx - 20) ** 2 + (yy - 18) ** 2 > 15 ** 2] = np.inf
    zfront[5, 20] = np.nan
    obj = np.isfinite(zfront)
    obj[18, 20:24] = False  # a receiver in front
    oi = np.flatnonzero(obj)
    xi = oi[rng.random(len(oi)) < 0.7]
    exit_pos = rng.normal(size=(H, W, 3))
    exit_dir = rng.normal(size=(H, W, 3))
    eta = 1.0 / 1.33
    want = _final_rays_numpy(cam, zfront, exit_pos, exit_dir, xi, oi, method, delta, eta)

    def run():
        n = len(xi) + len(oi)
        O, D, Ov, Dv = (np.empty((n, 3)) for _ in range(4))
        Wk, Hk, sx, sy = cam.kernel_args()
        m, t = view_affine(cam)
        ic.final_rays_kernel(
            ic.FrontView(Wk, Hk, float(sx), float(sy), bool(cam.ortho), eta, NORMAL_METHODS[method], delta),
            no_lut(zfront.shape),
            ic.FinalRays(xi, exit_pos.reshape(-1, 3), exit_dir.reshape(-1, 3), oi,
                          np.where(np.isfinite(zfront), zfront, np.inf)[None], zfront.reshape(-1), np.eye(3),
                          np.ascontiguousarray(cam.basis), np.ascontiguousarray(cam.eye, dtype=np.float64),
                          np.zeros(3), m, t, O, D, Ov, Dv))
        return O, D, Ov, Dv

    for O, D, Ov, Dv in on_one_and_two_threads(run):
        assert np.array_equal(O, want[0]) and np.array_equal(D, want[1])
        assert np.array_equal(Ov, cam.world_to_view(want[0])) and np.array_equal(Dv, cam.dir_world_to_view(want[1]))
    assert np.isfinite(want[1]).all() and want[1][len(xi):].std() > 0


@pytest.mark.parametrize("n_receivers", [1, 2])
def test_shade_rows_equals_gathered_shade_points(on_one_and_two_threads, n_receivers):
    lights = [{"type": "directional", "direction": [0.2, -1.0, -0.1], "radiance": [1, 0.5, 0.25]},
              {"type": "directional", "direction": [-0.3, -1.0, 0.2], "radiance": [0.5, 1, 1]}]
    sc, rs, P, faces, d, maps, rng = _case(lights, n_receivers)
    zmin = rng.uniform(2.5, 3.8, (32, 32))
    vis = ShadowMaps([(_light_cam(False), zmin, 0.01), None])
    N = 4000
    face = faces[:N].copy()
    face[rng.random(N) < 0.3] = -1
    hi = np.flatnonzero(face >= 0)
    direct = (P[N:], faces[N:], d[N:])
    c = shade_points_numpy(rs, sc.data["lights"], maps, np.concatenate([P[:N][hi], direct[0]]),
                            np.concatenate([face[hi], direct[1]]), np.concatenate([d[:N][hi], direct[2]]), vis)
    want = np.zeros((N, 3))
    want[hi] = c[:len(hi)]

    nd, K = len(direct[0]), len(direct[0]) + 500
    dest = rng.permutation(K)[:nd]
    code_w = np.zeros((2, K), np.uint8)
    margin_w = np.full((2, K), np.nan, np.float32)
    lcam = vis.shadow[0][0]
    code_w[0, dest] = np.where(shadow_map_visibility(lcam, zmin, direct[0], 0.01) > 0, 1, 2)
    margin_w[0, dest] = shadow_map_margin_numpy(lcam, zmin, direct[0], 0.01, 0.3)
    code_w[1, dest], margin_w[1, dest] = 1, -np.inf  # no shadow map
    assert (code_w[0, dest] == 2).sum() > 10 and (margin_w[0, dest] == 0).sum() > 10

    def run(bufs):
        out = np.zeros((N, 3))
        code = np.zeros((2, K), np.uint8)
        margin = np.full((2, K), np.nan, np.float32)
        cd = shade.shade_rows(shade.ReceiverLighting(rs, sc.data["lights"], maps, vis), P[:N], face, d[:N], hi,
                              direct, out, (dest, code, margin, 0.3) if bufs else None)
        return out, cd, code, margin

    for bufs in (False, True):
        for out, cd, code, margin in on_one_and_two_threads(lambda: run(bufs)):
            assert np.array_equal(out, want, equal_nan=True) and np.array_equal(cd, c[len(hi):], equal_nan=True)
            if bufs:
                assert np.array_equal(code, code_w) and np.array_equal(margin, margin_w, equal_nan=True)
            else:
                assert not code.any() and np.isnan(margin).all()
    # a point light: not this kernel's (None, out untouched)
    out = np.zeros((N, 3))
    pl = [{"type": "point", "position": [0.5, 1.5, 0.3], "radiance": [2.0, 2.0, 1.0]}]
    assert shade.shade_rows(shade.ReceiverLighting(rs, pl, maps, vis), P[:N], face, d[:N], hi, direct,
                            out) is None and not out.any()


def test_final_composite_kernels_equal_numpy(on_one_and_two_threads):
    from refraction_ref.imagespace import caustics as ic

    rng = np.random.default_rng(31)
    H, W = 30, 40
    cls = rng.integers(0, 3, H * W)  # 0 receiver seen directly, 1 environment, 2 object
    st = rng.integers(0, 4, H * W).astype(np.int8)
    ri, bi, oi = (np.flatnonzero(cls == v) for v in range(3))
    obj = cls == 2
    xi = np.flatnonzero(obj & (st == 1))
    si = np.flatnonzero(obj & (st != 1))
    cd, env_bg, env_stuck = rng.random((len(ri), 3)), rng.random((len(bi), 3)), rng.random((len(si), 3)) * 3
    c = rng.random((len(xi) + len(oi), 3)) * 5
    trans = np.exp(-rng.random((len(oi), 3)))
    # the NumPy expressions _final_imagespace used
    base = np.zeros((H * W, 3))
    base[bi] = env_bg
    base[ri] = cd
    full, single = base.copy(), base.copy()
    full[xi] = c[:len(xi)]
    full[si] = env_stuck
    full[oi] *= trans
    single[oi] = c[len(xi):]
    # each object pixel's row among the exited (xi) or the stuck (si) pixels
    orow = np.where(st[oi] == 1, np.searchsorted(xi, oi), np.searchsorted(si, oi))

    def run():
        f32, s32 = np.empty((H * W, 3), np.float32), np.empty((H * W, 3), np.float32)
        ic.put32_kernel(ri, cd, f32, s32)
        ic.put32_kernel(bi, env_bg, f32, s32)
        ic.object_pixels_kernel(ic.ObjectRows(oi, orow, st, c, len(xi), env_stuck, trans, f32, s32))
        return f32, s32

    for f32, s32 in on_one_and_two_threads(run):
        assert np.array_equal(f32, full.astype(np.float32)) and np.array_equal(s32, single.astype(np.float32))


@pytest.mark.parametrize("ortho", [False, True])
def test_pixel_classes_and_direct_rays_equal_numpy(on_one_and_two_threads, ortho):
    from refraction_ref.imagespace import caustics as ic

    rng = np.random.default_rng(29)
    cam = _light_cam(ortho, 36)
    H, W = cam.shape
    zfront = rng.uniform(2.0, 4.0, (H, W))
    zfront[rng.random((H, W)) < 0.4] = np.inf
    zfront[rng.random((H, W)) < 0.05] = np.nan
    rdepth = rng.uniform(2.0, 4.0, (H, W))
    rdepth[rng.random((H, W)) < 0.3] = np.inf
    rtri = rng.integers(-1, 9, (H, W))
    st = rng.integers(0, 4, (H, W)).astype(np.int8)
    # the NumPy expressions of _final_imagespace
    obj = np.isfinite(zfront)
    rec = np.isfinite(rdepth) & (rdepth < np.where(obj, zfront, np.inf))
    obj &= ~rec
    want = [np.flatnonzero(m) for m in (rec, ~rec & ~obj, obj, obj & (st == 1), obj & (st != 1))]
    assert all(len(w) > 10 for w in want)
    origin, rdir = cam.primary_rays()
    rdir_f = rdir.reshape(-1, 3)
    ri, bi = want[0], want[1]
    dirs = rdir_f[ri]
    fwd = -cam.basis[2]
    pts = origin.reshape(-1, 3)[ri] + dirs * (rdepth.reshape(-1)[ri] / (dirs[:, 0] * fwd[0] + dirs[:, 1] * fwd[1]
                                                                        + dirs[:, 2] * fwd[2]))[:, None]

    def run():
        px, ldi = ic.classify_pixels(zfront, rdepth, st)
        Wk, Hk, sx, sy = cam.kernel_args()
        out = ic.DirectOut(np.empty((len(px.ri), 3)), np.empty(len(px.ri), np.int64), np.empty((len(px.ri), 3)),
                            np.empty((len(px.bi), 3)))
        ic.direct_rays_kernel(ic.EyeView(Wk, Hk, float(sx), float(sy), bool(cam.ortho)),
                               ic.DirectGeometry(np.ascontiguousarray(cam.basis), np.asarray(cam.eye, dtype=float),
                                                  np.ascontiguousarray(fwd), rdepth.reshape(-1), rtri.reshape(-1)),
                               px, out)
        return px, ldi, out

    oi, xi, si = want[2], want[3], want[4]
    orow = np.where(st.reshape(-1)[oi] == 1, np.searchsorted(xi, oi), np.searchsorted(si, oi))
    for px, ldi, out in on_one_and_two_threads(run):
        for got, w in zip((px.ri, px.bi, px.oi, px.xi, px.si, px.orow), want + [orow]):
            assert np.array_equal(got, w)
        assert np.array_equal(ldi[0], np.where(np.isfinite(zfront), zfront, np.inf))
        assert np.array_equal(out.Pd, pts) and np.array_equal(out.fd, rtri.reshape(-1)[ri])
        assert np.array_equal(out.dd, dirs) and np.array_equal(out.db, rdir_f[bi])
