"""The exact reference against closed forms on flat-faced meshes: a glass slab, a cube, a prism.

A flat-faced mesh describes flat facets meeting at sharp edges. Interpolated
vertex normals (``exact.normals = "smooth"``) round those edges and turn a
cube into a lens; the default crease normals keep every facet flat, so:

- a slab (and a cube, for rays through two opposite faces) shifts a ray
  sideways by ``d = t sin(theta - theta') / cos(theta')`` without turning it;
- a prism of apex angle A deviates a ray in its principal section by
  ``delta = theta1 + theta2' - A`` (Snell at both faces), with the minimum
  ``n = sin((A + delta_m) / 2) / sin(A / 2)`` at symmetric incidence.

Tolerances: 1e-9 rad for directions, 1e-9 (relative to the scene's size) for
positions; the tracer is float64 Möller-Trumbore, so its errors are ~1e-15.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
import trimesh

import refraction_ref as rr
from refraction_ref.exact import STATUS_EXITED, ExactMesh, trace_exact
from refraction_ref.exact.knobs import EXACT_DEFAULTS
from refraction_ref.meshes import (corner_normals, crease_edge_angles, file_vertex_normals, load_mesh, rotation_matrix,
                                   vertex_normals)
from refraction_ref.scene import SceneError, load_scene

IOR = 1.5
DIR_TOL = 1e-9    # rad
POS_TOL = 1e-9    # relative to the object's size (about 1 here)
CAMERA = {"eye": [0.0, 0.0, 2.6], "target": [0.0, 0.0, 0.0], "width": 40, "height": 40}


def _box(extents):
    m = trimesh.creation.box(extents=extents)
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


def _box_planes(extents, rotate):
    """Outward unit normals (6, 3) and offsets (6,) of a centred box after ``rotate`` (inside: n.x <= c)."""
    R = rotation_matrix(rotate)
    n = np.vstack([np.eye(3), -np.eye(3)]) @ R.T
    c = np.tile(np.asarray(extents, float) / 2.0, 2)
    return n, c


def _angle(a, b):
    """Angle in radians between unit vectors (rows), accurate for tiny angles."""
    return 2.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))


def _snell(d, n, eta):
    """Refract unit ``d`` at a surface of unit normal ``n`` (n.d < 0), ``eta = n1 / n2``; None under TIR."""
    ci = -float(n @ d)
    k = 1.0 - eta * eta * (1.0 - ci * ci)
    if k < 0:
        return None
    return eta * d + (eta * ci - math.sqrt(k)) * n


def _convex_path(normals, offsets, o, d, ior, margin=1e-4):
    """The closed-form path of a ray through a convex polyhedron with flat faces.

    Returns (entry face, exit face, entry point, exit point, exit direction),
    or None for a ray that misses, passes within ``margin`` of an edge (where
    two faces meet, the mesh's triangulation decides) or is totally
    reflected inside.
    """
    nd = normals @ d
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (offsets - normals @ o) / nd
    front = nd < 0
    if not front.any():
        return None
    i_in = int(np.flatnonzero(front)[np.argmax(t[front])])
    t_in = t[i_in]
    t_out = np.min(np.where(nd > 0, t, np.inf))
    if not (0 < t_in < t_out):
        return None
    p = o + t_in * d
    if np.any(np.delete(normals @ p - offsets, i_in) > -margin):
        return None
    d1 = _snell(d, normals[i_in], 1.0 / ior)
    nd1 = normals @ d1
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = np.where(nd1 > 0, (offsets - normals @ p) / nd1, np.inf)
    t1[i_in] = np.inf
    i_out = int(np.argmin(t1))
    q = p + t1[i_out] * d1
    if np.any(np.delete(normals @ q - offsets, i_out) > -margin):
        return None
    d2 = _snell(d1, -normals[i_out], ior)
    if d2 is None:
        return None
    return i_in, i_out, p, q, d2


def _render(mesh, rotate=(0.0, 0.0, 0.0), **exact):
    scene = {"camera": CAMERA, "objects": [{"mesh": mesh, "material": {"ior": IOR},
                                            "transform": {"rotate": list(rotate)}}], "exact": exact}
    return rr.render(scene, method="exact")


def _opposite_face_rays(res, extents, rotate):
    """Pixels whose closed-form path enters and leaves through two parallel faces, with that path."""
    n, c = _box_planes(extents, rotate)
    o = res.arrays["ray_origin"].reshape(-1, 3)
    d = res.arrays["ray_dir"].reshape(-1, 3)
    rows = []
    for k in range(len(o)):
        path = _convex_path(n, c, o[k], d[k], IOR)
        if path is not None and abs(path[0] - path[1]) == 3:  # faces i and i + 3 are parallel
            rows.append((k, path))
    return rows


# --------------------------------------------------------------------------- slab
@pytest.mark.parametrize("rotate", [(0.0, 0.0, 0.0), (25.0, 35.0, 0.0)], ids=["head-on", "oblique"])
def test_slab_shifts_rays_without_turning_them(rotate):
    ext = (2.0, 2.0, 0.3)
    res = _render(_box(ext), rotate)
    rows = _opposite_face_rays(res, ext, rotate)
    assert len(rows) > 0.5 * CAMERA["width"] * CAMERA["height"]
    ex_pos = res.arrays["exit_pos"].reshape(-1, 3)
    ex_dir = res.arrays["exit_dir"].reshape(-1, 3)
    o = res.arrays["ray_origin"].reshape(-1, 3)
    d = res.arrays["ray_dir"].reshape(-1, 3)
    st = res.arrays["status"].ravel()
    nf = res.arrays["interfaces"].ravel()
    n_big = rotation_matrix(rotate) @ np.array([0.0, 0.0, 1.0])
    t = ext[2]
    theta_max = 0.0
    for k, (_, _, _, q, d2) in rows:
        assert st[k] == STATUS_EXITED and nf[k] == 2
        # parallel to the primary ray: not turned
        assert _angle(ex_dir[k], d[k]) < DIR_TOL
        assert _angle(ex_dir[k], d2) < DIR_TOL
        np.testing.assert_allclose(ex_pos[k], q, rtol=0, atol=POS_TOL)
        # shifted sideways by d = t sin(theta - theta') / cos(theta')
        th = math.acos(abs(float(d[k] @ n_big)))
        th_t = math.asin(math.sin(th) / IOR)
        shift = np.linalg.norm(np.cross(ex_pos[k] - o[k], d[k]))
        assert abs(shift - t * math.sin(th - th_t) / math.cos(th_t)) < POS_TOL * t
        theta_max = max(theta_max, th)
    assert theta_max > math.radians(10 if rotate == (0.0, 0.0, 0.0) else 40)


# --------------------------------------------------------------------------- cube
@pytest.mark.parametrize("rotate", [(0.0, 0.0, 0.0), (20.0, 30.0, 0.0)], ids=["head-on", "oblique"])
def test_cube_is_no_lens_with_the_default_normals(rotate):
    ext = (1.0, 1.0, 1.0)
    mesh = _box(ext)
    res = _render(mesh, rotate)
    rows = _opposite_face_rays(res, ext, rotate)
    assert len(rows) > 0.1 * CAMERA["width"] * CAMERA["height"]
    ks = np.array([k for k, _ in rows])
    d = res.arrays["ray_dir"].reshape(-1, 3)
    o = res.arrays["ray_origin"].reshape(-1, 3)
    ex_dir = res.arrays["exit_dir"].reshape(-1, 3)
    ex_pos = res.arrays["exit_pos"].reshape(-1, 3)
    n_in = _box_planes(ext, rotate)[0]
    for k, (i_in, _, _, q, _) in rows:
        assert _angle(ex_dir[k], d[k]) < DIR_TOL
        np.testing.assert_allclose(ex_pos[k], q, rtol=0, atol=POS_TOL)
        th = math.acos(-float(d[k] @ n_in[i_in]))
        th_t = math.asin(math.sin(th) / IOR)
        shift = np.linalg.norm(np.cross(ex_pos[k] - o[k], d[k]))
        assert abs(shift - ext[0] * math.sin(th - th_t) / math.cos(th_t)) < POS_TOL
    # smooth normals (exact.normals=smooth) turn the same rays: the cube acts as a lens
    sm = _render(mesh, rotate, normals="smooth")
    turn = _angle(sm.arrays["exit_dir"].reshape(-1, 3)[ks], d[ks])
    # measured (40x40 pixels): median 28.3 deg head-on, 20.5 deg oblique; smallest 1.6 / 1.2 deg
    assert np.degrees(np.median(turn)) > 10.0
    assert np.degrees(np.min(turn)) > 0.5
    # face normals agree with the default; 'file' falls back to crease for arrays (bit for bit)
    fc = _render(mesh, rotate, normals="face")
    assert np.max(_angle(fc.arrays["exit_dir"].reshape(-1, 3)[ks], ex_dir[ks])) < DIR_TOL
    fl = _render(mesh, rotate, normals="file")
    for key in ("exit_dir", "exit_pos", "status", "interfaces"):
        np.testing.assert_array_equal(fl.arrays[key], res.arrays[key])


# --------------------------------------------------------------------------- prism
A_DEG = 60.0


def _prism(apex_deg=A_DEG, base=1.0, length=6.0):
    """A right prism along z: cross-section a triangle with its apex angle at the top, apex on +y."""
    a = math.radians(apex_deg)
    h = base / 2.0 / math.tan(a / 2.0)
    tri = np.array([[-base / 2, -h / 2], [base / 2, -h / 2], [0.0, h / 2]])  # counter-clockwise seen from +z
    z = length / 2.0
    v = np.array([[x, y, -z] for x, y in tri] + [[x, y, z] for x, y in tri])
    f = [[3, 4, 5], [0, 2, 1]]  # caps
    for i in range(3):
        j = (i + 1) % 3
        f += [[i, j, j + 3], [i, j + 3, i + 3]]
    return v, np.array(f, np.int64)


def _through_prism(theta1_deg, normals_mode="default"):
    """Trace one ray in the principal section (z = 0) hitting the left face at ``theta1``."""
    v, f = _prism()
    A = math.radians(A_DEG)
    n_left = np.array([-math.cos(A / 2), math.sin(A / 2), 0.0])  # outward normal of the left face
    th = math.radians(theta1_deg)
    t_left = np.array([math.sin(A / 2), math.cos(A / 2), 0.0])  # along the left face, up to the apex
    # coming from the base's side of the normal at angle theta1 (the textbook set-up)
    d = -math.cos(th) * n_left + math.sin(th) * t_left
    hit = np.array([0.0, v[:, 1].max(), 0.0]) - 0.45 * t_left  # on the left face (length 1), below the apex
    o = hit - 2.0 * d
    if normals_mode == "default":
        normals, smooth = corner_normals(v, f, EXACT_DEFAULTS["crease_deg"]), True
    else:
        normals, smooth = None, normals_mode != "face"
    mesh = ExactMesh(v, f, np.zeros(len(f), int), [IOR], [[0.0, 0.0, 0.0]], normals, smooth)
    r = trace_exact(mesh, o[None], d[None], record=2)
    return d, r


def _prism_deviation(theta1):
    """delta = theta1 + theta2' - A, with Snell at both faces (radians in, radians out)."""
    A = math.radians(A_DEG)
    t1 = math.asin(math.sin(theta1) / IOR)
    t2 = A - t1
    return theta1 + math.asin(IOR * math.sin(t2)) - A


def test_prism_geometry_is_outward_and_sharp():
    v, f = _prism()
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    ang = crease_edge_angles(v, f)
    assert np.all((np.abs(ang - 120.0) < 1e-9) | (np.abs(ang - 90.0) < 1e-9) | (ang < 1e-6))


@pytest.mark.parametrize("theta1_deg", [35.0, 40.0, 48.6, 55.0, 65.0, 75.0])
def test_prism_deviates_by_the_prism_formula(theta1_deg):
    d, r = _through_prism(theta1_deg)
    assert r["status"][0] == STATUS_EXITED and r["interfaces"][0] == 2 and r["bounces"][0] == 2
    out = r["exit_dir"][0]
    delta = _prism_deviation(math.radians(theta1_deg))
    # the deviation, and its sense: towards the base (-y), in the principal section
    assert abs(_angle(out, d) - delta) < DIR_TOL
    expect = np.array([[math.cos(-delta), -math.sin(-delta), 0], [math.sin(-delta), math.cos(-delta), 0],
                       [0, 0, 1]]) @ d
    assert _angle(out, expect) < DIR_TOL
    assert abs(out[2]) < 1e-15
    # the default normals and the face normals give the same path
    _, rf = _through_prism(theta1_deg, "face")
    assert _angle(rf["exit_dir"][0], out) < DIR_TOL
    np.testing.assert_allclose(rf["exit_pos"][0], r["exit_pos"][0], rtol=0, atol=POS_TOL)


def test_prism_minimum_deviation():
    A = math.radians(A_DEG)
    th_m = math.asin(IOR * math.sin(A / 2))  # symmetric incidence: inside, the ray runs parallel to the base
    d, r = _through_prism(math.degrees(th_m))
    inside = r["path_dir"][0, 0]
    assert abs(inside[1]) < DIR_TOL  # parallel to the base
    delta_m = float(_angle(r["exit_dir"][0], d))
    assert abs(math.sin((A + delta_m) / 2) / math.sin(A / 2) - IOR) < 1e-9 * IOR
    assert abs(delta_m - _prism_deviation(th_m)) < DIR_TOL
    for step in (-5.0, -1.0, 1.0, 5.0):  # it is the minimum
        d_s, rs = _through_prism(math.degrees(th_m) + step)
        assert float(_angle(rs["exit_dir"][0], d_s)) > delta_m + 1e-6


def test_prism_smooth_normals_are_wrong():
    """Smooth vertex normals on the prism miss the prism formula by degrees (measured: 45.9 deg for 37.2)."""
    d, r = _through_prism(48.6, "smooth")
    delta = _prism_deviation(math.radians(48.6))
    assert r["status"][0] != STATUS_EXITED or abs(_angle(r["exit_dir"][0], d) - delta) > math.radians(1.0)


# --------------------------------------------------------------------------- the normals themselves
def test_corner_normals_rules():
    v, f = _box((1.0, 1.0, 1.0))
    un = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    un /= np.linalg.norm(un, axis=1, keepdims=True)
    for deg in (1.0, 40.0, 89.0, 90.0):  # every cube edge is 90 deg: all corners carry their face's normal
        cn = corner_normals(v, f, deg)
        assert np.max(np.abs(cn - un[:, None, :])) < 1e-15
    # an edge at exactly the crease angle is sharp whatever the rounding: a turned cube at 90 deg
    vt = v @ rotation_matrix((20.0, 30.0, 10.0)).T
    ut = un @ rotation_matrix((20.0, 30.0, 10.0)).T
    assert np.max(np.abs(corner_normals(vt, f, 90.0) - ut[:, None, :])) < 1e-14
    assert np.max(np.abs(corner_normals(vt, f, 90.001) - ut[:, None, :])) > 0.1
    # 180 deg: every face around the vertex, i.e. the area-weighted vertex normals
    np.testing.assert_allclose(corner_normals(v, f, 180.0), vertex_normals(v, f)[f], rtol=0, atol=1e-15)
    # a smooth mesh (icosphere: edges of a few degrees) keeps its smooth normals
    sv, sf = load_mesh("sphere")
    assert crease_edge_angles(sv, sf).max() < 10.0
    np.testing.assert_allclose(corner_normals(sv, sf, EXACT_DEFAULTS["crease_deg"]), vertex_normals(sv, sf)[sf],
                               rtol=0, atol=1e-14)
    with pytest.raises(ValueError, match="crease_deg"):
        corner_normals(v, f, 0.0)
    with pytest.raises(ValueError, match="crease_deg"):
        corner_normals(v, f, 180.5)


def test_crease_knob_validation_and_plan_note():
    for bad in ({"crease_deg": 0}, {"crease_deg": 181}, {"crease_deg": "40"}, {"normals": "auto"}):
        with pytest.raises(SceneError, match="exact"):
            load_scene({"exact": bad})
    sc = load_scene({"exact": {"crease_deg": 180}})
    assert sc.data["exact"]["normals"] == "crease" and sc.data["exact"]["crease_deg"] == 180
    res = _render(_box((1.0, 1.0, 1.0)))
    note = next(p["why"] for p in res.meta["plan"] if p["stage"] == "trace")
    assert "crease normals" in note
    assert f"12 of the scene's 18 edges at {EXACT_DEFAULTS['crease_deg']:g} deg or sharper" in note


def test_file_normals_are_used_and_turned_with_the_object(tmp_path):
    """A PLY whose vertex normals are radial (a cube shaded like a sphere): 'file' uses them, rotated."""
    v, f = _box((1.0, 1.0, 1.0))
    radial = v / np.linalg.norm(v, axis=1, keepdims=True)
    m = trimesh.Trimesh(v, f, vertex_normals=radial, process=False)
    path = os.path.join(tmp_path, "cube_radial.ply")
    m.export(path, vertex_normal=True)
    got = file_vertex_normals(path)
    assert got is not None and got.shape == v.shape
    np.testing.assert_allclose(got, radial, atol=1e-7)  # float32 in the file
    plain = os.path.join(tmp_path, "cube_plain.ply")
    m.export(plain, vertex_normal=False)
    assert file_vertex_normals(plain) is None
    rot = (0.0, 30.0, 0.0)
    res = _render(path, rot, normals="file")
    note = next(p["why"] for p in res.meta["plan"] if p["stage"] == "trace")
    assert "file normals" in note and "objects[0]" in note
    # the same as tracing with the radial normals of the rotated cube
    R = rotation_matrix(rot)
    vw = v @ R.T
    o = res.arrays["ray_origin"].reshape(-1, 3)
    d = res.arrays["ray_dir"].reshape(-1, 3)
    ref = trace_exact(ExactMesh(vw, f, np.zeros(len(f), int), [IOR], [[0.0, 0.0, 0.0]],
                                vw / np.linalg.norm(vw, axis=1, keepdims=True), True), o, d)
    ex = ref["status"] == STATUS_EXITED
    assert ex.sum() > 100
    np.testing.assert_array_equal(res.arrays["status"].ravel(), ref["status"])
    assert np.max(_angle(res.arrays["exit_dir"].reshape(-1, 3)[ex], ref["exit_dir"][ex])) < 1e-5
    # the default (crease) ignores the file's normals: no lens
    cr = _render(path, rot)
    rows = _opposite_face_rays(cr, (1.0, 1.0, 1.0), rot)
    ks = np.array([k for k, _ in rows])
    assert np.max(_angle(cr.arrays["exit_dir"].reshape(-1, 3)[ks], d[ks])) < DIR_TOL
    # a file without normals falls back to crease under 'file', and the note says why
    pl = _render(plain, rot, normals="file")
    note = next(p["why"] for p in pl.meta["plan"] if p["stage"] == "trace")
    assert "stores no vertex normals" in note
    np.testing.assert_array_equal(pl.arrays["exit_dir"], _render(plain, rot).arrays["exit_dir"])


def test_trace_exact_accepts_per_corner_normals():
    v, f = _box((1.0, 1.0, 1.0))
    rng = np.random.default_rng(3)
    src = rng.normal(size=(500, 3))
    src = 3.0 * src / np.linalg.norm(src, axis=1, keepdims=True)
    d = rng.uniform(-0.4, 0.4, (500, 3)) - src
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    mesh = ExactMesh(v, f, np.zeros(len(f), int), [IOR], [[0.0, 0.0, 0.0]])
    vn = vertex_normals(v, f)
    a = trace_exact(mesh._replace(normals=vn), src, d)
    b = trace_exact(mesh._replace(normals=vn[f]), src, d)  # per corner, the same values: bit for bit
    for key in ("exit_dir", "exit_pos", "status", "path_length"):
        np.testing.assert_array_equal(a[key], b[key])
    with pytest.raises(ValueError, match="normals must have shape"):
        trace_exact(mesh._replace(normals=np.zeros((len(f), 3))), src, d)
