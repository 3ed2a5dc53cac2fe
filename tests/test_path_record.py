"""Tests of the per-event path record (``record=K``) of the image-space tracer
(:func:`refraction_ref.imagespace.trace.trace_layers`) and of the exact tracer
(:func:`refraction_ref.exact.trace_exact`): row ``k`` is the ``k``-th surface
event, its point and the direction Snell's law (or the mirror, under total
internal reflection) gives there.

The scene is the built-in ``sphere`` (icosphere, subdivision 5, radius 0.5)
seen by a 64x64 camera from ``z = 3``; the image-space layers are the exact
A-buffer depths (:func:`collect_depths`), so that the first layer point is the
true first hit up to the rasterizer's rounding. Measured numbers quoted in
comments come from this machine's run of the same code.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from refraction_ref.analytic import sphere_refraction
from refraction_ref.camera import Camera
from refraction_ref.exact import ExactMesh, trace_exact
from refraction_ref.imagespace.depth_bounds import depth_bounds
from refraction_ref.imagespace.knobs import IMAGESPACE_DEFAULTS, trace_knobs
from refraction_ref.imagespace.search_bounds import search_bounds
from refraction_ref.imagespace.trace import ImagespaceLayers, ImagespaceOptics, exit_thresholds, trace_layers
from refraction_ref.imagespace.voxelize import collect_depths
from refraction_ref.meshes import load_mesh
from refraction_ref.raster import raster_setup
from refraction_ref.status import EXITED, LIMIT, MISSED, TIR

W = 64
RADIUS = 0.5
K = 4
PATH_KEYS = ("path_pos", "path_dir")
EYE = (0.0, 0.0, 3.0)
# one pixel at the sphere's depth (about 2.5): 2 tan(15 deg) 2.5 / 64
PIXEL = 2.0 * math.tan(math.radians(15.0)) * 2.5 / W


@functools.lru_cache(maxsize=None)
def _setup():
    v, f = load_mesh("sphere")[:2]
    cam = Camera(EYE, (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30.0, W, W, 0.1, 10.0)
    rs = raster_setup(cam.world_to_view(v), cam, faces=f)
    zmin, zmax = depth_bounds(rs, cam)
    ldi, total = collect_depths(rs, cam, 8)
    bhi, blo = search_bounds(ldi, "global")
    thr = exit_thresholds(zmin, zmax, 256, 1.0)
    return v, f, cam, (ldi, total, zmax, thr, bhi, blo)


def _imagespace(ior=1.5, outside_ior=1.0, world=False, **knobs):
    """The image-space trace of :func:`_setup`'s layers with the trace's knobs by name, over the knobs'
    defaults but ``delta`` 1 and the layers' own count as the layer limit."""
    v, f, cam, layers = _setup()
    assert set(knobs) <= set(IMAGESPACE_DEFAULTS), set(knobs) - set(IMAGESPACE_DEFAULTS)
    record = knobs.pop("record", 0)
    block = {**IMAGESPACE_DEFAULTS, "delta": 1, "layers": layers[0].shape[0], **knobs}
    return trace_layers(ImagespaceLayers(*layers), cam, trace_knobs(block, record),
                        ImagespaceOptics(ior, outside_ior), world=world)


def _exact(ior=1.5, outside_ior=1.0, **kw):
    v, f, cam, _ = _setup()
    o, d = cam.primary_rays()
    mesh = ExactMesh(v, f, np.zeros(len(f), int), [ior], [[0.0, 0.0, 0.0]], outside_ior=outside_ior)
    r = trace_exact(mesh, o.reshape(-1, 3), d.reshape(-1, 3), **kw)
    return r, d.reshape(-1, 3)


def _rows(r):
    """Recorded events per ray (finite rows), after checking that they form a prefix."""
    fin = np.isfinite(r["path_pos"][..., 0])
    n = fin.sum(axis=-1)
    np.testing.assert_array_equal(fin, np.arange(fin.shape[-1]) < n[..., None])  # no gap, NaN after
    assert np.all(np.isnan(r["path_pos"][~fin])) and np.all(np.isnan(r["path_dir"][~fin]))
    return n


def _row(a, n):
    """``a[..., n, :]`` per ray."""
    return np.take_along_axis(a, np.asarray(n)[..., None, None], axis=-2)[..., 0, :]


# --------------------------------------------------------------------------
# image space
# --------------------------------------------------------------------------

@pytest.mark.parametrize("tir", [False, True])
@pytest.mark.parametrize("world", [False, True])
def test_imagespace_record_leaves_the_outputs_bit_identical(world, tir):
    r0 = _imagespace(world=world, tir=tir)
    assert not set(PATH_KEYS) & set(r0)
    for rec in (1, K):
        r = _imagespace(world=world, tir=tir, record=rec)
        assert set(r) == set(r0) | set(PATH_KEYS)
        for k in r0:
            np.testing.assert_array_equal(r[k], r0[k], err_msg=k)
            assert r[k].dtype == r0[k].dtype
        for k in PATH_KEYS:
            assert r[k].shape == (W, W, rec, 3) and r[k].dtype == np.float64


@pytest.mark.parametrize("world", [False, True])
def test_imagespace_last_event_is_the_exit(world):
    """Without ``tir`` every event of an exited ray is a refraction: as many rows
    as ``interfaces``, the last one ``exit_pos`` / ``exit_dir`` bit for bit."""
    r = _imagespace(world=world, record=K)
    st, nint = r["status"], r["interfaces"]
    n = _rows(r)
    assert np.all(n[st == MISSED] == 0) and np.all(n[st != MISSED] >= 1)
    ex = (st == EXITED) & (nint <= K)
    assert np.count_nonzero(ex) > 1000  # measured 1224 of 1280 pixels on the sphere
    np.testing.assert_array_equal(n[ex], nint[ex])
    np.testing.assert_array_equal(_row(r["path_pos"], n - 1)[ex], r["exit_pos"][ex])
    np.testing.assert_array_equal(_row(r["path_dir"], n - 1)[ex], r["exit_dir"][ex])
    fin = np.isfinite(r["path_dir"][..., 0])
    np.testing.assert_allclose(np.linalg.norm(r["path_dir"][fin], axis=-1), 1.0, atol=1e-12)
    # stopped by a reflection the tracer does not follow (silhouette normals): that
    # reflection is the last row, after the refractions it did make
    tr = (st == TIR) & (nint < K)
    assert np.count_nonzero(tr) > 0  # measured 56
    np.testing.assert_array_equal(n[tr], nint[tr] + 1)


def test_imagespace_first_event_is_the_first_layer_point():
    """Row 0 (view space) is the primary ray's point at the depth of layer 0 of its pixel,
    and the world-space record is the view-space one moved by the camera's frame."""
    v, f, cam, (ldi, total, *_rest) = _setup()
    r = _imagespace(record=K)
    hit = r["status"] != MISSED
    p0 = r["path_pos"][..., 0, :]
    np.testing.assert_allclose(-p0[hit][:, 2], ldi[0][hit].astype(np.float64), rtol=1e-14)
    dirs = cam.primary_rays_view()
    np.testing.assert_allclose(np.linalg.norm(np.cross(p0[hit], dirs[hit]), axis=-1), 0.0, atol=1e-12)
    rw = _imagespace(record=K, world=True)
    for k, conv in (("path_pos", cam.view_to_world), ("path_dir", cam.dir_view_to_world)):
        fin = np.isfinite(r[k])
        np.testing.assert_array_equal(np.isfinite(rw[k]), fin)
        np.testing.assert_allclose(rw[k][fin], conv(r[k])[fin], atol=1e-12, rtol=0)


def test_imagespace_tir_row_is_the_mirror_direction():
    """An air bubble in glass (ior 1 inside 1.5) without ``tir``: grazing primary rays
    are totally reflected at the first event and stop there (status TIR, no
    interface crossed); the one row holds the mirror direction, ``last_dir`` the
    incident ray. ``d' - d`` is then along the normal the tracer estimated from the
    depths, close to the sphere's own normal at the point."""
    v, f, cam, _ = _setup()
    r = _imagespace(ior=1.0, outside_ior=1.5, record=K)
    tr = r["status"] == TIR
    assert np.count_nonzero(tr) > 500  # measured 740
    n = _rows(r)
    assert np.all(n[tr] == 1) and np.all(r["interfaces"][tr] == 0)
    d = cam.primary_rays_view()[tr]
    np.testing.assert_array_equal(r["last_dir"][tr], d)
    refl = r["path_dir"][tr, 0]
    np.testing.assert_allclose(np.linalg.norm(refl, axis=-1), 1.0, atol=1e-12)
    nrm = refl - d
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    c = r["path_pos"][tr, 0] - cam.world_to_view(np.zeros((1, 3)))[0]  # from the centre, view space
    c /= np.linalg.norm(c, axis=-1, keepdims=True)
    cos = np.sum(nrm * c, axis=-1)
    assert np.all(cos > 0.0)  # mirrored back out: d' - d along the outward normal
    ang = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    # central differences of the depths near the silhouette: measured median 2.2 deg, max 14 deg
    assert np.median(ang) < 4.0, np.median(ang)


def test_imagespace_record_is_deterministic_across_threads(on_one_and_two_threads):
    a, b = on_one_and_two_threads(lambda: _imagespace(record=K, tir=True, world=True))
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_record_must_be_a_count():
    with pytest.raises(ValueError, match="record"):
        _imagespace(record=-1)
    with pytest.raises(ValueError, match="record"):
        _exact(record=-1)


# --------------------------------------------------------------------------
# exact tracer
# --------------------------------------------------------------------------

def test_exact_record_leaves_the_outputs_bit_identical():
    r0, _ = _exact()
    r, _ = _exact(record=K)
    assert set(r) == set(r0) | set(PATH_KEYS)
    for k in r0:
        np.testing.assert_array_equal(r[k], r0[k], err_msg=k)
    for k in PATH_KEYS:
        assert r[k].shape == (W * W, K, 3) and r[k].dtype == np.float64


def test_exact_sphere_path_is_entry_then_exit():
    """Through a sphere every hit ray has two events: row 0 is the entry on the sphere
    and obeys Snell's law against the sphere's normal, row 1 the exit, rows 2, 3 NaN."""
    r, d = _exact(record=K)
    n = _rows(r)
    hit = r["hit"]
    assert np.all(r["status"][hit] == EXITED) and np.count_nonzero(hit) > 1000  # 1280 pixels
    np.testing.assert_array_equal(n, r["bounces"])
    assert np.all(n[hit] == 2) and np.all(n[~hit] == 0)
    pp, pd = r["path_pos"][hit], r["path_dir"][hit]
    np.testing.assert_array_equal(pp[:, 0], r["hit_pos"][hit])
    np.testing.assert_array_equal(pd[:, 0], r["first_dir"][hit])
    np.testing.assert_array_equal(pp[:, 1], r["exit_pos"][hit])
    np.testing.assert_array_equal(pd[:, 1], r["exit_dir"][hit])
    # on the tessellated sphere: vertices on it, faces at most the sagitta inside
    # (measured radii 0.49986 .. 0.49998)
    rad = np.linalg.norm(pp[:, :2], axis=-1)
    assert np.all(rad <= RADIUS + 1e-12) and np.all(rad > RADIUS - 5e-4)
    # Snell at the entry with the analytic normal: sin(theta_i) = 1.5 sin(theta_t);
    # the interpolated vertex normals differ from it by a little (measured max
    # |error| 2.4e-3, median 8e-5)
    nrm = pp[:, 0] / rad[:, :1]
    si = np.linalg.norm(np.cross(d[hit], nrm), axis=-1)
    stt = np.linalg.norm(np.cross(pd[:, 0], nrm), axis=-1)
    err = np.abs(si - 1.5 * stt)
    assert err.max() < 5e-3 and np.median(err) < 5e-4, (err.max(), np.median(err))
    # both directions in the plane of incidence, on the far side of the normal
    assert np.max(np.abs(np.sum(np.cross(d[hit], nrm) * pd[:, 0], axis=-1))) < 5e-3
    assert np.all(np.sum(pd[:, 0] * nrm, axis=-1) < 0.0)
    # and the analytic sphere: entry, exit and the chord between them
    a = sphere_refraction(_setup()[2].primary_rays()[0].reshape(-1, 3), d, [0.0, 0.0, 0.0], RADIUS, 1.5)
    np.testing.assert_array_equal(a["hit"], hit)
    assert np.max(np.linalg.norm(pp[:, 0] - a["entry_pos"][hit], axis=-1)) < 3e-3  # measured 1.1e-3
    assert np.max(np.linalg.norm(pp[:, 1] - a["exit_pos"][hit], axis=-1)) < 3e-3  # measured 2.0e-3
    chord = a["exit_pos"][hit] - a["entry_pos"][hit]
    chord /= np.linalg.norm(chord, axis=-1, keepdims=True)
    ang = np.degrees(np.arccos(np.clip(np.sum(chord * pd[:, 0], axis=-1), -1.0, 1.0)))
    assert ang.max() < 0.25, ang.max()  # measured 0.126 deg


def test_exact_tir_and_bounce_limit_rows():
    """An air bubble in glass: a grazing ray is mirrored at its first event and leaves
    (one row: the exit, the mirror direction about the normal used); the others
    cross twice. With ``max_bounces=1`` only the first event is recorded."""
    r, d = _exact(ior=1.0, outside_ior=1.5, record=K)
    n = _rows(r)
    np.testing.assert_array_equal(n, r["bounces"])
    refl = r["hit"] & (r["interfaces"] == 0)
    assert np.count_nonzero(refl) > 500 and np.all(r["status"][refl] == EXITED)  # measured 724
    assert np.all(n[refl] == 1)
    pd0 = r["path_dir"][refl, 0]
    nrm = r["first_normal"][refl]
    mirror = d[refl] - 2.0 * np.sum(d[refl] * nrm, axis=-1, keepdims=True) * nrm
    np.testing.assert_allclose(pd0, mirror, atol=1e-12)
    np.testing.assert_array_equal(r["path_pos"][refl, 0], r["exit_pos"][refl])
    np.testing.assert_array_equal(pd0, r["exit_dir"][refl])
    two = r["hit"] & ~refl
    assert np.all(n[two] == 2) and np.all(r["interfaces"][two] == 2)
    np.testing.assert_array_equal(r["path_pos"][two, 1], r["exit_pos"][two])

    r1, _ = _exact(ior=1.0, outside_ior=1.5, record=K, max_bounces=1)
    n1 = _rows(r1)
    assert np.all(r1["status"][two] == LIMIT) and np.all(n1[r["hit"]] == 1)
    np.testing.assert_array_equal(r1["path_pos"][:, 0], r["path_pos"][:, 0])
    np.testing.assert_array_equal(r1["path_dir"][:, 0], r["path_dir"][:, 0])


# --------------------------------------------------------------------------
# image space against the exact path
# --------------------------------------------------------------------------

def test_imagespace_path_follows_the_exact_path():
    """Event by event in world space: the first point is the same hit (A-buffer depth vs
    ray/triangle, measured max 0.018 pixel), the direction after it differs by the
    depth-estimated normal (median 0.44 deg); the second event, the exit, lies within a
    few pixels (median 0.67 pixel, 92.5 % within 3)."""
    im = _imagespace(world=True, record=K)
    ex, _ = _exact(record=K)
    pi, di = im["path_pos"].reshape(-1, K, 3), im["path_dir"].reshape(-1, K, 3)
    pe, de = ex["path_pos"], ex["path_dir"]
    both = (im["status"].ravel() != MISSED) & ex["hit"]
    np.testing.assert_array_equal(im["status"].ravel() != MISSED, ex["hit"])
    e0 = np.linalg.norm(pi[both, 0] - pe[both, 0], axis=-1) / PIXEL
    assert e0.max() < 0.1 and np.median(e0) < 0.01, (e0.max(), np.median(e0))
    a0 = np.degrees(np.arccos(np.clip(np.sum(di[both, 0] * de[both, 0], axis=-1), -1.0, 1.0)))
    assert np.median(a0) < 1.5, np.median(a0)
    e1 = np.linalg.norm(pi[both, 1] - pe[both, 1], axis=-1) / PIXEL
    e1 = e1[np.isfinite(e1)]
    assert len(e1) > 0.95 * np.count_nonzero(both)
    assert np.median(e1) < 1.5 and np.mean(e1 < 3.0) > 0.85, (np.median(e1), np.mean(e1 < 3.0))
