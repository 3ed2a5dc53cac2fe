"""The command line: render, compare and scene, on small images."""

import json
import os

import numpy as np

from refraction_ref.cli import main
from refraction_ref.result import load_result

DATA = os.path.join(os.path.dirname(__file__), "..", "refraction_ref", "data")


def test_render_compare_and_refuse_overwrite(tmp_path, capsys):
    out = str(tmp_path / "is")
    small = ["--set", "camera.width=48", "--set", "camera.height=40", "--quiet"]
    assert main(["render", "--out", out] + small) == 0
    assert main(["render", "--method", "exact", "--out", str(tmp_path / "ex")] + small) == 0
    r = load_result(out + ".npz")
    assert r.arrays["exit_dir"].shape == (40, 48, 3)
    assert json.loads(json.dumps(r.meta))["params"]["iterations"] == 5
    capsys.readouterr()
    assert main(["compare", out + ".npz", str(tmp_path / "ex.npz"), "--json",
                 "--plot", str(tmp_path / "cmp.png")]) == 0
    stats = json.loads(capsys.readouterr().out.split("\nwrote")[0])
    assert stats["pixels"] == int(load_result(str(tmp_path / "ex.npz")).arrays["hit"].sum()) > 0
    assert 0.0 <= stats["exit_dir_deg"]["median"] < 5.0
    assert (tmp_path / "cmp.png").stat().st_size > 0
    # an existing output is never overwritten unless asked
    assert main(["render", "--out", out] + small) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["render", "--out", out, "--force"] + small) == 0


def test_water_runs_compare_by_caustic_maps(tmp_path, capsys):
    scene = os.path.join(DATA, "levelmap_default.json")
    small = ["--set", "camera.width=32", "--set", "camera.height=32", "--set", "levelmap.map_size=64",
             "--set", "water.resolution=32", "--set", "levelmap.exact_samples=256", "--quiet"]
    assert main(["render", scene, "--method", "levelmap", "--out", str(tmp_path / "lm")] + small) == 0
    assert main(["render", scene, "--method", "exact", "--out", str(tmp_path / "ex")] + small) == 0
    capsys.readouterr()
    assert main(["compare", str(tmp_path / "lm.npz"), str(tmp_path / "ex.npz"), "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert set(stats["caustic_rel_l1"]) >= {"caustic_map_0"}
    assert all(np.isfinite(v) and v >= 0 for v in stats["caustic_rel_l1"].values())


def test_bad_input_is_a_clear_error(tmp_path, capsys):
    assert main(["render", str(tmp_path / "missing.json"), "--out", str(tmp_path / "x")]) == 2
    assert "missing.json" in capsys.readouterr().err
    assert main(["scene", "--set", "imagespace.iterations=7"]) == 0
    assert json.loads(capsys.readouterr().out)["imagespace"]["iterations"] == 7


BLOCKS_FROM_SET = [("camera", '{"width":64}', {"camera": {"width": 64}}),
                   ("objects.0", '{"mesh":"sphere"}', {"objects": [{"mesh": "sphere"}]}),
                   ("lights.0", '{"type":"point","position":[0,0,0]}',
                    {"lights": [{"type": "point", "position": [0, 0, 0]}]}),
                   ("lights", '[{"type":"directional"}]', {"lights": [{"type": "directional"}]}),
                   ("imagespace", '{"iterations":3}', {"imagespace": {"iterations": 3}})]


def test_blocks_given_through_set_get_the_defaults_of_a_scene_file(tmp_path, capsys):
    for key, value, as_file in BLOCKS_FROM_SET:
        f = tmp_path / "s.json"
        f.write_text(json.dumps(as_file))
        assert main(["scene", "--set", f"{key}={value}"]) == 0, key
        from_set = json.loads(capsys.readouterr().out)
        assert main(["scene", str(f)]) == 0
        assert from_set == json.loads(capsys.readouterr().out), key
    assert main(["scene", "--set", 'objects.0={"mesh":"sphere","bogus":1}']) == 2
    err = capsys.readouterr().err
    assert "unknown key 'objects[0].bogus'" in err and "Traceback" not in err


def test_bad_dotted_keys_say_what_is_there(capsys):
    assert main(["scene", "--set", "camera..width=5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("refraction-ref: error:") and "eye, far, fov_y, height, near, target, up, width" in err
    assert main(["scene", "--set", "objects.5.fit=2"]) == 2
    assert "'objects' has 1 item (indices 0 to 0)" in capsys.readouterr().err
    assert main(["scene", "--set", "camra.width=3"]) == 2
    assert "known keys at the top level: camera," in capsys.readouterr().err
