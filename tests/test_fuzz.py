"""Property-based fuzzing of everything a user types (issue 30): scene dicts and files, ``--set`` values,
CLI flags, and the ``.npz`` files ``compare`` and ``check`` read.

The property, for every input: it is refused with one line (``SceneError`` and its kin from Python; exit 2
and one ``refraction-ref: error:`` line from the CLI, argparse's usage line aside; never a traceback) and the
refusal leaves nothing on disk, or it is accepted, and then a render (tiny: 8 to 48 pixels, the cheap
methods) has finite values wherever docs/oracle.md promises them (every float array but ``exit_pos`` and
``exit_dir``, which are finite where ``status`` is 1).

Two profiles: the fast one runs in CI (derandomized, a few hundred inputs, about a minute); the long one
(``pytest -m slow tests/test_fuzz.py``) runs at least 5,000 inputs and writes its counts (inputs,
refusals, renders, tracebacks, non-finite outputs, files left) to ``benchmarks/results/fuzz_long.json``.
"""

from __future__ import annotations

import collections
import contextlib
import io
import json
import os
import shutil
import tempfile
import traceback

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import refraction_ref as rr
from refraction_ref import cli
from refraction_ref.compare import CompareError
from refraction_ref.files import NotNpzError, OutputError
from refraction_ref.validation import SceneError

#: What a refusal from Python may raise (each names the input; the CLI maps them to exit 2).
REFUSALS = (SceneError, CompareError, NotNpzError, OutputError, FileExistsError, FileNotFoundError)
COUNTS = collections.Counter()
FAILURES = []  # (kind, input, detail) of the first few property violations, for the long profile's report

BASE = {"camera": {"width": 12, "height": 12},
        "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.3}}],
        "receivers": [{"mesh": "plane", "transform": {"translate": [0, -1.2, 0]}}],
        "lights": [{"type": "directional", "direction": [0, -1, 0], "radiance": [1, 1, 1]}],
        "caustics": {"map_size": 16}, "imagespace": {"photons": 16}}

#: Keys whose values the fuzzer sets (dotted, list items by index); renders follow only from these
SCENE_KEYS = ["camera", "camera.eye", "camera.target", "camera.up", "camera.fov_y", "camera.width", "camera.height",
              "camera.near", "camera.far", "outside_ior", "environment", "environment.type", "environment.colors",
              "environment.intensity", "environment.tiles", "environment.path", "objects", "objects.0",
              "objects.0.mesh", "objects.0.fit", "objects.0.size", "objects.0.transform", "objects.0.transform.scale",
              "objects.0.transform.rotate", "objects.0.transform.translate", "objects.0.material",
              "objects.0.material.ior", "objects.0.material.absorption", "objects.0.deform", "objects.0.name",
              "receivers", "receivers.0", "receivers.0.fit", "receivers.0.size", "receivers.0.albedo",
              "receivers.0.mesh", "receivers.0.transform.translate", "lights", "lights.0", "lights.0.type",
              "lights.0.direction", "lights.0.position", "lights.0.radiance"]
#: Keys set but not rendered (their accepted values may be slow to render: knob blocks, water, volume)
LOAD_ONLY_KEYS = ["water", "water.height", "water.size", "water.waves", "volume", "volume.ior", "volume.bounds",
                  "imagespace", "imagespace.iterations", "exact", "exact.max_bounces", "exact.photons",
                  "caustics", "caustics.map_size", "levelmap", "levelmap.planes", "volumetric",
                  "volumetric.resolution", "no_such_key", "objects.0.no_such_key"]

SPECIAL = [0, -1, 1, 0.5, 2.6, 1e-300, 1e-7, 1e6, 1e7, -1e7, 1e200, 1e300, 10**30, 10**400, 2**31, 2**63,
           float("nan"), float("inf"), -float("inf"), True, False, None, "", "x", "abc", "red", "sphere", "plane",
           "bunny", "point", "checker", "constant", "latlong", [], {}, [None], [1], [1, 2], [0, 0, 0], [1, 2, 3],
           [True, 0, 2.6], [0, 1e200, 0], [float("nan"), 0, 0], [[1, 2, 3], [4, 5, 6]], [[0.9] * 3, [0.1] * 3],
           {"a": 1}, {"height": 0.5}, {"mesh": "sphere"}, [{"mesh": "sphere"}], [[[[[]]]]], "[" * 50]
weird = st.one_of(
    st.sampled_from(SPECIAL),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-5, 5),
    st.integers(-10**7, 10**7),
    st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-3, 3), st.booleans()),
             max_size=4),
    st.lists(st.floats(-3, 3), min_size=2, max_size=3),
    st.text(max_size=8),
)
def _vec(lo, hi, n=3):
    return st.lists(st.floats(lo, hi), min_size=n, max_size=n)


#: Values inside (or at the edges of) the documented ranges, so that a good share of inputs is accepted and
#: rendered: the extremes the issue found (radiance, intensity, eye distance, fov_y, fit) at their limits
PLAUSIBLE = {
    "camera.eye": st.one_of(_vec(-5, 5), st.sampled_from([[0, 0, 1e6], [0, 0, 9e5], [0, 0, 3]])),
    "camera.target": _vec(-1, 1), "camera.up": _vec(-1, 1),
    "camera.fov_y": st.one_of(st.floats(0.1, 179), st.sampled_from([0.1, 1, 179])),
    "camera.width": st.integers(8, 48), "camera.height": st.integers(8, 48),
    "camera.near": st.floats(1e-3, 1), "camera.far": st.floats(2, 1e6),
    "outside_ior": st.floats(0.5, 3), "environment.type": st.sampled_from(["checker", "constant"]),
    "environment.colors": st.lists(_vec(0, 1e6), min_size=2, max_size=2),
    "environment.intensity": st.one_of(st.floats(0, 1e6), st.just(1e6)), "environment.tiles": st.integers(1, 10**6),
    "objects.0.mesh": st.sampled_from(["sphere", "plane", "teapot"]),
    "objects.0.fit": st.one_of(st.floats(1e-3, 3), st.just(1e6)), "objects.0.size": _vec(0.1, 10, 2),
    "objects.0.transform.scale": st.floats(1e-3, 3), "objects.0.transform.rotate": _vec(-1e6, 1e6),
    "objects.0.transform.translate": _vec(-3, 3), "objects.0.material.ior": st.floats(0.5, 1e6),
    "objects.0.material.absorption": _vec(0, 1e6), "objects.0.deform": st.fixed_dictionaries(
        {"amplitude": st.floats(-0.1, 0.1), "wavelength": st.floats(0.01, 2), "direction": _vec(-1, 1)}),
    "receivers.0.fit": st.floats(1e-3, 1e6), "receivers.0.size": _vec(1e-3, 1e6, 2),
    "receivers.0.albedo": _vec(0, 1), "receivers.0.transform.translate": _vec(-3, 3),
    "lights.0.type": st.sampled_from(["directional", "point"]), "lights.0.direction": _vec(-1, 1),
    "lights.0.position": _vec(-1e6, 1e6), "lights.0.radiance": st.one_of(_vec(0, 1e6), st.just([1e6] * 3)),
}
mutations = st.lists(st.one_of(st.tuples(st.sampled_from(SCENE_KEYS + LOAD_ONLY_KEYS), weird),
                               st.sampled_from(sorted(PLAUSIBLE)).flatmap(lambda k: st.tuples(st.just(k),
                                                                                             PLAUSIBLE[k])),
                               st.sampled_from(sorted(PLAUSIBLE)).flatmap(lambda k: st.tuples(st.just(k),
                                                                                             PLAUSIBLE[k]))),
                     min_size=1, max_size=3)


def _set(d, key, value):
    """Set a dotted key in a raw scene dict (creating objects on the way); False where the path is blocked."""
    node, parts = d, key.split(".")
    for p in parts[:-1]:
        if isinstance(node, list):
            if not p.isdigit() or int(p) >= len(node) or not isinstance(node[int(p)], (dict, list)):
                return False
            node = node[int(p)]
        elif isinstance(node, dict):
            if not isinstance(node.get(p), (dict, list)):
                node[p] = {}
            node = node[p]
        else:
            return False
    if isinstance(node, list):
        if not parts[-1].isdigit() or int(parts[-1]) >= len(node):
            return False
        node[int(parts[-1])] = value
    elif isinstance(node, dict):
        node[parts[-1]] = value
    else:
        return False
    return True


def _scene(muts, receivers):
    raw = json.loads(json.dumps(BASE))
    if not receivers:
        raw.pop("receivers")
    for k, v in muts:
        _set(raw, k, v)
    return raw


def _one_line(msg, kind, what):
    if not msg.strip() or "\n" in msg.strip() or "Traceback" in msg:
        _fail(kind, what, f"not one line: {msg[:300]!r}")


def _fail(kind, what, detail):
    COUNTS["violations"] += 1
    if len(FAILURES) < 20:
        FAILURES.append({"kind": kind, "input": str(what)[:300], "detail": detail[:600]})
    raise AssertionError(f"{kind}: {str(what)[:300]}: {detail[:600]}")


def _nonfinite(arrays):
    """The keys of a run's arrays that hold a non-finite value where docs/oracle.md promises finite ones."""
    bad = []
    st_ = arrays.get("status")
    for k, v in arrays.items():
        v = np.asarray(v)
        if k.startswith("stage.") or v.dtype.kind != "f":
            continue
        if k in ("exit_pos", "exit_dir"):
            if st_ is not None and not np.all(np.isfinite(v[np.asarray(st_) == 1])):
                bad.append(k)
        elif not np.all(np.isfinite(v)):
            bad.append(k)
    return bad


def _renderable(muts, data):
    c = data["camera"]
    return (all(k in SCENE_KEYS for k, _ in muts) and c["width"] * c["height"] <= 48 * 48
            and data.get("water") is None and data.get("volume") is None)


def _render_checked(scene, method, what):
    try:
        res = rr.render(scene, method=method)
    except SceneError as e:  # a method's precondition (the camera inside an object, a light inside the objects)
        _one_line(str(e), "render refusal", what)
        COUNTS["refusals"] += 1
        return
    except Exception as e:  # noqa: BLE001 - the property: nothing else may escape
        COUNTS["tracebacks"] += 1
        _fail("traceback", what, "".join(traceback.format_exception(e))[-600:])
    COUNTS["renders"] += 1
    bad = _nonfinite(res.arrays)
    if bad:
        COUNTS["nonfinite"] += 1
        _fail("non-finite", what, f"{method}: {bad}")


# --------------------------------------------------------------------- properties
def prop_scene_api(muts, receivers, render, method):
    """``load_scene(dict)``: refused in one line, or accepted (and rendered finite when tiny)."""
    COUNTS["inputs"] += 1
    raw = _scene(muts, receivers)
    try:
        sc = rr.load_scene(raw)
    except SceneError as e:
        COUNTS["refusals"] += 1
        _one_line(str(e), "refusal", muts)
        return
    except Exception as e:  # noqa: BLE001
        COUNTS["tracebacks"] += 1
        _fail("traceback", muts, "".join(traceback.format_exception(e))[-600:])
    COUNTS["accepted"] += 1
    if render and _renderable(muts, sc.data):
        _render_checked(sc, method, muts)


def _run_cli(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = cli.main([str(a) for a in argv])
        except SystemExit as e:
            rc = e.code
        except Exception as e:  # noqa: BLE001
            COUNTS["tracebacks"] += 1
            _fail("traceback", argv, "".join(traceback.format_exception(e))[-600:])
    return rc, out.getvalue(), err.getvalue()


def _check_cli(argv, tmp, out_dir, ok=(0,)):
    """Run the CLI; check exit status, the refusal's one line, no file left by a refusal; the status."""
    before = set(os.listdir(tmp))
    rc, out, err = _run_cli(argv)
    if rc == 2:
        COUNTS["refusals"] += 1
        lines = [x for x in err.strip().splitlines() if not x.startswith(("usage:", "       ", "refraction-ref: warning"))]
        if len(lines) != 1 or not lines[0].startswith("refraction-ref: error:"):
            _fail("refusal not one line", argv, err[-600:])
        left = sorted(set(os.listdir(tmp)) - before) + (os.listdir(out_dir) if os.path.isdir(out_dir) else [])
        if left:
            COUNTS["files_left"] += 1
            _fail("files left", argv, str(left))
    elif rc not in ok:
        _fail("exit status", argv, f"{rc}: {err[-400:]}")
    return rc, out, err


def _tiny_text(text):
    return text


texts = st.one_of(
    mutations.map(lambda m: json.dumps(_scene(m, True), allow_nan=True)),
    mutations.map(lambda m: "\ufeff" + json.dumps(_scene(m, False), allow_nan=True)),
    st.text(max_size=40),
    st.binary(max_size=40).map(lambda b: b.decode("latin-1")),
    st.integers(1, 200).map(lambda n: json.dumps(BASE)[:n]),
    st.sampled_from(['{"camera": {"width": ' + "9" * 5001 + "}}", "[" * 100000, "{" * 3000, '{"a": 1, "a": 2}',
                     "null", "[]", "42", '"scene"', '{"camera": NaN}', '{"camera": {"fov_y": Infinity}}']),
)


def prop_scene_file(text, command, render):
    """A scene file through ``refraction-ref scene`` or ``render``: exit 0 or 2 with one line, nothing left."""
    COUNTS["inputs"] += 1
    tmp = tempfile.mkdtemp(prefix="fuzz")
    try:
        p = os.path.join(tmp, "s.json")
        with open(p, "w", encoding="utf-8", errors="surrogatepass") as f:
            f.write(text)
        out_dir = os.path.join(tmp, "out")
        if command == "render" and render:
            argv = ["render", p, "--quiet", "--set", "camera.width=8", "--set", "camera.height=8",
                    "--set", "imagespace.photons=16", "--set", "caustics.map_size=16", "--out", os.path.join(out_dir, "r")]
        else:
            argv = ["scene", p]
        rc, _, _ = _check_cli(argv, tmp, out_dir)
        if rc == 0:
            COUNTS["accepted"] += 1
            if argv[0] == "render":
                COUNTS["renders"] += 1
                res = rr.load_result(os.path.join(out_dir, "r.npz"))
                bad = _nonfinite(res.arrays)
                if bad:
                    COUNTS["nonfinite"] += 1
                    _fail("non-finite", text[:200], str(bad))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


set_values = st.one_of(weird.map(lambda v: json.dumps(v, allow_nan=True)), st.text(max_size=12),
                       st.sampled_from(["9" * 5001, "[" * 2000, "null", "true", "{}", "[1,2,3]", "=", ""]))
set_keys = st.one_of(st.sampled_from(SCENE_KEYS + LOAD_ONLY_KEYS + ["water.height", "volume.ior",
                                                                    "objects.0.deform.amplitude", "objects.5.fit",
                                                                    "camera.eye.0", "camera.width.x", ".", ""]),
                     st.text(max_size=10))


def prop_set(key, value):
    """``refraction-ref scene --set KEY=VALUE``: exit 0 or 2 with one line."""
    COUNTS["inputs"] += 1
    tmp = tempfile.mkdtemp(prefix="fuzz")
    try:
        rc, _, _ = _check_cli(["scene", "--set", f"{key}={value}"], tmp, os.path.join(tmp, "none"))
        COUNTS["accepted"] += rc == 0
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


flag_values = st.one_of(st.text(max_size=10), st.sampled_from(["", ",", "stages", "peel", "trace", "peel,trace",
                                                               "x" * 300, "a/" * 3, "/", ".", "..", ".npz", "-1"]))


def prop_flags(out_name, keep, method, extra):
    """``render`` with random ``--out``, ``--keep``, ``--method`` and extra flags on a tiny scene."""
    COUNTS["inputs"] += 1
    tmp = tempfile.mkdtemp(prefix="fuzz")
    try:
        out_dir = os.path.join(tmp, "out")
        argv = ["render", "--quiet", "--set", "camera.width=8", "--set", "camera.height=8",
                "--out", os.path.join(out_dir, out_name) if out_name else "", "--method", method]
        if keep is not None:
            argv += ["--keep", keep]
        argv += extra
        rc, _, _ = _check_cli(argv, tmp, out_dir)
        if rc == 0:
            COUNTS["accepted"] += 1
            COUNTS["renders"] += 1
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _fake_npz(path, meta_kind, arrays_kind, seed):
    rng = np.random.default_rng(seed)
    H, W = 4, 4
    arrays = {}
    if arrays_kind in ("per_pixel", "broken"):
        st_ = rng.integers(0, 5, (H, W)).astype(np.int8)
        arrays = {"status": st_, "hit": st_ != 0, "exit_dir": rng.normal(size=(H, W, 3)),
                  "interfaces": rng.integers(0, 4, (H, W)).astype(np.int16),
                  "image": rng.random((H, W, 3)).astype(np.float32)}
        if arrays_kind == "broken":
            k = sorted(arrays)[seed % len(arrays)]
            arrays[k] = [np.zeros(3), np.array([None, 1], dtype=object), np.zeros((2, 2, 2)), np.array("x"),
                         None][seed % 5]
            if arrays[k] is None:
                del arrays[k]
    elif arrays_kind == "caustics":
        arrays = {"caustic_map_0": rng.random([(8, 8), (4, 4, 3), (), (2,)][seed % 4])}
    meta = {"json": np.array(json.dumps({"scene": {"camera": {"width": W, "height": H}}})),
            "text": np.array("{not json"), "list": np.array("[1]"), "object": np.array([{"a": 1}], dtype=object),
            "numbers": np.zeros(3), "none": None}[meta_kind]
    if meta is not None:
        arrays["meta"] = meta
    np.savez(path, **arrays)


def prop_compare(meta_a, arrays_a, meta_b, arrays_b, seed, flags, truncate):
    """``compare A.npz B.npz`` on random, partial or corrupt files: exit 0 or 2 with one line."""
    COUNTS["inputs"] += 1
    tmp = tempfile.mkdtemp(prefix="fuzz")
    try:
        a, b = os.path.join(tmp, "a.npz"), os.path.join(tmp, "b.npz")
        _fake_npz(a, meta_a, arrays_a, seed)
        _fake_npz(b, meta_b, arrays_b, seed + 1)
        if truncate:
            data = open(a, "rb").read()
            with open(a, "wb") as f:
                f.write(data[: max(1, len(data) * truncate // 8)])
        out_dir = os.path.join(tmp, "plots")
        argv = ["compare", a, b] + flags
        if "--plot" in flags:
            argv[argv.index("--plot") + 1] = os.path.join(out_dir, "p.png")
        rc, _, _ = _check_cli(argv, tmp, out_dir)
        COUNTS["accepted"] += rc == 0
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# --------------------------------------------------------------------- check (a one-case golden suite)
CHECK_CASE = "is_diamond_2_4"


@pytest.fixture(scope="module")
def golden(tmp_path_factory):
    from refraction_ref.golden import build

    d = str(tmp_path_factory.mktemp("golden"))
    build(d, only=(CHECK_CASE,), log=lambda *a: None)
    with np.load(os.path.join(d, CHECK_CASE, "golden.npz")) as z:
        arrays = {k: z[k] for k in z.files}
    return d, arrays


def prop_check(golden, key, damage, meta_kind, truncate):
    """``check`` on a candidate whose result.npz is damaged: exit 0, 1 (a verdict) or 2 (one line); no traceback."""
    COUNTS["inputs"] += 1
    suite, arrays = golden
    tmp = tempfile.mkdtemp(prefix="fuzz")
    try:
        cand = os.path.join(tmp, "cand", CHECK_CASE)
        os.makedirs(cand)
        arr = {k: v for k, v in arrays.items() if k != "meta"}
        keys = sorted(arr)
        k = keys[key % len(keys)]
        arr[k] = {"object": np.array([None] * 3, dtype=object), "text": np.array("x"), "zeros": np.zeros(1),
                  "nan": np.full(np.shape(arr[k]), np.nan), "drop": None, "none": arr[k]}[damage]
        if arr[k] is None:
            del arr[k]
        arr["meta"] = {"json": np.array("{}"), "text": np.array("{not json"),
                       "object": np.array([{"a": 1}], dtype=object)}[meta_kind]
        p = os.path.join(cand, "result.npz")
        np.savez(p, **arr)
        if truncate:
            data = open(p, "rb").read()
            with open(p, "wb") as f:
                f.write(data[: len(data) * truncate // 8])
        report = os.path.join(tmp, "report")
        rc, _, _ = _check_cli(["check", os.path.join(tmp, "cand"), "--golden", suite, "--report", report,
                               "--no-panels", "--allow-extra"], tmp, os.path.join(tmp, "none"), ok=(0, 1))
        COUNTS["accepted"] += rc in (0, 1)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# --------------------------------------------------------------------- profiles
def _settings(n):
    return settings(max_examples=n, derandomize=True, deadline=None, database=None, print_blob=True,
                    suppress_health_check=list(HealthCheck))


STRATEGIES = {
    "scene_api": (prop_scene_api, (mutations, st.booleans(), st.booleans().filter(lambda x: True),
                                   st.sampled_from(["imagespace", "imagespace", "exact"]))),
    "scene_file": (prop_scene_file, (texts, st.sampled_from(["scene", "render"]),
                                     st.integers(0, 3).map(lambda k: k == 0))),
    "set": (prop_set, (set_keys, set_values)),
    "flags": (prop_flags, (flag_values, st.one_of(st.none(), flag_values),
                           st.sampled_from(["imagespace", "exact", "nope", ""]),
                           st.lists(st.sampled_from(["--force", "--quiet", "--set", "camera.fov_y=5", "--bogus",
                                                     "x=1"]), max_size=2))),
    "compare": (prop_compare, (st.sampled_from(["json", "text", "list", "object", "numbers", "none"]),
                               st.sampled_from(["per_pixel", "broken", "caustics", "empty"]),
                               st.sampled_from(["json", "text", "object", "none"]),
                               st.sampled_from(["per_pixel", "broken", "caustics", "empty"]),
                               st.integers(0, 1000),
                               st.lists(st.sampled_from(["--json", "--force", "--plot", "p.png"]), max_size=3,
                                        unique=True).map(lambda f: [x for x in f if x != "p.png"]
                                                         + (["x"] if "--plot" in f else [])),
                               st.sampled_from([0, 0, 0, 1, 4, 7]))),
}
CHECK_STRATEGIES = (st.integers(0, 100), st.sampled_from(["object", "text", "zeros", "nan", "drop", "none"]),
                    st.sampled_from(["json", "text", "object"]), st.sampled_from([0, 0, 0, 2, 6]))

FAST = {"scene_api": 40, "scene_file": 40, "set": 60, "flags": 12, "compare": 40, "check": 8}
LONG = {"scene_api": 2600, "scene_file": 900, "set": 700, "flags": 150, "compare": 500, "check": 150}


def _run(name, n, golden=None):
    if name == "check":
        @_settings(n)
        @given(*CHECK_STRATEGIES)
        def run(key, damage, meta_kind, truncate):
            prop_check(golden, key, damage, meta_kind, truncate)
    else:
        prop, strategies = STRATEGIES[name]
        run = _settings(n)(given(*strategies)(prop))
    run()


@pytest.mark.parametrize("name", list(STRATEGIES))
def test_fuzz_fast(name):
    _run(name, FAST[name])
    assert COUNTS["tracebacks"] == 0 and COUNTS["nonfinite"] == 0 and COUNTS["files_left"] == 0


def test_fuzz_fast_check(golden):
    _run("check", FAST["check"], golden)
    assert COUNTS["tracebacks"] == 0


@pytest.mark.slow
def test_fuzz_long(golden):
    """At least 5,000 inputs; the counts go to benchmarks/results/fuzz_long.json (and the test's output)."""
    import time

    COUNTS.clear()
    t0 = time.perf_counter()
    per = {}
    for name, n in LONG.items():
        before = COUNTS["inputs"]
        try:
            _run(name, n, golden)
        except Exception as e:  # noqa: BLE001 - record it, go on with the other suites, fail at the end
            FAILURES.append({"kind": "suite", "input": name, "detail": f"{type(e).__name__}: {str(e)[:500]}"})
        per[name] = COUNTS["inputs"] - before
    out = {"inputs": COUNTS["inputs"], "refusals": COUNTS["refusals"], "accepted": COUNTS["accepted"],
           "renders": COUNTS["renders"], "tracebacks": COUNTS["tracebacks"], "non_finite_outputs": COUNTS["nonfinite"],
           "files_left": COUNTS["files_left"], "violations": COUNTS["violations"], "per_suite": per,
           "seconds": round(time.perf_counter() - t0, 1), "failures": FAILURES[:20]}
    path = os.path.join(os.path.dirname(__file__), "..", "benchmarks", "results", "fuzz_long.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=1)
    print(json.dumps({k: v for k, v in out.items() if k != "failures"}))
    assert out["inputs"] >= 5000
    assert out["tracebacks"] == 0 and out["non_finite_outputs"] == 0 and out["files_left"] == 0, FAILURES[:3]
    assert not FAILURES, FAILURES[:3]
