"""Every input of issue 30 ("nothing a user types crashes or leaks NaN"), one test each.

Each input is either refused with one line naming the key (``SceneError`` from Python, exit 2 with
``refraction-ref: error:`` from the CLI, nothing left on disk) or accepted with a defined, finite result.
The fuzzer (tests/test_fuzz.py) checks the same property on random inputs.
"""

from __future__ import annotations

import contextlib
import io
import json
import os

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref import cli
from refraction_ref.compare import compare_arrays, format_comparison
from refraction_ref.validation import SceneError

TINY = {"camera": {"width": 8, "height": 8}}


def _run(argv):
    """``cli.main(argv)`` in-process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = cli.main([str(a) for a in argv])
        except SystemExit as e:
            rc = e.code
    return rc, out.getvalue(), err.getvalue()


def _one_line(msg):
    assert msg.strip() and "\n" not in msg.strip() and "Traceback" not in msg, msg
    return msg


def _with(path_value):
    """TINY with ``{dotted.path: value}`` set (list items by index), as a raw dict (no defaults filled)."""
    d = json.loads(json.dumps(TINY))
    for key, value in path_value.items():
        node, parts = d, key.split(".")
        for p in parts[:-1]:
            if isinstance(node, list):
                node = node[int(p)]
            else:
                node = node.setdefault(p, [{}] if p in ("objects", "receivers", "lights") else {})
        if isinstance(node, list):
            node[int(parts[-1])] = value
        else:
            node[parts[-1]] = value
    return d


NAN, INF = float("nan"), float("inf")

# (id, raw scene, words the message must contain: the key)
REFUSED = [
    ("camera_null", {"camera": None}, "'camera' is null"),
    ("environment_null", {**TINY, "environment": None}, "'environment' is null"),
    ("imagespace_null", {**TINY, "imagespace": None}, "'imagespace' is null"),
    ("caustics_null", {**TINY, "caustics": None}, "'caustics' is null"),
    ("objects_null_item", {**TINY, "objects": [None]}, "'objects[0]'"),
    ("receivers_null_item", {**TINY, "receivers": [None]}, "'receivers[0]'"),
    ("receiver_fit_text", _with({"receivers.0.fit": "abc"}), "'receivers[0].fit'"),
    ("receiver_size_text", _with({"receivers.0.size": "x"}), "'receivers[0].size'"),
    ("receiver_fit_nan", _with({"receivers.0.fit": NAN}), "'receivers[0].fit'"),
    ("receiver_fit_negative", _with({"receivers.0.fit": -1}), "'receivers[0].fit'"),
    ("receiver_size_zero", _with({"receivers.0.size": [0, 1]}), "'receivers[0].size'"),
    ("object_size_text", _with({"objects.0.size": "x"}), "'objects[0].size'"),
    ("env_colors_text", _with({"environment.colors": "red"}), "'environment.colors'"),
    ("env_colors_dict", _with({"environment.colors": {}}), "'environment.colors'"),
    ("env_colors_nan", _with({"environment.colors": [[NAN, 0, 0], [0, 0, 0]]}), "'environment.colors[0]'"),
    ("env_intensity_nan", _with({"environment.intensity": NAN}), "'environment.intensity'"),
    ("env_intensity_negative", _with({"environment.intensity": -1}), "'environment.intensity'"),
    ("env_intensity_1e300", _with({"environment.intensity": 1e300}), "'environment.intensity'"),
    ("env_tiles_huge", _with({"environment.tiles": 10**30}), "'environment.tiles'"),
    ("max_bounces_40000", _with({"exact.max_bounces": 40000}), "'exact.max_bounces'"),
    ("eye_1e200", _with({"camera.eye": [0, 0, 1e200]}), "'camera.eye'"),
    ("fit_1e300", _with({"objects.0.fit": 1e300}), "'objects[0].fit'"),
    ("radiance_1e300", {**TINY, "lights": [{"radiance": [1e300, 1, 1]}]}, "'lights[0].radiance'"),
    ("fov_tiny", _with({"camera.fov_y": 1e-6}), "'camera.fov_y'"),
    ("bool_in_vector", _with({"camera.eye": [True, 0, 2.6]}), "true and false are not numbers"),
    ("bool_in_translate", _with({"objects.0.transform.translate": [0, False, 0]}), "translate"),
    ("bool_fov", _with({"camera.fov_y": True}), "'camera.fov_y'"),
    ("huge_int_width", _with({"camera.width": 10**5000}), "'camera.width'"),
    ("huge_int_float", _with({"camera.fov_y": 10**400}), "'camera.fov_y'"),
    ("transform_null", _with({"objects.0.transform": None}), "transform"),
    ("material_null", _with({"objects.0.material": None}), "material"),
    ("deform_zero_direction", _with({"objects.0.deform": {"direction": [0, 0, 0]}}), "deform.direction"),
    ("albedo_1e300", _with({"receivers.0.albedo": [1e300, 0, 0]}), "'receivers[0].albedo'"),
    ("vol_scattering_bool", _with({"volumetric.scattering": True}), "'volumetric.scattering'"),
    ("vol_absorption_bool_in_rgb", _with({"volumetric.absorption": [0, True, 0]}), "'volumetric.absorption'"),
    ("vol_scattering_dict", _with({"volumetric.scattering": {}}), "'volumetric.scattering'"),
    ("deep_nesting", {**TINY, "objects": [{"name": [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]}]},
     "nests"),
]


@pytest.mark.parametrize("raw,words", [(r, w) for _, r, w in REFUSED], ids=[i for i, _, _ in REFUSED])
def test_refused_with_one_line_naming_the_key(raw, words):
    with pytest.raises(SceneError) as e:
        rr.load_scene(raw)
    assert words in _one_line(str(e.value))


@pytest.mark.parametrize("src", [42, [1, 2], 3.5, b"scene.json"], ids=["int", "list", "float", "bytes"])
def test_load_scene_refuses_what_is_not_a_path_or_dict(src):
    with pytest.raises(SceneError, match="load_scene: the scene must be"):
        rr.load_scene(src)


def test_documented_range_equals_the_kernels_max_bounces():
    assert rr.load_scene(_with({"exact.max_bounces": 32767})).data["exact"]["max_bounces"] == 32767
    doc = open(os.path.join(os.path.dirname(__file__), "..", "docs", "oracle.md")).read()
    assert "| `max_bounces` | 64 | integer 1..32767 |" in doc


@pytest.mark.parametrize("text,words", [
    ('{"camera": {"width": ' + "9" * 5001 + "}}", "cannot be read"),
    ("[" * 100000, "too deeply"),
    ('{"camera": {"width": 8, "width": 9}}', "twice"),
    ("\xff\xfe{", "not a text"),
], ids=["5001_digit_int", "100000_brackets", "duplicate_key", "not_utf8"])
def test_scene_files_refused_in_one_line(tmp_path, text, words):
    p = tmp_path / "s.json"
    p.write_bytes(text.encode("latin-1") if text.startswith("\xff") else text.encode())
    with pytest.raises(SceneError) as e:
        rr.load_scene(str(p))
    assert words in _one_line(str(e.value))
    rc, _, err = _run(["scene", p])
    assert rc == 2 and _one_line(err).startswith("refraction-ref: error:")


def test_utf8_bom_accepted(tmp_path):
    p = tmp_path / "bom.json"
    p.write_bytes(b"\xef\xbb\xbf" + json.dumps({"camera": {"width": 12}}).encode())
    assert rr.load_scene(str(p)).data["camera"]["width"] == 12


@pytest.mark.parametrize("key,block", [("water.height", "water"), ("volume.ior", "volume"),
                                       ("objects.0.deform.amplitude", "objects.0.deform")])
def test_set_into_a_null_block_says_it_is_absent(key, block):
    with pytest.raises(SceneError) as e:
        rr.load_scene(TINY, {key: "0.5"})
    msg = _one_line(str(e.value))
    assert f"no '{block}' block" in msg and f"--set '{block}=" in msg
    # and the advice works: the block set whole takes its defaults around the key given
    ok = rr.load_scene({**TINY, "objects": [{"mesh": "sphere"}]}, {"objects.0.deform": '{"amplitude": 0.05}'})
    assert ok.data["objects"][0]["deform"]["amplitude"] == 0.05


@pytest.mark.parametrize("value,words", [("9" * 5001, "5001-digit"), ("[" * 100000, "too deeply")])
def test_set_values_huge_or_deep(value, words):
    with pytest.raises(SceneError) as e:
        rr.load_scene(TINY, {"camera.width": value})
    assert words in _one_line(str(e.value))


def _volume_scene(ior):
    return {**TINY, "objects": [], "volume": {"ior": ior, "bounds": [[-1, -1, -1], [1, 1, 1]]}}


def test_volume_npy_read_and_checked_at_load(tmp_path):
    good = tmp_path / "good.npy"
    np.save(good, np.full((4, 4, 4), 1.2))
    assert rr.load_scene(_volume_scene(str(good))).data["volume"]["ior"] == str(good)
    trunc = tmp_path / "trunc.npy"
    trunc.write_bytes(good.read_bytes()[:-100])
    obj = tmp_path / "obj.npy"
    np.save(obj, np.array([{"a": 1}] * 64, dtype=object).reshape(4, 4, 4), allow_pickle=True)
    nan = tmp_path / "nan.npy"
    np.save(nan, np.full((4, 4, 4), np.nan))
    folder = tmp_path / "dir.npy"
    folder.mkdir()
    for p, words in ((trunc, "cannot be read"), (obj, "cannot be read"), (nan, "NaN"), (folder, "folder")):
        with pytest.raises(SceneError) as e:
            rr.load_scene(_volume_scene(str(p)))
        assert "volume.ior" in _one_line(str(e.value)) and words in str(e.value), (p, str(e.value))


def test_out_longer_than_the_file_system_takes_refused_before_the_render(tmp_path):
    out = tmp_path / "o" / ("x" * 300)
    rc, _, err = _run(["render", "--set", "camera.width=8", "--set", "camera.height=8", "--out", out])
    assert rc == 2 and "characters" in _one_line(err) and "--out" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("keep", [",", "", " , "])
def test_keep_with_no_stage_refused(tmp_path, keep):
    rc, _, err = _run(["render", "--keep", keep, "--out", tmp_path / "r"])
    assert rc == 2 and "names no stage" in _one_line(err)
    assert os.listdir(tmp_path) == []


def _npz(path, **arrays):
    np.savez(path, **arrays)
    return path


@pytest.mark.parametrize("meta,words", [
    (np.array("{not json"), "'meta' is not a JSON object"),
    (np.array("[1, 2]"), "'meta' is not a JSON object"),
    (np.array([{"a": 1}], dtype=object), "object array"),
    (np.zeros(3), "'meta' is not a JSON object"),
], ids=["not_json", "json_list", "object_array", "numbers"])
def test_compare_refuses_a_corrupt_npz_in_one_line(tmp_path, meta, words):
    p = _npz(tmp_path / "a.npz", meta=meta, status=np.zeros((2, 2), np.int8))
    rc, _, err = _run(["compare", p, p])
    assert rc == 2 and words in _one_line(err)


def test_compare_refuses_an_object_array_that_is_not_meta(tmp_path):
    p = _npz(tmp_path / "a.npz", meta=np.array("{}"), status=np.array([None, 1], dtype=object))
    rc, _, err = _run(["compare", p, p])
    assert rc == 2 and "'status'" in _one_line(err)


def test_compare_headline_counts_exit_versus_stop_each_way():
    H, W = 4, 5
    # B (the reference) exits everywhere; A stops at TIR (status 3) on 6 of the 20 pixels and is lost on 2
    sb = np.ones((H, W), np.int8)
    sa = sb.copy()
    sa.flat[:6] = 3
    sa.flat[6:8] = 4
    d = np.zeros((H, W, 3))
    d[..., 2] = 1.0
    A = {"status": sa, "hit": sa != 0, "exit_dir": d, "interfaces": np.zeros((H, W), np.int16)}
    B = {"status": sb, "hit": sb != 0, "exit_dir": d, "interfaces": np.zeros((H, W), np.int16)}
    c = compare_arrays(A, B)
    assert c["a_stopped_b_exited"] == pytest.approx(8 / 20) and c["a_exited_b_stopped"] == 0.0
    assert compare_arrays(B, A)["a_exited_b_stopped"] == pytest.approx(8 / 20)
    text = format_comparison(c, "A", "B")
    head = text.splitlines()[1]
    assert "median 0.000" in head and "stopped in A but exited in B: 40.0%" in head
    assert "over the 20 pixels hit in B" in text


def test_sweep_refuses_an_unknown_metric():
    from refraction_ref.sweep import ERROR_METRICS, SweepError, load_spec

    with pytest.raises(SweepError, match="'error' is 'nonsense'; choose one of " + ERROR_METRICS[0]):
        load_spec({"scenes": {"a": TINY}, "error": "nonsense"})
    with pytest.raises(SweepError, match="'time'"):
        load_spec({"scenes": {"a": TINY}, "time": "seconds"})
    assert load_spec({"scenes": {"a": TINY}, "error": "caustic_map_0_rel_l1"})["error"] == "caustic_map_0_rel_l1"


def test_sweep_refuses_to_overwrite_without_force(tmp_path):
    spec = tmp_path / "s.json"
    spec.write_text(json.dumps({"name": "run", "scenes": {"a": TINY}, "repeats": 1}))
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.png").write_bytes(b"old")
    rc, stdout, err = _run(["sweep", spec, "--out", out])
    assert rc == 2 and "run.png' exists" in _one_line(err) and "--force" in err and stdout == ""
    assert (out / "run.png").read_bytes() == b"old"


def test_docs_sweep_lists_the_metrics_and_readme_points_to_docs():
    from refraction_ref.sweep import ERROR_METRICS

    root = os.path.join(os.path.dirname(__file__), "..")
    doc = open(os.path.join(root, "docs", "sweep.md")).read()
    for m in ERROR_METRICS + ("caustic_map_<k>_rel_l1", "families", "reference_follows", "--force"):
        assert m in doc, m
    readme = open(os.path.join(root, "README.md")).read()
    assert "docs/sweep.md" in readme and "levelmap/knobs.py" not in readme


@pytest.mark.parametrize("raw,method,words", [
    ({"objects": [], "water": {}}, "imagespace", "ignores the scene's 'water'"),
    (_volume_scene(np.full((4, 4, 4), 1.2).tolist()), "imagespace", "read only by --method volumetric"),
])
def test_a_method_that_ignores_the_content_says_so(raw, method, words):
    from refraction_ref.scene import ignored_content

    data = rr.load_scene({**raw, "camera": {"width": 8, "height": 8, "eye": [0, 2, 2.6]}}).data
    assert words in _one_line(ignored_content(data, method))
    assert ignored_content(rr.load_scene(TINY).data, "imagespace") is None


def test_exact_reads_a_volume():
    """``--method exact`` on a volume scene is the graded-index reference (exact/volume.py): no warning."""
    from refraction_ref.scene import ignored_content

    raw = _volume_scene(np.full((4, 4, 4), 1.2).tolist())
    data = rr.load_scene({**raw, "camera": {"width": 8, "height": 8, "eye": [0, 2, 2.6]}}).data
    assert ignored_content(data, "exact") is None


def test_imagespace_on_water_only_scene_warns_on_the_cli(tmp_path):
    scene = tmp_path / "w.json"
    scene.write_text(json.dumps({"camera": {"width": 8, "height": 8, "eye": [0, 2, 2.6]}, "objects": [],
                                 "water": {}}))
    rc, _, err = _run(["render", scene, "--quiet", "--out", tmp_path / "r"])
    assert rc == 0 and err.count("refraction-ref: warning:") == 1 and "--method levelmap" in err


def test_mitsuba_side_files_named_after_the_xml(tmp_path):
    pytest.importorskip("trimesh")
    from refraction_ref.interop.mitsuba import export_files

    sc = {**TINY, "objects": [{"mesh": "sphere", "fit": 1.0}], "environment": {"type": "constant"}}
    a, b = tmp_path / "a.xml", tmp_path / "b.xml"
    sa = tmp_path / "sa.json"
    sa.write_text(json.dumps(sc))
    assert _run(["scene", sa, "--to", "mitsuba", a])[0] == 0
    assert _run(["scene", sa, "--to", "mitsuba", b])[0] == 0
    assert sorted(os.listdir(tmp_path)) == ["a.xml", "a_object_0.ply", "b.xml", "b_object_0.ply", "sa.json"]
    assert "a_object_0.ply" in a.read_text() and "b_object_0.ply" in b.read_text()
    assert export_files(rr.load_scene(sc), str(a))[1].endswith("a_object_0.ply")
    before = (tmp_path / "a_object_0.ply").read_bytes()
    rc, _, err = _run(["scene", sa, "--to", "mitsuba", a])
    assert rc == 2 and "exists" in _one_line(err) and "--force" in err
    assert _run(["scene", sa, "--to", "mitsuba", a, "--force"])[0] == 0
    assert (tmp_path / "a_object_0.ply").read_bytes() == before


def test_accepted_extremes_render_finite(tmp_path):
    """The largest accepted radiance, intensity and eye distance give finite images and caustics."""
    raw = {"camera": {"width": 8, "height": 8, "eye": [0, 0, 3]}, "objects": [{"mesh": "sphere", "fit": 1.0}],
           "receivers": [{"mesh": "plane", "transform": {"translate": [0, -1, 0]}}],
           "lights": [{"radiance": [1e6, 1e6, 1e6]}], "environment": {"intensity": 1e6},
           "caustics": {"map_size": 16}, "imagespace": {"photons": 16}}
    res = rr.render(rr.load_scene(raw), method="imagespace")
    for k in ("image", "caustic_rgb_0", "image_caustics", "ray_dir", "path_length"):
        assert np.all(np.isfinite(res[k])), k
    far = rr.render(rr.load_scene(_with({"camera.eye": [0, 0, 9e5], "camera.far": 1e6})), method="imagespace")
    assert np.all(np.isfinite(far["image"])) and np.all(np.isfinite(far["ray_dir"]))


@pytest.mark.parametrize("arrays", [
    {"meta": np.array("{not json"), "image": np.zeros((2, 2, 3), np.float32)},
    {"meta": np.array([{"a": 1}], dtype=object)},
    {"image": np.array([None, 1], dtype=object)},
], ids=["meta_not_json", "meta_object_array", "object_array"])
def test_check_reads_a_corrupt_candidate_npz_as_a_problem_of_the_case(tmp_path, arrays):
    """check judges a candidate's result.npz per case: a corrupt one is that case's one-line problem, no traceback
    (the whole command's exit statuses on such files: tests/test_fuzz.py, prop_check)."""
    from refraction_ref.golden.judging import read_result

    p = _npz(tmp_path / "result.npz", **arrays)
    got, problem = read_result(str(p))
    if problem is None:  # meta is not read by check: the arrays it judges are
        assert "meta" not in got and sorted(got) == sorted(k for k in arrays if k != "meta")
    else:
        assert got is None and "result.npz" in _one_line(problem)
    trunc = tmp_path / "t.npz"
    trunc.write_bytes(p.read_bytes()[:40])
    got, problem = read_result(str(trunc))
    assert got is None and _one_line(problem)


# ---------------------------------------------------------------- the CLI outsider's findings (after issue 30)

@pytest.mark.parametrize("kind", ["directional", "point"])
@pytest.mark.parametrize("key,value", [("position", {"0": 1}), ("position", "abc"), ("position", [1, True, 0]),
                                       ("direction", "down"), ("direction", [0, float("nan"), 0])])
def test_every_light_key_is_checked_whatever_the_kind(kind, key, value):
    light = {"type": kind, "position": [0, 3, 0]}
    light[key] = value
    with pytest.raises(SceneError) as e:
        rr.load_scene({**TINY, "lights": [light]})
    assert f"'lights[0].{key}'" in _one_line(str(e.value))
    rc, _, err = _run(["scene", "--set", f"lights.0.type={kind}", "--set", "lights.0.position=[0, 3, 0]",
                       "--set", f"lights.0.{key}={json.dumps(value)}"])
    assert rc == 2 and f"lights[0].{key}" in _one_line(err)


def test_set_into_a_null_key_suggests_a_value_that_is_valid():
    """The hint for a null key that is no block (a light's position) is a 3-vector, and following it works."""
    with pytest.raises(SceneError) as e:
        rr.load_scene(TINY, {"lights.0.position.0": "1"})
    msg = _one_line(str(e.value))
    hint = msg.split("--set '", 1)[1].split("'", 1)[0]
    assert '{"0"' not in msg and hint.startswith("lights.0.position=[")
    key, value = hint.split("=", 1)
    assert rr.load_scene(TINY, {key: value, "lights.0.type": "point"}).data["lights"][0]["position"] == \
        json.loads(value)


@pytest.mark.parametrize("key,value", [("volume.ior", "vol.npy"), ("volume.extinction", "0.1"),
                                       ("water.height", "0.2"), ("water.waves.0.amplitude", "0.01"),
                                       ("objects.0.deform.amplitude", "0.05")])
def test_null_block_hint_is_valid_json_that_loads_when_followed(tmp_path, key, value):
    np.save(tmp_path / "vol.npy", np.full((4, 4, 4), 1.2))
    base = {"camera": {"width": 8, "height": 8, "eye": [0, 2, 2.6]},
            "objects": [] if key.startswith(("volume", "water")) else [{"mesh": "sphere"}]}
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(base))
    with pytest.raises(SceneError) as e:
        rr.load_scene(str(scene), {key: value})
    hint = _one_line(str(e.value)).split("--set '", 1)[1].split("'", 1)[0]
    block, text = hint.split("=", 1)
    json.loads(text)  # valid JSON: the value quoted where it is a string
    s = rr.load_scene(str(scene), {block: text})  # and it loads as given (the volume's bounds included)
    node = s.data
    for p in key.split("."):
        node = node[int(p)] if isinstance(node, list) else node[p]
    assert node == json.loads(value) if value[0].isdigit() else node == value


def test_documented_keys_left_out_of_a_block_are_settable_one_at_a_time(tmp_path):
    np.save(tmp_path / "vol.npy", np.full((4, 4, 4), 1.2))
    vol = {"camera": {"width": 8, "height": 8}, "objects": [],
           "volume": {"ior": "vol.npy", "bounds": [[-1, -1, -1], [1, 1, 1]]}}
    (tmp_path / "v.json").write_text(json.dumps(vol))
    s = rr.load_scene(str(tmp_path / "v.json"), {"volume.extinction": "0.25", "volume.scattering": "[0.1, 0.1, 0.1]"})
    assert s.data["volume"]["extinction"] == 0.25 and s.data["volume"]["scattering"] == [0.1, 0.1, 0.1]
    w = rr.load_scene({"camera": {"width": 8, "height": 8, "eye": [0, 2, 2.6]}, "objects": []},
                      {"water": '{"height": 0.1}', "water.ior": "1.4"})
    assert w.data["water"]["ior"] == 1.4 and w.data["water"]["height"] == 0.1
    o = rr.load_scene({**TINY, "objects": [{"mesh": "sphere", "transform": {"scale": 2}}]},
                      {"objects.0.transform.rotate": "[0, 90, 0]"})
    assert o.data["objects"][0]["transform"]["rotate"] == [0, 90, 0]
    with pytest.raises(SceneError, match="unknown key 'iorr'; known keys here: absorption, height, ior"):
        rr.load_scene({**TINY, "water": {"height": 0.1}}, {"water.iorr": "1.4"})


def test_albedo_above_one_says_it_is_a_reflectance():
    with pytest.raises(SceneError) as e:
        rr.load_scene(_with({"receivers.0.albedo": [2, 0, 0]}))
    msg = _one_line(str(e.value))
    assert "must be in [0, 1]" in msg and "overflow" not in msg


@pytest.mark.parametrize("value", ['{"mesh": "sphere",}', "[1, 2", '"abc'])
def test_set_value_that_is_broken_json_says_so(value):
    with pytest.raises(SceneError) as e:
        rr.load_scene(TINY, {"objects.0": value})
    msg = _one_line(str(e.value))
    assert "did not parse as JSON" in msg and "got str" not in msg and "objects.0" in msg
    assert rr.load_scene(TINY, {"objects.0.mesh": "sphere"}).data["objects"][0]["mesh"] == "sphere"  # a plain word


def test_messages_show_values_as_json_and_set_takes_the_bracket_key():
    with pytest.raises(SceneError) as e:
        rr.load_scene(_with({"lights.0.type": True}))
    assert "is true;" in str(e.value) and "True" not in str(e.value)
    with pytest.raises(SceneError, match=r'\'receivers\[0\].fit\' must be a number, got "abc"'):
        rr.load_scene(_with({"receivers.0.fit": "abc"}))
    # a key as messages name it (objects[0].material.ior) works in --set as objects.0.material.ior does
    assert rr.load_scene(TINY, {"objects[0].material.ior": "1.4"}).data["objects"][0]["material"]["ior"] == 1.4


def test_camera_width_limit_is_the_real_one():
    from refraction_ref.scene import MAX_PIXELS

    with pytest.raises(SceneError, match=f"it must be <= {MAX_PIXELS}"):
        rr.load_scene(_with({"camera.width": 10**11}))
    with pytest.raises(SceneError, match=f"at most {MAX_PIXELS} pixels"):
        rr.load_scene(_with({"camera.width": 20000, "camera.height": 20000}))


def test_out_in_proc_says_the_folder_refuses_files(tmp_path):
    if not os.path.isdir("/proc/sys"):
        pytest.skip("no /proc")
    rc, _, err = _run(["render", "--set", "camera.width=8", "--out", "/proc/sys/r"])
    assert rc == 2 and "exists but new files cannot be made there" in _one_line(err)


def test_existing_output_names_force_on_the_cli_and_overwrite_in_python(tmp_path):
    from refraction_ref.result import check_writable

    (tmp_path / "r.npz").write_bytes(b"old")
    rc, _, err = _run(["render", "--set", "camera.width=8", "--out", tmp_path / "r"])
    assert rc == 2 and "pass --force to replace it" in _one_line(err) and "overwrite" not in err
    with pytest.raises(FileExistsError, match="overwrite=True"):
        check_writable([str(tmp_path / "r.npz")])


@pytest.mark.parametrize("name,words", [("truncated", "cannot be read"), ("flat", "has shape (64,)"),
                                        ("zero", "<= 0"), ("missing", "does not exist")])
def test_npy_errors_name_the_key_and_file_and_start_with_scene(tmp_path, name, words):
    p = tmp_path / f"{name}.npy"
    if name == "truncated":
        np.save(p, np.full((4, 4, 4), 1.2))
        p.write_bytes(p.read_bytes()[:-50])
    elif name == "flat":
        np.save(p, np.full(64, 1.2))
    elif name == "zero":
        np.save(p, np.zeros((4, 4, 4)))
    with pytest.raises(SceneError) as e:
        rr.load_scene(_volume_scene(str(p)))
    msg = _one_line(str(e.value))
    assert msg.startswith("scene: 'volume.ior'") and f"{name}.npy" in msg and words in msg, msg


def test_npy_extinction_shape_checked_at_load(tmp_path):
    np.save(tmp_path / "ior.npy", np.full((4, 4, 4), 1.2))
    np.save(tmp_path / "ext.npy", np.ones((5, 4, 4)))
    raw = _volume_scene(str(tmp_path / "ior.npy"))
    raw["volume"]["extinction"] = str(tmp_path / "ext.npy")
    with pytest.raises(SceneError, match=r"^scene: 'volume.extinction' \('.*ext.npy'\) has shape \(5, 4, 4\)"):
        rr.load_scene(raw)


def test_sweep_grid_message_names_the_key():
    from refraction_ref.sweep import SweepError, load_spec

    with pytest.raises(SweepError, match='grid key "imagespace.iterations" is 5; give a non-empty list'):
        load_spec({"scenes": {"a": TINY}, "grid": {"camera.width": [8], "imagespace.iterations": 5}})


def test_keep_names_checked_before_compiling(tmp_path, monkeypatch):
    import refraction_ref.warm as warm

    def no_compile(*a, **k):
        raise AssertionError("compiled before --keep was checked")

    monkeypatch.setattr(warm, "compile_report", no_compile)
    rc, _, err = _run(["render", "--keep", "peal", "--set", "camera.width=8", "--out", tmp_path / "r"])
    assert rc == 2 and "unknown stage 'peal'" in _one_line(err) and "peel" in err
    assert os.listdir(tmp_path) == []


def test_compare_plot_refuses_to_overwrite_without_force(tmp_path):
    a = _npz(tmp_path / "a.npz", meta=np.array("{}"), status=np.ones((2, 2), np.int8))
    png = tmp_path / "p.png"
    png.write_bytes(b"old")
    rc, out, err = _run(["compare", a, a, "--plot", png])
    assert rc == 2 and "p.png' exists" in _one_line(err) and "--force" in err and out == ""
    assert png.read_bytes() == b"old"
    rc, out, err = _run(["compare", "-h"])
    assert "and replace an existing --plot PNG" in " ".join(out.split())


def test_the_outsiders_guesses_are_in_the_docs():
    """Each sentence a new CLI user had to guess is in the doc it names (checked against the source above)."""
    root = os.path.join(os.path.dirname(__file__), "..")

    def text(p):
        return " ".join(open(os.path.join(root, p)).read().split())

    readme, oracle, sweep = text("README.md"), text("docs/oracle.md"), text("docs/sweep.md")
    for phrase in ["are fractions of the pixels hit in B", "`hit agree` is over every pixel", "`--json` adds `mean`",
                   "dominated by the caustic focus", "replaced only with `--force`", "creates missing parent folders",
                   "before its kernels are compiled or loaded", "`receiver_hit` are in"]:
        assert phrase in readme, phrase
    for phrase in ["`--set` takes that key as it is or as `objects.0.material.ior`", "did not parse as JSON",
                   "pixels that show only a receiver have `hit` false and status 0",
                   "whether or not its kind reads the key", "`--set volume.extinction=0.1`"]:
        assert phrase in oracle, phrase
    for phrase in ["sum|A - B| / sum|B|", 'mode="constant"', "`base` (not `grid`) overrides apply to the reference",
                   "created if missing", "`ok` for a task that succeeded", "`caustic_rel_l1.caustic_map_<k>`"]:
        assert phrase in sweep, phrase
