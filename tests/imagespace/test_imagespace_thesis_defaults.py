"""The image-space method's seed defaults (Chaudhari 2008), as numerical truths.

* ``blend='add'`` (§3.3: "Since current Direct3D version does not support
  logical OR blending, we employ additive blending"): the bitmask is the
  32-bit sum of the fragments' slice bits, so it equals ``or`` wherever no two
  fragments of a pixel share a slice and differs only by the carries where
  they do.
* ``endpoint='probe'`` (§3.6: "Surface normal of the point R3 is then
  calculated using the texture coordinate t_P3 of the point P3"): a search
  ends on the last probe's texel, at the layer's surface on the line of sight
  through that probe.
* ``filter='bilinear'`` (§3.4.2: "hardware filtering can be easily applied
  while sampling these textures"): exactly the nearest texel's result where
  the layer's depth is constant, and a smaller exit-direction error than
  nearest sampling against the closed-form sphere.
* ``peel_all`` (the thesis's fixed 32 layers): ``layers`` images, ``+inf``
  beyond the depth complexity, and the same outputs.

Measured numbers quoted in comments come from this machine's run of the same code.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref.analytic import icosphere_mesh, sphere_refraction
from refraction_ref.camera import Camera
from refraction_ref.compare import angular_error_deg
from refraction_ref.imagespace.depth_bounds import depth_bounds
from refraction_ref.imagespace.knobs import IMAGESPACE_DEFAULTS, trace_knobs
from refraction_ref.imagespace.peel import peel_layers
from refraction_ref.imagespace.search_bounds import search_bounds
from refraction_ref.imagespace.trace import ImagespaceLayers, ImagespaceOptics, exit_thresholds, trace_layers
from refraction_ref.imagespace.voxelize import collect_depths, slice_bounds, voxelize_bitmask
from refraction_ref.raster import raster_setup, rasterize


def _trace(*args, ior, outside_ior=1.0, lut=None, **knobs):
    """:func:`trace_layers` called as ``(ldi, total, zback, thr, bounds_hi, bounds_lo, dirs_view, camera)``
    with the trace's knobs by name, over these tests' settings: the knobs' defaults, but ``delta`` 1 and
    the layers' own count as the layer limit."""
    *arrays, dirs, cam = args
    assert set(knobs) <= set(IMAGESPACE_DEFAULTS), set(knobs) - set(IMAGESPACE_DEFAULTS)
    record = knobs.pop("record", 0)
    block = {**IMAGESPACE_DEFAULTS, "delta": 1, "layers": arrays[0].shape[0], **knobs}
    return trace_layers(ImagespaceLayers(*arrays), cam, trace_knobs(block, record), ImagespaceOptics(ior, outside_ior),
                        dirs_view=dirs, lut=lut)


KEYS = ("hit", "exit_pos", "exit_dir", "interfaces", "path_length", "status", "image", "depth_complexity")


def test_the_seed_defaults():
    d = IMAGESPACE_DEFAULTS
    assert (d["blend"], d["endpoint"], d["filter"], d["peel_all"]) == ("add", "probe", "bilinear", False)
    assert (d["iterations"], d["layers"], d["slices"], d["normals"], d["delta"]) == (5, 32, 256, "central", 2)


# --------------------------------------------------------------------------
# blend = add (§3.3)
# --------------------------------------------------------------------------

def _overlapping_spheres(W=64):
    """A sphere and the right half of a copy 0.004 further back: on the right the fragments come
    in pairs 0.004 apart (one slice is 0.016 at 64 global slices), on the left they are single."""
    cam = Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30.0, W, W, 0.1, 10.0)
    v, f = icosphere_mesh(4, 0.5)
    right = f[v[f].mean(axis=1)[:, 0] > 0.0]
    v2 = np.concatenate([v, v + [0.0, 0.0, -0.004]])
    f2 = np.concatenate([f, right + len(v)])
    return cam, raster_setup(cam.world_to_view(v2), cam, faces=f2)


@pytest.mark.parametrize("slicing,S", [("global", 64), ("local", 256), ("global", 256)])
def test_additive_blend_is_the_sum_of_the_slice_bits(slicing, S):
    """Every word of the 'add' bitmask is the 32-bit sum of its fragments' slice bits (carries
    move up, a carry out of bit 31 is lost), the 'or' bitmask their OR; the two are equal in
    exactly the pixels where no two fragments share a slice.

    Measured: 47% of the covered pixels have a shared slice at 64 global slices, 8.8% at 256
    global slices, 0.6% at 256 local ones.
    """
    cam, rs = _overlapping_spheres()
    zmin, zmax = depth_bounds(rs, cam)
    zlo, zhi = slice_bounds(zmin, zmax, slicing)
    add = voxelize_bitmask(rs, cam, zlo, zhi, S, "add")
    orb = voxelize_bitmask(rs, cam, zlo, zhi, S, "or")
    depths, count = rasterize(rs, cam, "collect", capacity=16)
    assert count.max() <= 16
    H, W = count.shape
    want_add = np.zeros((H, W, S // 32), np.uint64)
    want_or = np.zeros((H, W, S // 32), np.uint32)
    shared = np.zeros((H, W), bool)
    for i, j in zip(*np.nonzero(count)):
        d = depths[: count[i, j], i, j]
        rng = zhi[i, j] - zlo[i, j]
        # the rasterizer's slice rule, the same float64 operations
        s = np.floor((d - zlo[i, j]) / rng * (S - 1) + 0.5).astype(np.int64) if rng > 0 else np.zeros(len(d), int)
        s = np.clip(s, 0, S - 1)
        shared[i, j] = len(np.unique(s)) < len(s)
        for b in s:
            want_add[i, j, b >> 5] = (want_add[i, j, b >> 5] + (1 << int(b & 31))) & 0xFFFFFFFF
            want_or[i, j, b >> 5] |= np.uint32(1 << int(b & 31))
    np.testing.assert_array_equal(add, want_add.astype(np.uint32))
    np.testing.assert_array_equal(orb, want_or)
    cov = count > 0
    same = np.all(add == orb, axis=-1)
    np.testing.assert_array_equal(same[cov], ~shared[cov])  # equal exactly where no slice is shared
    assert shared.sum() > 0 and (cov & ~shared).sum() > 0.4 * cov.sum()
    if slicing == "global" and S == 64:
        assert shared.sum() > 0.4 * cov.sum()  # measured 0.47
    # where no slice is shared the peeled layers are the same too
    la, ta = peel_layers(add, zlo, zhi, S, 32)
    lo_, to_ = peel_layers(orb, zlo, zhi, S, 32)
    keep = cov & ~shared
    np.testing.assert_array_equal(ta[keep], to_[keep])
    n = min(la.shape[0], lo_.shape[0])
    np.testing.assert_array_equal(la[:n, keep], lo_[:n, keep])
    assert np.all(ta[shared] <= to_[shared] + 1)  # a carry can only merge bits (or set a new one above)


def test_additive_blend_changes_nothing_without_shared_slices(same_arrays):
    """The default sphere (local slicing, 256 slices): no pixel has two fragments in one slice
    away from the rim, and the whole pipeline gives the same result with 'add' and 'or'
    wherever the bitmasks agree."""
    sc = {"camera": {"width": 64, "height": 64, "eye": [0, 0, 3]},
          "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.5}}]}
    a = rr.render(sc, keep="voxelize")
    o = rr.render(sc, overrides={"imagespace.blend": "or"}, keep="voxelize")
    same = np.all(a["stage.voxelize.bits"] == o["stage.voxelize.bits"], axis=-1)
    assert np.mean(same[a["hit"]]) > 0.97
    if same.all():
        same_arrays(a, o, KEYS)
    else:  # a pixel whose mask differs can move its neighbours' normals: compare away from them
        from scipy.ndimage import binary_dilation

        far = ~binary_dilation(~same, iterations=4)
        for k in ("status", "interfaces", "exit_dir"):
            np.testing.assert_array_equal(a[k][far], o[k][far])


# --------------------------------------------------------------------------
# endpoint = probe (§3.6)
# --------------------------------------------------------------------------

W = 48


@functools.lru_cache(maxsize=None)
def _sphere_layers():
    v, f = icosphere_mesh(5, 0.5)
    cam = Camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30.0, W, W, 0.1, 10.0)
    rs = raster_setup(cam.world_to_view(v), cam, faces=f)
    zmin, zmax = depth_bounds(rs, cam)
    ldi, total = collect_depths(rs, cam, 8)
    bhi, blo = search_bounds(ldi, "mip", 16, 0.01)
    thr = exit_thresholds(zmin, zmax, 256, 1.0)
    return cam, (ldi, total, zmax, thr, bhi, blo)


def _project(p, cam):
    """(row, col) of view-space points, as the tracer projects them."""
    inv = 1.0 / -p[..., 2]  # camera.project_point's operations, in its order
    col = p[..., 0] * inv * (0.5 * cam.width / cam.sx) + 0.5 * cam.width
    row = 0.5 * cam.height - p[..., 1] * inv * (0.5 * cam.height / cam.sy)
    return row, col


def _sample(layer, r, c, filt):
    """The tracer's depth sampling (normals.sample_depth) in Python."""
    H, Wd = layer.shape

    def at(i, j):
        return float(layer[i, j]) if 0 <= i < H and 0 <= j < Wd else math.inf

    if not (r >= 0 and c >= 0) or int(math.floor(r)) >= H or int(math.floor(c)) >= Wd:
        return math.inf
    dn = at(int(math.floor(r)), int(math.floor(c)))
    if filt == "nearest" or not math.isfinite(dn):
        return dn
    u, v = c - 0.5, r - 0.5
    j0, i0 = math.floor(u), math.floor(v)
    fx, fy = u - j0, v - i0
    q = [at(i0, j0), at(i0, j0 + 1), at(i0 + 1, j0), at(i0 + 1, j0 + 1)]
    if not all(math.isfinite(x) for x in q):
        return dn
    a = q[0] + fx * (q[1] - q[0])
    b = q[2] + fx * (q[3] - q[2])
    return a + fy * (b - a)


@pytest.mark.parametrize("filt", ["nearest", "bilinear"])
@pytest.mark.parametrize("iterations", [5, 3])
def test_probe_endpoint_is_the_unprojection_of_the_last_probe(filt, iterations):
    """The search replayed in Python from the recorded entry point and direction: the second
    recorded point (the exit) is the last probe's line of sight at the layer's sampled depth,
    and it lies on the last probe's texel."""
    cam, layers = _sphere_layers()
    ldi, total, zmax, thr, bhi, blo = layers
    tr = _trace(*layers, None, cam, ior=1.5, iterations=iterations, normals="central", delta=2,
                      record=2, endpoint="probe", filter=filt)
    m = (tr["status"] == 1) & (tr["interfaces"] == 2)
    assert m.sum() > 500  # of about 700 hit pixels
    S = tr["path_pos"][..., 0, :][m]
    v = tr["path_dir"][..., 0, :][m]
    got = tr["path_pos"][..., 1, :][m]
    np.testing.assert_array_equal(got, tr["exit_pos"][m])
    layer = ldi[1]
    texel_same = 0
    for s, d, g in zip(S, v, got):
        k = (bhi[1] - (-s[2])) / (-d[2])
        e = s + k * d
        a, b, t = 0.0, 1.0, 1.0
        for _ in range(iterations):
            t = 0.5 * (a + b)
            p = s + t * (e - s)
            r, c = _project(p, cam)
            ls = _sample(layer, r, c, filt)
            if 0 <= c < W and 0 <= r < W and math.isfinite(ls) and -p[2] >= ls:
                b = t
            else:
                a = t
        p = s + t * (e - s)
        r, c = _project(p, cam)
        dq = _sample(layer, r, c, filt)
        want = np.array([(c * (2.0 / W) - 1.0) * cam.sx * dq, (1.0 - r * (2.0 / W)) * cam.sy * dq, -dq])
        np.testing.assert_allclose(g, want, rtol=0, atol=1e-12)
        assert g[2] == -dq  # on the layer's (sampled) surface, exactly
        rg, cg = _project(g, cam)
        texel_same += (math.floor(rg), math.floor(cg)) == (math.floor(r), math.floor(c))
        assert abs(rg - r) < 1e-9 and abs(cg - c) < 1e-9  # the same line of sight
    assert texel_same == len(got)  # on the last probe's texel


@pytest.mark.parametrize("iterations", [0, 1, 5, 12])
def test_probe_endpoint_of_a_flat_slab_is_on_its_back_face(iterations):
    """Normal incidence through a slab between depths 2 and 3: every probe's texel holds the
    back face at depth 3, so the exit is on it whatever the iterations (the 'bracket'
    end point is 3 - 2^-(k+1), tests/imagespace/test_imagespace.py), and the path is exactly 1 long."""
    cam, ldi, total, zback, thr, bhi, blo = _flat_slab(16)
    dirs = np.zeros((16, 16, 3))
    dirs[..., 2] = -1.0
    for filt in ("nearest", "bilinear"):
        tr = _trace(ldi, total, zback, thr, bhi, blo, dirs, cam, ior=1.5, iterations=iterations,
                          endpoint="probe", filter=filt)
        assert np.all(tr["status"] == 1) and np.all(tr["interfaces"] == 2)
        np.testing.assert_array_equal(tr["exit_dir"], dirs)
        assert np.all(tr["exit_pos"][..., 2] == -3.0)
        assert np.all(tr["path_length"] == 1.0)


def test_probe_endpoint_fails_only_where_the_probes_texel_lacks_the_layer():
    """A layer-1 hole under the left half of the image, straight rays (ior 1) through every
    pixel: where the last probe lands in the hole the ray is lost inside the object (status
    4), elsewhere it exits on layer 1; the 'bracket' end point tests E and also gives up."""
    cam, ldi, total, zback, thr, bhi, blo = _flat_slab(16)
    ldi = ldi.copy()
    ldi[1, :, :8] = np.inf
    for endpoint in ("probe", "bracket"):
        tr = _trace(ldi, total, zback, thr, bhi, blo, None, cam, ior=1.0, endpoint=endpoint)
        assert np.all(tr["status"][:, :8] == 4) and np.all(tr["status"][:, 8:] == 1)
        assert np.all(tr["interfaces"][:, :8] == 1) and np.all(tr["interfaces"][:, 8:] == 2)


# --------------------------------------------------------------------------
# filter = bilinear (§3.4.2)
# --------------------------------------------------------------------------

def _flat_slab(Wd=16, fov=30.0):
    cam = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), fov, Wd, Wd, 0.1, 100.0)
    ldi = np.empty((2, Wd, Wd), np.float32)
    ldi[0], ldi[1] = 2.0, 3.0
    total = np.full((Wd, Wd), 2, np.int32)
    return cam, ldi, total, np.full((Wd, Wd), 3.0), np.zeros((Wd, Wd)), np.array([2.0, 3.0]), np.array([2.0, 3.0])


@pytest.mark.parametrize("endpoint", ["probe", "bracket"])
@pytest.mark.parametrize("normals", ["central", "mesh3x3", "cross", "forward"])
def test_bilinear_equals_nearest_on_a_flat_slab(endpoint, normals):
    """A slab seen head-on through a wide perspective camera: the refracted rays are oblique,
    so the probes land between texel centres, but every layer's depth is constant; bilinear
    filtering gives the nearest result bit for bit with the differences of eqs. 3.1 and 3.2
    (their gradients of a constant depth are exactly 0). The 3x3 mesh and the cross product
    build each texel's normal from unprojected points, whose round-off tilts a plane's
    normal by ~1e-16 differently at each texel: the blend of four of them then differs from
    the nearest one at that level (measured <= 5e-16), and no status changes."""
    cam, ldi, total, zback, thr, bhi, blo = _flat_slab(40, fov=70.0)
    kw = dict(ior=1.5, iterations=5, normals=normals, delta=2, endpoint=endpoint, record=3)
    near = _trace(ldi, total, zback, thr, bhi, blo, None, cam, filter="nearest", **kw)
    bil = _trace(ldi, total, zback, thr, bhi, blo, None, cam, filter="bilinear", **kw)
    assert np.count_nonzero(near["status"] == 1) > 1000
    for k in near:
        if normals in ("central", "forward") or near[k].dtype.kind != "f":
            assert np.array_equal(near[k], bil[k], equal_nan=True), k
        else:
            np.testing.assert_allclose(bil[k], near[k], rtol=0, atol=1e-13, err_msg=k)
    # the exits are off the texel centres (so the bilinear path was taken)
    ex = near["status"] == 1
    r, c = _project(near["exit_pos"][ex], cam)
    assert np.mean(np.abs(c - np.floor(c) - 0.5) > 0.05) > 0.5


def _sphere_error(res, **im):
    sc = {"camera": {"width": res, "height": res, "eye": [0.0, 0.0, 3.0]},
          "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.5}}], "imagespace": im}
    r = rr.render(sc)
    o, d = r["ray_origin"].reshape(-1, 3), r["ray_dir"].reshape(-1, 3)
    an = sphere_refraction(o, d, (0.0, 0.0, 0.0), 0.5, 1.5)
    hit = an["hit"].reshape(r["hit"].shape)
    np.testing.assert_array_equal(r["hit"], hit)
    m = hit & (r["status"] == 1)
    e = angular_error_deg(r["exit_dir"][m], an["exit_dir"].reshape(r["exit_dir"].shape)[m])
    return np.median(e), np.percentile(e, 90), np.mean(r["status"][hit] == 1)


def test_bilinear_beats_nearest_against_the_closed_form_sphere():
    """128x128 icosphere (ior 1.5) against the analytic sphere, the seed's other defaults.

    Measured: bilinear median 0.130 deg, p90 1.47, 95.8% exit; nearest median 0.503,
    p90 1.78, 95.8% exit. Nearest sampling reads a hit's depth and normal up to half a
    texel away from where the ray meets the layer (0.8 deg of normal at the back
    surface); filtering interpolates them at the hit's own texture coordinate.
    """
    bil = _sphere_error(128, filter="bilinear")
    near = _sphere_error(128, filter="nearest")
    assert bil[0] < 0.5 * near[0], (bil, near)
    assert bil[1] < near[1], (bil, near)
    assert bil[2] > 0.93 and near[2] > 0.93


# --------------------------------------------------------------------------
# peel_all (the thesis's fixed layer count)
# --------------------------------------------------------------------------

@pytest.mark.parametrize("extra", [{}, {"depth": "float"}, {"peeling": "lut"}, {"tir": True, "filter": "nearest"}])
def test_peel_all_peels_every_layer_and_changes_no_output(extra, same_arrays):
    sc = {"camera": {"width": 48, "height": 48, "eye": [0.3, 0.4, 3.0]},
          "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.4}},
                      {"mesh": "sphere", "fit": 0.6, "material": {"ior": 1.4},
                       "transform": {"translate": [0.1, 0.0, -1.2]}}],
          "imagespace": dict(layers=8, **extra)}
    a = rr.render(sc, keep="peel,reduce")
    b = rr.render(sc, overrides={"imagespace.peel_all": True}, keep="peel,reduce")
    same_arrays(a, b, KEYS)
    dc = int(a["depth_complexity"].max())
    assert dc == 4
    if extra.get("peeling") == "lut":
        assert "stage.peel.ldi" not in a.arrays and b.meta["layers_used"] == 8
        return
    la, lb = a["stage.peel.ldi"], b["stage.peel.ldi"]
    assert la.shape[0] == dc and lb.shape[0] == 8 and lb.dtype == la.dtype
    np.testing.assert_array_equal(lb[:dc], la)
    assert np.all(np.isposinf(lb[dc:]))
    hb = b["stage.reduce.bounds_hi"]
    np.testing.assert_array_equal(hb[:dc], a["stage.reduce.bounds_hi"])
    assert np.all(np.isneginf(hb[dc:]))
    assert b.meta["layers_used"] == 8 and a.meta["layers_used"] == dc


# --------------------------------------------------------------------------
# determinism of the new paths
# --------------------------------------------------------------------------

def test_seed_paths_are_thread_count_independent(on_one_and_two_threads):
    sc = rr.load_scene({"camera": {"width": 48, "height": 48, "eye": [0.5, 0.6, 2.4]},
                        "objects": [{"mesh": "bunny", "fit": 1.0, "material": {"ior": 1.33}}],
                        "imagespace": {"tir": True, "normals": "mesh3x3", "peel_all": True}})
    a, b = on_one_and_two_threads(lambda: rr.render(sc))
    for k in a.arrays:
        assert a[k].tobytes() == b[k].tobytes(), k


def test_bad_values_are_refused():
    for key, value in (("endpoint", "midpoint"), ("filter", "trilinear"), ("blend", "xor"), ("peel_all", 1)):
        with pytest.raises(rr.SceneError, match=f"imagespace.{key}"):
            rr.load_scene({"imagespace": {key: value}})
