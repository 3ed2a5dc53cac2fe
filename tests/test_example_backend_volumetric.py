"""The clean-room NumPy volumetric backend (examples/numpy_backend/volumetric.py) against `check`.

The golden suite's volumetric cases are built once; the port must pass `check` on every one of
them from `voxelize` to `march` (and `smooth`), and each planted porter's bug must fail with its own
pass named as the earliest failing stage in every case whose physics exposes it, and pass where it
cannot be seen (`EXPOSED` says why per bug). The two volume cases run by default; the voxelized
bunny (a slower build and port) is `slow`. ``REFRACTION_REF_GOLDEN=DIR`` reuses a suite already
built (it must hold the cases) instead of building one.
"""
import importlib.util
import json
import os
import subprocess
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
BACKEND = os.path.join(HERE, "..", "examples", "numpy_backend", "volumetric.py")
CLI = os.path.join(os.path.dirname(sys.executable), "refraction-ref")   # the public CLI
FAST = ("vol_luneburg", "vol_sharp_step")
SLOW = ("vol_bunny",)


def _load_backend():
    spec = importlib.util.spec_from_file_location("numpy_backend_volumetric", BACKEND)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


vb = _load_backend()


def _build(d, cases):
    pre = os.environ.get("REFRACTION_REF_GOLDEN")     # a suite built already (holding these cases)
    if pre:
        with open(os.path.join(pre, "manifest.json")) as f:
            have = json.load(f)["cases"]
        missing = [c for c in cases if c not in have]
        assert not missing, f"REFRACTION_REF_GOLDEN={pre} lacks {missing}; build them or unset it"
        return pre
    r = subprocess.run([CLI, "golden", "build", d, "--only", ",".join(cases), "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    return d


def _check(cand, golden, cases):
    """(overall ok, {case: (ok, earliest failing stage)}), by the Python API when present, else by
    the CLI's summary.json."""
    import refraction_ref as rr
    if hasattr(rr, "check"):
        rep = rr.check(cand, golden, cases=list(cases), panels=False)
        return rep.ok, {c: (r.ok, r.earliest_failing_stage) for c, r in rep.cases.items()}
    out = os.path.join(cand, "report")
    subprocess.run([CLI, "check", cand, "--golden", golden, "--cases", ",".join(cases), "--no-panels",
                    "--report", out], capture_output=True)
    with open(os.path.join(out, "summary.json")) as f:
        s = json.load(f)
    return s["ok"], {c: (v["ok"], v.get("earliest_failing_stage")) for c, v in s["cases"].items()}


@pytest.fixture(scope="module")
def golden(tmp_path_factory):
    return _build(str(tmp_path_factory.mktemp("golden_vol")), FAST)


@pytest.fixture(scope="module")
def golden_bunny(tmp_path_factory):
    return _build(str(tmp_path_factory.mktemp("golden_vol_bunny")), SLOW)


#: bug -> {case: the stage `check` must name}; a case left out cannot expose the bug and must pass.
EXPOSED = {
    # n varies in every case: central and forward differences differ wherever it does
    "forward_gradient": {"vol_luneburg": "gradient", "vol_sharp_step": "gradient", "vol_bunny": "gradient"},
    # vol_sharp_step's node ranges are 0 or >= 0.5, never in [eps, eps'): the swap changes no leaf
    "eps_swap": {"vol_luneburg": "octree", "vol_bunny": "octree"},
    # the index varies across the photons' paths in every case: a half-voxel shift bends them apart
    "half_voxel": {"vol_luneburg": "march", "vol_sharp_step": "march", "vol_bunny": "march"},
    # constant nodes crossed in ds_max pieces: more steps in every case (photon_steps, paths); on the
    # Luneburg lens the exit rows stay within tolerance (the extra steps are straight)
    "step_ds_max": {"vol_luneburg": "march", "vol_sharp_step": "march", "vol_bunny": "march"},
    # texel order flipped: start_pos rows permuted in every case
    "window_flip": {"vol_luneburg": "photons", "vol_sharp_step": "photons", "vol_bunny": "photons"},
    # a step ends on its node's boundary, so the next one starts in the same node and takes ds_min
    "no_nudge": {"vol_luneburg": "march", "vol_sharp_step": "march", "vol_bunny": "march"},
}


def _verdicts(golden, cases, tmp, bugs=()):
    vb.run(golden, tmp, cases=cases, bugs=bugs)
    return _check(tmp, golden, cases)


def test_port_passes_check_on_the_volume_cases(golden, tmp_path):
    assert set(FAST) <= set(vb.volumetric_cases(golden))
    ok, per = _verdicts(golden, FAST, str(tmp_path))
    assert per == {c: (True, None) for c in FAST}
    assert ok
    z = np.load(os.path.join(str(tmp_path), "vol_luneburg", "result.npz"))
    stages = {k.split(".")[1] for k in z.files if k.startswith("stage.")}
    assert stages == {"voxelize", "gradient", "octree", "photons", "march", "photon_paths", "smooth"}


@pytest.mark.parametrize("bug", sorted(EXPOSED))
def test_planted_bug_names_its_pass(bug, golden, tmp_path):
    ok, per = _verdicts(golden, FAST, str(tmp_path), (bug,))
    assert per == {c: (c not in EXPOSED[bug], EXPOSED[bug].get(c)) for c in FAST}
    assert not ok


@pytest.mark.slow
def test_port_passes_check_on_the_bunny(golden_bunny, tmp_path):
    ok, per = _verdicts(golden_bunny, SLOW, str(tmp_path))
    assert ok and per == {"vol_bunny": (True, None)}


@pytest.mark.slow
@pytest.mark.parametrize("bug", sorted(EXPOSED))
def test_planted_bug_names_its_pass_on_the_bunny(bug, golden_bunny, tmp_path):
    ok, per = _verdicts(golden_bunny, SLOW, str(tmp_path), (bug,))
    assert per == {"vol_bunny": (False, EXPOSED[bug]["vol_bunny"])}
    assert not ok
