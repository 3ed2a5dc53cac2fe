"""The clean-room level-map backend (examples/numpy_backend/levelmap.py) against `check`.

The backend was written from docs/oracle.md and docs/backends.md alone. It must
pass `check` on every level-map case of the golden suite, `image` included, and
each bug planted in it (mistakes porters really make) must fail with the pass
that holds it named as the earliest failing stage, in every case whose physics
exposes it, and pass where it cannot be seen (the comments say why).

By default only ``lm_two_lights`` is built (two lights of radiance means 1.4
and 0.5 on wavy water: casting and the view through the water both matter)
and judged with the bugs issue 29 names; every case and every bug run with
``-m slow``. ``REFRACTION_REF_GOLDEN=DIR`` reuses a suite already built (it
must hold the cases) instead of building one.
"""

import importlib.util
import json
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FAST = ["lm_two_lights"]
CASES = ["lm_all_planes", "lm_flat", "lm_point_light", "lm_slanted_sun", "lm_steep", "lm_steep_slanted",
         "lm_tir", "lm_two_lights"]
WAVY = [c for c in CASES if c != "lm_flat"]
ONE_LIGHT = [c for c in CASES if c != "lm_two_lights"]


def _only(stage, cases):
    """{case: stage} for ``cases``, None (passes) for the others."""
    return {c: (stage if c in cases else None) for c in CASES}


# bug -> {case: the earliest failing stage `check` must name, or None where the
# case cannot expose the bug (the backend then passes, which is asserted too)}.
EXPECTED = {
    # planes_r_l is judged in `planes`: every case shows the shifted offsets.
    "half_slice": dict.fromkeys(CASES, "planes"),
    # eta enters T0 (the box axes, `planes`), T at the vertices (`caustics`) and
    # the eye rays at the water (`image`). lm_flat: a vertical sun on flat water
    # refracts straight down whatever eta is and the flux does not depend on it,
    # so the maps are right, but the camera looks through the water obliquely:
    # `image`. lm_steep, lm_all_planes: the sun is vertical, so T0 and the box
    # are right, but the wavy vertices refract wrongly (`caustics`). The slanted
    # suns and the point light turn T0 (`planes`).
    "inverted_eta": {"lm_flat": "image", "lm_point_light": "planes",
                     "lm_slanted_sun": "planes", "lm_steep": "caustics",
                     "lm_steep_slanted": "planes", "lm_all_planes": "caustics",
                     "lm_tir": "planes", "lm_two_lights": "planes"},
    # lm_flat: on flat water both splits give beams of the same flux per area
    # tiling the same prism, so the map is the same (and the view's normals are
    # all (0, 1, 0)); the wavy cases differ.
    "other_diagonal": _only("caustics", WAVY),
    # only beams focused below one texel feel the floor: flat water does not
    # focus, and the gentle waves of lm_point_light and lm_slanted_sun do not
    # focus that far in the component box (contract_version 5); the steep waves,
    # lm_tir's (a slanted sun at eta 1.5) and lm_two_lights' do.
    "no_ad_floor": _only("caustics", ["lm_steep", "lm_steep_slanted", "lm_all_planes", "lm_tir",
                                      "lm_two_lights"]),
    # the sphere receiver's normal is never the box axis, in every case.
    "receiver_cos_axis": dict.fromkeys(CASES, "caustics"),
    # casting: one light's radiance weighted twice, the maps averaged, or added
    # texel by texel without the projection into light 0's frame: only a second
    # light can show it; every other case has one light of radiance 1 (w^2 = w).
    "radiance_twice": _only("casting", ["lm_two_lights"]),
    "casting_mean": _only("casting", ["lm_two_lights"]),
    "cast_texelwise": _only("casting", ["lm_two_lights"]),
    # light 1's shadow on the floor is cast by the sphere, another receiver, and
    # `own` already refuses it; the depth test decides only where the sphere
    # shadows itself from light 1, a band of 184 texels along its terminator
    # that lies beside light 0's depth discontinuity (the ambiguity mask): no
    # catalogue case has a receiver that shadows itself from a second light.
    "cast_no_depth_test": dict.fromkeys(CASES),
    # the map lookup half a texel off (rounded, or texel centres at integers) or
    # read bottom-up: lm_flat's maps are flat but for the sphere's shadow, which
    # sits at z = 0 (rows are symmetric about it) and whose edges the silhouette
    # mask frees; every wavy case's caustics show the shift.
    "rounded_lookup": _only("image", WAVY),
    "half_texel_lookup": _only("image", WAVY),
    "v_flip_lookup": _only("image", WAVY),
    # u and v swapped moves lm_flat's shadow from x = 0.3 to z = 0.3.
    "swapped_lookup": dict.fromkeys(CASES, "image"),
    # flat water's vertex normals are all (0, 1, 0): their interpolation is unit.
    "unnormalised_water_normal": _only("image", WAVY),
    # every case has K = 0.1 and receivers seen beside the pool.
    "absorb_direct": dict.fromkeys(CASES, "image"),
    "view_inverted_eta": dict.fromkeys(CASES, "image"),
    "ambient_unweighted": dict.fromkeys(CASES, "image"),
    # the flat rectangle and the mesh disagree only on rays grazing the pool's
    # wavy border: 43 status pixels on the gentle waves (all beside a status
    # boundary, 0.09 % of the colours: within the allowance), 172 on the steep
    # ones (lm_steep, lm_all_planes: 0.5 % of the colours beyond the mask plus
    # water_pos beyond 1 %); flat water's border is the rectangle.
    "water_rectangle": _only("image", ["lm_steep", "lm_all_planes"]),
}
# Plane acceptance by two inclusive comparisons: with 24 planes and a vertical
# sun the floor lies on the boundary between planes 11 and 12 and passes both
# (in lm_all_planes' literal eq. 4-3 box, caustics.placement = thesis: the
# default component box is 4e-6 thick there and rounds the floor to one side);
# smart slicing draws only plane 12 there, so only lm_all_planes (smart_slicing
# off) draws the floor twice and shows it.
EXPECTED["two_comparisons"] = _only("caustics", ["lm_all_planes"])

#: the bugs issue 29 names, judged by default on FAST
NAMED = ("radiance_twice", "rounded_lookup", "unnormalised_water_normal")

# Not bugs: ways of computing the same thing that check admits (asserted to pass every case).
# image_direct ray-cast from the eye instead of rasterized: the points differ by the 1/256 snap only,
# the masks agree on every golden case and 6 of lm_tir's pixels read the neighbouring texel.
ADMITTED = ("direct_raycast",)


# Not a bug since the depth keys' slope term (docs/oracle.md, "Unsnapped and analytic rasterizers"):
# the maps' rasterizer without the 1/256 snap moves position-map depths on every receiver (up to 93 %
# of a map's texels beyond atol + rtol |g|, 9.7e-4 at most) by at most 1/512 texel's worth of the
# map's slope, and the beams' coverage only at beam edges; check passes it in every case.
UNSNAPPED = "no_snap"


def _load_backend():
    path = os.path.join(ROOT, "examples", "numpy_backend", "levelmap.py")
    spec = importlib.util.spec_from_file_location("example_levelmap_backend", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _verdicts(candidate, golden, cases):
    """{case: (ok, earliest failing stage)} of ``cases``, by the Python API or the CLI."""
    try:
        from refraction_ref import check
    except ImportError:
        check = None
    if check is not None:
        rep = check(candidate, golden, cases=list(cases), panels=False)
        return {c: (r.ok, r.earliest_failing_stage) for c, r in rep.cases.items()}
    subprocess.run([sys.executable, "-m", "refraction_ref", "check", candidate, "--golden",
                    golden, "--cases", ",".join(cases), "--no-panels"], capture_output=True, text=True)
    with open(os.path.join(candidate, "report", "summary.json")) as fh:
        summary = json.load(fh)
    return {c: (r["ok"], r.get("earliest_failing_stage")) for c, r in summary["cases"].items()}


def _build(folder, cases):
    pre = os.environ.get("REFRACTION_REF_GOLDEN")     # a suite built already (holding these cases)
    if pre:
        with open(os.path.join(pre, "manifest.json")) as fh:
            have = json.load(fh)["cases"]
        missing = [c for c in cases if c not in have]
        assert not missing, f"REFRACTION_REF_GOLDEN={pre} lacks {missing}; build them or unset it"
        return pre
    run = subprocess.run([sys.executable, "-m", "refraction_ref", "golden", "build", folder,
                          "--only", ",".join(cases), "--quiet"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return folder


@pytest.fixture(scope="module")
def golden(tmp_path_factory):
    return _build(str(tmp_path_factory.mktemp("golden_lm_fast")), FAST)


@pytest.fixture(scope="module")
def golden_all(tmp_path_factory):
    return _build(str(tmp_path_factory.mktemp("golden_lm")), CASES)


@pytest.fixture(scope="module")
def backend():
    return _load_backend()


def _every_key_supplied(golden, cand, cases):
    """check skips keys a candidate leaves out: the port must write every golden key, `image`'s too."""
    import numpy as np
    for case in cases:
        with np.load(os.path.join(golden, case, "golden.npz")) as g, \
                np.load(os.path.join(cand, case, "result.npz")) as c:
            assert set(g.files) <= set(c.files), (case, sorted(set(g.files) - set(c.files)))


def test_backend_passes_the_two_lights(golden, backend, tmp_path):
    cand = str(tmp_path / "cand")
    assert backend.run(golden, cand, cases=FAST) == FAST
    cases = _verdicts(cand, golden, FAST)
    assert cases == {c: (True, None) for c in FAST}
    _every_key_supplied(golden, cand, FAST)


@pytest.mark.slow
def test_backend_passes_every_levelmap_case(golden_all, backend, tmp_path):
    cand = str(tmp_path / "cand")
    assert backend.run(golden_all, cand, cases=CASES) == CASES
    cases = _verdicts(cand, golden_all, CASES)
    assert cases == {c: (True, None) for c in CASES}
    _every_key_supplied(golden_all, cand, CASES)


def _planted(golden, backend, tmp_path, bug, cases):
    cand = str(tmp_path / bug)
    backend.run(golden, cand, cases=cases, bugs=(bug,))
    got = _verdicts(cand, golden, cases)
    want = {c: (EXPECTED[bug][c] is None, EXPECTED[bug][c]) for c in cases}
    assert got == want


@pytest.mark.parametrize("bug", NAMED)
def test_named_bug_names_its_pass(golden, backend, tmp_path, bug):
    assert EXPECTED[bug]["lm_two_lights"] is not None          # the default case exposes each
    _planted(golden, backend, tmp_path, bug, FAST)


@pytest.mark.slow
@pytest.mark.parametrize("bug", sorted(EXPECTED))
def test_planted_bug_names_its_pass(golden_all, backend, tmp_path, bug):
    _planted(golden_all, backend, tmp_path, bug, CASES)


@pytest.mark.slow
@pytest.mark.parametrize("bug", ADMITTED)
def test_admitted_alternative_passes(golden_all, backend, tmp_path, bug):
    cand = str(tmp_path / bug)
    backend.run(golden_all, cand, cases=CASES, bugs=(bug,))
    got = _verdicts(cand, golden_all, CASES)
    assert got == {c: (True, None) for c in CASES}


def test_every_planted_bug_has_its_stages(backend):
    assert set(EXPECTED) | set(ADMITTED) | {UNSNAPPED} == set(backend.BUGS)


@pytest.mark.slow
def test_unsnapped_rasterizer_passes_every_levelmap_case(golden_all, backend, tmp_path):
    """The maps rasterized without the 1/256 snap (an analytic rasterizer) pass, position maps included,
    and only through the slope term: without it a position map fails `level_map` in every case."""
    import numpy as np
    from refraction_ref.golden.masks import ambiguity, ambiguity_context
    from refraction_ref.golden.tolerances import judge

    golden = golden_all
    cand = str(tmp_path / "unsnapped")
    backend.run(golden, cand, cases=CASES, bugs=(UNSNAPPED,))
    cases = _verdicts(cand, golden, CASES)
    assert cases == {c: (True, None) for c in CASES}
    with open(os.path.join(golden, "manifest.json")) as fh:
        man = json.load(fh)
    for case in CASES:
        g = dict(np.load(os.path.join(golden, case, "golden.npz")))
        c = np.load(os.path.join(cand, case, "result.npz"))
        pics = ambiguity_context(g)
        strict = []
        for key in (k for k in g if k.startswith("stage.level_map.position_")):
            spec = man["cases"][case]["keys"][key]["tolerance"]
            assert spec["slope"] == 1.0 / 512.0, key
            assert np.array_equal(np.isfinite(c[key]), np.isfinite(g[key])), (case, key)  # same coverage
            amb = ambiguity(key, g[key], spec, pics, c[key])
            strict.append(judge(c[key], g[key], dict(spec, slope=0.0), ambiguous=amb)["ok"])
        assert not all(strict), case  # the sphere's map fails on about 22 % of its texels without the term
