"""The ``slope`` term of ``close`` (rasterized depths): a sample shift within 1/512 pixel passes, a snap step fails.

No golden suite: a perspective depth image of a slanted plane, ``d = 1 / (a + b x + c y)`` (1/d is affine
in the image, as in the oracle's rasterizer), sampled at the pixel centres and at shifted points.
"""

from __future__ import annotations

import numpy as np
import pytest

from refraction_ref.golden.tolerances import SNAP_SLOPE, judge, neighbour_step, tolerance_for

H, W = 48, 64
A, B, C = 0.2, 0.0031, -0.0012  # 1/d at pixel (0, 0) and its steps along columns and rows: d from 3.4 to 7


def _depth(dx=0.0, dy=0.0):
    """The plane's depth sampled at the pixel centres moved by (dx, dy) pixels."""
    i, j = np.mgrid[0:H, 0:W].astype(np.float64)
    return 1.0 / (A + B * (j + 0.5 + dx) + C * (i + 0.5 + dy))


SPEC = tolerance_for("stage.minmax.zmin")


def _judge(c, g, spec=SPEC):
    return judge(c, g, spec, ambiguous=np.zeros(g.shape, bool))


def test_the_depth_keys_carry_the_slope_and_say_why():
    for key in ("stage.minmax.zmin", "stage.minmax.zmax", "stage.voxelize.zlo", "stage.voxelize.zhi",
                "stage.peel.ldi", "stage.photon_trace.ldi_0", "stage.level_map.position_0",
                "stage.receiver_depth.depth"):
        spec = tolerance_for(key)
        assert spec["kind"] == "close" and spec["slope"] == SNAP_SLOPE == 1.0 / 512.0, key
        assert "1/512" in spec["why"], key
    for key in ("exit_pos", "stage.trace.path_pos", "path_length", "image"):  # not rasterized depths
        assert "slope" not in tolerance_for(key), key


def test_neighbour_step_is_the_largest_step_to_a_finite_neighbour():
    g = np.array([[0.0, 1.0, np.inf], [3.0, 0.5, 2.0], [np.nan, 0.0, 0.0]])
    s = neighbour_step(g)
    assert s[1, 1] == 2.5  # to 3.0; the inf and NaN neighbours left out
    assert s[0, 0] == 3.0 and s[0, 2] == 0.0 and s[2, 0] == 0.0  # non-finite elements: no step
    assert s[2, 2] == 2.0  # to 2.0 above it
    np.testing.assert_array_equal(neighbour_step(np.stack([g, g])), np.stack([s, s]))  # per layer
    with pytest.raises(ValueError, match="picture axes"):
        neighbour_step(np.zeros(5))


@pytest.mark.parametrize("dx,dy", [(1 / 600, 0.0), (0.0, -1 / 600), (1 / 560, -1 / 560), (-1 / 560, 1 / 560)])
def test_a_sample_shift_within_the_allowance_passes(dx, dy):
    g = _depth()
    c = _depth(dx, dy)
    assert np.abs(c - g).max() > 1e-6 + 1e-5 * np.abs(g).max()  # beyond atol + rtol |g| ...
    without = dict(SPEC, slope=0.0)
    assert not _judge(c, g, without)["ok"]
    r = _judge(c, g)  # ... admitted by the slope term
    assert r["ok"] and r["counts"]["failing"] == 0, r["detail"]
    assert "step(g)" in r["detail"]


@pytest.mark.parametrize("dx,dy", [(1 / 256, 0.0), (1 / 256, -1 / 256), (1 / 300, -1 / 300)])
def test_a_shift_beyond_the_allowance_fails(dx, dy):
    """A whole snap step along the steeper axis (columns), or a shift well past 1/512 along both axes."""
    g = _depth()
    r = _judge(_depth(dx, dy), g)
    assert not r["ok"] and r["counts"]["located"] > 0.5 * g.size, r["detail"]


def test_a_constant_offset_of_one_snap_step_fails():
    """The depth change of a 1/256 pixel step along the steeper axis, added everywhere: twice the allowance."""
    g = _depth()
    step = neighbour_step(g)
    r = _judge(g + step / 256.0, g)
    assert not r["ok"] and r["counts"]["located"] == g.size
    assert _judge(g + 0.9 * step / 512.0, g)["ok"]  # within the term: passes


def test_the_slope_term_does_not_admit_coarse_errors():
    """float16 depths, a half-pixel offset, a row flip: orders of magnitude beyond 1/512 pixel."""
    g = _depth()
    for c in (g.astype(np.float16).astype(np.float64), _depth(0.5, 0.5), g[::-1]):
        r = _judge(c, g)
        assert not r["ok"] and r["failing"] > 0.5, r["detail"]
