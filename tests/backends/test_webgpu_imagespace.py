"""The WebGPU image-space backend (examples/webgpu_backend/imagespace.py) against the golden suite.

WGSL shaders through wgpu-py, float32 throughout, on whatever adapter wgpu
finds (Mesa's lavapipe in CI). Without an adapter the test skips, naming the
two install lines; under CI (``CI`` set) a missing adapter fails instead.

The backend passes `check` on every image-space case. Its float32 depths move
the trace's positions beyond `close`'s float64 tolerance (one ulp of a depth
tilts the normals' central differences by ~8e-6 rad); `check` judges them also
against the oracle's trace run on the candidate's own LDI, and the photons'
exits and hits against the oracle's passes on its own light LDI and photons
(docs/oracle.md, "Float32 rasterizers"). Each planted bug (``BUGS``) fails
`check` with its pass as the earliest failing stage where the physics exposes
it. A suite built before that rule records the light LDI's older tolerance
(no float32 snap term): `is_caustics_sphere` fails `stage.photon_trace.ldi_0`
on 2 texels there; rebuild it.
By default (and in CI) the backend runs every image-space case of the catalogue
and each bug on one case that shows it; every bug on every case is ``-m slow``.
``REFRACTION_REF_GOLDEN=DIR`` reuses a suite already built (holding the cases).
"""
import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import refraction_ref as rr

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("webgpu_imagespace_backend",
                                               ROOT / "examples" / "webgpu_backend" / "imagespace.py")
backend = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(backend)

CASES = ["is_bubble_0_75", "is_bunny_1_2", "is_caustics_slanted", "is_caustics_sphere", "is_close_camera",
         "is_diamond_2_4", "is_grazing", "is_ior_1", "is_ior_1_01", "is_layer_limit",
         "is_open_mesh", "is_sphere_1_5", "is_tir_followed", "is_two_objects"]
CAUSTIC_CASES = {"is_caustics_slanted", "is_caustics_sphere"}

_IOR_ONE = {"is_ior_1"}                              # the bubble is air in water: it refracts
_ALL = set(CASES)
_NO_CAUSTICS = _ALL - CAUSTIC_CASES
#: bug -> (the stage check must name, cases whose physics cannot expose it); README's bug table says why
EXPOSED = {
    "half_pixel": ("rays", set()),
    "cull_back": ("minmax", set()),
    "depth16": ("minmax", set()),
    # a 24-bit depth step is 4e-6 at d = 2.6, inside minmax's 1e-6 + 1e-5 |g|: depths within tolerance, and
    # positions that follow from them (the oracle's trace on the candidate's own LDI): check admits it as it
    # admits float32 depths
    "depth24": ("minmax", _ALL),
    "nonatomic_bits": ("voxelize", _ALL),            # lavapipe shades one tile's fragments in order
    # lost fragments: a pixel whose count takes no neighbour's count lost a fragment from inside a surface
    # (not a silhouette tie); the convex cases put their two fragments in two words, where none is lost
    "bits_replace": ("voxelize", {"is_bubble_0_75", "is_caustics_slanted", "is_caustics_sphere",
                                  "is_close_camera", "is_diamond_2_4", "is_ior_1_01", "is_sphere_1_5",
                                  "is_tir_followed", "is_two_objects"}),
    "mip_drop_odd": ("reduce", _ALL),                # 128 x 128 at mip_size 256: no MIP level is built
    "texture_y_flip": ("trace", set()),
    "nearest_sampling": ("trace", _IOR_ONE),         # straight rays probe texel centres
    "wrong_bound_layer": ("trace", _IOR_ONE),        # straight rays: R_n is on the line of sight anyway
    "splat_no_atomics": ("splat", _NO_CAUSTICS),
    "caustic_half_texel": ("splat", _NO_CAUSTICS),
}
#: the default run's bugs, on the bunny (eye passes) and the slanted caustic case (caustic stages)
QUICK_BUGS = {"half_pixel": "is_bunny_1_2", "cull_back": "is_bunny_1_2", "depth16": "is_bunny_1_2",
              "bits_replace": "is_bunny_1_2", "texture_y_flip": "is_bunny_1_2",
              "splat_no_atomics": "is_caustics_slanted"}


def _adapter():
    ok, why = backend.gpu.available()
    if not ok:
        msg = f"no WebGPU adapter: {why}"              # `why` names the two install lines
        if os.environ.get("CI"):
            pytest.fail(msg + " (CI is set: the WebGPU backend must run here)")
        pytest.skip(msg)
    return why


def _cli():
    exe = Path(sys.executable).with_name("refraction-ref")
    return str(exe) if exe.exists() else shutil.which("refraction-ref")


def _golden(tmp_path_factory, cases):
    pre = os.environ.get("REFRACTION_REF_GOLDEN")
    if pre:
        with open(os.path.join(pre, "manifest.json")) as fh:
            have = json.load(fh)["cases"]
        missing = [c for c in cases if c not in have]
        assert not missing, f"REFRACTION_REF_GOLDEN={pre} lacks {missing}; build them or unset it"
        return pre
    d = tmp_path_factory.mktemp("golden_webgpu") / "golden"
    subprocess.run([_cli(), "golden", "build", str(d), "--quiet", "--only", ",".join(cases)],
                   check=True, capture_output=True, text=True)
    return str(d)


@pytest.fixture(scope="module")
def adapter():
    return _adapter()


@pytest.fixture(scope="module")
def golden_all(adapter, tmp_path_factory):
    return _golden(tmp_path_factory, CASES)


def failing(case_report):
    """(earliest failing stage, failing keys) of a case; (None, []) when it passes."""
    if case_report.ok:
        return None, []
    return case_report.earliest_failing_stage or "problems", sorted(case_report.failing_keys)


#: float32 positions beyond the float64 tolerance, each passing against the oracle's pass run on the
#: candidate's own upstream buffer named (docs/oracle.md, "Float32 rasterizers")
EXPLAINED = {"is_bunny_1_2": {"exit_pos": "stage.peel.ldi", "stage.trace.path_pos": "stage.peel.ldi"},
             "is_caustics_slanted": {"exit_pos": "stage.peel.ldi",
                                     "stage.photon_trace.exit_pos_0": "stage.photon_trace.ldi_0",
                                     "stage.receiver_hit.hit_pos_0": "stage.photon_trace.exit_pos_0"},
             "is_caustics_sphere": {"stage.photon_trace.exit_pos_0": "stage.photon_trace.ldi_0",
                                    "stage.receiver_hit.hit_pos_0": "stage.photon_trace.exit_pos_0"}}


def _clean(golden, cand, cases):
    written = backend.run(golden, str(cand), cases)
    assert sorted(written) == sorted(cases)
    rep = rr.check(str(cand), golden, cases=cases, panels=False)
    for case in cases:
        c = rep.cases[case]
        first, keys = failing(c)
        assert first is None, f"{case}: {first} fails: {keys}\n{c.problems}"
        if "CPU" in backend.gpu.describe():  # lavapipe's numbers (another adapter rounds elsewhere)
            for key, up in EXPLAINED.get(case, {}).items():
                assert f"candidate's own {up}" in c["keys"][key]["detail"], (case, key, c["keys"][key]["detail"])
    if "is_caustics_sphere" in cases and "CPU" in backend.gpu.describe():
        # 2 texels of the light's LDI on the neighbouring 1/256 step of a float32 projection
        d = rep.cases["is_caustics_sphere"]["keys"]["stage.photon_trace.ldi_0"]["detail"]
        assert "2 of 24736 (0.0081 %) more beyond it but within" in d, d
    judged = {r["stage"] for r in rep.rows}
    assert {"rays", "geometry", "minmax", "voxelize", "peel", "reduce", "normals", "trace", "shade"} <= judged
    assert rep.ok


def test_the_catalogue_image_space_cases_are_the_ones_listed():
    cat = Path(rr.__file__).parent / "data" / "golden"
    assert sorted(p.stem for p in cat.glob("is_*.json")) == sorted(CASES)


def test_every_planted_bug_is_listed():
    assert sorted(EXPOSED) == sorted(backend.all_bugs().keys() - {"hw_interp"})


def test_an_unknown_bug_is_refused(golden_all):
    with pytest.raises(ValueError, match="unknown planted bug"):
        backend.render_case(os.path.join(golden_all, "is_ior_1", "scene.json"), bugs=["typo"])


def _assert_bug(golden, out, bug, cases):
    backend.run(golden, str(out), cases, bugs=[bug])
    rep = rr.check(str(out), golden, cases=cases, panels=False)
    stage, hidden = EXPOSED[bug]
    adapter_cpu = "CPU" in backend.gpu.describe()
    for case in cases:
        first, keys = failing(rep.cases[case])
        if bug == "nonatomic_bits" and not adapter_cpu:
            continue                                # a GPU may race: either verdict is the hardware's
        want = stage.get(case) if isinstance(stage, dict) else stage
        if case in hidden:
            assert first is None, f"{bug} on {case}: expected no effect, got {first} ({keys})"
        else:
            assert first == want, f"{bug} on {case}: expected {want}, got {first} ({keys})"


@pytest.mark.parametrize("bug", sorted(QUICK_BUGS))
def test_planted_bug_names_its_pass(golden_all, tmp_path, bug):
    _assert_bug(golden_all, tmp_path, bug, [QUICK_BUGS[bug]])


def test_backend_passes_check_on_every_image_space_case(golden_all, tmp_path):
    _clean(golden_all, tmp_path, CASES)


@pytest.mark.slow
@pytest.mark.parametrize("bug", sorted(EXPOSED))
def test_planted_bug_full_matrix(golden_all, tmp_path, bug):
    cases = CASES if bug not in ("splat_no_atomics", "caustic_half_texel") else sorted(CAUSTIC_CASES)
    _assert_bug(golden_all, tmp_path, bug, cases)


@pytest.mark.slow
def test_mip_drop_odd_fails_reduce_where_a_mip_level_is_odd(adapter, tmp_path):
    """No catalogue case builds a MIP level (128 x 128 at mip_size 256): on a 127 x 127 view at mip_size 32
    (4 x 4 blocks, the last row and column partial), with the sphere cut by the bottom edge, the
    floor-sized level drops the blocks that hold the front layer's nearest depth, and `reduce`'s bound
    fails against the oracle's own render (check's judge and tolerance)."""
    from refraction_ref.golden.tolerances import judge, tolerance_for

    scene = {"objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.5},
                          "transform": {"translate": [0.0, -0.69, 0.0]}}],
             "camera": {"width": 127, "height": 127}, "imagespace": {"mip_size": 32}}
    d = tmp_path / "odd"
    d.mkdir()
    (d / "scene.json").write_text(json.dumps(scene))
    from refraction_ref.meshes import scene_geometry
    g = scene_geometry(rr.load_scene(str(d / "scene.json")))
    np.savez(d / "geometry.npz", vertices=g.vertices, faces=g.faces, face_object=g.face_object)
    ref = rr.render(rr.load_scene(str(d / "scene.json")), method="imagespace", keep="reduce").arrays
    for bugs, ok in (((), True), (("mip_drop_odd",), False)):
        mine = backend.render_case(str(d / "scene.json"), bugs=bugs)
        verdicts = {key: judge(mine[key], ref[key], tolerance_for(key, dtype=ref[key].dtype))
                    for key in ("stage.reduce.bounds_hi", "stage.reduce.bounds_lo")}
        # the front layer's nearest point lies on the bottom rows: bounds_lo is the one that moves
        assert all(r["ok"] for r in verdicts.values()) == ok, f"{bugs}: {verdicts}"
