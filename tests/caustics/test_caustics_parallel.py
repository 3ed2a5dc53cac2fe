"""The caustic stages and the exact reference's geometry on several threads: bit-identical
whatever the thread count, and equal to the NumPy code they replaced.

Every buffer the caustic stages keep (``keep="stages"``: receiver depth, photon
trace, receiver hits, splat, gather, the final pass) is compared between 1 and
2 Numba threads for the image-space method (eye-space and Embree receiver
hits) and the exact photon reference. The kernels that replaced NumPy code
(the gather's second pass, the channel means, the bilinear look-ups, the
shadow-map test, the chunked Embree receiver hits, the parallel vertex and
crease normals and edge angles, the chunked photon stream, the grouped splat,
the kernel blur of ``relative_l1``, the map positions) are checked against
that code, kept here as the reference (measured: bit-identical).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref.caustics import shade, shadow, splat
from refraction_ref.caustics.exact_hits import hit_exact
from refraction_ref.exact import mesh_normals
from refraction_ref.meshes import corner_normals, crease_edge_angles, load_mesh, vertex_normals

DATA = os.path.join(os.path.dirname(rr.__file__), "data")
SCENE = os.path.join(DATA, "caustics_default.json")
SMALL = {"camera.width": 96, "camera.height": 96, "imagespace.photons": 64, "imagespace.caustic_map": 64,
         "exact.photons": 96}


def _arrays(res):
    return {k: v for k, v in res.arrays.items() if isinstance(v, np.ndarray)}


@pytest.mark.parametrize("method, over", [
    ("imagespace", {}),
    ("imagespace", {"imagespace.receiver_hit": "exact", "imagespace.gather": 5}),
    ("exact", {}),
])
def test_every_caustic_stage_buffer_is_the_same_on_one_and_two_threads(on_one_and_two_threads, method, over, same_arrays):
    sc = rr.load_scene(SCENE, {**SMALL, **over})
    a, b = on_one_and_two_threads(lambda: _arrays(rr.render(sc, method=method, keep="stages")))
    stages = {k.split(".")[1] for k in a if k.startswith("stage.")}
    want = {"receivers", "photon_trace", "receiver_hit", "splat", "gather", "caustic_final"}
    if method == "imagespace":
        want.add("peel")
        if "receiver_hit" not in over:
            want.add("receiver_depth")
    assert want <= stages
    assert a["caustic_map_0"].sum() > 0  # photons reached the floor
    same_arrays(a, b)


def _odd_mesh():
    """A bunny patch with a zero-area face, a face using one vertex twice, a non-manifold edge and a
    boundary: every branch of the edge and normal kernels."""
    v, f = load_mesh("teapot")
    f = np.asarray(f, dtype=np.int64)[:400].copy()
    v = np.asarray(v, dtype=np.float64)
    extra = np.array([[f[0, 0], f[0, 1], len(v)],          # a third face on edge (f0, f1): non-manifold
                      [f[1, 0], f[1, 0], f[1, 2]],          # a vertex used twice: zero area
                      [f[2, 0], f[2, 1], len(v) + 1]])      # a face of zero area (collinear)
    v2 = np.vstack([v, v[f[0, 0]] + [0.0, 0.0, 0.3], 2.0 * v[f[2, 1]] - v[f[2, 0]]])
    return v2, np.vstack([f, extra])


@pytest.mark.parametrize("mesh", ["bunny", "fandisk", "odd"])
def test_parallel_mesh_normals_equal_the_serial_functions_on_any_thread_count(on_one_and_two_threads, mesh):
    v, f = _odd_mesh() if mesh == "odd" else load_mesh(mesh)
    a, b = on_one_and_two_threads(lambda: mesh_normals(v, f, 60.0))
    for x, y in zip(a, b):
        assert np.array_equal(x, y)
    assert np.array_equal(a.vertex, vertex_normals(np.asarray(v, float), np.asarray(f, np.int64)))
    assert np.array_equal(a.corner, corner_normals(v, f, 60.0))
    assert np.array_equal(np.sort(a.edge_angles), np.sort(crease_edge_angles(v, f)))
    assert np.array_equal(mesh_normals(v, f, 180.0).corner, corner_normals(v, f, 180.0))
    assert mesh_normals(v, f).corner is None


def test_the_exact_reference_is_the_same_on_one_and_two_threads_for_every_normals_rule(on_one_and_two_threads, same_arrays):
    for normals in ("crease", "smooth", "file"):
        sc = rr.load_scene(None, {"camera.width": 48, "camera.height": 48, "exact.normals": normals})
        a, b = on_one_and_two_threads(lambda: _arrays(rr.render(sc, method="exact", keep="stages")))
        same_arrays(a, b)


def _fold_rows_numpy(a, w):
    """Mirror-folded correlation along each row: per texel the taps in order, each tap's direct
    source, then the mass that left through the first edge, then through the last (NumPy, one
    tap at a time over every texel; a missing source adds 0)."""
    H, N, C = a.shape
    r = (len(w) - 1) // 2
    j = np.arange(N)
    out = np.zeros(a.shape)
    for t in range(-r, r + 1):
        for src in (j - t, -1 - j - t, 2 * N - 1 - j - t):
            ok = (src >= 0) & (src < N)
            out += np.where(ok[None, :, None], w[t + r] * a[:, np.clip(src, 0, N - 1), :], 0.0)
    return out


def _gather_transposed(E, window):
    """The gather by rows, a transposed copy, rows again, transposed back (the reference of the separable pass)."""
    a = np.asarray(E, dtype=np.float64)
    w = splat.gaussian_weights(window)
    tmp = _fold_rows_numpy(a, w)
    out = _fold_rows_numpy(np.ascontiguousarray(tmp.transpose(1, 0, 2)), w)
    return np.ascontiguousarray(out.transpose(1, 0, 2))


def test_map_kernels_equal_numpy(on_one_and_two_threads):
    rng = np.random.default_rng(3)
    E = rng.random((37, 53, 3)) * rng.integers(0, 2, (37, 53, 1))
    for window in (3, 7, 11):
        a, b = on_one_and_two_threads(lambda: splat.gather_gaussian(E, window))
        assert np.array_equal(a, b) and np.array_equal(a, _gather_transposed(E, window))
        assert abs(a.sum() - E.sum()) < 1e-9 * E.sum()  # flux kept
    assert np.array_equal(splat.channel_mean(E), E.mean(axis=2))
    F = E.copy()
    F[0, :3, 0], F[1, 1, :], F[2, 2, 1] = np.nan, np.inf, -np.inf
    want = np.nan_to_num(F, nan=0.0, posinf=0.0, neginf=0.0)
    got, got32 = splat.finite_maps(F.copy())
    assert np.array_equal(got, want) and np.array_equal(got32, want.astype(np.float32)) and got32.dtype == np.float32
    unit, rgb = np.ones(E.shape[:2]), np.full(E.shape, 0.5)
    L = np.array([0.3, 1.7, 0.9])
    splat.accumulate_light(E, L, unit, rgb)
    assert np.array_equal(unit, 1.0 + E.mean(axis=2)) and np.array_equal(rgb, 0.5 + E * L)
    # splat: the same map whatever the threads (bands owned by one thread each)
    col, row = rng.uniform(-3, 56, 5000), rng.uniform(-3, 40, 5000)
    col[::97] = np.nan
    val = rng.random((5000, 3))
    a, b = on_one_and_two_threads(lambda: splat.splat_bilinear(col, row, val, (37, 53)))
    assert np.array_equal(a, b)
    assert np.allclose(a.sum(axis=(0, 1)), val[np.isfinite(col)].sum(axis=0))


def test_receiver_lookups_equal_numpy(on_one_and_two_threads):
    rng = np.random.default_rng(5)
    E = rng.random((20, 30, 3))
    col, row = rng.uniform(-5, 35, 4000), rng.uniform(-5, 25, 4000)
    col[::50], row[::77] = np.nan, np.inf
    sel = np.arange(4000)
    out = np.zeros((4000, 3))
    shade.add_bilinear(E, col, row, sel, out)
    assert np.array_equal(out, shade.sample_bilinear(E, col, row))

    from refraction_ref.camera import Camera

    for ortho in (True, False):
        lcam = Camera.from_dict({"eye": [0.3, 3.0, 0.2], "target": [0, 0, 0], "up": [0, 0, 1], "fov_y": 40,
                                 "width": 32, "height": 32, "near": 0.1, "far": 10, "ortho": ortho,
                                 **({"ortho_height": 2.0} if ortho else {})})
        zmin = rng.uniform(2.5, 3.5, (32, 32))
        zmin[rng.random((32, 32)) < 0.2] = np.inf
        p = rng.uniform(-1.5, 1.5, (3000, 3))
        a, b = on_one_and_two_threads(lambda: shadow.shadow_map_visibility(lcam, zmin, p, 0.01))
        col_, row_, d = lcam.to_screen(lcam.world_to_view(p))
        inside = np.isfinite(col_) & np.isfinite(row_) & (col_ >= 0) & (col_ < 32) & (row_ >= 0) & (row_ < 32) & (d > 0)
        i = np.where(inside, np.floor(np.nan_to_num(row_)), 0).astype(np.int64).clip(0, 31)
        j = np.where(inside, np.floor(np.nan_to_num(col_)), 0).astype(np.int64).clip(0, 31)
        z = zmin[i, j]
        ref = (~(inside & np.isfinite(z) & (d > z + 0.01))).astype(np.float64)
        assert np.array_equal(a, b) and np.array_equal(a, ref) and 0 < ref.sum() < len(ref)


def test_chunked_receiver_hits_equal_one_embree_call(on_one_and_two_threads):
    from refraction_ref.embree import soup_scene

    rng = np.random.default_rng(7)
    tris = rng.uniform(-1, 1, (300, 3, 3))
    o = rng.uniform(-2, 2, (20000, 3))
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o[5] = np.nan
    a, b = on_one_and_two_threads(lambda: hit_exact(tris, o, d))
    assert np.array_equal(a[0], b[0], equal_nan=True) and np.array_equal(a[1], b[1])
    # one call for every ray, the float64 recomputation in NumPy
    res = soup_scene(tris).run(o[np.isfinite(o[:, 0])].astype(np.float32),
                               d[np.isfinite(o[:, 0])].astype(np.float32), output=1)
    face = np.asarray(res["primID"], dtype=np.int64)
    assert np.array_equal(np.delete(a[1], 5), face) and (face >= 0).sum() > 1000
    # the float64 distance as the NumPy code computed it (np.cross, einsum)
    ok = np.flatnonzero(np.isfinite(o[:, 0]))
    hit = face >= 0
    hi, f = ok[hit], face[hit]
    v0, v1, v2 = tris[f, 0], tris[f, 1], tris[f, 2]
    e1, e2 = v1 - v0, v2 - v0
    pv = np.cross(d[hi], e2)
    det = np.einsum("ij,ij->i", e1, pv)
    qv = np.cross(o[hi] - v0, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = np.einsum("ij,ij->i", e2, qv) / det
    tf = np.asarray(res["tfar"], dtype=np.float64)[hit]
    want = np.full(len(o), np.nan)
    want[hi] = np.where(np.isfinite(tt) & (tt > 0), tt, tf)
    assert np.array_equal(a[0], want, equal_nan=True)
    # triangles read in place (IndexedTriangles) give the same bits
    from refraction_ref.caustics.exact_hits import IndexedTriangles

    V = tris.reshape(-1, 3)
    c = hit_exact(IndexedTriangles(V, np.arange(len(V)).reshape(-1, 3)), o, d, soup_scene(tris))
    assert np.array_equal(c[0], a[0], equal_nan=True) and np.array_equal(c[1], a[1])


def shade_points_numpy(rs, lights, maps_rgb, P, faces, ray_dirs, visibility):
    """shade_points in NumPy, the reference of its kernels."""
    from refraction_ref.caustics.receivers import map_position
    from refraction_ref.lights import light_direction_at

    M = len(P)
    n = rs.normals[faces].copy()
    flip = np.einsum("ij,ij->i", n, ray_dirs) > 0
    n[flip] = -n[flip]
    owner = rs.owner[faces]
    light_sum = np.zeros((M, 3))
    for l, lt in enumerate(lights):
        L, fall = light_direction_at(lt, P)
        cos = np.maximum(0.0, -np.einsum("ij,ij->i", n, L))
        lit = cos > 0
        v = np.zeros(M)
        if lit.any():
            v[lit] = visibility(l, P[lit], n[lit])
        light_sum += np.asarray(lt["radiance"], dtype=np.float64)[None, :] * (cos * fall * v)[:, None]
    for r in range(len(rs.boxes)):
        sel = owner == r
        if sel.any():
            col, row = map_position(rs, r, P[sel])
            light_sum[sel] += shade.sample_bilinear(maps_rgb[r], col, row)
    return rs.albedo[owner] * light_sum


def test_shade_points_equals_numpy_for_directional_and_point_lights(on_one_and_two_threads):
    from refraction_ref.caustics.receivers import receiver_set

    import json

    with open(SCENE) as f:
        raw = json.load(f)
    raw["lights"] = [{"type": "directional", "direction": [0.2, -1.0, -0.1], "radiance": [1, 0.5, 0.25]},
                     {"type": "point", "position": [0.5, 1.5, 0.3], "radiance": [2.0, 2.0, 1.0]}]
    raw["receivers"] = [{"mesh": "plane", "size": [4, 4], "transform": {"translate": [0, -0.5, 0]}},
                        {"mesh": "plane", "size": [2, 2], "transform": {"translate": [0, 0.3, -1.0],
                                                                        "rotate": [90, 0, 0]}}]
    sc = rr.load_scene(raw)
    rs = receiver_set(sc, sc.data["lights"][0], 32)
    rng = np.random.default_rng(11)
    M = 5000
    faces = rng.integers(0, len(rs.tris), M)
    b = rng.dirichlet([1, 1, 1], M)
    P = np.einsum("ij,ijk->ik", b, rs.tris[faces])
    d = rng.normal(size=(M, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    maps = [rng.random(box.size + (3,)) for box in rs.boxes]

    def vis(l, p, nrm):
        return (p[:, 0] + 0.1 * l > 0).astype(np.float64)

    want = shade_points_numpy(rs, sc.data["lights"], maps, P, faces, d, vis)
    a, b2 = on_one_and_two_threads(lambda: shade.shade_points(rs, sc.data["lights"], maps, P, faces, d, vis))
    assert np.array_equal(a, b2) and np.array_equal(a, want) and want.std() > 0


def _exact_visibility_numpy(obj_tris, light, p, n):
    """exact_visibility in NumPy with one Embree call, the reference of the chunked one."""
    from refraction_ref.caustics.exact_hits import occluded
    from refraction_ref.lights import light_direction_at

    L, _ = light_direction_at(light, p)
    to_light = -np.asarray(L)
    side = np.where(np.einsum("ij,ij->i", n, to_light) >= 0, 1.0, -1.0)[:, None]
    scale = max(float(np.abs(obj_tris).max()), 1.0)
    o = p + 1e-6 * scale * (to_light + side * n)
    tmax = None
    if light["type"] == "point":
        tmax = np.linalg.norm(np.asarray(light["position"], dtype=np.float64) - o, axis=1)
    return (~occluded(obj_tris, o, to_light, tmax)).astype(np.float64)


def test_exact_shadow_rays_equal_numpy_with_indexed_triangles_and_any_chunks(on_one_and_two_threads):
    from refraction_ref.caustics.exact_hits import IndexedTriangles
    from refraction_ref.embree import mesh_scene

    v, f = load_mesh("teapot")
    v = np.asarray(v, dtype=np.float64)
    v = (v - v.mean(axis=0)) / np.abs(v).max()
    f = np.asarray(f, dtype=np.int64)
    tris = v[f]
    rng = np.random.default_rng(13)
    p = rng.uniform(-1.2, 1.2, (30000, 3))
    p[:, 1] = -1.1
    n = np.tile([0.0, 1.0, 0.0], (len(p), 1))
    it = IndexedTriangles(v, f)
    assert it.abs_max() == np.abs(tris).max() and np.array_equal(np.asarray(it), tris)
    for light in ({"type": "directional", "direction": [0.1, -1.0, 0.2]},
                  {"type": "point", "position": [0.2, 2.0, -0.1]}):
        want = _exact_visibility_numpy(tris, light, p, n)
        assert 0 < want.sum() < len(want)
        a, b = on_one_and_two_threads(lambda: shadow.exact_visibility(it, light, p, n, scene=mesh_scene(v, f)))
        assert np.array_equal(a, want) and np.array_equal(b, want)
        assert np.array_equal(shadow.exact_visibility(tris, light, p, n, chunk=777), want)


def _window_samples_numpy(cam, n, seed):
    """window_samples from one generator, the whole grid in NumPy (the reference of the chunked draws)."""
    rng = np.random.default_rng(int(seed))
    jj, ii = np.meshgrid(np.arange(n), np.arange(n))
    u = (jj + rng.random((n, n))) / n
    v = (ii + rng.random((n, n))) / n
    x = (u * 2.0 - 1.0) * cam.sx
    y = (1.0 - v * 2.0) * cam.sy
    b = cam.basis
    if cam.ortho:
        o = np.asarray(cam.eye) + x[..., None] * b[0] + y[..., None] * b[1]
        d = np.broadcast_to(-b[2], o.shape).copy()
        flux = np.full(n * n, (2.0 * cam.sx / n) * (2.0 * cam.sy / n))
    else:
        d = x[..., None] * b[0] + y[..., None] * b[1] - b[2]
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        o = np.broadcast_to(np.asarray(cam.eye, dtype=np.float64), d.shape).copy()
        flux = ((2.0 * cam.sx / n) * (2.0 * cam.sy / n) / (1.0 + x * x + y * y) ** 1.5).ravel()
    half = ((ii + jj) % 2).astype(np.int8).ravel()
    return o.reshape(-1, 3), d.reshape(-1, 3), flux, half


@pytest.mark.parametrize("light", [{"type": "directional", "direction": [0.2, -1.0, -0.1]},
                                   {"type": "point", "position": [0.5, 3.0, 0.3]}])
def test_window_samples_chunked_stream_equals_one_generator(on_one_and_two_threads, light):
    from refraction_ref.caustics.light import window_samples
    from refraction_ref.lights import light_camera

    v, _ = load_mesh("bunny")
    for n in (1, 5, 96, 301):
        cam = light_camera(light, v, n)
        want = _window_samples_numpy(cam, n, 7)
        a, b = on_one_and_two_threads(lambda: window_samples(cam, n, 7))
        for x, y, w in zip(a, b, want):
            assert x.dtype == w.dtype and x.shape == w.shape
            assert np.array_equal(x, w) and np.array_equal(y, w)


def test_grouped_splat_equals_one_splat_per_group(on_one_and_two_threads):
    rng = np.random.default_rng(17)
    n = 6000
    col, row = rng.uniform(-3, 56, n), rng.uniform(-3, 40, n)
    row[:3000] = rng.normal(20, 1.5, 3000)  # a crowded band, as a caustic makes
    col[::97] = np.nan
    val = rng.random((n, 3))
    grp = rng.integers(-1, 3, n)  # group -1: in no group's map
    a, b = on_one_and_two_threads(lambda: splat.splat_bilinear_groups(col, row, val, (37, 53), grp, 3))
    assert np.array_equal(a, b) and a.shape == (4, 37, 53, 3)
    assert np.array_equal(a[0], splat.splat_bilinear(col, row, val, (37, 53)))
    for g in range(3):
        m = grp == g
        assert np.array_equal(a[1 + g], splat.splat_bilinear(col[m], row[m], val[m], (37, 53)))
    assert np.array_equal(splat.splat_bilinear_groups(col, row, val, (37, 53), None, 0)[0], a[0])


def _relative_l1_scipy(test, ref, mask=None, blur=1.0):
    """relative_l1 by SciPy's gaussian_filter and NumPy (the reference of its kernel)."""
    from scipy.ndimage import gaussian_filter

    a = np.nan_to_num(np.asarray(test, dtype=np.float64))
    b = np.nan_to_num(np.asarray(ref, dtype=np.float64))
    if mask is not None:
        m = np.asarray(mask, bool)
        a, b = np.where(m, a, 0.0), np.where(m, b, 0.0)
    if blur > 0:
        a, b = gaussian_filter(a, blur, mode="constant"), gaussian_filter(b, blur, mode="constant")
    if mask is not None:
        a, b = a[m], b[m]
    den = np.abs(b).sum()
    return float(np.abs(a - b).sum() / den) if den > 0 else float(np.abs(a).sum() > 0)


def test_relative_l1_kernel_blur_equals_scipy(on_one_and_two_threads):
    from scipy.ndimage import gaussian_filter

    from refraction_ref.filters import gaussian_filter_zero
    from refraction_ref.metrics import relative_l1

    rng = np.random.default_rng(19)
    for shape in ((64, 48), (5, 3), (1, 9)):
        a = rng.random(shape) * (rng.random(shape) < 0.4) - 0.1 * (rng.random(shape) < 0.1)
        b = rng.random(shape) * (rng.random(shape) < 0.4)
        a.flat[0], b.flat[-1] = np.nan, np.inf
        for blur in (0.0, 0.5, 1.0, 2.5):
            g1, g2 = on_one_and_two_threads(lambda: gaussian_filter_zero(np.nan_to_num(a), blur or 1.0))
            want = gaussian_filter(np.nan_to_num(a), blur or 1.0, mode="constant")
            assert np.array_equal(g1, want) and np.array_equal(g2, want)
            for mask in (None, rng.random(shape) < 0.7):
                x, y = on_one_and_two_threads(lambda: relative_l1(a, b, mask, blur))
                assert x == y == _relative_l1_scipy(a, b, mask, blur)
        assert relative_l1(a, np.zeros(shape)) == _relative_l1_scipy(a, np.zeros(shape))


def test_map_position_kernel_equals_to_map(on_one_and_two_threads):
    from refraction_ref.caustics.receivers import map_position, receiver_set
    from refraction_ref.levelmap.planes import to_map

    sc = rr.load_scene(SCENE, SMALL)
    rs = receiver_set(sc, sc.data["lights"][0], 64)
    p = np.random.default_rng(23).uniform(-3, 3, (5000, 3))
    p[7] = np.nan
    (c, r), (c2, r2) = on_one_and_two_threads(lambda: map_position(rs, 0, p))
    q = to_map(rs.boxes[0], p)
    for x in (c, c2):
        assert np.array_equal(x, q[:, 0], equal_nan=True)
    for x in (r, r2):
        assert np.array_equal(x, q[:, 1], equal_nan=True)


def _march_plain(O, D, depth, cam, rel_thick=0.01, max_samples=1 << 16):
    """march_eyespace testing every sample, one ray after another (the reference of the
    tiled march, which steps over runs of samples that cannot hit)."""
    import math

    import numba as nb

    from refraction_ref.camera import project_point
    from refraction_ref.caustics.eyespace import clip_interval

    @nb.njit
    def run(O, D, depth, W, H, sx, sy, ortho, near, far, t_hit, pix):
        for k in range(O.shape[0]):
            t_hit[k] = np.nan
            pix[k, 0] = -1
            pix[k, 1] = -1
            ox, oy, oz = O[k, 0], O[k, 1], O[k, 2]
            dx, dy, dz = D[k, 0], D[k, 1], D[k, 2]
            if not (math.isfinite(ox) and math.isfinite(dx)):
                continue
            t0, t1 = 0.0, 1e30
            t0, t1 = clip_interval(near + oz, dz, t0, t1)
            t0, t1 = clip_interval(-oz - far, -dz, t0, t1)
            if ortho:
                t0, t1 = clip_interval(ox - sx, dx, t0, t1)
                t0, t1 = clip_interval(-ox - sx, -dx, t0, t1)
                t0, t1 = clip_interval(oy - sy, dy, t0, t1)
                t0, t1 = clip_interval(-oy - sy, -dy, t0, t1)
            else:
                t0, t1 = clip_interval(ox + sx * oz, dx + sx * dz, t0, t1)
                t0, t1 = clip_interval(-ox + sx * oz, -dx + sx * dz, t0, t1)
                t0, t1 = clip_interval(oy + sy * oz, dy + sy * dz, t0, t1)
                t0, t1 = clip_interval(-oy + sy * oz, -dy + sy * dz, t0, t1)
            if not (t1 > t0) or t1 >= 1e29:
                continue
            c0, r0, dA = project_point(ox + t0 * dx, oy + t0 * dy, oz + t0 * dz, W, H, sx, sy, ortho)
            c1, r1, dB = project_point(ox + t1 * dx, oy + t1 * dy, oz + t1 * dz, W, H, sx, sy, ortho)
            n = np.int64(math.ceil(max(abs(c1 - c0), abs(r1 - r0)))) + 1
            n = min(max(n, 2), max_samples)
            prev_gap, prev_t, prev_rd = -np.inf, t0, dA
            for m in range(n + 1):
                u = m / n
                if ortho or not (dA > 0.0 and dB > 0.0):
                    s = u
                else:
                    s = (u / dB) / ((1.0 - u) / dA + u / dB)
                t = t0 + s * (t1 - t0)
                col, row, rd = project_point(ox + t * dx, oy + t * dy, oz + t * dz, W, H, sx, sy, ortho)
                i = min(max(np.int64(math.floor(row)), 0), H - 1)
                j = min(max(np.int64(math.floor(col)), 0), W - 1)
                sd = depth[i, j]
                gap = rd - sd if math.isfinite(sd) else -np.inf
                if gap >= 0.0 and prev_gap < 0.0:
                    if gap <= abs(rd - prev_rd) + rel_thick * sd:
                        f = 1.0
                        if math.isfinite(prev_gap):
                            f = -prev_gap / (gap - prev_gap)
                        t_hit[k] = prev_t + f * (t - prev_t)
                        pix[k, 0] = i
                        pix[k, 1] = j
                        break
                prev_gap, prev_t, prev_rd = gap, t, rd

    t = np.empty(len(O))
    pix = np.empty((len(O), 2), np.int64)
    W, H, sx, sy = cam.kernel_args()
    run(np.ascontiguousarray(O, dtype=np.float64), np.ascontiguousarray(D, dtype=np.float64),
        np.ascontiguousarray(depth, dtype=np.float64), W, H, sx, sy, bool(cam.ortho), float(cam.near),
        float(cam.far), t, pix)
    return t, pix


@pytest.mark.parametrize("ortho", [False, True])
def test_tiled_eyespace_march_equals_testing_every_sample(on_one_and_two_threads, ortho):
    """The march steps over runs of samples nearer than a tile's nearest receiver; the hits (t and
    pixel, NaN and -1 included) are those of the per-sample march, on the receivers' depth image of
    the caustics scene and on a noisy one with holes, NaN and depth steps at tile corners."""
    from refraction_ref.camera import Camera
    from refraction_ref.caustics.eyespace import march_eyespace
    from refraction_ref.caustics.receivers import eye_buffers, receiver_set

    sc = rr.load_scene(SCENE, {"camera.width": 150, "camera.height": 130})
    raw = dict(sc.data["camera"], width=150, height=130)
    if ortho:
        raw.update(ortho=True, ortho_height=3.0)
    cam = Camera.from_dict(raw)
    rs = receiver_set(sc, sc.data["lights"][0], 64)
    floor, _ = eye_buffers(rs, cam)
    rng = np.random.default_rng(29)
    noisy = floor * rng.uniform(0.97, 1.03, floor.shape)
    noisy[rng.random(floor.shape) < 0.05] = np.inf
    noisy[rng.random(floor.shape) < 0.01] = np.nan
    noisy[40:72, 32:64] = 1.5  # a near block on tile edges (the coarse tiles are 32 pixels)
    noisy[100:, :7] = np.inf
    N = 6000
    o = rng.uniform(-1.0, 1.0, (N, 3)) * [1.0, 0.6, 1.0]
    d = rng.normal(size=(N, 3)) + [0.0, -0.8, 0.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:300] = [0.0, -1.0, 0.0]  # straight down: screen-vertical lines
    d[300:400] = -cam.basis[2]  # along the view axis: one pixel on screen
    o[400] = np.nan
    o[401:500] = cam.eye + 0.001 * rng.normal(size=(99, 3))  # from the camera: through the near plane
    ov, dv = cam.world_to_view(o), cam.dir_world_to_view(d)
    for depth in (floor, noisy):
        want = _march_plain(ov, dv, depth, cam)
        assert (want[1][:, 0] >= 0).sum() > N // 4 and np.isnan(want[0]).sum() > 100
        a, b = on_one_and_two_threads(lambda: march_eyespace(ov, dv, depth, cam))
        for got in (a, b):
            assert np.array_equal(got[0], want[0], equal_nan=True) and np.array_equal(got[1], want[1])


def test_caustic_stages_at_a_larger_size_are_the_same_on_one_and_two_threads(on_one_and_two_threads, same_arrays):
    """The default caustics scene at 192^2 (several 32-pixel tiles of the march, photon bands over many
    rows): receiver_depth, peel, splat, gather and caustic_final's buffers, bit for bit."""
    sc = rr.load_scene(SCENE, {"camera.width": 192, "camera.height": 192, "imagespace.photons": 160,
                               "caustics.map_size": 160})
    a, b = on_one_and_two_threads(lambda: _arrays(rr.render(sc, method="imagespace", keep="stages")))
    for stage in ("receiver_depth", "peel", "splat", "gather", "caustic_final"):
        assert any(k.startswith(f"stage.{stage}.") for k in a), stage
    assert np.isfinite(a["stage.receiver_depth.depth"]).mean() > 0.5 and a["caustic_map_0"].sum() > 0
    same_arrays(a, b)


def _shade_rays_numpy(scene, rs, cam, o, d, mode, eyebuf, rgb_maps, vis, direct):
    """shade_rays by boolean indexing and np.concatenate, the reference of its row kernels."""
    from refraction_ref.caustics.receivers import receiver_hits
    from refraction_ref.environment import environment_lookup

    out = np.zeros((len(o), 3))
    P, face = receiver_hits(rs, o, d, mode, cam, eyebuf)
    hit = face >= 0
    pts, fcs, drs = P[hit], face[hit], d[hit]
    pts, fcs, drs = (np.concatenate([x, y]) for x, y in zip((pts, fcs, drs), direct))
    c = shade.shade_points(rs, scene.data["lights"], rgb_maps, pts, fcs, drs, vis)
    nh = int(hit.sum())
    out[hit] = c[:nh]
    out[~hit] = environment_lookup(scene.data["environment"], d[~hit], scene.base_dir)
    return out, c[nh:]


@pytest.mark.parametrize("mode", ["eyespace", "exact"])
def test_shade_rays_row_kernels_equal_boolean_indexing(on_one_and_two_threads, mode):
    from refraction_ref.camera import Camera
    from refraction_ref.caustics.receivers import ReceiverHitMode, eye_buffers, receiver_set
    from refraction_ref.caustics.shade import ReceiverLighting, shade_rays

    sc = rr.load_scene(SCENE, SMALL)
    cam = Camera.from_dict(sc.data["camera"])
    rs = receiver_set(sc, sc.data["lights"][0], 32)
    eyebuf = eye_buffers(rs, cam)
    rng = np.random.default_rng(31)
    o = rng.uniform(-0.6, 0.6, (3000, 3))
    d = rng.normal(size=(3000, 3)) + [0.0, -0.5, 0.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    maps = [rng.random(b.size + (3,)) for b in rs.boxes]
    dp = rng.uniform(-1.5, 1.5, (500, 3))
    dp[:, 1] = -0.5
    direct = (dp, rng.integers(0, len(rs.tris), 500), np.tile([0.0, -1.0, 0.0], (500, 1)))

    def vis(l, p, nrm):
        return (p[:, 0] > 0.1).astype(np.float64)

    want = _shade_rays_numpy(sc, rs, cam, o, d, mode, eyebuf, maps, vis, direct)
    assert 0 < (want[0].sum(axis=1) > 0).sum() and want[1].std() > 0
    lighting = ReceiverLighting(rs, sc.data["lights"], maps, vis)
    hits = ReceiverHitMode(mode, cam, eyebuf)
    a, b = on_one_and_two_threads(lambda: shade_rays(sc, lighting, hits, o, d, direct))
    for got in (a, b):
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def shadow_map_margin_numpy(lcam, zmin, points, bias, tie=0.0):
    """shadow_map_margin in NumPy, the reference of its kernel."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    zmin = np.asarray(zmin, dtype=np.float64)
    H, W = zmin.shape
    pv = lcam.world_to_view(p)
    d = -pv[:, 2]
    s = np.ones_like(d) if lcam.ortho else d
    with np.errstate(divide="ignore", invalid="ignore"):
        col = (pv[:, 0] / (s * float(lcam.sx)) * 0.5 + 0.5) * float(lcam.width)
        row = (0.5 - pv[:, 1] / (s * float(lcam.sy)) * 0.5) * float(lcam.height)

    def margin(col, row):
        inside = np.isfinite(col) & np.isfinite(row) & (col >= 0) & (col < W) & (row >= 0) & (row < H) & (d > 0)
        i = np.clip(np.floor(np.where(inside, row, 0.0)).astype(np.int64), 0, H - 1)
        j = np.clip(np.floor(np.where(inside, col, 0.0)).astype(np.int64), 0, W - 1)
        z = zmin[i, j]
        with np.errstate(invalid="ignore"):
            return np.where(inside & np.isfinite(z), d - (z + float(bias)), -np.inf)

    m = margin(col, row)
    if tie > 0:
        for dc, dr in ((tie, 0.0), (-tie, 0.0), (0.0, tie), (0.0, -tie)):
            m = np.where((margin(col + dc, row + dr) > 0) != (m > 0), 0.0, m)
    return m


@pytest.mark.parametrize("ortho", [False, True])
def test_shadow_map_margin_kernel_equals_numpy(on_one_and_two_threads, ortho):
    from refraction_ref.camera import Camera

    rng = np.random.default_rng(37)
    lcam = Camera.from_dict({"eye": [0.3, 3.0, 0.2], "target": [0, 0, 0], "up": [0, 0, 1], "fov_y": 40,
                             "width": 32, "height": 32, "near": 0.1, "far": 10, "ortho": ortho,
                             **({"ortho_height": 2.0} if ortho else {})})
    zmin = rng.uniform(2.5, 3.5, (32, 32))
    zmin[rng.random((32, 32)) < 0.2] = np.inf
    p = rng.uniform(-1.5, 1.5, (4000, 3))
    p[::500] = np.nan
    p[1::500] = [0.3, 5.0, 0.2]  # behind the light
    for tie in (0.0, 5e-3, 0.3):
        want = shadow_map_margin_numpy(lcam, zmin, p, 0.01, tie)
        assert (want > 0).sum() > 100 and (want == -np.inf).sum() > 100
        if tie >= 0.3:
            assert (want == 0).sum() > 100
        a, b = on_one_and_two_threads(lambda: shadow.shadow_map_margin(lcam, zmin, p, 0.01, tie))
        for got in (a, b):
            assert np.array_equal(got, want)
