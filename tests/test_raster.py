"""Tests of the shared triangle rasterizer (refraction_ref.raster.rasterize).

Geometry is built directly in view space with a camera at the origin looking
down -z, so that view space equals world space. Where a test needs exact
depths, vertices are placed at known *screen* positions on the 1/256-pixel
snapping grid (``_unproject``), so that snapping moves nothing and the only
error left is floating-point round-off.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from refraction_ref.analytic import icosphere_mesh
from refraction_ref.camera import Camera
from refraction_ref.raster import clip_near, raster_setup, raster_stats, rasterize

NEAR = 0.1


def _cam(W=64, H=64, fov=40.0, near=NEAR):
    return Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), fov, W, H, near, 100.0)


def _unproject(cam, col, row, d):
    """View-space point at depth d seen at continuous screen position (col, row)."""
    return np.array([(col / cam.width * 2 - 1) * cam.sx * d, (1 - row / cam.height * 2) * cam.sy * d, -d])


def _quad(cam, j0, j1, i0, i1, d):
    """Two triangles sharing the diagonal; screen rectangle [j0, j1] x [i0, i1] at depth d."""
    p = [_unproject(cam, j0, i0, d), _unproject(cam, j1, i0, d), _unproject(cam, j1, i1, d), _unproject(cam, j0, i1, d)]
    return np.array([[p[0], p[1], p[2]], [p[0], p[2], p[3]]])


def _sphere_tris(center=(0.0, 0.0, -3.0), radius=0.5, sub=5):
    v, f = icosphere_mesh(sub, radius)
    return (v + np.asarray(center))[f]


def _pixel_rays(cam):
    """Unnormalised view rays through pixel centres with z = -1 (so the ray parameter is the depth)."""
    jj, ii = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    return np.stack([(jj / cam.width * 2 - 1) * cam.sx, (1 - ii / cam.height * 2) * cam.sy, -np.ones_like(jj)], -1)


def _plane_depth(cam, p0, p1, p2):
    n = np.cross(p1 - p0, p2 - p0)
    with np.errstate(divide="ignore"):
        return (n @ p0) / (_pixel_rays(cam) @ n)


# --------------------------------------------------------------------------
# coverage
# --------------------------------------------------------------------------

def test_closed_icosphere_even_count_and_projected_area():
    cam = _cam(128, 128, fov=30.0)
    D, R = 3.0, 0.5
    c = rasterize(_sphere_tris((0, 0, -D), R), cam, "count")
    assert c.dtype == np.int32 and c.shape == (128, 128)
    # a closed mesh: every pixel centre is inside it an even number of times,
    # so no shared edge or vertex produced a duplicate (or a missing) fragment
    assert np.all(c % 2 == 0)
    assert set(np.unique(c)) == {0, 2}  # a convex closed surface: front and back only
    # silhouette: a cone of half-angle asin(R / D), a disc of radius tan(.) on the image plane z = -1
    r_px = math.tan(math.asin(R / D)) / cam.sy * cam.height / 2
    area = np.count_nonzero(c)
    # measured 5108 vs 5120.8 (-0.25%: the icosphere is inscribed, plus pixel quantisation)
    assert abs(area / (math.pi * r_px**2) - 1) < 0.02


def test_view_aligned_square_counted_once():
    cam = _cam(64, 64)
    j0, j1, i0, i1 = 10, 40, 20, 50  # edges on pixel boundaries, the diagonal through pixel centres
    q = _quad(cam, j0, j1, i0, i1, 2.0)
    # the shared diagonal runs through the centres (k + 0.5, k + 0.5) of 30 pixels
    expected = np.zeros((64, 64), np.int32)
    expected[i0:i1, j0:j1] = 1
    for tris in (q, q[::-1], q[:, ::-1]):  # triangle order and winding do not matter
        np.testing.assert_array_equal(rasterize(tris, cam, "count"), expected)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(3, 40))
def test_planar_triangulation_partitions_pixels(seed, n):
    """A triangulated rectangle (interior vertices on half-pixel positions, so many
    edges run through pixel centres) covers every pixel inside exactly once."""
    from scipy.spatial import Delaunay

    cam = _cam(48, 40)
    rng = np.random.default_rng(seed)
    j0, j1, i0, i1 = 3, 45, 2, 37
    pts = np.array([[j0, i0], [j1, i0], [j1, i1], [j0, i1]], float)
    inner = np.stack([rng.integers(2 * j0 + 1, 2 * j1, n), rng.integers(2 * i0 + 1, 2 * i1, n)], 1) / 2.0
    pts = np.unique(np.vstack([pts, inner]), axis=0)
    tri = Delaunay(pts).simplices
    # a tilted plane: depth varies across the rectangle
    d = 2.0 + 0.03 * pts[:, 0] + 0.02 * pts[:, 1]
    v = np.stack([_unproject(cam, c, r, z) for (c, r), z in zip(pts, d)])
    c = rasterize(v[tri], cam, "count")
    expected = np.zeros(c.shape, np.int32)
    expected[i0:i1, j0:j1] = 1
    np.testing.assert_array_equal(c, expected)


def test_tie_rule_is_top_left():
    cam = _cam(32, 32)
    # edges exactly through pixel centres: top edge row 5.5, left column 7.5, bottom 20.5, right 25.5
    c = rasterize(_quad(cam, 7.5, 25.5, 5.5, 20.5, 2.0), cam, "count")
    rows, cols = np.nonzero(c)
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (5, 19, 7, 24)


def test_edges_through_centres_have_a_consistent_tie_rule():
    """Whatever the rule, two rectangles sharing an edge through pixel centres cover
    the union exactly once, and each rectangle covers exactly its width in pixels."""
    cam = _cam(32, 32)
    a = _quad(cam, 4.5, 12.5, 5.5, 20.5, 2.0)
    b = _quad(cam, 12.5, 27.5, 5.5, 20.5, 2.0)
    ca, cb = rasterize(a, cam, "count"), rasterize(b, cam, "count")
    assert ca.max() == 1 and cb.max() == 1
    assert np.count_nonzero(ca & cb) == 0
    u = ca + cb
    assert np.count_nonzero(u) == 15 * 23  # 15 rows and 8 + 15 columns
    rows, cols = np.nonzero(u)
    assert rows.max() - rows.min() == 14 and cols.max() - cols.min() == 22


# --------------------------------------------------------------------------
# depth
# --------------------------------------------------------------------------

def test_perspective_correct_depth_on_tilted_plane():
    cam = _cam(64, 64)
    # vertices on the 1/256-pixel grid, at very different depths
    p = np.array([_unproject(cam, -3.25, -2.5, 1.0), _unproject(cam, 70.0, 5.125, 3.0),
                  _unproject(cam, 10.5, 80.0, 6.0)])
    exact = _plane_depth(cam, *p)
    for op in ("min", "max"):
        m = rasterize(p[None], cam, op)
        cov = np.isfinite(m)
        assert cov.sum() > 1000
        # measured max relative error 4.4e-16
        assert np.max(np.abs(m[cov] / exact[cov] - 1)) < 1e-9
    lo, hi = rasterize(p[None], cam, "minmax")
    np.testing.assert_array_equal(lo, rasterize(p[None], cam, "min"))
    np.testing.assert_array_equal(hi, rasterize(p[None], cam, "max"))


def test_depth_of_unsnapped_vertices_is_close():
    """Off the snapping grid, a vertex moves by at most 1/512 pixel: the depth error stays small."""
    cam = _cam(64, 64)
    p = np.array([_unproject(cam, -3.25, -2.5, 1.0), _unproject(cam, 70.0, 5.125, 3.0),
                  _unproject(cam, 10.5, 80.0, 6.0)])
    p += np.array([[0.0013, 0.0007, 0.0], [0.002, -0.001, 0.0], [0.0, 0.001, 0.0]])
    m = rasterize(p[None], cam, "min")
    cov = np.isfinite(m)
    exact = _plane_depth(cam, *p)
    assert np.max(np.abs(m[cov] / exact[cov] - 1)) < 1e-3  # measured 4.3e-5


def test_empty_pixels_hold_the_identities():
    cam = _cam(32, 32)
    q = _quad(cam, 4, 10, 4, 10, 2.0)
    assert np.all(np.isposinf(rasterize(q, cam, "min")[20:, 20:]))
    assert np.all(np.isneginf(rasterize(q, cam, "max")[20:, 20:]))
    d, n = rasterize(q, cam, "collect", capacity=4)
    assert np.all(np.isposinf(d[:, 20:, 20:])) and np.all(n[20:, 20:] == 0)


# --------------------------------------------------------------------------
# bitmask blending: logical OR vs 32-bit additive blending
# --------------------------------------------------------------------------

S = 64


def _slice_depth(s, lo=1.0, hi=3.0):
    return lo + s / (S - 1) * (hi - lo)


def _bits(tris, cam, op):
    H, W = cam.shape
    return rasterize(tris, cam, op, bounds=(np.full((H, W), 1.0), np.full((H, W), 3.0)), slices=S)


@pytest.mark.parametrize("s", [0, 5, 30, 40, 62])
def test_or_and_add_with_one_and_two_fragments_per_slice(s):
    cam = _cam(32, 32)
    q = _quad(cam, 4, 20, 6, 26, _slice_depth(s))
    inside = np.zeros(cam.shape, bool)
    inside[6:26, 4:20] = True
    w, b = divmod(s, 32)

    one_or, one_add = _bits(q, cam, "or"), _bits(q, cam, "add")
    assert one_or.dtype == np.uint32 and one_or.shape == (32, 32, S // 32)
    np.testing.assert_array_equal(one_or, one_add)  # at most one fragment per slice
    assert np.all(one_or[inside][:, w] == np.uint32(1 << b))
    assert np.all(one_or[~inside] == 0)

    two = np.concatenate([q, q])  # two coincident quads: two fragments in one slice
    t_or, t_add = _bits(two, cam, "or"), _bits(two, cam, "add")
    np.testing.assert_array_equal(t_or, one_or)  # OR sets the bit once
    assert np.all(t_add[~inside] == 0)
    if b < 31:  # 2 * 2^b = 2^(b+1): bit b cleared, bit b + 1 set
        expect = np.zeros(S // 32, np.uint32)
        expect[w] = np.uint32(1 << (b + 1))
        assert np.all(t_add[inside] == expect)
    three = _bits(np.concatenate([q, q, q]), cam, "add")  # 3 * 2^b: bits b and b + 1
    if b < 31:
        assert np.all(three[inside][:, w] == np.uint32(3 << b))


def test_add_carry_out_of_bit_31_is_lost():
    cam = _cam(32, 32)
    q = _quad(cam, 4, 20, 6, 26, _slice_depth(31))  # bit 31 of word 0
    inside = np.zeros(cam.shape, bool)
    inside[6:26, 4:20] = True
    assert np.all(_bits(q, cam, "or")[inside][:, 0] == np.uint32(1 << 31))
    two = _bits(np.concatenate([q, q]), cam, "add")
    # 2^31 + 2^31 = 2^32 wraps to 0 in a 32-bit word; nothing carries into word 1
    assert np.all(two == 0)
    three = _bits(np.concatenate([q, q, q]), cam, "add")
    assert np.all(three[inside] == np.array([1 << 31, 0], np.uint32))


def _popcount(bits):
    b = bits.view(np.uint8).reshape(bits.shape[:2] + (-1,))
    return np.unpackbits(b, axis=-1).sum(axis=-1)


def test_or_equals_add_where_no_slice_is_shared():
    cam = _cam(64, 64, fov=30.0)
    tris = np.concatenate([_sphere_tris((0.0, 0.0, -3.0)), _sphere_tris((0.2, 0.1, -3.6))])
    lo, hi = rasterize(tris, cam, "minmax")
    cov = np.isfinite(lo)
    zlo, zhi = np.where(cov, lo, 0.0), np.where(cov, hi, 0.0)
    o = rasterize(tris, cam, "or", bounds=(zlo, zhi), slices=128)
    a = rasterize(tris, cam, "add", bounds=(zlo, zhi), slices=128)
    c = rasterize(tris, cam, "count")
    distinct = _popcount(o) == c  # every fragment in a slice of its own
    assert distinct.sum() > 0.9 * cov.sum()
    np.testing.assert_array_equal(o[distinct], a[distinct])
    assert np.all(_popcount(o)[~cov] == 0)


# --------------------------------------------------------------------------
# collect (A-buffer)
# --------------------------------------------------------------------------

def test_collect_matches_min_max_count():
    cam = _cam(64, 64, fov=30.0)
    tris = np.concatenate([_sphere_tris((0.0, 0.0, -3.0)), _sphere_tris((0.2, 0.1, -3.6)),
                           _quad(cam, 0, 64, 30, 34, 3.3)])
    cnt = rasterize(tris, cam, "count")
    cap = int(cnt.max())
    assert cap == 5
    d, n = rasterize(tris, cam, "collect", capacity=cap)
    assert d.shape == (cap, 64, 64) and d.dtype == np.float64 and n.dtype == np.int32
    np.testing.assert_array_equal(n, cnt)
    fin = np.isfinite(d)
    assert np.all(fin.sum(axis=0) == cnt)
    assert np.all((d[1:] >= d[:-1])[fin[1:]])  # sorted front to back
    cov = cnt > 0
    np.testing.assert_array_equal(d[0][cov], rasterize(tris, cam, "min")[cov])
    last = np.take_along_axis(d, np.maximum(cnt - 1, 0)[None], axis=0)[0]
    np.testing.assert_array_equal(last[cov], rasterize(tris, cam, "max")[cov])
    # with a smaller capacity: the nearest fragments, and still the total count
    d3, n3 = rasterize(tris, cam, "collect", capacity=3)
    np.testing.assert_array_equal(n3, cnt)
    np.testing.assert_array_equal(d3, d[:3])


# --------------------------------------------------------------------------
# degenerate triangles and near-plane clipping
# --------------------------------------------------------------------------

def test_degenerate_triangles_produce_no_fragments():
    cam = _cam(32, 32)
    a, b, c = _unproject(cam, 3, 3, 2.0), _unproject(cam, 28, 5, 2.5), _unproject(cam, 10, 29, 3.0)
    m = _unproject(cam, 15.5, 4, 7.0)  # on the screen segment a-b (at another depth): collinear on screen
    degenerate = np.array([[a, a, b], [a, b, b], [c, c, c], [a, m, b], [a, b, a]])
    for op in ("count", "min", "max"):
        res, stats = rasterize(degenerate, cam, op), raster_stats(raster_setup(degenerate, cam))
        assert stats["degenerate"] == len(degenerate)
        if op == "count":
            assert np.all(res == 0)
        else:
            assert not np.isfinite(res).any()
    bits = rasterize(degenerate, cam, "add", bounds=(np.ones((32, 32)), np.full((32, 32), 3.0)), slices=32)
    assert np.all(bits == 0)
    # mixed with a real triangle: identical to the real triangle alone
    real = np.array([[a, b, c]])
    mixed = np.concatenate([degenerate[:2], real, degenerate[2:]])
    np.testing.assert_array_equal(rasterize(mixed, cam, "min"), rasterize(real, cam, "min"))
    np.testing.assert_array_equal(rasterize(mixed, cam, "count"), rasterize(real, cam, "count"))


def test_triangles_crossing_the_near_plane_are_clipped():
    cam = _cam(64, 64, fov=60.0, near=NEAR)
    # one vertex behind the eye, one between the eye and the near plane, one far
    p = np.array([[-0.3, -0.2, 0.5], [0.4, -0.1, -0.05], [0.0, 0.6, -3.0]])
    behind = np.array([[[-1.0, -1.0, 0.5], [1.0, -1.0, 0.5], [0.0, 1.0, 0.05]]])  # entirely behind the near plane
    tris = np.concatenate([p[None], behind])
    clipped = clip_near(tris, NEAR)
    assert len(clipped) in (1, 2) and np.all(-clipped[..., 2] >= NEAR * (1 - 1e-12))
    n = np.cross(p[1] - p[0], p[2] - p[0])
    # clipping keeps the plane of the triangle
    assert np.max(np.abs((clipped.reshape(-1, 3) - p[0]) @ n)) < 1e-12 * np.linalg.norm(n) * 10
    m = rasterize(tris, cam, "min")
    c = rasterize(tris, cam, "count")
    assert not np.isnan(m).any()
    cov = np.isfinite(m)
    assert cov.sum() > 100
    assert np.all(m[cov] >= NEAR * (1 - 1e-9))
    assert c.max() == 1  # the (up to) two clipped triangles share their diagonal without duplicates
    exact = _plane_depth(cam, *p)
    assert np.max(np.abs(m[cov] / exact[cov] - 1)) < 1e-3  # clipped vertices are off the snapping grid
    # the behind-the-eye triangle alone draws nothing
    assert rasterize(behind, cam, "count").max() == 0
    # without clipping, vertices behind the eye are dropped rather than wrapped around
    assert raster_stats(raster_setup(tris, cam, clip=False))["dropped"] == 2


# --------------------------------------------------------------------------
# determinism
# --------------------------------------------------------------------------

def test_bit_identical_whatever_the_thread_count(on_one_and_two_threads):
    cam = _cam(96, 80, fov=30.0)
    tris = np.concatenate([_sphere_tris((0.0, 0.0, -3.0)), _sphere_tris((0.15, 0.1, -3.4)),
                           _quad(cam, -5, 100, 30, 34, 3.2), _quad(cam, -5, 100, 30, 34, 3.2)])
    lo, hi = rasterize(tris, cam, "minmax")
    zlo, zhi = np.where(np.isfinite(lo), lo, 0.0), np.where(np.isfinite(hi), hi, 0.0)

    def run():
        out = [rasterize(tris, cam, op) for op in ("min", "max", "count")]
        out += list(rasterize(tris, cam, "minmax"))
        out += [rasterize(tris, cam, op, bounds=(zlo, zhi), slices=96) for op in ("or", "add")]
        out += list(rasterize(tris, cam, "collect", capacity=6))
        return out

    a, b = on_one_and_two_threads(run)
    for x, y in zip(a, b):
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(x, y)
        assert x.tobytes() == y.tobytes()


def test_unknown_op_and_bad_slices_are_refused():
    cam = _cam(8, 8)
    q = _quad(cam, 1, 6, 1, 6, 2.0)
    with pytest.raises(ValueError, match="op"):
        rasterize(q, cam, "xor")
    with pytest.raises(ValueError, match="slices"):
        rasterize(q, cam, "or", bounds=(np.ones((8, 8)), np.ones((8, 8)) * 3), slices=48)
    with pytest.raises(ValueError, match="zlo"):
        rasterize(q, cam, "or")


@pytest.mark.parametrize("blend", ["or", "add"])
def test_recorded_fragments_voxelize_like_a_second_rasterization(blend):
    """The min/max pass's recorded fragments give the very bitmask a second pass gives (§3.3)."""
    import refraction_ref as rr
    from refraction_ref.meshes import scene_geometry
    from refraction_ref.raster import Fragments

    sc = rr.load_scene({"camera": {"width": 96, "height": 80}})
    cam = Camera.from_dict(sc.data["camera"])
    g = scene_geometry(sc)
    rs = raster_setup(cam.world_to_view(g.vertices), cam, faces=g.faces)
    zmin, zmax, fr = rasterize(rs, cam, "minmax", keep_fragments=True)
    assert isinstance(fr, Fragments)
    assert int(fr.counts.sum()) == int(rasterize(rs, cam, "count").sum())
    z2 = rasterize(rs, cam, "minmax")
    np.testing.assert_array_equal(zmin, z2[0])
    np.testing.assert_array_equal(zmax, z2[1])
    a = rasterize(fr, cam, blend, bounds=(zmin, zmax), slices=128)
    b = rasterize(rs, cam, blend, bounds=(zmin, zmax), slices=128)
    np.testing.assert_array_equal(a, b)
    assert np.count_nonzero(a) > 0


@given(st.integers(min_value=1, max_value=200_000))
@settings(max_examples=200, deadline=None)
def test_strided_order_visits_every_row_once(n):
    """The prange work order (refraction_ref.schedule) is a permutation of 0..n-1."""
    from refraction_ref.schedule import coprime_stride, strided

    s = coprime_stride(n)
    order = np.array([strided(k, s, n) for k in range(n)]) if n <= 5000 else (np.arange(n, dtype=np.int64) * s) % n
    assert np.array_equal(np.sort(order), np.arange(n))


def test_strided_order_for_multiples_of_the_small_primes():
    from refraction_ref.schedule import coprime_stride

    n = 7 * 11 * 13 * 17 * 19 * 23 * 29 * 31 * 37 * 41 * 43 * 47
    assert coprime_stride(n) == 1
    for n in (7, 77, 7 * 11 * 13, 512, 511):
        s = coprime_stride(n)
        assert np.array_equal(np.sort((np.arange(n) * s) % n), np.arange(n))


@pytest.mark.parametrize("T", [0, 5, 5000, 300_000])
def test_bin_lists_triangles_per_band_in_index_order(T):
    """The parallel counting sort gives every band the triangles whose rows meet it,
    in triangle order (what a serial pass gives), and empty triangles nowhere."""
    from refraction_ref.raster import bin_bands

    rng = np.random.default_rng(T)
    H, band = 100, 8
    i0 = rng.integers(0, H, T)
    rows = np.stack([i0, np.minimum(i0 + rng.integers(-3, 20, T), H - 1)], 1).astype(np.int64)
    counts, tris = bin_bands(rows, H, band)
    nb_bands = -(-H // band)
    assert counts.shape == (nb_bands + 1,) and counts[0] == 0 and counts[-1] == len(tris)
    for b in range(nb_bands):
        expect = np.flatnonzero((rows[:, 0] <= rows[:, 1]) & (rows[:, 0] // band <= b) & (rows[:, 1] // band >= b))
        np.testing.assert_array_equal(tris[counts[b]:counts[b + 1]], expect)
    with pytest.raises(ValueError):
        bin_bands(rows, H, 6)
