"""Tests of the level-map water caustics (refraction_ref.levelmap, Tipprasert 2006).

Small maps and meshes throughout so that the whole file runs in well under a
minute; every assertion is a numerical truth (closed forms, identities,
bounds), none is about wall-clock time.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref.levelmap import default_scene
from refraction_ref.levelmap.illumination import illumination_volumes
from refraction_ref.levelmap.knobs import levelmap_knobs
from refraction_ref.levelmap.pipeline import pair_caustics, prepare, render_levelmap
from refraction_ref.levelmap.planes import from_map
from refraction_ref.levelmap.water import WaterMesh, water_mesh
from refraction_ref.metrics import luv_difference, relative_l1
from refraction_ref.scene import SceneError, load_scene

FLOOR_Y = -0.5


def flat_scene(direction=(0.3, -1.0, 0.1), K=0.3, planes=5, variant="levelmap", lights=None, **lm):
    """Flat water (4 x 4) over a smaller flat floor (2 x 2): light reaches every floor texel."""
    knobs = {"planes": planes, "map_size": 64, "variant": variant, "smart_slicing": False}
    knobs.update(lm)
    return load_scene({
        "camera": {"width": 24, "height": 24, "eye": [0, 2, 2], "target": [0, FLOOR_Y, 0]},
        "objects": [],
        "lights": lights or [{"type": "directional", "direction": list(direction)}],
        "receivers": [{"mesh": "plane", "size": [2, 2], "transform": {"translate": [0, FLOOR_Y, 0]}}],
        "water": {"size": [4, 4], "height": 0.0, "resolution": 16, "absorption": K, "waves": []},
        "levelmap": knobs,
    })


def closed_form(direction, K, depth=-FLOOR_Y, ior=1.33):
    d = np.asarray(direction, float)
    d /= np.linalg.norm(d)
    cos_i = -d[1]
    sin_t = math.sqrt(1 - cos_i ** 2) / ior
    cos_t = math.sqrt(1 - sin_t ** 2)
    return cos_i * math.exp(-K * depth / cos_t)


def own_texels(scene, r=0):
    ctx = prepare(scene)
    return ctx["pairs"][r][0].lm.own


def wavy_scene(**lm):
    knobs = {"planes": 20, "map_size": 96, "exact_samples": 384}
    knobs.update(lm)
    return load_scene({
        "camera": {"width": 24, "height": 24, "eye": [0, 2, 2], "target": [0, -0.6, 0]},
        "objects": [],
        "lights": [{"type": "directional", "direction": [0.2, -1.0, 0.1]}],
        "receivers": [{"mesh": "plane", "size": [1.5, 1.5], "transform": {"translate": [0, -0.6, 0]}},
                      {"mesh": "sphere", "fit": 0.4, "transform": {"translate": [0.2, -0.35, 0.1]}}],
        "water": {"size": [2.5, 2.5], "resolution": 48, "absorption": 0.2,
                  "waves": [{"amplitude": 0.01, "wavelength": 0.6, "direction": [1, 0.3]},
                            {"amplitude": 0.006, "wavelength": 0.37, "direction": [-0.4, 1], "phase": 1.0}]},
        "levelmap": knobs,
    })


# --- closed forms -----------------------------------------------------------------------------

@pytest.mark.parametrize("variant", ["levelmap", "volumetric", "per_ray"])
def test_flat_water_closed_form(variant):
    d, K = (0.3, -1.0, 0.1), 0.3
    sc = flat_scene(d, K, variant=variant)
    a, info = render_levelmap(sc)
    E = a["caustic_map_0"].astype(float)
    own = own_texels(sc)
    # the thesis's box (eq. 4-3) spans 2 |P| of the farthest corner: the floor fills about half the map
    assert own.sum() > 0.4 * E.size
    np.testing.assert_allclose(E[own], closed_form(d, K), rtol=1e-5)
    assert np.all(E[~own] == 0)
    assert a["caustic_frame_0"].shape == (4, 3)


@pytest.mark.parametrize("planes", [1, 500])
def test_one_and_500_planes(planes):
    d, K = (0.2, -1.0, -0.3), 0.5
    sc = flat_scene(d, K, planes=planes)
    a, info = render_levelmap(sc)
    assert info["planes_requested"] == planes
    E = a["caustic_map_0"].astype(float)
    # 5e-5 (was 1e-5 with the tight box): the distance exp(-K d) is interpolated from vertices snapped to
    # 1/256 texel, and the thesis's box (eq. 4-3) has 1.4x larger texels; one plane far from the tilted floor
    np.testing.assert_allclose(E[own_texels(sc)], closed_form(d, K), rtol=5e-5)


def test_grazing_light_closed_form():
    d, K = (1.0, -0.03, 0.0), 0.2  # 1.7 degrees above the horizon
    sc = flat_scene(d, K)
    a, _ = render_levelmap(sc)
    E = a["caustic_map_0"].astype(float)
    assert np.all(np.isfinite(E))
    # 5e-5 (was 1e-5): distances interpolated at 1/256-texel snapped vertices, 1.4x larger texels (eq. 4-3 box)
    np.testing.assert_allclose(E[own_texels(sc)], closed_form(d, K), rtol=5e-5)


def test_several_lights_sum():
    l1, l2 = (0.3, -1.0, 0.1), (-0.2, -1.0, 0.25)
    sc = flat_scene(K=0.3, lights=[{"type": "directional", "direction": list(l1)},
                                   {"type": "directional", "direction": list(l2), "radiance": [2, 2, 2]}])
    a, info = render_levelmap(sc)
    assert len(info["planes_used_per_receiver"][0]) == 2  # one set of planes per light (eq. 4-20)
    E = a["caustic_map_0"].astype(float)
    own = own_texels(sc)
    # the floor's texels two texels in from its edges (the thesis's box, eq. 4-3, puts the floor mid-map)
    from scipy.ndimage import binary_erosion

    inner = binary_erosion(own, iterations=2)
    np.testing.assert_allclose(E[inner], closed_form(l1, 0.3) + 2 * closed_form(l2, 0.3), rtol=5e-5)


# --- extreme cases -----------------------------------------------------------------------------

@pytest.mark.parametrize("direction", [(0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.3, 0.2, 0.1)])
def test_light_from_below_horizon_is_refused(direction):
    with pytest.raises(SceneError, match="horizon"):
        flat_scene(direction)


def test_point_light_under_water_is_refused():
    with pytest.raises(SceneError, match="above the water"):
        flat_scene(lights=[{"type": "point", "position": [0, -0.1, 0]}])


def test_bad_water_inputs_are_refused():
    with pytest.raises(SceneError, match="water.size"):
        load_scene({"water": {"size": [0, 4]}})
    with pytest.raises(SceneError, match="water.absorption"):
        load_scene({"water": {"absorption": -1}})
    with pytest.raises(SceneError, match="unknown key 'water.waves\\[0\\].height'"):
        load_scene({"water": {"waves": [{"height": 1}]}})
    with pytest.raises(SceneError, match="levelmap.variant"):
        load_scene({"levelmap": {"variant": "nope"}})
    with pytest.raises(SceneError, match="no 'water' block"):
        render_levelmap(load_scene({}))


def test_point_light_finite_and_positive():
    sc = flat_scene(lights=[{"type": "point", "position": [0.3, 2.0, 0.1]}])
    a, _ = render_levelmap(sc)
    E = a["caustic_map_0"]
    own = own_texels(sc)
    assert np.all(np.isfinite(E)) and E[own].min() > 0
    # a point light 2 above the water: irradiance falls off with distance
    assert E[own].max() < 1.0 / 2.0 ** 2 * 1.01


def test_water_that_cannot_be_meant_is_refused():
    base = {"camera": {"width": 16, "height": 16, "eye": [0, 2, 2], "target": [0, -0.5, 0]},
            "objects": [], "lights": [{"type": "directional", "direction": [0.4, -1, 0]}],
            "receivers": [{"mesh": "plane", "size": [2, 2], "transform": {"translate": [0, -0.5, 0]}}],
            "water": {"size": [3, 3], "resolution": 16, "waves": [
                {"amplitude": 0.15, "wavelength": 0.25, "direction": [1, 0]},   # slope up to 3.8: folds
                {"amplitude": 0.1, "wavelength": 0.2, "direction": [0, 1]}]},
            "levelmap": {"planes": 8, "map_size": 32}}
    with pytest.raises(SceneError, match=r"too steep.*6\.9.*water\.waves"):
        load_scene(base)
    gentle = {"amplitude": 0.01, "wavelength": 0.5, "direction": [1, 0]}
    with pytest.raises(SceneError, match="camera.eye is at y = -1.*not above the water"):
        load_scene(base, {"water.waves": [gentle], "camera.eye": [0, -1, 2]})
    # waves reaching the floor 0.5 below the surface: refused when the receivers are placed
    deep = {"amplitude": 0.6, "wavelength": 20.0, "direction": [1, 0]}  # slope 0.19: no fold, but too deep
    with pytest.raises(SceneError, match="reach down to the highest receiver below the surface"):
        render_levelmap(load_scene(base, {"water.waves": [deep]}))
    # steep but single-valued waves render, with the broken assumption named in the plan
    steep = {"amplitude": 0.03, "wavelength": 0.4, "direction": [1, 0]}  # slope 0.47
    a, info = render_levelmap(load_scene(base, {"water.waves": [steep]}))
    assert np.all(np.isfinite(a["caustic_map_0"])) and a["caustic_map_0"].min() >= 0
    assert "steep waves" in next(p["why"] for p in info["plan"] if p["stage"] == "water")


def test_receiver_above_water_gets_nothing():
    sc = load_scene({
        "camera": {"width": 16, "height": 16, "eye": [0, 3, 2], "target": [0, 0, 0]},
        "objects": [], "lights": [{"type": "directional", "direction": [0.1, -1, 0]}],
        "receivers": [{"mesh": "plane", "size": [2, 2], "transform": {"translate": [0, -0.5, 0]}},
                      {"mesh": "plane", "size": [0.5, 0.5], "transform": {"translate": [0, 0.3, 0]}}],
        "water": {"size": [4, 4], "resolution": 16, "waves": [{"amplitude": 0.02, "wavelength": 0.5}]},
        "levelmap": {"planes": 4, "map_size": 48}})
    for v in ("levelmap", "volumetric", "per_ray"):
        a, _ = render_levelmap(load_scene(sc, {"levelmap.variant": v}))
        assert np.all(a["caustic_map_1"] == 0)
        assert a["caustic_map_0"].max() > 0
        # ...and it shadows the floor below it (receivers occlude each other)
        assert np.count_nonzero(a["caustic_map_0"] == 0) > 0.01 * a["caustic_map_0"].size


def test_zero_area_water_triangles():
    sc = flat_scene(K=0.0)
    mesh = water_mesh(sc.data["water"])
    v = mesh.vertices.copy()
    n = int(sc.data["water"]["resolution"]) + 1
    v[5 * n + 5] = v[5 * n + 6]  # collapse a vertex onto its neighbour: two triangles of zero area
    bad = WaterMesh(v, mesh.faces, mesh.normals)
    vols = illumination_volumes(sc.data["lights"][0], bad, 1.0 / 1.33)
    area = np.linalg.norm(np.cross(vols.origins[:, 1] - vols.origins[:, 0],
                                   vols.origins[:, 2] - vols.origins[:, 0]), axis=1)
    assert np.count_nonzero(area == 0) == 2
    assert np.all(vols.flux[area == 0] == 0) and np.all(np.isfinite(vols.flux))
    ctx = prepare(sc)
    ctx["vols"] = [vols]
    knobs = levelmap_knobs(sc.data["levelmap"], sc.data["caustics"]["placement"], ctx["K"])
    for variant in ("levelmap", "per_ray"):
        E = pair_caustics(ctx, 0, 0, knobs._replace(variant=variant)).map
        assert np.all(np.isfinite(E)) and E.min() >= 0
        # total flux on the floor equals the flux through the water above it (nothing lost, nothing made)
        assert E.sum() > 0


# --- identities --------------------------------------------------------------------------------

def test_smart_slicing_changes_no_pixel_and_uses_fewer_planes():
    """Lattice smart slicing (levelmap.smart_spacing = lattice) keeps the
    normal slicing's planes: no texel changes. The default re-slicing (respace) moves planes: see
    test_levelmap_thesis.py and Table 5-5."""
    base = {
        "camera": {"width": 48, "height": 48, "eye": [0, 1.5, 1.5], "target": [0, -0.6, 0]},
        "objects": [], "lights": [{"type": "directional", "direction": [0.02, -1, 0.01]}],
        "receivers": [{"mesh": "plane", "size": [1.5, 1.5], "transform": {"translate": [0, -0.6, 0]}},
                      {"mesh": "teapot", "fit": 0.5, "transform": {"translate": [-0.3, -0.48, 0]}},
                      {"mesh": "sphere", "fit": 0.3, "transform": {"translate": [0.35, -0.45, 0.1]}}],
        "water": {"size": [2, 2], "resolution": 32, "absorption": 0.1,
                  "waves": [{"amplitude": 0.01, "wavelength": 0.5, "direction": [1, 0.4]}]},
        "levelmap": {"planes": 24, "map_size": 96, "depth_levels": 32, "smart_spacing": "lattice"}}
    a, ia = render_levelmap(load_scene(base, {"levelmap.smart_slicing": False}))
    b, ib = render_levelmap(load_scene(base, {"levelmap.smart_slicing": True}))
    for r in range(3):
        assert np.array_equal(a[f"caustic_map_{r}"], b[f"caustic_map_{r}"])
    assert luv_difference(a["image"], b["image"], a["object_mask"]) == 0.0  # Table 5-5
    used = [u[0] for u in ib["planes_used_per_receiver"]]
    assert ia["planes_used_per_receiver"] == [[24]] * 3
    assert used[1] < 24 and used[2] < 24  # teapot and sphere (Table 5-4)
    assert used[2] <= 0.6 * 24  # the lower half of a sphere is hidden from the light


def test_volumetric_baseline_is_texel_identical_to_level_map():
    sc = wavy_scene()
    a, _ = render_levelmap(load_scene(sc, {"levelmap.smart_slicing": False}))
    b, _ = render_levelmap(load_scene(sc, {"levelmap.variant": "volumetric"}))
    for r in range(2):
        assert np.array_equal(a[f"caustic_map_{r}"], b[f"caustic_map_{r}"])


@pytest.mark.parametrize("variant", ["levelmap", "volumetric", "per_ray"])
def test_deterministic_across_thread_counts(variant, on_one_and_two_threads):
    sc = load_scene(wavy_scene(), {"levelmap.variant": variant})
    (a, _), (b, _) = on_one_and_two_threads(lambda: render_levelmap(sc))
    for k in a:
        assert np.array_equal(a[k], b[k]), k


def test_agreement_with_exact_reference():
    """Relative L1 of the floor's caustic map (both blurred by one texel) against the Embree reference."""
    sc = wavy_scene()
    ex = rr.render(sc, method="exact")
    own = own_texels(sc)
    errs = {}
    for v in ("levelmap", "per_ray"):
        a = rr.render(load_scene(sc, {"levelmap.variant": v}), method="levelmap")
        errs[v] = relative_l1(a["caustic_map_0"], ex["caustic_map_0"], own, blur=1.0)
    assert errs["levelmap"] < 0.08, errs  # stated tolerance: 8 % at 48x48 water, 96^2 maps, 20 planes
    assert errs["per_ray"] < 0.08, errs
    # the exact reference conserves the flux through the water above the floor (K = 0.2, depth 0.6)
    E = ex["caustic_map_0"].astype(float)
    # the floor's texels 8 in from its edges (the thesis's box, eq. 4-3, puts the floor mid-map)
    from scipy.ndimage import binary_erosion

    inner = binary_erosion(own, iterations=8)
    mean = E[inner].mean()
    assert abs(mean / closed_form((0.2, -1.0, 0.1), 0.2, depth=0.6) - 1) < 0.03


def test_luv_metric():
    w = np.ones((2, 2, 3))
    k = np.zeros((2, 2, 3))
    assert luv_difference(w, w) == 0.0
    assert abs(luv_difference(w, k) - 100.0) < 1e-6  # white vs black: L* 100 apart
    r = np.zeros((1, 1, 3)); r[..., 0] = 1
    b = np.zeros((1, 1, 3)); b[..., 2] = 1
    assert 150 < luv_difference(r, b) < 600  # the thesis's most distinct colours


def test_default_scene_and_render_entry_point():
    sc = default_scene({"levelmap.map_size": 64, "water.resolution": 16, "camera.width": 32,
                        "camera.height": 32, "levelmap.planes": 6})
    res = rr.render(sc, method="levelmap")
    assert res.meta["planes_requested"] == 6 and 1 <= res.meta["planes_used"] <= 6
    assert set(res.meta["timings_ms"]) >= {"water", "planes", "level_map", "caustics", "image"}
    assert {"caustic_map_0", "caustic_frame_0", "caustic_map_1", "caustic_frame_1", "image"} <= set(res.arrays)
    assert res["image"].dtype == np.float32 and res["image"].shape == (32, 32, 3)
    f = res["caustic_frame_0"]
    box = prepare(sc)["pairs"][0][0].box
    a, b = 10, 20  # texel (a, b) covers origin + (b + .5)/Wc u + (a + .5)/Hc v (docs/oracle.md)
    p = from_map(box, np.array([b + 0.5]), np.array([a + 0.5]), np.array([-box.h / 2]))[0]
    assert np.allclose(p, f[0] + (b + 0.5) / 64 * f[1] + (a + 0.5) / 64 * f[2], atol=1e-12)
    assert abs(np.linalg.norm(f[3]) - 1) < 1e-12 and abs(f[3] @ f[1]) < 1e-9 and abs(f[3] @ f[2]) < 1e-9
    assert f[3][1] > 0  # the normal points towards the light


def test_every_variant_keeps_its_stage_buffers():
    sc = default_scene({"camera.width": 16, "camera.height": 16, "levelmap.map_size": 16, "water.resolution": 8,
                        "levelmap.planes": 4})
    for v in ("levelmap", "volumetric", "per_ray"):
        res = rr.render(sc, method="levelmap", overrides={"levelmap.variant": v}, keep="stages")
        assert "stage.level_map.position_0_0" in res.arrays
        assert ("stage.plane_maps.plane_maps_0_0" in res.arrays) == (v == "levelmap")
