"""What a new user hit (issue: sharp edges): each fix held by a test that failed before it."""

from __future__ import annotations

import os
import sys

import matplotlib
import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref import cli
from refraction_ref.compare import check_comparable, plot_comparison

SMALL = {"camera": {"width": 24, "height": 24}}
POOL = "refraction_ref/data/levelmap_default.json"
POOL_SMALL = {"camera.width": 24, "camera.height": 24, "levelmap.map_size": 32, "water.resolution": 16,
              "levelmap.exact_samples": 32}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("runs")
    bunny = rr.render(SMALL)
    sphere = rr.render({**SMALL, "objects": [{"mesh": "sphere", "fit": 1.0}]})
    pool = rr.render(POOL, method="levelmap", overrides=POOL_SMALL)
    pool_exact = rr.render(POOL, method="exact", overrides=POOL_SMALL)
    paths = {}
    for name, r in (("bunny", bunny), ("sphere", sphere), ("pool", pool), ("pool_exact", pool_exact)):
        paths[name] = r.save(d / name)[0]
    big = rr.render({"camera": {"width": 32, "height": 24}})
    paths["big"] = big.save(d / "big")[0]
    return paths


def test_compare_refuses_different_scenes_naming_the_key(runs, capsys):
    assert cli.main(["compare", runs["bunny"], runs["sphere"]]) == 2
    err = capsys.readouterr().err
    assert "different scenes" in err and "objects.0" in err and "Traceback" not in err
    assert cli.main(["compare", runs["bunny"], runs["pool"]]) == 2
    assert cli.main(["compare", runs["bunny"], runs["sphere"], "--force"]) == 0
    assert "warning" in capsys.readouterr().err


def test_compare_accepts_two_methods_of_one_scene():
    a, b = rr.render(SMALL), rr.render(SMALL, method="exact", overrides={"imagespace.iterations": 3})
    assert check_comparable(a.meta, b.meta) is None


def test_different_resolutions_give_one_clear_message(runs, capsys):
    assert cli.main(["compare", runs["bunny"], runs["big"], "--force"]) == 2
    err = capsys.readouterr().err
    assert "different resolutions (24x24 and 32x24)" in err and "Traceback" not in err


def test_compare_plots_water_runs(runs, tmp_path):
    png = tmp_path / "pool.png"
    assert cli.main(["compare", runs["pool"], runs["pool_exact"], "--plot", str(png)]) == 0
    assert png.stat().st_size > 1000
    import imageio.v3 as iio

    img = iio.imread(png)
    assert img.ndim == 3 and img.shape[0] > 300  # image row and two caustic-map rows


def test_plotting_leaves_the_matplotlib_backend_alone(tmp_path):
    before = matplotlib.get_backend()
    matplotlib.use("svg")
    try:
        a = rr.render(SMALL)
        plot_comparison(a.arrays, a.arrays, tmp_path / "p.png")
        assert matplotlib.get_backend() == "svg"
        assert (tmp_path / "p.png").exists()
    finally:
        matplotlib.use(before)


def test_existing_output_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    (tmp_path / "o.npz").write_bytes(b"x")

    def no_render(*a, **k):
        raise AssertionError("rendered before checking the outputs")

    monkeypatch.setattr(sys.modules["refraction_ref.render"], "run_method", no_render)
    assert cli.main(["render", "--out", str(tmp_path / "o"), "--set", "camera.width=8"]) == 2
    assert "exists" in capsys.readouterr().err


def test_an_interrupted_save_leaves_no_file(tmp_path, monkeypatch):
    res = rr.render(SMALL)

    def broken(path, **arrays):
        with open(path, "wb") as f:
            f.write(b"PK partial")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(KeyboardInterrupt):
        res.save(tmp_path / "r")
    assert os.listdir(tmp_path) == []


def test_compile_time_is_reported_apart(capsys, tmp_path):
    res = rr.render(SMALL)
    assert "jit_ms" in res.meta and res.meta["total_ms"] < 60_000
    assert sys.modules["refraction_ref.render"].kernels_cached("imagespace")
    assert cli.main(["render", "--out", str(tmp_path / "x"), "--set", "camera.width=16",
                     "--set", "camera.height=16"]) == 0
    out = capsys.readouterr()
    assert "ms to render" in out.out and "\r" not in out.err  # no progress bar off a terminal


def test_missed_pixels_leave_unchanged_in_every_method():
    for method, extra in (("imagespace", {}), ("exact", {}),
                          ("volumetric", {"volumetric": {"resolution": 16, "photons": 8, "padding": 2}})):
        r = rr.render({**SMALL, **extra}, method=method)
        miss = r["status"] == 0
        assert miss.any(), method
        assert np.all(np.isnan(r["exit_pos"][miss])), method
        np.testing.assert_array_equal(r["exit_dir"][miss], r["ray_dir"][miss], err_msg=method)


def test_exact_status_3_on_a_sphere_is_grazing_only():
    r = rr.render({"objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.2}}],
                   "camera": {"width": 256, "height": 256}, "exact": {"normals": "smooth"}}, method="exact")
    trapped = r["status"] == 3
    o, d = r["ray_origin"][trapped], r["ray_dir"][trapped]
    sin_i = np.linalg.norm(np.cross(o, d), axis=1) / 0.5  # the sphere of radius 0.5 at the origin
    assert np.all(sin_i > 0.999)  # incidence above 87.4 degrees: rays the facets trap


def test_memory_refusals_name_the_method_s_own_keys():
    sc = rr.load_scene({"camera": {"width": 16000, "height": 16000}})  # loads: the check is each method's
    with pytest.raises(rr.SceneError, match=r"imagespace: .*GiB; lower camera.width"):
        rr.render(sc)
    with pytest.raises(rr.SceneError, match=r"exact: .*GiB for the exact trace; lower camera.width") as e:
        rr.render(sc, method="exact")
    assert "slices" not in str(e.value) and "layers" not in str(e.value)


def test_default_environment_shows_the_refraction():
    sc = {"camera": {"width": 96, "height": 96}}
    with_obj = rr.render(sc)
    without = rr.render({**sc, "objects": []})
    hit = with_obj["hit"]
    changed = np.any(with_obj["image"] != without["image"], axis=-1)
    assert changed[hit].mean() > 0.3  # the checker behind the bunny visibly moves
    colours = np.unique(without["image"].reshape(-1, 3), axis=0)
    assert len(colours) == 2
    tiles = np.count_nonzero(np.diff(without["image"][48, :, 0]) != 0) + 1
    assert tiles >= 3  # squares across the middle row of the default view
