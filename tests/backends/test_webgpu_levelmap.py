"""The WebGPU level-map backend (examples/webgpu_backend/levelmap.py) against `check`.

A float32 port in WGSL, run by wgpu-py on whatever adapter is there (Mesa's
lavapipe on the CPU in CI): the maps and the additive splat drawn by the
render pipeline, the rest in compute shaders. It must pass `check` on every
level-map case, and each bug planted in it (mistakes GPU porters really make)
must fail with its pass named as the earliest failing stage in every case
whose physics exposes it, and pass where it cannot be seen (the comments say
why).

Without wgpu or an adapter the tests skip naming the two install lines;
under CI (``CI`` set) they fail instead. By default (and in CI) the backend
runs every level-map case of the catalogue, and each bug is judged on one case
that shows it (lm_two_lights: casting and the view; lm_steep: folded beams;
lm_all_planes: the floor on a slab boundary); every bug on every case runs
with ``-m slow``. ``REFRACTION_REF_GOLDEN=DIR``
reuses a suite already built (it must hold the cases).
"""

import importlib.util
import json
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CASES = ["lm_all_planes", "lm_flat", "lm_point_light", "lm_slanted_sun", "lm_steep", "lm_steep_slanted",
         "lm_tir", "lm_two_lights"]
FAST = ["lm_all_planes", "lm_steep", "lm_two_lights"]
WAVY = [c for c in CASES if c != "lm_flat"]
FOLDING = ["lm_steep", "lm_steep_slanted", "lm_all_planes"]


def _only(stage, cases):
    """{case: stage} for ``cases``, None (passes) for the others."""
    return {c: (stage if c in cases else None) for c in CASES}


# bug -> {case: the earliest failing stage check names, or None where the case cannot show it}
EXPECTED = {
    # the primary rays through the pixel corners move every view buffer; in lm_two_lights casting's
    # texel centres move first (light 1's map is read half a texel off)
    "pixel_corner": dict(dict.fromkeys(CASES, "image"), lm_two_lights="casting"),
    # the maps drawn bottom-up: no receiver's map is symmetric about its middle row to the position
    # tolerance (the icosphere's triangles are not mirror-symmetric), so every case shows it
    "y_flip": dict.fromkeys(CASES, "level_map"),
    # culling keeps every surface the maps and the camera see (they face the light or the eye) and
    # drops only the intersection triangles of beams that crossed before the plane: only the steep
    # waves fold beams
    "cull_back": _only("caustics", FOLDING),
    # flat water's vertex normals are all (0, 1, 0): every way of blending them gives the same normal
    "nearest_normal": _only("image", WAVY),
    "unnormalised_water_normal": _only("image", WAVY),
    # a bilinear fetch blends neighbouring texels: lm_flat's map is uniform but for the sphere's
    # shadow, whose edges the ambiguity mask frees
    "linear_lookup": _only("image", WAVY),
    # a position map rebuilt from a depth buffer spanning every receiver's zeta (R about 6 here) has
    # steps of R / 2^16 (9e-5: every position map fails) or R / 2^24 (3.6e-7: within the positions'
    # 1e-6). Under a vertical sun the floor's component box is 4e-6 thick and the floor (zeta = 0)
    # sits exactly on the boundary of depth levels 15 and 16 ((0 + h/2) / h * 32 = 16): any step
    # moves it a level and its respaced plane by 1.25e-7, beyond planes_r_l's 1e-7, and check names
    # `planes` (it judges planes_r_l with the box) though the fault is the level map's depth
    "depth16": dict(dict.fromkeys(CASES, "level_map"), lm_flat="planes", lm_steep="planes",
                    lm_two_lights="planes"),
    "depth24": _only("planes", ["lm_flat", "lm_steep", "lm_two_lights"]),
    # the splat half a texel off the position map's grid: lm_flat's map is uniform (edges masked)
    "half_texel_splat": _only("caustics", WAVY),
    # replace instead of add loses deposits only where two beams cover one texel on one plane
    # (each texel is accepted by one plane): folded beams
    "no_blend": _only("caustics", FOLDING),
    # the thesis's two-sided threshold accepts the floor of lm_all_planes (24 planes, smart slicing
    # off, vertical sun: the floor on the boundary of planes 11 and 12) on both planes; with smart
    # slicing every texel sits within eps of one plane only
    "threshold_test": _only("caustics", ["lm_all_planes"]),
    # beams focused below one texel: the steep waves, lm_tir's and lm_two_lights'
    "no_ad_floor": _only("caustics", ["lm_steep", "lm_steep_slanted", "lm_all_planes", "lm_tir",
                                      "lm_two_lights"]),
    # flat water: both diagonals tile the same prism with the same flux per area
    "other_diagonal": _only("caustics", WAVY),
    # eta turns T0 (planes) under slanted suns and the point light; under a vertical sun the box is
    # right but the wavy vertices refract wrongly (caustics); flat water under a vertical sun: only
    # the oblique view through the water (image)
    "inverted_eta": {"lm_flat": "image", "lm_point_light": "planes", "lm_slanted_sun": "planes",
                     "lm_steep": "caustics", "lm_steep_slanted": "planes", "lm_all_planes": "caustics",
                     "lm_tir": "planes", "lm_two_lights": "planes"},
    # the sphere's normal is never the box axis
    "receiver_cos_axis": dict.fromkeys(CASES, "caustics"),
}

#: the case each bug is judged on by default (the first of FAST that shows it)
FAST_CASE = {b: next(c for c in FAST if exp[c] is not None) for b, exp in EXPECTED.items()}


def _load_backend():
    path = os.path.join(ROOT, "examples", "webgpu_backend", "levelmap.py")
    spec = importlib.util.spec_from_file_location("webgpu_levelmap_backend", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def backend():
    mod = _load_backend()
    ok, why = mod.available()
    if not ok:
        if os.environ.get("CI"):
            pytest.fail(f"CI: the WebGPU backend needs an adapter: {why}")
        pytest.skip(why)                        # names the two install lines
    return mod


def _build(folder, cases):
    pre = os.environ.get("REFRACTION_REF_GOLDEN")     # a suite built already (holding these cases)
    if pre:
        with open(os.path.join(pre, "manifest.json")) as fh:
            have = json.load(fh)["cases"]
        missing = [c for c in cases if c not in have]
        assert not missing, f"REFRACTION_REF_GOLDEN={pre} lacks {missing}; build them or unset it"
        return pre
    run = subprocess.run([sys.executable, "-m", "refraction_ref", "golden", "build", folder,
                          "--only", ",".join(cases), "--quiet"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return folder


@pytest.fixture(scope="module")
def golden_all(tmp_path_factory, backend):
    return _build(str(tmp_path_factory.mktemp("golden_webgpu_lm")), CASES)


def _verdicts(candidate, golden, cases):
    """{case: (ok, earliest failing stage)}."""
    from refraction_ref import check
    rep = check(candidate, golden, cases=list(cases), panels=False)
    return {c: (r.ok, r.earliest_failing_stage) for c, r in rep.cases.items()}


def _every_key_supplied(golden, cand, cases):
    """check skips keys a candidate leaves out: the port must write every golden key."""
    import numpy as np
    for case in cases:
        with np.load(os.path.join(golden, case, "golden.npz")) as g, \
                np.load(os.path.join(cand, case, "result.npz")) as c:
            assert set(g.files) <= set(c.files), (case, sorted(set(g.files) - set(c.files)))


def _expected(bug, cases):
    return {c: ((True, None) if EXPECTED[bug][c] is None else (False, EXPECTED[bug][c])) for c in cases}


def test_every_bug_is_planted(backend):
    assert set(EXPECTED) == set(backend.BUGS)


@pytest.mark.parametrize("bug", sorted(EXPECTED))
def test_bug_names_its_pass(golden_all, backend, bug, tmp_path):
    case = FAST_CASE[bug]
    cand = str(tmp_path / "cand")
    backend.run(golden_all, cand, cases=[case], bugs=[bug])
    assert _verdicts(cand, golden_all, [case]) == _expected(bug, [case])


def test_backend_passes_every_levelmap_case(golden_all, backend, tmp_path):
    cand = str(tmp_path / "cand")
    assert backend.run(golden_all, cand, cases=CASES) == CASES
    assert _verdicts(cand, golden_all, CASES) == {c: (True, None) for c in CASES}
    _every_key_supplied(golden_all, cand, CASES)


@pytest.mark.slow
@pytest.mark.parametrize("bug", sorted(EXPECTED))
def test_bug_in_every_case(golden_all, backend, bug, tmp_path):
    cand = str(tmp_path / "cand")
    backend.run(golden_all, cand, cases=CASES, bugs=[bug])
    assert _verdicts(cand, golden_all, CASES) == _expected(bug, CASES)
