"""Tests of the volumetric relighting pipeline (Sun et al. 2008) against analytic optics.

Small volumes (32^3..48^3) and few photons keep the file fast; the targets
at 128^3 are in ``benchmarks/bench_volumetric.py``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref.volumetric.gradient import gradient_field
from refraction_ref.volumetric.knobs import march_knobs, octree_dilations
from refraction_ref.volumetric.march import STATUS, march_grid, march_photons, trace_paths
from refraction_ref.volumetric.octree import build_octree
from refraction_ref.volumetric.photons import generate_photons

BOUNDS = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def _centres(N, b=BOUNDS):
    h = (b[1] - b[0]) / N
    axes = [b[0, a] + (np.arange(N) + 0.5) * h[a] for a in range(3)]
    return np.meshgrid(*axes, indexing="ij")


def luneburg(N, R=0.8):
    X, Y, Z = _centres(N)
    r2 = (X ** 2 + Y ** 2 + Z ** 2) / R ** 2
    return np.where(r2 < 1, np.sqrt(np.maximum(2 - r2, 1.0)), 1.0)


def robust(**knobs):
    """The march's knobs with ``stepping = 'robust'`` (the stepping these analytic tests were written for)."""
    return march_knobs({"stepping": "robust", **knobs})


def _setup(ior, eps=0.005, eps2=0.02, ds_max=8.0, kappa=0.0, stepping="robust"):
    """The march's grid of an index volume (uniform extinction ``kappa``), its octree built for ``stepping``."""
    field = gradient_field(ior, BOUNDS)
    level, step_max, st = build_octree(ior, eps, eps2, ds_max, dilate=octree_dilations(stepping)[0])
    ext = np.full(ior.shape + (3,), kappa, np.float32)
    return march_grid(field, ext, level, step_max, BOUNDS), st


def _luneburg_miss(N, integrator, ds_min, M=24, R=0.8):
    ior = luneburg(N, R)
    grid, _ = _setup(ior)
    pos, dirs, rad, _, _ = generate_photons([{"type": "directional", "direction": [0, 0, -1],
                                              "radiance": [1, 1, 1]}], BOUNDS, ior.shape, M)
    sums, info = march_photons(grid, (pos, dirs, rad), robust(ds_min=ds_min, integrator=integrator))
    sel = (info["status"] == STATUS["exited"]) & (np.hypot(pos[:, 0], pos[:, 1]) < 0.7 * R)
    F = np.array([0.0, 0.0, -R])  # antipodal point of the photons' entry side
    p, d = info["exit_pos"][sel], info["exit_dir"][sel]
    w = F - p
    miss = np.linalg.norm(w - np.sum(w * d, axis=1)[:, None] * d, axis=1) / (2.0 / N)
    return np.median(miss), info


# ------------------------------------------------------------------ analytic optics
def test_luneburg_focuses_on_antipode():
    m_euler, info_e = _luneburg_miss(48, "euler", 1.0)
    m_rk4, info_r = _luneburg_miss(48, "rk4", 1.0)
    assert m_euler < 0.6, m_euler            # the target, at ds_min = 1 voxel
    assert m_rk4 < m_euler                   # higher order wins at equal steps
    assert info_e["total_steps"] > 0 and np.isfinite(info_e["drift_max"])


def test_luneburg_rk4_fewer_steps_same_accuracy():
    m_euler, info_e = _luneburg_miss(48, "euler", 1.0)
    m_rk4, info_r = _luneburg_miss(48, "rk4", 8.0)
    assert m_rk4 <= m_euler
    assert info_e["total_steps"] >= 2.5 * info_r["total_steps"]


@pytest.mark.parametrize("integrator,tol", [("euler", 0.5), ("rk4", 0.05)])
def test_square_linear_index_gives_parabolas(integrator, tol):
    """n^2 = n0^2 + k y: with dx/dt = v = n dx/ds, dv/dt = grad(n^2)/2 = (0, k/2, 0): a parabola in t."""
    N, n0, k = 40, 1.2, 0.3
    X, Y, Z = _centres(N)
    ior = np.sqrt(n0 ** 2 + k * Y)
    grid, _ = _setup(ior)
    y0s = np.array([-0.6, -0.3, 0.0, 0.3])
    pos = np.stack([np.full(4, -1.0), y0s, np.zeros(4)], axis=1)
    dirs = np.tile([1.0, 0.0, 0.0], (4, 1))
    paths = trace_paths(grid, pos, dirs, robust(ds_min=1.0, integrator=integrator))
    h = 2.0 / N
    for y0, path in zip(y0s, paths):
        assert len(path) > 5
        a = np.sqrt(n0 ** 2 + k * y0)            # dx/dt, constant
        t = (path[:, 0] + 1.0) / a               # the parameter t of every vertex
        y_exact = y0 + 0.25 * k * t ** 2
        assert np.max(np.abs(path[:, 1] - y_exact)) < tol * h, (integrator, y0)
        assert np.max(np.abs(path[:, 2])) < 1e-9
    # exit directions from the full marcher: v(t) = (a, k t / 2, 0)
    rad = np.ones_like(pos)
    _, info = march_photons(grid, (pos, dirs, rad), robust(ds_min=1.0, integrator=integrator))
    assert np.all(info["status"] == STATUS["exited"])
    a = np.sqrt(n0 ** 2 + k * y0s)
    t = (info["exit_pos"][:, 0] + 1.0) / a
    v = np.stack([a, 0.5 * k * t, 0 * t], axis=1)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    ang = np.degrees(np.arccos(np.clip(np.sum(v * info["exit_dir"], axis=1), -1, 1)))
    assert np.max(ang) < (0.5 if integrator == "euler" else 0.05)


def test_sharp_sphere_is_stiff_but_bounded():
    N = 32
    X, Y, Z = _centres(N)
    ior = np.where(X ** 2 + Y ** 2 + Z ** 2 < 0.5 ** 2, 1.5, 1.0)   # no blur
    grid, _ = _setup(ior)
    pos, dirs, rad, _, _ = generate_photons([{"type": "directional", "direction": [0, -1, 0],
                                              "radiance": [1, 1, 1]}], BOUNDS, ior.shape, 24)
    for integ in ("euler", "rk4"):
        for ds in (1.0, 4.0):
            sums, info = march_photons(grid, (pos, dirs, rad), robust(ds_min=ds, integrator=integ))
            assert np.all(np.isfinite(sums))
            ex = info["status"] == STATUS["exited"]
            assert ex.mean() > 0.95
            assert np.all(np.isfinite(info["exit_pos"][ex])) and np.all(np.isnan(info["exit_pos"][~ex]))
            assert np.allclose(np.linalg.norm(info["exit_dir"][ex], axis=1), 1.0)
            # |v| = n drift is bounded (stiff steps are capped and halved) and reported; the worst
            # photons graze the unblurred surface, most keep |v| = n
            assert 0.0 < info["drift_max"] < 1.0, (integ, ds, info["drift_max"])
            assert info["drift_median"] < 0.01, (integ, ds, info["drift_median"])
    # and reported in the plan of a full render
    res = rr.render({"camera": {"width": 16, "height": 16}, "objects": [],
                     "volume": {"ior": ior, "bounds": BOUNDS.tolist()},
                     "volumetric": {"photons": 16}}, method="volumetric")
    assert "sha1" in json.dumps(res.meta, default=str)          # the array is described, not dumped
    assert "drift max" in next(p["why"] for p in res.meta["plan"] if p["stage"] == "march")
    assert np.isfinite(res.meta["stats"]["drift_max"])
    assert np.all(np.isfinite(res["image"]))


# ------------------------------------------------------------------ octree
@pytest.mark.parametrize("N", [32, 37])
def test_octree_leaves_constant_regions(N):
    X, Y, Z = _centres(N)
    ior = 1.0 + 0.3 * np.clip(1.0 - np.sqrt(X ** 2 + Y ** 2 + Z ** 2) / 0.3, 0, 1)  # a cone of index in the middle
    level, step_max, st = build_octree(ior, 0.005, 0.02, 8.0, dilate=True)
    assert level.shape == ior.shape and step_max.shape == ior.shape
    corner = (slice(0, N // 4),) * 3
    assert np.all(np.isinf(step_max[corner]))            # far corner: constant, unbounded step
    assert level[0, 0, 0] >= 2                        # crossed by big nodes
    assert np.all(level[N // 2 - 1:N // 2 + 1, N // 2 - 1:N // 2 + 1, N // 2] == 0)  # the varying tip
    assert np.all(np.isfinite(step_max[N // 2, N // 2, N // 2]))
    assert 0.3 < st["constant_fraction"] < 1.0 and not st["constant_index"]
    # every voxel labelled constant really lies in a node whose range is < eps
    K = int(np.ceil(np.log2(N)))
    assert level.max() <= K
    const = np.ones((N, N, N))
    lv, sm, st2 = build_octree(const)
    assert st2["constant_index"] and np.all(lv == K) and np.all(np.isinf(sm))


def test_constant_nodes_are_crossed_in_one_step():
    N = 32
    ior = np.ones((N, N, N))
    grid, _ = _setup(ior)
    pos = np.array([[-1.0, 0.1, 0.2]])
    dirs = np.array([[1.0, 0.0, 0.0]])
    _, info = march_photons(grid, (pos, dirs, np.ones((1, 3))), robust(ds_min=1.0))
    assert info["total_steps"] == 1 and info["status"][0] == STATUS["exited"]
    assert np.allclose(info["exit_pos"][0], [1.0, 0.1, 0.2])


# ------------------------------------------------------------------ determinism
def test_deterministic_whatever_the_thread_count(on_one_and_two_threads):
    scene = rr.load_scene({"camera": {"width": 24, "height": 24},
                           "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.4, "absorption": [0.5, 0.2, 0]}}],
                           "lights": [{"type": "point", "position": [0.3, 2.0, 0.5], "radiance": [1, 0.5, 0.2]}],
                           "volumetric": {"resolution": 32, "photons": 48, "padding": 3, "phase_g": 0.4}})
    (a, _), (b, _) = on_one_and_two_threads(lambda: rr.volumetric.render_volumetric(scene))
    for k in ("radiance", "direction", "photon_exit_pos", "photon_exit_dir", "image", "ior"):
        assert np.array_equal(a[k], b[k], equal_nan=True), k
    assert int(a["photon_steps"]) == int(b["photon_steps"]) > 0
    assert a["radiance"].max() > 0


# ------------------------------------------------------------------ session and plan
def _small(**vol):
    return {"camera": {"width": 24, "height": 24},
            "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.3, "absorption": [0, 0, 0]}}],
            "volumetric": {"resolution": 32, "photons": 32, "padding": 3, **vol}}


def _ran(res):
    return [p["stage"] for p in res.meta["plan"] if p["ran"]]


def test_session_reruns_only_what_changed():
    s = rr.Session(_small())
    first = s.render("volumetric")
    assert _ran(first) == ["voxelize", "gradient", "octree", "photons", "march", "smooth", "view"]
    s.update({"camera.eye": [0.4, 0.2, 2.6]})
    cam = s.render("volumetric")
    assert _ran(cam) == ["view"]
    assert "camera.eye" in next(p["why"] for p in cam.meta["plan"] if p["stage"] == "view")
    # photon_paths runs only when kept; receivers and caustics are left out of a scene without receivers
    assert all("reused" in p["why"] for p in cam.meta["plan"]
               if not p["ran"] and p["stage"] not in ("photon_paths", "receivers", "caustics"))
    assert np.array_equal(cam["radiance"], first["radiance"])
    assert not np.array_equal(cam["image"], first["image"])
    s.update({"lights.0.direction": [0.3, -1.0, 0.0]})
    light = s.render("volumetric")
    assert _ran(light) == ["photons", "march", "smooth", "view"]
    assert "lights.0.direction" in light.meta["plan"][3]["why"]
    s.update({"objects.0.material.ior": 1.5})
    mat = s.render("volumetric")
    assert _ran(mat) == list(rr.volumetric.pipeline.STAGES)
    again = s.render("volumetric")
    assert _ran(again) == []
    assert again.meta["timings_ms"] == {}  # one entry per stage that ran


def test_volume_input_bypasses_voxelization(tmp_path):
    ior = luneburg(32)
    p = tmp_path / "n.npy"
    np.save(p, ior)
    res = rr.render({"camera": {"width": 16, "height": 16}, "objects": [],
                     "volume": {"ior": str(p), "extinction": 0.1, "scattering": [0.2, 0.2, 0.2],
                                "bounds": BOUNDS.tolist()},
                     "volumetric": {"photons": 16}}, method="volumetric")
    vox = res.meta["plan"][0]
    assert vox["stage"] == "voxelize" and "bypasses voxelization" in vox["why"]
    assert np.array_equal(res["ior"], ior)
    assert res["radiance"].shape == (32, 32, 32, 3) and res["direction"].shape == (32, 32, 32, 3)
    assert res["volume_bounds"].shape == (2, 3)
    P = len(res["photon_exit_pos"])
    assert res["photon_exit_dir"].shape == (P, 3) and P > 0
    ok = res["photon_status"] == STATUS["exited"]
    assert np.all(np.isnan(res["photon_exit_pos"][~ok])) and np.all(np.isfinite(res["photon_exit_pos"][ok]))
    for k, shape in (("ray_origin", (16, 16, 3)), ("exit_dir", (16, 16, 3)), ("hit", (16, 16)),
                     ("status", (16, 16)), ("image", (16, 16, 3))):
        assert res[k].shape == shape, k
    assert res["exit_dir"].dtype == np.float64 and res["image"].dtype == np.float32
    assert np.all(np.isfinite(res["image"]))
    # the meta stays small: arrays are described, not dumped
    assert len(json.dumps(res.meta, default=str)) < 20000


def test_voxelization_closed_and_open_meshes():
    from refraction_ref.meshes import scene_geometry
    from refraction_ref.volumetric.voxelize import voxelize_objects

    sc = rr.load_scene(_small())
    g = scene_geometry(sc)
    ior, absn, b, notes = voxelize_objects(g, 1.0, 32, 3, 4, 1)
    h = (b[1, 0] - b[0, 0]) / 32
    vol = (ior - 1.0).sum() / 0.3 * h ** 3
    assert abs(vol - np.pi / 6) / (np.pi / 6) < 0.02       # unit-diameter sphere
    assert "closed" in notes[0]
    sc = rr.load_scene({"objects": [{"mesh": "bunny", "fit": 1.0}]})
    ior, absn, b, notes = voxelize_objects(scene_geometry(sc), 1.0, 32, 3, 4, 1)
    assert "open" in notes[0] and "vote" in notes[0]
    pad = np.ones((32, 32, 32), bool)
    pad[1:-1, 1:-1, 1:-1] = False
    assert np.all(np.abs(ior[pad] - 1.0) < 1e-6)            # no garbage leaking to the borders
    assert ior.max() > 1.4


# ------------------------------------------------------------------ errors
@pytest.mark.parametrize("over,words", [
    ({"volumetric": {"integrator": "leapfrog"}}, ["volumetric.integrator", "euler"]),
    ({"volumetric": {"ds_min": 4, "ds_max": 2}}, ["ds_max", "ds_min"]),
    ({"volumetric": {"eps": 0.05, "eps2": 0.01}}, ["eps2"]),
    ({"volumetric": {"blur": 8}}, ["blur", "odd"]),
    ({"volumetric": {"phase_g": 1.5}}, ["phase_g"]),
    ({"volumetric": {"scattering": -1}}, ["scattering", ">= 0"]),
    ({"volumetric": {"nope": 1}}, ["volumetric.nope"]),
    ({"volume": {"ior": "missing.npy", "bounds": [[0, 0, 0], [1, 1, 1]]}}, ["volume.ior", "missing.npy"]),
    ({"volume": {"ior": np.ones((4, 4, 4))}}, ["volume.bounds"]),
    ({"volume": {"ior": np.ones((4, 4, 4)), "bounds": [[0, 0, 0], [1, 0, 1]]}}, ["volume.bounds"]),
    ({"volume": {"ior": np.ones((4, 4, 4)), "bounds": [[0, 0, 0], [1, 1, 1]], "colour": 1}}, ["volume.colour"]),
])
def test_bad_scenes_are_refused_on_load(over, words):
    with pytest.raises(rr.SceneError) as e:
        rr.load_scene(over)
    for w in words:
        assert w in str(e.value)


@pytest.mark.parametrize("vol,words", [
    ({"ior": -np.ones((8, 8, 8))}, ["volume.ior", "> 0"]),
    ({"ior": np.full((8, 8, 8), np.nan)}, ["volume.ior", "NaN"]),
    ({"ior": np.ones((8, 8))}, ["volume.ior", "3D"]),
    ({"ior": np.ones((8, 8, 2))}, ["volume.ior", "at least 4"]),
    ({"ior": np.ones((8, 8, 8)), "extinction": np.ones((4, 4, 4))}, ["volume.extinction", "shape"]),
    ({"ior": np.ones((8, 8, 8)), "scattering": -np.ones((8, 8, 8))}, ["volume.scattering", ">= 0"]),
])
def test_bad_volumes_are_refused_before_work(vol, words):
    sc = {"camera": {"width": 8, "height": 8}, "objects": [],
          "volume": dict(vol, bounds=[[-1, -1, -1], [1, 1, 1]])}
    with pytest.raises(rr.SceneError) as e:
        rr.render(sc, method="volumetric")
    for w in words:
        assert w in str(e.value)


def test_point_light_inside_volume_and_empty_scene_are_refused():
    sc = _small()
    sc["lights"] = [{"type": "point", "position": [0, 0, 0], "radiance": [1, 1, 1]}]
    with pytest.raises(rr.SceneError, match="inside the volume"):
        rr.render(sc, method="volumetric")
    with pytest.raises(rr.SceneError, match="no objects and no 'volume'"):
        rr.render({"objects": [], "camera": {"width": 8, "height": 8}}, method="volumetric")


# ------------------------------------------------------------------ speed-ups keep the results
def test_reused_deposit_buffers_give_identical_results():
    """The march keeps its deposit buffers for the next call (zeroed again): same sums, any order of calls."""
    from refraction_ref.volumetric.march import release_workspace

    ior = luneburg(32)
    grid, _ = _setup(ior, kappa=0.3)
    pos, dirs, rad, _, _ = generate_photons([{"type": "directional", "direction": [0.2, -1, 0.1],
                                              "radiance": [1, 0.5, 0.25]}], BOUNDS, ior.shape, 24)
    knobs = robust(stop_fraction=0.05)
    release_workspace()
    a, ia = march_photons(grid, (pos, dirs, rad), knobs)
    b, ib = march_photons(grid, (pos, dirs, rad), knobs)  # reused buffers
    release_workspace()
    c, _ = march_photons(grid, (pos, dirs, rad), knobs)   # fresh buffers
    assert ia["truncated"] > 0                      # the stopping rule removed late deposits again
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert a[..., :3].min() >= 0.0                  # removal is exact: nothing negative is left behind


def test_view_box_entry_in_kernel_matches_slab_test():
    """The viewing kernel's per-ray box entry equals photons.box_entry, edge cases included."""
    from refraction_ref.volumetric.photons import box_entry
    from refraction_ref.volumetric.view import box_entry_one

    rng = np.random.default_rng(3)
    o = rng.uniform(-3, 3, (4000, 3))
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[::7, 0] = 0.0                                  # rays parallel to a slab
    d[::11, 1] = -0.0
    o[::13, 0] = 1.0                                 # origins on a face
    o[::17] = 0.0                                    # origins inside
    t_ref, _ = box_entry(o, d, BOUNDS)
    lo, hi = BOUNDS[0].copy(), BOUNDS[1].copy()
    t = np.array([box_entry_one(lo, hi, *o[r], *d[r]) for r in range(len(o))])
    assert np.array_equal(t, t_ref)


def test_camera_only_rerender_matches_fresh_render():
    """The source volume is packed once (smooth stage); a camera change re-renders exactly as from scratch."""
    s = rr.Session(_small(scattering=[0.3, 0.2, 0.1], absorption=0.1, phase_g=0.3))
    s.render("volumetric")
    s.update({"camera.eye": [0.5, 0.3, 2.4]})
    cam = s.render("volumetric")
    assert _ran(cam) == ["view"]
    fresh = rr.Session(s.scene).render("volumetric")
    for k in ("image", "exit_pos", "exit_dir", "hit", "interfaces", "path_length", "status"):
        assert np.array_equal(cam[k], fresh[k], equal_nan=True), k
