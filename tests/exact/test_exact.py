"""Tests of the exact Snell tracer (refraction_ref.exact) and of the analytic
sphere reference (refraction_ref.analytic) it is checked against."""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings, strategies as st

from refraction_ref import optics
from refraction_ref.analytic import icosphere_mesh, sphere_refraction
from refraction_ref.exact import (
    STATUS_BOUNCE_LIMIT,
    STATUS_BOUNCE_LIMIT_TIR,
    STATUS_EXITED,
    STATUS_MISSED,
    ExactMesh,
    area_weighted_vertex_normals,
    trace_exact,
)

BUNNY = Path(__file__).resolve().parents[2] / "refraction_ref" / "data" / "bunny.ply"


@functools.lru_cache(maxsize=None)
def _ico(sub, radius=0.5):
    v, f = icosphere_mesh(sub, radius)
    v.setflags(write=False)
    f.setflags(write=False)
    return v, f


def _trace_single(v, f, ior, origins, dirs, absorption=(0.0, 0.0, 0.0), normals=None, smooth=True,
                  outside_ior=1.0, **kw):
    mesh = ExactMesh(v, f, np.zeros(len(f), dtype=int), [ior], [absorption], normals, smooth, outside_ior)
    return trace_exact(mesh, origins, dirs, **kw)


def _parallel_grid(direction, half_width, n, distance=2.0):
    """Rays parallel to `direction`, on a disc of radius `half_width` around the
    axis through the origin, starting `distance` before the origin."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    a = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(d, a)
    g = np.linspace(-half_width, half_width, n)
    x, y = np.meshgrid(g, g)
    keep = x**2 + y**2 <= half_width**2
    x, y = x[keep], y[keep]
    o = -distance * d + x[:, None] * a + y[:, None] * b
    return o, np.tile(d, (len(o), 1))


def _angle_deg(a, b):
    c = np.clip(np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)), -1, 1)
    return np.degrees(np.arccos(c))


# --------------------------------------------------------------------------
# index matched: nothing bends
# --------------------------------------------------------------------------

def test_ior_one_is_transparent():
    v, f = _ico(3)
    o, d = _parallel_grid([0.3, -0.2, 1.0], 0.4, 25)
    rng = np.random.default_rng(1)
    # plus random rays aimed at random points inside the sphere
    src = rng.normal(size=(200, 3))
    src = 2.0 * src / np.linalg.norm(src, axis=1, keepdims=True)
    tgt = rng.uniform(-0.2, 0.2, (200, 3))
    dd = tgt - src
    dd /= np.linalg.norm(dd, axis=1, keepdims=True)
    o = np.vstack([o, src])
    d = np.vstack([d, dd])
    for smooth in (True, False):
        r = _trace_single(v, f, 1.0, o, d, smooth=smooth)
        assert np.all(r["status"] == STATUS_EXITED)
        assert np.all(r["interfaces"] == 2)
        assert np.all(r["bounces"] == 2)
        assert np.max(np.abs(r["exit_dir"] - d)) < 1e-12
        # exit point is on the original line
        assert np.max(np.linalg.norm(np.cross(r["exit_pos"] - o, d), axis=1)) < 1e-12
        assert np.all(r["transmittance"] == 1.0)


# --------------------------------------------------------------------------
# icosphere vs analytic sphere
# --------------------------------------------------------------------------

# Measured (subdivision 5, radius 0.5, ior 1.5, smooth, 61x61 grid within
# 0.9 R, axis-aligned rays): max exit-direction error 0.158 deg, mean 0.026
# deg, max |path_length error| 1.09e-3, max exit-position error 1.5e-3.
# Face normals instead: max 2.18 deg, mean 0.45 deg, path error 7.3e-3.
SPHERE_MAX_ANGLE_DEG = 0.25
SPHERE_MEAN_ANGLE_DEG = 0.05
SPHERE_PATH_TOL = 2e-3
SPHERE_EXIT_POS_TOL = 3e-3


@pytest.mark.parametrize("direction", [[0.0, 0.0, 1.0], [1.0, 2.0, 3.0]])
def test_icosphere_matches_analytic_sphere(direction):
    v, f = _ico(5)
    o, d = _parallel_grid(direction, 0.9 * 0.5, 61)
    r = _trace_single(v, f, 1.5, o, d, smooth=True)
    a = sphere_refraction(o, d, [0.0, 0.0, 0.0], 0.5, 1.5)
    assert np.all(a["hit"]) and np.all(r["status"] == STATUS_EXITED)
    assert np.all(r["interfaces"] == 2)
    ang = _angle_deg(r["exit_dir"], a["exit_dir"])
    assert ang.max() < SPHERE_MAX_ANGLE_DEG, ang.max()
    assert ang.mean() < SPHERE_MEAN_ANGLE_DEG, ang.mean()
    assert np.max(np.abs(r["path_length"] - a["path_length"])) < SPHERE_PATH_TOL
    assert np.max(np.linalg.norm(r["exit_pos"] - a["exit_pos"], axis=1)) < SPHERE_EXIT_POS_TOL
    assert np.max(np.linalg.norm(r["hit_pos"] - a["entry_pos"], axis=1)) < SPHERE_EXIT_POS_TOL

    # face normals are a much worse approximation of the sphere
    rf = _trace_single(v, f, 1.5, o, d, smooth=False)
    assert _angle_deg(rf["exit_dir"], a["exit_dir"]).max() > 4 * ang.max()


def test_analytic_sphere_closed_form():
    """Deviation 2 (theta_i - theta_t) and chord 2 R cos(theta_t)."""
    ior, rad = 1.5, 0.5
    h = np.linspace(0.0, 0.99, 50) * rad  # impact parameter
    o = np.stack([h, np.zeros_like(h), np.full_like(h, -3.0)], axis=1)
    d = np.tile([0.0, 0.0, 1.0], (len(h), 1))
    a = sphere_refraction(o, d, [0, 0, 0], rad, ior)
    th_i = np.arcsin(h / rad)
    th_t = np.arcsin(np.sin(th_i) / ior)
    dev = np.radians(_angle_deg(a["exit_dir"], d))
    np.testing.assert_allclose(dev, 2 * (th_i - th_t), atol=1e-7)
    np.testing.assert_allclose(a["path_length"], 2 * rad * np.cos(th_t), atol=1e-12)
    # rays bend towards the axis (converging lens)
    assert np.all(a["exit_dir"][1:, 0] < 0)
    # misses, and rays starting inside, are NaN rows
    m = sphere_refraction([[0.6, 0, -3], [0, 0, 0]], [[0, 0, 1], [0, 0, 1]], [0, 0, 0], rad, ior)
    assert not m["hit"].any() and np.all(np.isnan(m["exit_dir"]))


# --------------------------------------------------------------------------
# Snell's law at the first interface (property test)
# --------------------------------------------------------------------------

@settings(max_examples=40, deadline=None)
@given(
    theta=st.floats(0.0, math.pi),
    phi=st.floats(0.0, 2 * math.pi),
    aim=st.tuples(*[st.floats(-0.3, 0.3)] * 3),
    ior=st.floats(1.05, 2.5),
    outside_ior=st.floats(1.0, 1.04),
    smooth=st.booleans(),
)
def test_snell_invariant_first_interface(theta, phi, aim, ior, outside_ior, smooth):
    v, f = _ico(3)
    o = 2.0 * np.array([[math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)]])
    d = np.asarray(aim)[None] - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = _trace_single(v, f, ior, o, d, smooth=smooth, outside_ior=outside_ior)
    assert r["hit"][0] and r["interfaces"][0] >= 1
    n = r["first_normal"][0]
    t = r["first_dir"][0]
    x = r["hit_pos"][0]
    fi = r["first_face"][0]
    tri = v[f[fi]]
    ng = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    ng /= np.linalg.norm(ng)
    # the hit point is on the ray and on the plane of the reported triangle
    assert np.linalg.norm(np.cross(x - o[0], d[0])) < 1e-12
    assert abs(np.dot(x - tri[0], ng)) < 1e-12
    # the normal is a unit outward normal (exactly the face normal without smoothing)
    assert abs(np.linalg.norm(n) - 1) < 1e-12 and np.dot(n, ng) > 0
    if not smooth:
        np.testing.assert_allclose(n, ng, atol=1e-12)
    else:  # interpolated normal close to the sphere's normal
        assert _angle_deg(n, x / np.linalg.norm(x)) < 3.0
    # Snell: n1 sin(theta_i) = n2 sin(theta_t), coplanar, transmitted inwards
    sin_i = np.linalg.norm(np.cross(d[0], n))
    sin_t = np.linalg.norm(np.cross(t, n))
    assert abs(outside_ior * sin_i - ior * sin_t) < 1e-10
    assert abs(np.dot(np.cross(d[0], n), t)) < 1e-10
    assert np.dot(t, n) < 0 and np.dot(d[0], n) < 0
    assert abs(np.linalg.norm(t) - 1) < 1e-12
    # and it is what optics.refract gives
    t_ref, tir = optics.refract(d[0], n, outside_ior / ior)
    assert not tir
    np.testing.assert_array_equal(t, t_ref)


# --------------------------------------------------------------------------
# total internal reflection in a glass cube
# --------------------------------------------------------------------------

def _cube():
    m = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    return np.asarray(m.vertices, float), np.asarray(m.faces)


def test_cube_total_internal_reflection():
    v, f = _cube()
    ior, th_in = 1.5, math.radians(60.0)
    entry = np.array([0.2, 0.1, 0.5])
    d = np.array([[math.sin(th_in), 0.0, -math.cos(th_in)]])
    o = entry[None] - d
    th_t = math.asin(math.sin(th_in) / ior)
    # inside: hits x = 0.5 at 90 deg - th_t = 54.7 deg > critical 41.8 deg -> TIR
    assert math.pi / 2 - th_t > math.asin(1 / ior)
    s1 = (0.5 - entry[0]) / math.sin(th_t)
    z1 = 0.5 - s1 * math.cos(th_t)
    s2 = (z1 + 0.5) / math.cos(th_t)
    x2 = 0.5 - s2 * math.sin(th_t)
    absorption = [0.3, 0.0, 0.7]

    r = _trace_single(v, f, ior, o, d, absorption=absorption, smooth=False)
    assert r["status"][0] == STATUS_EXITED
    assert r["interfaces"][0] == 2  # entry top, exit bottom; the TIR is not a crossing
    assert r["bounces"][0] == 3
    np.testing.assert_allclose(r["hit_pos"][0], entry, atol=1e-12)
    np.testing.assert_allclose(r["exit_pos"][0], [x2, 0.1, -0.5], atol=1e-12)
    np.testing.assert_allclose(r["exit_dir"][0], [-math.sin(th_in), 0.0, -math.cos(th_in)], atol=1e-12)
    np.testing.assert_allclose(r["path_length"][0], s1 + s2, atol=1e-12)
    tr = r["transmittance"][0]
    np.testing.assert_allclose(tr, np.exp(-np.array(absorption) * (s1 + s2) * ior), rtol=1e-12)
    assert np.all(tr <= 1.0) and np.all(tr > 0.0)
    assert not r["leaked"][0]

    # bounce limits: after 1 event (entry) the next event is pending
    r1 = _trace_single(v, f, ior, o, d, smooth=False, max_bounces=1)
    assert r1["status"][0] == STATUS_BOUNCE_LIMIT and r1["interfaces"][0] == 1
    assert np.all(np.isnan(r1["exit_pos"][0])) and np.all(np.isnan(r1["exit_dir"][0]))
    np.testing.assert_allclose(r1["last_dir"][0], [math.sin(th_t), 0, -math.cos(th_t)], atol=1e-12)
    # after 2 events the last one was the TIR
    r2 = _trace_single(v, f, ior, o, d, smooth=False, max_bounces=2)
    assert r2["status"][0] == STATUS_BOUNCE_LIMIT_TIR and r2["interfaces"][0] == 1
    np.testing.assert_allclose(r2["last_dir"][0], [-math.sin(th_t), 0, -math.cos(th_t)], atol=1e-12)
    np.testing.assert_allclose(r2["path_length"][0], s1, atol=1e-12)
    # 3 events suffice: nothing further is hit, so the ray exited
    r3 = _trace_single(v, f, ior, o, d, smooth=False, max_bounces=3)
    assert r3["status"][0] == STATUS_EXITED
    # zero bounces: the first hit is found but not processed
    r0 = _trace_single(v, f, ior, o, d, smooth=False, max_bounces=0)
    assert r0["status"][0] == STATUS_BOUNCE_LIMIT and r0["hit"][0] and r0["interfaces"][0] == 0
    np.testing.assert_allclose(r0["hit_pos"][0], entry, atol=1e-12)


# --------------------------------------------------------------------------
# absorption
# --------------------------------------------------------------------------

@pytest.mark.parametrize("direction", [[0.0, 0.0, 1.0], [1.0, 2.0, 3.0]])
def test_absorption_through_centre(direction):
    v, f = _ico(5)
    d = np.asarray(direction, float)[None]
    d /= np.linalg.norm(d)
    o = -2.0 * d
    r = _trace_single(v, f, 1.5, o, d, absorption=[1.0, 0.0, 0.0])
    assert r["status"][0] == STATUS_EXITED and r["interfaces"][0] == 2
    assert abs(r["path_length"][0] - 1.0) < 1e-3
    assert abs(r["transmittance"][0, 0] - math.exp(-1.0 * 1.0 * 1.5)) < 1e-3
    assert np.all(r["transmittance"][0, 1:] == 1.0)
    # through the centre the ray is (nearly) undeviated
    assert _angle_deg(r["exit_dir"][0], d[0]) < 0.05


def test_two_objects_media_bookkeeping():
    """Two spheres with different ior/absorption on one axis: 4 crossings and
    the transmittance is the product of the two objects' own Beer-Lambert."""
    v, f = _ico(4)
    verts = np.vstack([v, v + [0.0, 0.0, 2.0]])
    faces = np.vstack([f, f + len(v)])
    fo = np.repeat([0, 1], len(f))
    o = np.array([[0.0, 0.0, -2.0]])
    d = np.array([[0.0, 0.0, 1.0]])  # through both poles (mesh vertices on the sphere)
    r = trace_exact(ExactMesh(verts, faces, fo, [1.5, 1.3], [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]), o, d)
    assert r["status"][0] == STATUS_EXITED and r["interfaces"][0] == 4
    np.testing.assert_allclose(r["path_length"][0], 2.0, atol=1e-12)
    np.testing.assert_allclose(r["transmittance"][0], [math.exp(-1.5), math.exp(-2 * 1.3), 1.0], rtol=1e-12)
    np.testing.assert_allclose(r["exit_pos"][0], [0, 0, 2.5], atol=1e-12)
    np.testing.assert_allclose(r["exit_dir"][0], d[0], atol=1e-12)


def test_open_mesh_leak_is_flagged():
    v, f = _ico(3)
    cz = v[f].mean(axis=1)[:, 2]
    f = f[cz < 0.4]  # remove the top cap
    o = np.array([[0.0, 0.0, -2.0], [0.0, 0.0, 2.0]])
    d = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, -1.0]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = _trace_single(v, f, 1.5, o, d)
    # upward ray enters the bottom and escapes through the hole
    assert r["status"][0] == STATUS_EXITED and r["leaked"][0] and r["interfaces"][0] == 1
    # downward ray enters through the hole onto the back side of the bottom: a
    # "leaving" event from the outside medium (index 1 -> 1), not a leak
    assert r["status"][1] == STATUS_EXITED and not r["leaked"][1]
    assert r["interfaces"][1] == 1 and r["hit_pos"][1, 2] < 0  # hit the inside of the bottom
    np.testing.assert_allclose(r["exit_dir"][1], d[1], atol=1e-12)


# --------------------------------------------------------------------------
# misses, determinism, validation
# --------------------------------------------------------------------------

def test_missing_rays():
    v, f = _ico(3)
    o = np.array([[0.0, 0.0, -2.0], [0.7, 0.0, -2.0], [0.0, 0.0, -2.0]])
    d = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    r = _trace_single(v, f, 1.5, o, d, absorption=[1, 1, 1])
    assert np.all(r["status"] == STATUS_MISSED)
    assert not r["hit"].any()
    assert not np.isnan(r["exit_dir"]).any()
    np.testing.assert_array_equal(r["exit_dir"], d)
    np.testing.assert_array_equal(r["last_dir"], d)
    assert np.isnan(r["exit_pos"]).all() and np.isnan(r["hit_pos"]).all()
    assert np.all(r["first_face"] == -1) and np.all(r["interfaces"] == 0)
    assert np.all(r["transmittance"] == 1.0) and np.all(r["path_length"] == 0.0)
    # empty input
    e = _trace_single(v, f, 1.5, np.zeros((0, 3)), np.zeros((0, 3)))
    assert e["status"].shape == (0,) and e["exit_dir"].shape == (0, 3)


def _bunny_rays(n=48):
    m = trimesh.load(BUNNY)
    v = np.asarray(m.vertices, float)
    v = v - (v.min(0) + v.max(0)) / 2
    v = v / (v.max(0) - v.min(0)).max()
    s = math.tan(math.radians(15.0))
    g = ((np.arange(n) + 0.5) / n * 2 - 1) * s
    x, y = np.meshgrid(g, -g)
    d = np.stack([x.ravel(), y.ravel(), -np.ones(n * n)], axis=1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.tile([0.0, 0.0, 2.6], (n * n, 1))
    return v, np.asarray(m.faces), o, d


def test_deterministic_and_chunk_independent():
    v, f, o, d = _bunny_rays()
    fo = np.zeros(len(f), dtype=int)
    args = (ExactMesh(v, f, fo, [1.5], [[0.5, 0.2, 0.1]]), o, d)
    a = trace_exact(*args)
    b = trace_exact(*args)
    c = trace_exact(*args, chunk_size=257)
    assert a["hit"].sum() > 100 and (a["interfaces"] >= 2).sum() > 100
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=a[key].dtype.kind == "f"), key
        assert np.array_equal(a[key], c[key], equal_nan=a[key].dtype.kind == "f"), key
    assert not np.any(a["status"] == 4)
    assert np.all(a["transmittance"] <= 1.0)


def test_vertex_normals_default_and_explicit():
    v, f = _ico(2)
    vn = area_weighted_vertex_normals(v, f)
    # brute force: normalised sum of the cross products of the incident faces
    ref = np.zeros_like(v)
    for a, b, c in f:
        ref[[a, b, c]] += np.cross(v[b] - v[a], v[c] - v[a])
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    np.testing.assert_allclose(vn, ref, atol=1e-12)
    assert _angle_deg(vn, v).max() < 2.0  # close to radial on an icosphere
    o, d = _parallel_grid([0, 0, 1], 0.4, 9)
    a = _trace_single(v, f, 1.5, o, d)
    b = _trace_single(v, f, 1.5, o, d, normals=vn)
    np.testing.assert_array_equal(a["exit_dir"], b["exit_dir"])
    # inward-pointing shading normals are flipped to the geometric side
    i = _trace_single(v, f, 1.5, o, d, normals=-vn)
    np.testing.assert_array_equal(i["first_normal"], a["first_normal"])
    np.testing.assert_allclose(i["exit_dir"], a["exit_dir"], atol=1e-15)
    # explicit normals are really used: exact radial normals differ from the
    # area-weighted ones and bring the result closer to the analytic sphere
    # (measured max error 1.72 deg -> 1.12 deg on this coarse icosphere)
    c = _trace_single(v, f, 1.5, o, d, normals=v / np.linalg.norm(v, axis=1, keepdims=True))
    s = sphere_refraction(o, d, [0, 0, 0], 0.5, 1.5)
    assert _angle_deg(c["exit_dir"], a["exit_dir"]).max() > 0.1
    assert _angle_deg(c["exit_dir"], s["exit_dir"]).max() < _angle_deg(a["exit_dir"], s["exit_dir"]).max()


def _good():
    v, f = _ico(1)
    return dict(vertices=v.copy(), faces=f.copy(), face_object=np.zeros(len(f), int),
                object_ior=[1.5], object_absorption=[[0.0, 0.0, 0.0]],
                origins=np.array([[0.0, 0.0, -2.0]]), dirs=np.array([[0.0, 0.0, 1.0]]))


def _trace_kw(origins, dirs, normals=None, smooth=True, outside_ior=1.0, max_bounces=64, **mesh):
    """``trace_exact`` of :func:`_good`'s keywords (the mesh's and the rays')."""
    return trace_exact(ExactMesh(**mesh, normals=normals, smooth=smooth, outside_ior=outside_ior), origins, dirs,
                       max_bounces=max_bounces)


def _with(**kw):
    g = _good()
    for k, val in kw.items():
        g[k] = val(g[k]) if callable(val) else val
    return g


def _nan_vertex(v):
    v[3, 1] = np.nan
    return v


@pytest.mark.parametrize("bad, match", [
    (_with(vertices=_nan_vertex), "non-finite"),
    (_with(vertices=lambda v: v[:, :2]), "vertices must have shape"),
    (_with(object_ior=[0.0]), "object_ior"),
    (_with(object_ior=[-1.5]), "object_ior"),
    (_with(object_absorption=[[0.1, -0.2, 0.0]]), "absorption"),
    (_with(object_absorption=[[0.1, 0.2]]), "object_absorption must have shape"),
    (_with(face_object=lambda fo: fo[:-1]), "face_object must have shape"),
    (_with(face_object=lambda fo: fo + 1), "face_object values"),
    (_with(faces=lambda f: f + 1000), "out of range"),
    (_with(dirs=np.array([[0.0, 0.0, 1.0], [0, 0, 1.0]])), "dirs must have the shape"),
    (_with(dirs=np.array([[0.0, 0.0, 2.0]])), "unit"),
    (_with(origins=np.array([[0.0, np.inf, -2.0]])), "finite"),
])
def test_input_validation(bad, match):
    with pytest.raises(ValueError, match=match):
        _trace_kw(**bad)


def test_input_validation_keywords():
    g = _good()
    with pytest.raises(ValueError, match="outside_ior"):
        _trace_kw(**g, outside_ior=0.0)
    with pytest.raises(ValueError, match="max_bounces"):
        _trace_kw(**g, max_bounces=-1)
    with pytest.raises(ValueError, match="normals must have shape"):
        _trace_kw(**g, normals=np.zeros((3, 3)))


def test_smooth_normals_never_break_the_geometry():
    """On a cube, averaged corner normals tilt up to 54.7 deg from the faces;
    events where the shading normal would send the ray to the wrong side of
    the triangle fall back to the face normal, so no ray ends up outside
    while believing it is inside (no leaks on a closed mesh)."""
    v, f = _cube()
    rng = np.random.default_rng(7)
    n = 4000
    src = rng.normal(size=(n, 3))
    src = 3.0 * src / np.linalg.norm(src, axis=1, keepdims=True)
    tgt = rng.uniform(-0.5, 0.5, (n, 3))
    d = tgt - src
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = _trace_single(v, f, 1.5, src, d, smooth=True)
    hit = r["hit"]
    assert hit.all()
    assert not r["leaked"].any()
    assert not np.any(r["status"] == 4)
    tri = v[f[r["first_face"]]]
    ng = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.sum(r["first_dir"] * ng, axis=1) < 0)  # went inside
    # the shading normals were really used (not the face normals everywhere)
    assert np.mean(np.sum(r["first_normal"] * ng / np.linalg.norm(ng, axis=1, keepdims=True), axis=1) < 0.999) > 0.5


@pytest.mark.parametrize("mode", ["crease", "file", "smooth", "face"])
def test_geometry_stage_normals_feed_trace_exact(mode):
    """The ``geometry`` stage's ``normals`` and ``smooth`` buffers are what trace_exact takes
    (the photon trace of the exact caustics passes them the same way)."""
    import refraction_ref as rr
    from refraction_ref.meshes import scene_geometry
    from refraction_ref.scene import load_scene

    scene = load_scene({"camera": {"width": 24, "height": 24},
                        "objects": [{"mesh": "fandisk", "fit": 1.0, "material": {"ior": 1.5}}],
                        "exact": {"normals": mode}})
    res = rr.render(scene, method="exact", keep="geometry")
    geom = scene_geometry(scene)
    nrm = res.arrays.get("stage.geometry.normals")
    if mode == "face":
        assert nrm is None
    elif mode == "smooth":
        np.testing.assert_array_equal(nrm, res.arrays["stage.geometry.vertex_normals"])
    else:
        assert nrm.shape == (len(geom.faces), 3, 3)
    o = res.arrays["ray_origin"].reshape(-1, 3)
    d = res.arrays["ray_dir"].reshape(-1, 3)
    tr = trace_exact(ExactMesh.of(geom, nrm, mode != "face"), o, d)
    np.testing.assert_array_equal(tr["exit_dir"], res.arrays["exit_dir"].reshape(-1, 3))
    note = next(p["why"] for p in res.meta["plan"] if p["stage"] == "trace")
    assert f"exact.normals={mode}" in note
