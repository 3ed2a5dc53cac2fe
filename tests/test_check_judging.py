"""``check``'s judging finds the bugs a port really makes (issue 29): a 1 % scale error of a map, a different
photon count, a shifted Monte-Carlo map, a wrong receiver face, an index, near-empty voxels, a key no rule names.

The first tests need no golden suite (synthetic arrays through :func:`judge` and its helpers); the rest build
three small cases once (the glass sphere's image-space caustic, the Luneburg lens, the exact water reference)
and play a buggy backend by changing the golden's own buffers.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref.golden import build
from refraction_ref.golden.check import FACE_TIE_PIXELS, align_photons, format_report
from refraction_ref.golden.tolerances import (DEFAULT, DEFAULT_INT, FLUX, RADIANCE_FLOOR, VOLUME_FLUX, flux_error,
                                              fmt_share, judge, moments_test, tolerance_for)


# --------------------------------------------------------------------- no suite
def test_a_share_never_reads_zero():
    assert fmt_share(3, 262144) == "3 of 262144 (0.0011 %)"
    assert fmt_share(0, 10) == "0 of 10 (0 %)" and fmt_share(1, 3) == "1 of 3 (33 %)"


def test_index_keys_are_exact_and_each_key_has_its_own_rationale():
    for k in ("stage.march.hit_receiver", "stage.photon_paths.path_index", "stage.receiver_hit.hit_face_0",
              "stage.octree.level", "stage.receiver_depth.triangle", "photon_status", "photon_steps"):
        assert tolerance_for(k)["kind"] == "exact", k
    colours = tolerance_for("image")["why"]
    for k in ("stage.image.water_pos", "stage.image.receiver_pos", "stage.image.water_length"):
        spec = tolerance_for(k)
        assert spec["kind"] == "close" and spec["why"] != colours and "colour" not in spec["why"], k
    assert len({tolerance_for(k)["why"] for k in ("stage.image.water_pos", "stage.image.receiver_pos",
                                                  "stage.image.water_length")}) == 3


def test_a_key_no_rule_names_gets_a_named_default():
    f = tolerance_for("stage.newpass.buffer")
    i = tolerance_for("stage.newpass.index", dtype=np.int32)
    assert f == DEFAULT and i == DEFAULT_INT and f["default"] and i["kind"] == "exact"
    assert "no rule names this key" in f["why"] and "no rule names this key" in i["why"]


@pytest.mark.parametrize("key", ["stage.splat.splat_0", "stage.gather.caustic_map_0", "caustic_rgb_1",
                                 "stage.caustics.caustic_map_0_0", "stage.casting.caustic_map_0",
                                 "stage.plane_maps.plane_maps_0_0", "radiance", "stage.march.deposit"])
def test_a_one_percent_scale_error_of_a_map_fails_on_its_total(key):
    """A smooth, mostly dim map: 1 % brighter passes every texel's allowance (relative to the maximum)
    but not the total."""
    spec = tolerance_for(key)
    assert spec["flux"] in (FLUX, VOLUME_FLUX) and spec["flux"] <= 0.005
    shape = {"stage.plane_maps.plane_maps_0_0": (3, 64, 64), "caustic_rgb_1": (64, 64, 3),
             "radiance": (16, 16, 16, 3), "stage.march.deposit": (16, 16, 16, 3)}.get(key, (64, 64))
    rng = np.random.default_rng(1)
    g = 0.05 + 0.05 * rng.random(shape)  # a dim lit region ...
    g.reshape(-1)[rng.choice(g.size, g.size // 200, replace=False)] = 1.0  # ... and a focus on 0.5 % of it
    g = g.astype(np.float32)
    assert judge(g, g, spec)["ok"]
    r = judge(g * np.float32(1.01), g, spec)
    per_texel = judge(g * np.float32(1.01), g, dict(spec, flux=None))
    assert per_texel["ok"], per_texel["detail"]  # the per-texel rule alone would pass it ...
    assert not r["ok"] and abs(r["error"]["flux_error"] - 0.01) < 1e-4 and "FAIL" in r["detail"]  # ... the total not
    assert judge(g * np.float32(1.0005), g, spec)["ok"]  # a rounding-sized change passes


def test_flux_is_per_channel_and_per_plane():
    g = np.ones((4, 4, 3))
    c = g.copy()
    c[..., 1] *= 1.01
    err, ratio = flux_error(c, g)
    np.testing.assert_allclose(err, [0, 0.01, 0], atol=1e-12)
    np.testing.assert_allclose(ratio, [1, 1.01, 1])
    p = np.ones((3, 5, 5))
    q = p.copy()
    q[2] *= 0.99
    np.testing.assert_allclose(flux_error(q, p)[0], [0, 0, 0.01], atol=1e-12)
    assert flux_error(np.ones(3), np.zeros(3))[0][0] == np.inf and flux_error(np.zeros(3), np.zeros(3))[0][0] == 0


def test_direction_is_judged_only_where_there_is_radiance():
    """Near-empty voxels whose normalised direction flips are not judged; a flip in a lit voxel fails."""
    rng = np.random.default_rng(2)
    rad = rng.random((8, 8, 8, 3))
    rad[:4] *= 1e-16  # the Gaussian's far tail
    d = rng.normal(size=(8, 8, 8, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    spec = tolerance_for("direction")
    assert spec["weight_key"] == "radiance" and spec["floor"] == RADIANCE_FLOOR
    from refraction_ref.golden.check import _weight_mask

    m = _weight_mask("stage.smooth.direction", spec, {"stage.smooth.direction": d, "stage.smooth.radiance": rad})
    assert m.shape == (8, 8, 8, 1) and not m[:4].any() and m[4:].all()
    c = d.copy()
    c[:4] = -c[:4]  # flipped where empty
    assert not judge(c, d, spec)["ok"]  # judged everywhere, as before
    r = judge(c, d, spec, judged=m)
    assert r["ok"] and "above 0.0001 of its maximum" in r["detail"], r["detail"]
    c[6, 6, 6] = -c[6, 6, 6]  # and one lit voxel: 1 of 256 within the 1 % ...
    c[5, :, :] = -c[5, :, :]  # ... 64 more are not
    assert not judge(c, d, spec, judged=m)["ok"]


def test_photons_are_matched_one_by_one():
    rng = np.random.default_rng(3)
    g = rng.random((500, 3))
    c = np.delete(g, [10, 11, 250], axis=0)
    c = np.insert(c, 400, [5.0, 5.0, 5.0], axis=0)  # one photon the golden does not have
    gi, ci = align_photons(c, g)
    assert sorted(set(range(500)) - set(gi.tolist())) == [10, 11, 250]
    assert sorted(set(range(len(c))) - set(ci.tolist())) == [400]
    np.testing.assert_array_equal(c[ci], g[gi])


def _poisson_map(rng, n, shift=0.0, size=64):
    """A caustic-like map of n photons: a bright Gaussian spot on a dim disc, binned (texel units)."""
    k = rng.random(n) < 0.6
    x = np.where(k, rng.normal(24.0, 3.0, n), rng.uniform(4, 60, n)) + shift
    y = np.where(k, rng.normal(30.0, 4.0, n), rng.uniform(4, 60, n))
    m, _, _ = np.histogram2d(y, x, bins=size, range=[[0, size], [0, size]])
    return m / n


def test_the_moments_test_fails_a_shift_and_passes_a_fresh_seed():
    rng = np.random.default_rng(4)
    batches = np.stack([_poisson_map(rng, 200_000) for _ in range(8)])
    fresh = moments_test(_poisson_map(rng, 200_000), batches, 1e-3)
    moved = moments_test(np.roll(_poisson_map(rng, 200_000), 1, axis=1), batches, 1e-3)
    assert fresh["ok"] and max(abs(t) for t in fresh["t"]) < fresh["threshold"]
    assert not moved["ok"] and abs(moved["shift"][0] - 1.0) < 0.05 and abs(moved["t"][1]) > 3 * moved["threshold"]
