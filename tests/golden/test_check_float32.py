"""``check`` admits a float32 pipeline's results by what they follow from, and still fails the bugs.

docs/oracle.md, "Float32 rasterizers": the trace's positions are judged also against the oracle's trace
run on the candidate's own LDI, the photons' exits against the oracle's light passes on its own light LDI,
their hits against the oracle's march of its own photons; the light's LDI admits the neighbouring 1/256
snap step on 0.5 % of its texels; a bit word whose pixel count changes is a silhouette tie only where the
count is a neighbour's. Candidates are written from the golden's own arrays with the last bits of a depth
buffer moved as float32 arithmetic moves them (1-2 ulps), or with one bug.
``REFRACTION_REF_GOLDEN=DIR`` reuses a suite already built (holding ``CASES``).
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref.golden import build
from refraction_ref.golden.masks import neighbour_changes, popcount
from refraction_ref.golden.replay import hit_explanations, photon_explanations, trace_explanations
from refraction_ref.golden.tolerances import (FLOAT32_SNAP_FRACTION, FLOAT32_SNAP_SLOPE, SNAP_SLOPE, judge,
                                              neighbour_step, tolerance_for)

EYE, LIGHT = "is_bunny_1_2", "is_caustics_sphere"
CASES = [EYE, LIGHT]


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    pre = os.environ.get("REFRACTION_REF_GOLDEN")
    if pre:
        with open(os.path.join(pre, "manifest.json")) as fh:
            have = json.load(fh)["cases"]
        assert all(c in have for c in CASES), f"REFRACTION_REF_GOLDEN={pre} lacks {CASES}"
        return pre
    d = str(tmp_path_factory.mktemp("golden_f32"))
    build(d, only=CASES, log=lambda *a: None)
    return d


def _gold(suite, case):
    with np.load(os.path.join(suite, case, "golden.npz")) as z:
        return {k: z[k] for k in z.files}


def _check(suite, tmp_path, case, arrays, name="cand"):
    d = tmp_path / name / case
    d.mkdir(parents=True, exist_ok=True)
    np.savez(d / "result.npz", **arrays)
    return rr.check(str(tmp_path / name), suite, cases=[case], panels=False).cases[case]


def _ulps(a, seed, n=2):
    """float32 depths moved by -n..n ulps at random (finite elements): a float32 rasterizer's last bits."""
    rng = np.random.default_rng(seed)
    a = np.asarray(a, np.float32).copy()
    fin = np.isfinite(a)
    k = rng.integers(-n, n + 1, size=a.shape)
    for _ in range(n):
        up, down = fin & (k > 0), fin & (k < 0)
        a[up] = np.nextafter(a[up], np.float32(np.inf))
        a[down] = np.nextafter(a[down], np.float32(-np.inf))
        k = k - np.sign(k)
    return a


def _all_passed(cand):
    return {k: True for k in cand}


# --------------------------------------------------------------------- the eye's trace
def test_positions_that_follow_from_the_candidates_own_ldi_pass(suite, tmp_path):
    """The LDI's last bits move the positions beyond `close`'s float64 tolerance (the normals' central
    differences amplify them); against the oracle's trace on that LDI they pass, against the golden's they
    fail, and a trace error on top of them fails however the LDI moved."""
    g = _gold(suite, EYE)
    a = dict(g, **{"stage.peel.ldi": _ulps(g["stage.peel.ldi"], 1)})
    ex = trace_explanations(suite, EYE, g, a, _all_passed(a))
    assert set(ex) == {"exit_pos", "path_length", "stage.trace.exit_pos", "stage.trace.path_pos",
                       "stage.trace.path_length"}
    for k, v in ex.items():
        a[k] = v.astype(g[k].dtype)
    res = _check(suite, tmp_path, EYE, a)
    assert res.ok, (res.failing_keys, res.earliest_failing_stage)
    assert "candidate's own stage.peel.ldi" in res["keys"]["exit_pos"]["detail"]
    moved = judge(a["exit_pos"], g["exit_pos"], tolerance_for("exit_pos"))
    assert not moved["ok"], moved["detail"]  # beyond float64 rounding
    # the golden's LDI supplied: nothing explains the moved positions
    res = _check(suite, tmp_path, EYE, dict(a, **{"stage.peel.ldi": g["stage.peel.ldi"]}), "unexplained")
    assert res.earliest_failing_stage == "trace" and "exit_pos" in res.failing_keys
    # an index 0.5 % high (the trace's own arithmetic wrong) on top of the moved LDI
    b = dict(a)
    for k in ("exit_pos", "stage.trace.exit_pos"):
        b[k] = a[k] + 1e-3 * (a[k] - a["ray_origin"])
    res = _check(suite, tmp_path, EYE, b, "bug")
    assert res.earliest_failing_stage == "trace" and "exit_pos" in res.failing_keys


# --------------------------------------------------------------------- the light's photons and their hits
def test_photons_that_follow_from_the_candidates_own_light_ldi_pass(suite, tmp_path):
    g = _gold(suite, LIGHT)
    # the light's texels are larger than the eye's pixels (the normals' baseline longer): a few more ulps
    a = dict(g, **{"stage.photon_trace.ldi_0": _ulps(g["stage.photon_trace.ldi_0"], 2, 6)})
    ex = photon_explanations(suite, LIGHT, g, a, _all_passed(a), 0)
    assert set(ex) == {"stage.photon_trace.exit_pos_0"}
    a["stage.photon_trace.exit_pos_0"] = ex["stage.photon_trace.exit_pos_0"]
    hx = hit_explanations(suite, LIGHT, g, a, _all_passed(a), 0)
    a["stage.receiver_hit.hit_pos_0"] = hx["stage.receiver_hit.hit_pos_0"]
    res = _check(suite, tmp_path, LIGHT, a)
    assert res.ok, (res.failing_keys, res.earliest_failing_stage)
    d = res["keys"]["stage.photon_trace.exit_pos_0"]["detail"]
    assert "candidate's own stage.photon_trace.ldi_0" in d, d
    d = res["keys"]["stage.receiver_hit.hit_pos_0"]["detail"]  # within the fraction, or explained
    assert res["keys"]["stage.receiver_hit.hit_pos_0"]["counts"]["located"] > 0 or "candidate's own" in d, d
    # the golden's light LDI supplied: the moved photons fail where they are made
    res = _check(suite, tmp_path, LIGHT, dict(a, **{"stage.photon_trace.ldi_0": g["stage.photon_trace.ldi_0"]}),
                 "unexplained")
    assert res.earliest_failing_stage == "photon_trace", res.failing_keys
    assert res.failing_keys == ["stage.photon_trace.exit_pos_0"]
    # hits moved along the photon's line by 1e-3 (a march stepping past the crossing): not explained
    b = dict(a)
    h, dirs = a["stage.receiver_hit.hit_pos_0"], a["stage.photon_trace.exit_dir_0"]
    b["stage.receiver_hit.hit_pos_0"] = h + 1e-3 * dirs
    res = _check(suite, tmp_path, LIGHT, b, "bug")
    assert res.earliest_failing_stage == "receiver_hit" and res.failing_keys == ["stage.receiver_hit.hit_pos_0"]


# --------------------------------------------------------------------- the light's LDI: a float32 snap
H, W = 48, 64


def _plane(dx=None, dy=None):
    i, j = np.mgrid[0:H, 0:W].astype(np.float64)
    dx = 0.0 if dx is None else dx
    dy = 0.0 if dy is None else dy
    return 1.0 / (0.2 + 0.0031 * (j + 0.5 + dx) - 0.0012 * (i + 0.5 + dy))


def _some(n):
    m = np.zeros((H, W), bool)
    m.ravel()[np.random.default_rng(3).choice(H * W, n, replace=False)] = True
    return m


def test_the_light_ldi_admits_the_neighbouring_snap_step_on_few_texels():
    """A texel sampled a whole snap step (1/256 pixel) off along the steeper axis: the light's LDI admits it
    on up to 0.5 % of its texels (a vertex a float32 projection rounded to the other step), the eye's LDI on
    none; two steps along both axes, or one step on 5 % of the texels, fails."""
    spec = tolerance_for("stage.photon_trace.ldi_0")
    assert (spec["slope"], spec["snap_slope"], spec["snap_fraction"]) == (SNAP_SLOPE, FLOAT32_SNAP_SLOPE,
                                                                          FLOAT32_SNAP_FRACTION)
    assert FLOAT32_SNAP_SLOPE == 2 * SNAP_SLOPE and "1/256" in spec["why"]
    g = _plane()[None]
    step = _plane(1 / 256)[None]
    none = np.zeros(g.shape, bool)
    few = _some(int(0.004 * H * W))[None]  # 12 texels
    r = judge(np.where(few, step, g), g, spec, ambiguous=none)
    assert r["ok"] and 0 < r["counts"]["snap"] <= few.sum() and "neighbouring snap step" in r["detail"], \
        r["detail"]
    assert not judge(np.where(few, step, g), g, tolerance_for("stage.peel.ldi"), ambiguous=none)["ok"]
    many = _some(int(0.05 * H * W))[None]  # a third of them beyond the 1/512 term: 1.7 % of the texels
    r = judge(np.where(many, step, g), g, spec, ambiguous=none)
    assert not r["ok"] and "FAIL" in r["detail"], r["detail"]
    one = _some(1)[None]
    r = judge(np.where(one, _plane(1 / 128, -1 / 128)[None], g), g, spec, ambiguous=none)
    assert not r["ok"] and r["counts"]["located"] == 1, r["detail"]
    # a whole step everywhere (a systematic offset) fails, as on every depth key
    assert not judge(g + neighbour_step(g) / 256.0, g, spec, ambiguous=none)["ok"]


# --------------------------------------------------------------------- lost fragments against silhouette ties
def test_a_fragment_lost_inside_a_surface_fails_voxelize_a_silhouette_tie_passes(suite, tmp_path):
    """A blend that replaces a word (instead of or-ing into it) loses the nearer of two fragments sharing
    a 32-slice word: on the bunny those pixels sit beside the folds' silhouettes (inside the ambiguity
    mask), but their count (one less) is no neighbour's, so `voxelize` fails. A pixel beside the outline
    that takes its neighbour's whole coverage (an edge moved across it) is a tie and passes."""
    g = _gold(suite, EYE)
    bits = g["stage.voxelize.bits"].copy()
    two = np.zeros(bits.shape, bool)
    for w in range(bits.shape[-1]):  # words holding two or more set bits: keep the highest only
        x = bits[..., w]
        many = (x & (x - np.uint32(1))) != 0
        two[..., w] = many
        hi = np.zeros_like(x)
        y = x.copy()
        while np.any(y):
            hi = np.where(y != 0, y, hi)
            y = y & (y - np.uint32(1))
        bits[..., w] = np.where(many, hi, x)
    lost = two.any(-1)
    assert lost.sum() >= 20
    res = _check(suite, tmp_path, EYE, {"stage.voxelize.bits": bits})
    assert res.earliest_failing_stage == "voxelize", res.failing_keys
    # one pixel beside the outline takes its covered neighbour's words: its count is the neighbour's
    dc = popcount(g["stage.voxelize.bits"])
    edge = np.argwhere((dc == 0) & neighbour_changes(dc > 0))
    i, j = edge[len(edge) // 2]
    nb = [(i + a, j + b) for a in (-1, 0, 1) for b in (-1, 0, 1) if dc[i + a, j + b] > 0]
    tie = g["stage.voxelize.bits"].copy()
    tie[i, j] = tie[nb[0]]
    res = _check(suite, tmp_path, EYE, {"stage.voxelize.bits": tie}, "tie")
    assert res.ok, res["keys"]["stage.voxelize.bits"]["detail"]
    assert res["keys"]["stage.voxelize.bits"]["counts"]["inside_ambiguity"] == np.count_nonzero(
        tie[i, j] != g["stage.voxelize.bits"][i, j])  # the pixel's words, inside the mask
