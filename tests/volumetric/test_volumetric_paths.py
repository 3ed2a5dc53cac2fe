"""Recorded photon paths: ``march_photons(record=K)`` and the ``photon_paths`` inspection stage.

Numerical truths: straight lines where the index is constant, steps that end
where the octree lets them, the exit point on the box face, convergence on
the Luneburg lens focus, and a march that records bit-identical to one that
does not.
"""

from __future__ import annotations

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref.volumetric.gradient import gradient_field
from refraction_ref.volumetric.knobs import march_knobs, octree_dilations
from refraction_ref.volumetric.march import STATUS, march_grid, march_photons, trace_paths
from refraction_ref.volumetric.octree import build_octree
from refraction_ref.volumetric.photons import generate_photons
from refraction_ref.volumetric.pipeline import PATH_SAMPLE, PATH_STEPS, path_sample

BOUNDS = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
OBLIQUE = [{"type": "directional", "direction": [0.3, -1.0, 0.2], "radiance": [1, 1, 1]}]


def luneburg(N, R=0.8):
    """The Luneburg lens of tests/volumetric/test_volumetric.py: n = sqrt(2 - r^2 / R^2) inside radius R, 1 outside."""
    h = 2.0 / N
    c = -1.0 + (np.arange(N) + 0.5) * h
    X, Y, Z = np.meshgrid(c, c, c, indexing="ij")
    r2 = (X ** 2 + Y ** 2 + Z ** 2) / R ** 2
    return np.where(r2 < 1, np.sqrt(np.maximum(2 - r2, 1.0)), 1.0)


def robust(**knobs):
    """The march's knobs with ``stepping = 'robust'`` (the stepping these tests were written for)."""
    return march_knobs({"stepping": "robust", **knobs})


def _setup(ior, eps=0.005, eps2=0.02, ds_max=8.0, kappa=(0.0, 0.0, 0.0)):
    """The march's grid of an index volume (extinction ``kappa`` per channel), its octree for 'robust' stepping."""
    field = gradient_field(ior, BOUNDS)
    level, step_max, _ = build_octree(ior, eps, eps2, ds_max, dilate=octree_dilations("robust")[0])
    ext = np.empty(ior.shape + (3,), np.float32)
    ext[...] = kappa
    return march_grid(field, ext, level, step_max, BOUNDS)


def _finite_rows(path):
    """Rows of a recorded path up to its first NaN (checking that NaN rows only follow)."""
    ok = np.all(np.isfinite(path), axis=1)
    n = int(np.count_nonzero(ok))
    assert ok[:n].all() and not ok[n:].any(), "NaN rows must only follow the recorded ones"
    return path[:n]


def _box_exit_distance(x, u):
    """Distance along unit u from x (inside BOUNDS) to the box face."""
    t = np.inf
    for a in range(3):
        if u[a] > 0:
            t = min(t, (BOUNDS[1, a] - x[a]) / u[a])
        elif u[a] < 0:
            t = min(t, (BOUNDS[0, a] - x[a]) / u[a])
    return t


def _on_face(p, tol=1e-12):
    return np.any(np.abs(np.abs(p) - 1.0) <= tol)


# ------------------------------------------------------------------ (a) constant index: straight lines
def test_constant_index_paths_are_straight_and_cross_the_box_in_one_step():
    N = 16
    ior = np.ones((N, N, N))
    grid = _setup(ior)
    assert np.all(np.isinf(grid.step_max)) and np.all(grid.level == 4)     # one constant node: the whole box
    pos, dirs, rad, _, _ = generate_photons(OBLIQUE, BOUNDS, ior.shape, 12)
    _, info = march_photons(grid, (pos, dirs, rad), robust(), record=5)
    P = len(pos)
    assert info["paths"].shape == (P, 6, 3) and info["paths"].dtype == np.float64
    # one step across the box; a photon that starts on an upper face (x, y or z = +1) sits in a
    # node indexed just past the box, at distance 0 from its boundary, and takes one ds_min step first
    upper = np.any(pos >= 1.0, axis=1)
    assert np.all(info["status"] == STATUS["exited"])
    assert np.all(info["steps"][~upper] == 1) and np.all(info["steps"][upper] <= 2) and (~upper).any()
    h = 2.0 / N
    for p in range(P):
        path = _finite_rows(info["paths"][p])
        assert len(path) == info["steps"][p] + 1
        assert np.array_equal(path[0], pos[p])                 # the start point, as given
        d = path[1:] - path[0]
        assert np.all(np.linalg.norm(np.cross(d, dirs[p]), axis=1) <= 1e-9 * np.linalg.norm(d, axis=1))
        if len(path) == 3:
            assert abs(np.linalg.norm(path[1] - path[0]) - 1.0 * h) <= 1e-12
        chord = _box_exit_distance(pos[p], dirs[p])
        assert abs(np.linalg.norm(path[-1] - path[0]) - chord) <= 1e-12 * max(chord, 1.0)
        assert np.allclose(path[-1], pos[p] + chord * dirs[p], rtol=0, atol=1e-12)
        assert _on_face(path[-1])


@pytest.mark.parametrize("lev", [1, 2])
def test_constant_index_steps_end_at_octree_node_boundaries(lev):
    """Index 1.3 everywhere, an octree of 2^lev-voxel constant nodes: straight steps from node to node.

    Each step is the distance along the start direction to the boundary of the node holding the
    point, plus the march's nudge of 1e-4 of a voxel (or ds_min if longer), clipped at the box.
    """
    N = 16
    ior = np.full((N, N, N), 1.3)
    field = gradient_field(ior, BOUNDS)
    ext = np.zeros((N, N, N, 3), np.float32)
    level = np.full((N, N, N), lev, np.int8)
    step_max = np.full((N, N, N), np.inf, np.float32)
    pos, dirs, rad, _, _ = generate_photons(OBLIQUE, BOUNDS, ior.shape, 10)
    ds_min = 0.01
    grid = march_grid(field, ext, level, step_max, BOUNDS)
    _, info = march_photons(grid, (pos, dirs, rad), robust(ds_min=ds_min), record=400)
    h = 2.0 / N
    node = h * 2 ** lev
    nudge, ds_w = 1e-4 * h, ds_min * h
    assert np.all(info["status"] == STATUS["exited"])
    assert np.all(info["steps"] < 400) and np.median(info["steps"]) >= 2 ** (4 - lev)
    for p in range(len(pos)):
        path = _finite_rows(info["paths"][p])
        assert len(path) == info["steps"][p] + 1
        u = dirs[p]
        # collinear with the start direction, to 1e-9 relative
        d = path[1:] - path[0]
        dist = np.linalg.norm(d, axis=1)
        assert np.all(np.linalg.norm(np.cross(d, u), axis=1) <= 1e-9 * dist)
        assert np.all(d @ u > 0) and np.all(np.diff(dist) > 0)  # forward, never back
        for s in range(len(path) - 1):
            x = path[s]
            t = np.inf                     # the boundary of x's node along u
            for a in range(3):
                k = (x[a] + 1.0) / node    # in node units from the box corner
                if u[a] > 0:
                    t = min(t, ((np.floor(k) + 1) - k) * node / u[a])
                elif u[a] < 0:
                    t = min(t, (np.floor(k) - k) * node / u[a])
            ds = max(t + nudge, ds_w)
            face = _box_exit_distance(x, u)
            step = np.linalg.norm(path[s + 1] - x)
            if s < len(path) - 2:
                assert ds < face and abs(step - ds) <= 1e-9 * h, (p, s, step, ds)
            else:                          # the last step is clipped at the box face
                assert ds >= face - 1e-12 and abs(step - face) <= 1e-9 * h
                assert _on_face(path[s + 1])


# ------------------------------------------------------------------ (b) the exit point
@pytest.mark.parametrize("integrator", ["euler", "rk4"])
def test_last_recorded_point_is_the_exit_point_on_the_face(integrator):
    ior = luneburg(32)
    grid = _setup(ior)
    pos, dirs, rad, _, _ = generate_photons(OBLIQUE, BOUNDS, ior.shape, 16)
    K = 300
    _, info = march_photons(grid, (pos, dirs, rad), robust(integrator=integrator), record=K)
    ex = info["status"] == STATUS["exited"]
    assert ex.mean() > 0.95
    steps = info["steps"]
    assert steps.max() <= K                          # every path is complete
    for p in np.flatnonzero(ex):
        path = _finite_rows(info["paths"][p])
        assert len(path) == steps[p] + 1
        last = path[-1]
        assert np.array_equal(last, info["exit_pos"][p])
        assert _on_face(last)
        assert np.all(np.abs(path) <= 1.0 + 1e-12)           # every point inside the box
        # the step before reached from inside: it did not exit, the last one did (within one step)
        assert not _on_face(path[-2]) or len(path) == 2
    # a photon with more steps than recorded: the path holds exactly its first K steps
    few = 3
    _, short = march_photons(grid, (pos, dirs, rad), robust(integrator=integrator), record=few)
    long_ = steps > few
    assert long_.any()
    assert np.array_equal(short["paths"][long_], info["paths"][long_, :few + 1])
    assert np.all(np.isfinite(short["paths"][long_]))


# ------------------------------------------------------------------ (c) Luneburg lens focus
@pytest.mark.parametrize("integrator,tol", [("euler", 0.6), ("rk4", 0.1)])
def test_luneburg_paths_converge_on_the_far_side_focus(integrator, tol):
    """Parallel photons entering a Luneburg lens (n = sqrt(2 - r^2 / R^2)) all pass through the
    antipodal point of their entry side: the recorded paths converge there (tests/volumetric/test_volumetric.py)."""
    N, R = 48, 0.8
    ior = luneburg(N, R)
    grid = _setup(ior)
    light = [{"type": "directional", "direction": [0, 0, -1], "radiance": [1, 1, 1]}]
    pos, dirs, rad, _, _ = generate_photons(light, BOUNDS, ior.shape, 24)
    _, info = march_photons(grid, (pos, dirs, rad), robust(ds_min=1.0, integrator=integrator), record=512)
    sel = (info["status"] == STATUS["exited"]) & (np.hypot(pos[:, 0], pos[:, 1]) < 0.7 * R)
    assert sel.sum() >= 50
    F = np.array([0.0, 0.0, -R])
    h = 2.0 / N
    miss, spread_in = [], []
    for p in np.flatnonzero(sel):
        path = _finite_rows(info["paths"][p])
        assert len(path) == info["steps"][p] + 1
        # distance from the focus to the polyline
        a, b = path[:-1], path[1:]
        ab = b - a
        t = np.clip(np.sum((F - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0, 1)
        miss.append(np.min(np.linalg.norm(a + t[:, None] * ab - F, axis=1)) / h)
        spread_in.append(np.hypot(*path[0, :2]) / h)
        # the first point past the lens (where it leaves it) is the focus, within two voxels
        r = np.linalg.norm(path, axis=1)
        inside = np.flatnonzero(r < R)
        assert len(inside), p
        assert np.linalg.norm(path[inside[-1] + 1] - F) < 2.0 * h, p
    miss = np.array(miss)
    assert np.median(miss) < tol and np.max(miss) < 1.0, (np.median(miss), np.max(miss))
    assert np.median(spread_in) > 5.0          # they entered spread over the aperture


# ------------------------------------------------------------------ (d) the inspection stage
def _volume_scene(ior, photons=16, **vol):
    return {"camera": {"width": 8, "height": 8}, "objects": [],
            "lights": [{"type": "directional", "direction": [0.1, -1.0, 0.2], "radiance": [1, 1, 1]}],
            "volume": {"ior": ior, "bounds": BOUNDS.tolist(), **vol},
            "volumetric": {"photons": photons}}


def test_photon_paths_stage_runs_only_when_kept():
    sc = _volume_scene(luneburg(24), photons=16, extinction=0.2)
    res = rr.render(sc, method="volumetric", keep="photons,photon_paths")
    plan = {p["stage"]: p for p in res.meta["plan"]}
    assert plan["photon_paths"]["ran"] and "marched alone" in plan["photon_paths"]["why"]
    assert [p["stage"] for p in res.meta["plan"]].index("photon_paths") == \
        [p["stage"] for p in res.meta["plan"]].index("march") + 1
    assert "photon_paths" in res.meta["timings_ms"]
    paths, idx = res["stage.photon_paths.paths"], res["stage.photon_paths.path_index"]
    start = res["stage.photons.start_pos"]
    P = len(start)
    assert P > PATH_SAMPLE
    S = len(idx)
    assert S == PATH_SAMPLE and paths.shape == (S, PATH_STEPS + 1, 3) and paths.dtype == np.float64
    assert idx.dtype == np.int64 and np.array_equal(idx, np.unique(np.linspace(0, P - 1, 64).round()))
    assert idx[0] == 0 and idx[-1] == P - 1
    assert np.array_equal(paths[:, 0], start[idx])
    # the same paths as the full march: where it exited within the recorded steps, at its exit point
    status, exit_pos = res["photon_status"][idx], res["photon_exit_pos"][idx]
    n = 0
    for s in range(S):
        path = _finite_rows(paths[s])
        if status[s] == STATUS["exited"] and len(path) <= PATH_STEPS:
            assert np.array_equal(path[-1], exit_pos[s]) and _on_face(path[-1])
            n += 1
    assert n > S // 2
    # and the stage changes nothing else
    plain = rr.render(sc, method="volumetric")
    plan = {p["stage"]: p for p in plain.meta["plan"]}
    assert not plan["photon_paths"]["ran"] and "inspection" in plan["photon_paths"]["why"]
    assert "photon_paths" not in plain.meta["timings_ms"]
    assert not any(k.startswith("stage.") for k in plain.arrays)
    for k in plain.arrays:
        assert np.array_equal(plain[k], res[k], equal_nan=True), k


def test_path_sample_takes_all_photons_of_a_small_set():
    assert np.array_equal(path_sample(5), np.arange(5))
    assert len(path_sample(0)) == 0
    big = path_sample(10000)
    assert len(big) == PATH_SAMPLE and big[0] == 0 and big[-1] == 9999 and np.all(np.diff(big) > 0)
    res = rr.render(_volume_scene(np.ones((8, 8, 8)), photons=4), method="volumetric", keep="photon_paths")
    P = len(res["photon_status"])
    assert P < PATH_SAMPLE
    assert np.array_equal(res["stage.photon_paths.path_index"], np.arange(P))
    assert res["stage.photon_paths.paths"].shape == (P, PATH_STEPS + 1, 3)


def test_photon_paths_rerun_with_the_march_knobs():
    s = rr.Session(_volume_scene(luneburg(16), photons=8))
    s.render("volumetric", keep="photon_paths")
    s.update({"volumetric.ds_min": 2.0})
    res = s.render("volumetric", keep="photon_paths")
    ran = {p["stage"] for p in res.meta["plan"] if p["ran"]}
    assert {"march", "photon_paths"} <= ran
    s.update({"camera.eye": [0.2, 0.3, 3.0]})
    res = s.render("volumetric", keep="photon_paths")
    assert [p["stage"] for p in res.meta["plan"] if p["ran"]] == ["view"]


# ------------------------------------------------------------------ (e) recording changes nothing
@pytest.mark.parametrize("integrator", ["euler", "rk4"])
def test_recording_leaves_the_march_bit_identical(integrator):
    ior = luneburg(32)
    grid = _setup(ior, kappa=(0.3, 0.2, 0.0))
    pos, dirs, rad, _, _ = generate_photons([{"type": "directional", "direction": [0.2, -1, 0.1],
                                              "radiance": [1, 0.5, 0.25]}], BOUNDS, ior.shape, 24)
    knobs = robust(integrator=integrator, stop_fraction=0.05, min_radiance=0.5)
    a, ia = march_photons(grid, (pos, dirs, rad), knobs)
    K = 40
    b, ib = march_photons(grid, (pos, dirs, rad), knobs, record=K)
    assert "paths" not in ia and ib["paths"].shape == (len(pos), K + 1, 3)
    assert np.array_equal(a, b)
    for k in ia:
        x, y = np.asarray(ia[k]), np.asarray(ib[k])
        assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), k
    assert ia["truncated"] > 0                                  # the stopping rule cut some photons
    assert np.any(ia["status"] == STATUS["absorbed"])
    # NaN after the photon stopped: after its steps, the stopping rule's cut included
    n = np.count_nonzero(np.isfinite(ib["paths"][..., 0]), axis=1)
    assert np.array_equal(n, np.minimum(ib["steps"], K) + 1)
    assert np.all(np.isfinite(ib["paths"][n > 0, 0]))


def test_recorded_paths_match_trace_paths_and_any_thread_count(on_one_and_two_threads):
    ior = luneburg(24)
    grid = _setup(ior)
    pos, dirs, rad, _, _ = generate_photons(OBLIQUE, BOUNDS, ior.shape, 8)
    K = 200
    knobs = robust(integrator="rk4", ds_min=2.0, stop_fraction=0.0)
    (_, i1), (_, i2) = on_one_and_two_threads(lambda: march_photons(grid, (pos, dirs, rad), knobs, record=K))
    assert np.array_equal(i1["paths"], i2["paths"], equal_nan=True)
    ref = trace_paths(grid, pos, dirs, knobs)
    for p in range(len(pos)):
        assert np.array_equal(_finite_rows(i1["paths"][p]), ref[p][:K + 1])


def test_negative_record_is_refused():
    grid = _setup(np.ones((8, 8, 8)))
    with pytest.raises(ValueError, match="record"):
        march_photons(grid, (np.zeros((1, 3)), np.array([[0, 0, 1.0]]), np.ones((1, 3))), record=-1)
