"""The command line: render, compare and scene, on small images."""

import json
import os

import numpy as np
import pytest

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


PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 2\nproperty list uchar int vertex_indices\nend_header\n")


def test_broken_meshes_are_refused_with_their_own_messages(tmp_path, capsys):
    from refraction_ref.meshes import load_mesh
    from refraction_ref.scene import SceneError

    files = {"nan.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 nan 0\nf 1 2 3\nf 1 2 4\n",
                         "1 vertex with NaN or infinite coordinates (the first: vertex 3"),
             "inf.ply": (PLY_HEAD + "0 0 0\n1 0 0\n0 1 0\n0 inf 0\n3 0 1 2\n3 0 1 3\n",
                         "1 vertex with NaN or infinite coordinates (the first: vertex 3"),
             "range.ply": (PLY_HEAD + "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 7\n",
                           "1 face with vertex indices outside 0..3 (the first: face 1"),
             "range.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n",
                           "has a face that names a vertex the file does not have")}
    for name, (text, message) in files.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(SceneError) as e:
            load_mesh(str(tmp_path / name))
        assert message in str(e.value) and "format" not in str(e.value), name
    out = tmp_path / "o"
    assert main(["render", "--out", str(out), "--set", f"objects.0.mesh={tmp_path / 'nan.obj'}",
                 "--set", "camera.width=16", "--set", "camera.height=16", "--quiet"]) == 2
    assert "NaN or infinite" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == sorted(files)  # nothing written


def test_scene_files_with_a_key_twice_or_a_folder_are_refused(tmp_path, capsys):
    (tmp_path / "dup.json").write_text('{"camera": {"width": 16, "height": 16, "width": 32}}')
    assert main(["scene", str(tmp_path / "dup.json")]) == 2
    assert "gives the key 'width' twice" in capsys.readouterr().err
    assert main(["scene", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
    (tmp_path / "img.json").write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff")
    assert main(["scene", str(tmp_path / "img.json")]) == 2
    assert "not a text (JSON) file" in capsys.readouterr().err


def test_workers_0_is_refused_before_any_work(tmp_path, capsys):
    spec = tmp_path / "s.json"
    spec.write_text(json.dumps({"name": "t", "scenes": {"bunny": None}, "methods": ["imagespace"],
                                "grid": {"imagespace.iterations": [1]}, "base": {"camera.width": 16}}))
    assert main(["golden", "build", str(tmp_path / "g"), "--workers", "0"]) == 2
    assert "--workers is 0; give at least 1 worker process" in capsys.readouterr().err
    assert main(["sweep", str(spec), "--out", str(tmp_path / "o"), "--workers", "0"]) == 2
    assert "--workers is 0; give at least 1 worker process" in capsys.readouterr().err
    assert main(["crosscheck", "--only", "is_ior_1", "--out", str(tmp_path / "x"), "--workers", "0"]) == 2
    assert "--workers is 0; give at least 1 worker process" in capsys.readouterr().err
    assert os.listdir(tmp_path) == ["s.json"]


def test_a_sweep_is_quiet_and_its_plot_labelled_per_scene_and_knob(tmp_path, capfd):
    from refraction_ref.sweep import plot_series

    (tmp_path / "f.py").write_text("def f(n, scale):\n    return {'total_ms': n * scale, 'err': 1.0 / n}\n")
    spec = tmp_path / "s.json"
    spec.write_text(json.dumps({"name": "t", "task": "f.py:f", "grid": {"n": [1, 2, 4]}, "base": {"scale": 2.0},
                                "error": "err"}))
    assert main(["sweep", str(spec), "--out", str(tmp_path / "o"), "--workers", "1", "--quiet"]) == 0
    out, err = capfd.readouterr()  # the worker processes' output too
    assert "3 tasks ok" in out and err == ""  # no CommClosedError, "still alive ... killing", port warnings
    assert sorted(os.listdir(tmp_path / "o")) == ["t.csv", "t.png"]
    rows = [{"scene": s, "method": "imagespace", "imagespace.iterations": i, "camera.width": 16, "status": "ok",
             "total_ms": 10.0 * i, "e": 1.0 / i} for s in ("bunny", "sphere") for i in (1, 5)]
    series = plot_series(rows, "e", knobs=["imagespace.iterations", "camera.width"])
    assert [s[0] for s in series] == ["bunny, imagespace", "sphere, imagespace"]
    assert series[0][1] == [(10.0, 1.0), (50.0, 0.2)] and series[1][2] == ["iterations=1", "iterations=5"]


def test_bad_out_paths_are_refused_before_any_work_and_leave_nothing(tmp_path, monkeypatch, capsys):
    import sys

    def no_render(*a, **k):
        raise AssertionError("rendered before checking --out")

    monkeypatch.setattr(sys.modules["refraction_ref.render"], "run_method", no_render)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "f").write_text("a file")
    small = ["--set", "camera.width=16", "--set", "camera.height=16", "--quiet"]
    for out, message in (("o/dir/", "has no file name (it ends in a folder separator)"),
                         ("", "the output prefix (--out) is empty"),
                         ("/proc/nope/x", "cannot write the output in '/proc/nope'"),
                         ("f/x", "is a file, not a folder")):
        assert main(["render", "--out", out] + small) == 2, out
        err = capsys.readouterr().err
        assert err.startswith("refraction-ref: error:") and message in err, (out, err)
        assert os.listdir(tmp_path) == ["f"], out  # no hidden temporary file, no empty folder
    assert main(["golden", "build", "f"]) == 2
    err = capsys.readouterr().err
    assert "golden suite folder 'f' is a file, not a folder" in err and "Errno" not in err


def test_a_failed_save_removes_its_temporary_file_and_new_folders(tmp_path, monkeypatch):
    from refraction_ref.result import Result

    def broken(path, **arrays):
        with open(path, "wb") as f:
            f.write(b"PK partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(OSError):
        Result({"x": np.zeros(3)}).save(tmp_path / "new" / "deeper" / "r")
    assert os.listdir(tmp_path) == []


def test_files_that_are_not_npz_results_are_named_as_such(tmp_path, capsys):
    import imageio.v3 as iio

    from refraction_ref.files import NotNpzError, load_npz

    iio.imwrite(tmp_path / "r.png", np.zeros((4, 4, 3), np.uint8))
    (tmp_path / "r.txt").write_text("hello\n")
    np.savez(tmp_path / "ok.npz", x=np.zeros(2))
    for name, kind in (("r.png", "a PNG image"), ("r.txt", "a text file")):
        assert main(["compare", str(tmp_path / name), str(tmp_path / "ok.npz")]) == 2
        err = capsys.readouterr().err
        assert f"{tmp_path / name} is not a .npz result ({kind})" in err, err
        assert "pickle" not in err and "unsafe" not in err
        with pytest.raises(NotNpzError, match="is not a .npz result"):
            load_npz(tmp_path / name)
    with load_npz(tmp_path / "ok.npz") as z:
        assert z.files == ["x"]


def test_inputs_that_are_not_what_the_scene_says_are_refused_at_load(tmp_path, capsys):
    from refraction_ref import load_scene
    from refraction_ref.scene import SceneError

    (tmp_path / "env.txt").write_text("not an image\n")
    assert main(["scene", "--set", "environment.type=latlong", "--set", f"environment.path={tmp_path / 'env.txt'}"]) == 2
    err = capsys.readouterr().err
    assert "environment.path" in err and "is not an image imageio can read (a text file" in err
    (tmp_path / "ior.npy").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
    with pytest.raises(SceneError, match=r"^scene: 'volume.ior' \('.*ior.npy'\) is not a .npy array \(a PNG image\)") as e:
        load_scene({"volume": {"ior": str(tmp_path / "ior.npy"), "bounds": [[0, 0, 0], [1, 1, 1]]}})
    assert "pickle" not in str(e.value)


def test_compare_plot_names_its_panels_by_run(tmp_path, monkeypatch, capsys):
    import refraction_ref as rr
    from refraction_ref import compare

    res = rr.render({"camera": {"width": 16, "height": 16}})
    res.save(tmp_path / "mine")
    res.save(tmp_path / "theirs")
    seen = []
    monkeypatch.setattr(compare, "plot_comparison", lambda a, b, path, name_a, name_b: seen.append((name_a, name_b))
                        or str(path))
    assert main(["compare", str(tmp_path / "mine.npz"), str(tmp_path / "theirs.npz"), "--plot",
                 str(tmp_path / "p.png")]) == 0
    assert seen == [("mine.npz (imagespace)", "theirs.npz (imagespace)")]


def test_cli_conventions_version_help_and_usage_errors(capsys, monkeypatch):
    import refraction_ref
    from refraction_ref import cli

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"refraction-ref {refraction_ref.__version__}"
    assert main(["render", "--set", "camera.width"]) == 2  # no '=': a usage error, before any work
    err = capsys.readouterr().err
    assert err.startswith("refraction-ref: error: --set expects KEY=VALUE, got 'camera.width'")
    with pytest.raises(SystemExit) as e:
        main(["render", "--method", "nope"])
    assert e.value.code == 2 and "refraction-ref: error: render: argument --method" in capsys.readouterr().err
    parser = []

    def grab(self, *a, **k):  # the whole parser, as main builds it
        parser.append(self)
        raise SystemExit(0)

    monkeypatch.setattr(cli.argparse.ArgumentParser, "parse_args", grab)
    with pytest.raises(SystemExit):
        main([])
    monkeypatch.undo()

    def undocumented(p, name):
        for act in p._actions:
            if isinstance(act, cli.argparse._SubParsersAction):
                for n, sp in act.choices.items():
                    yield from undocumented(sp, f"{name} {n}")
            elif not act.help:
                yield f"{name} {'/'.join(act.option_strings) or act.dest}"

    assert list(undocumented(parser[0], "refraction-ref")) == []
    sweep_help = " ".join(parser[0]._subparsers._group_actions[0].choices["sweep"].format_help().split())
    assert "(and NAME.parquet where pyarrow is installed)" in sweep_help  # pyarrow is not a dependency


def test_render_quiet_prints_only_the_files_written(tmp_path, capsys):
    assert main(["render", "--out", str(tmp_path / "q"), "--set", "camera.width=16", "--set", "camera.height=16",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert out == f"wrote {tmp_path / 'q.npz'}, {tmp_path / 'q.png'}\n"


ORACLE = os.path.join(os.path.dirname(__file__), "..", "docs", "oracle.md")


def _section(text, title):
    """The lines of the oracle's section whose heading contains ``title``, up to the next heading."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("#") and title in ln)
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("#")), len(lines))
    return lines[start + 1:end]


def _documented_buffers(rows):
    """stage -> the buffer names its table rows list (``_r``, ``_l`` index suffixes dropped)."""
    import re

    out, stage = {}, None
    for ln in rows:
        cells = [c.strip() for c in ln.split("|")[1:-1]]
        if len(cells) < 2 or set(cells[0]) <= {"-"} and cells[0]:
            continue
        if cells[0]:
            stage = re.findall(r"`([a-z_]+)`", cells[0])
            stage = stage[0] if stage else None
        for name in re.findall(r"`([a-z_]+)`", cells[1]):
            out.setdefault(stage, set()).add(re.sub(r"(_[rl])+$", "", name))
    return out


def test_the_contract_documents_every_knob_meta_key_and_stage_buffer():
    import re

    import refraction_ref as rr
    from refraction_ref.scene import BLOCKS

    text = open(ORACLE).read()
    for name, block in BLOCKS.items():
        if block.defaults is None:
            continue
        rows = "\n".join(_section(text, f"### `{name}` block"))
        missing = [k for k in block.defaults if f"| `{k}` |" not in rows]
        assert not missing, f"docs/oracle.md, `{name}` block: no row for {missing}"
    pool = "refraction_ref/data/levelmap_default.json"
    runs = {"imagespace": rr.render("refraction_ref/data/caustics_default.json", keep="stages", overrides={
                "camera.width": 16, "camera.height": 16, "imagespace.photons": 32, "imagespace.caustic_map": 16}),
            "levelmap": rr.render(pool, method="levelmap", keep="caustics,casting", overrides={
                "camera.width": 16, "camera.height": 16, "levelmap.map_size": 16, "water.resolution": 8})}
    meta = "\n".join(_section(text, "## meta"))
    for res in runs.values():
        assert not [k for k in res.meta if f"`{k}`" not in meta], "docs/oracle.md, meta: undocumented keys"
    for method, res in runs.items():
        documented = _documented_buffers(_section(text, f"### `{method}` ("))
        for key in (k for k in res.arrays if k.startswith("stage.")):
            _, stage, buf = key.split(".", 2)
            assert re.sub(r"(_\d+)+$", "", buf) in documented.get(stage, ()), f"docs/oracle.md: {method} {key}"


def test_a_reader_that_leaves_early_gets_no_traceback():
    """``refraction-ref scene | head``: the pipe closes before the scene is printed."""
    import subprocess
    import sys

    p = subprocess.Popen([sys.executable, "-m", "refraction_ref.cli", "scene"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    p.stdout.close()  # the reader is gone before the child writes
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141, err
    assert "Traceback" not in err and "BrokenPipe" not in err
