"""refraction_ref.filters: the three separable Gaussians (voxel blur, photon gather, the metric's blur).

Numerical truths of each (unit-sum taps, what a constant field and a delta become, the edge
rule) and bit-for-bit equality with a reference: SciPy for the blur and the metric, and for the
fold the gather's loops written out below in plain Python (IEEE doubles, the same order).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from refraction_ref import filters
from refraction_ref.caustics.splat import gather_gaussian as splat_gather, gaussian_weights
from refraction_ref.metrics import relative_l1
from refraction_ref.volumetric.voxelize import gaussian_blur as voxel_blur, separable_correlate


def test_names_elsewhere_are_the_filters():
    # the public names other modules re-export are these very functions, not copies
    assert voxel_blur is filters.gaussian_blur and separable_correlate is filters.separable_correlate
    assert splat_gather is filters.gather_gaussian and gaussian_weights is filters.gather_taps


# ---- taps -------------------------------------------------------------------------------------

@pytest.mark.parametrize("window", [1, 2, 3, 5, 7, 9, 11])
def test_window_taps_are_the_gaussian_formulas_and_sum_to_one(window):
    # the voxel blur's (sigma = window / 6) and the gather's (sigma = (window - 1) / 6), written out
    r = window // 2
    x = np.arange(-r, r + 1, dtype=np.float64)
    if window > 1:
        w = np.exp(-0.5 * (x / (window / 6.0)) ** 2)
        w /= w.sum()
        assert np.array_equal(filters.window_taps(window, window / 6.0), w)
    if r:
        g = np.exp(-0.5 * (x / ((window - 1) / 6.0)) ** 2)
        assert np.array_equal(filters.gather_taps(window), g / g.sum())
    else:
        assert np.array_equal(filters.gather_taps(window), [1.0])
    for taps in (filters.window_taps(window, window / 6.0), filters.gather_taps(window)):
        assert len(taps) == 2 * r + 1 and np.array_equal(taps, taps[::-1])
        assert abs(taps.sum() - 1.0) < 1e-15


@pytest.mark.parametrize("sigma", [0.5, 1.0, 1.7, 3.0])
def test_scipy_taps_are_scipys(sigma):
    fw = filters.scipy_gaussian_taps(sigma)
    radius = int(4.0 * sigma + 0.5)
    assert len(fw) == 2 * radius + 1 and abs(fw.sum() - 1.0) < 1e-15
    delta = np.zeros(4 * radius + 3)
    delta[2 * radius + 1] = 1.0
    # correlating a delta with SciPy's own 1-D Gaussian returns its taps (reversed: the same, symmetric)
    got = ndimage.gaussian_filter1d(delta, sigma, mode="constant")[radius + 1: 3 * radius + 2]
    assert np.allclose(got, fw[::-1], rtol=0, atol=1e-17)


# ---- voxel blur (Sun et al. 2008 §4.1): clamped edges ------------------------------------------

def test_blur_keeps_a_constant_volume_and_clamps_its_edges():
    a = np.full((7, 6, 5), 1.33)
    out = filters.gaussian_blur(a, 9)  # the window is wider than the volume: every tap clamps somewhere
    assert np.allclose(out, 1.33, rtol=1e-15, atol=0)
    step = np.zeros((12, 4, 4))
    step[6:] = 1.0
    s = filters.gaussian_blur(step, 5)
    assert np.array_equal(s[0], np.zeros((4, 4))) and np.allclose(s[-1], 1.0, rtol=1e-15, atol=0)


def test_blur_of_a_delta_is_the_documented_kernel():
    a = np.zeros((13, 13, 13))
    a[6, 6, 6] = 1.0
    w = filters.window_taps(9, 9 / 6.0)
    out = filters.gaussian_blur(a, 9)
    want = np.zeros_like(a)
    want[2:11, 2:11, 2:11] = (w[:, None, None] * w[None, :, None]) * w[None, None, :]
    assert np.array_equal(out, want)  # x, then y, then z: the products rounded in that order


@pytest.mark.parametrize("shape", [(9, 8, 7), (6, 10, 5, 3)])
def test_blur_equals_scipy_nearest_bit_for_bit(shape):
    a = np.random.default_rng(1).random(shape) + 1.0
    w = filters.window_taps(9, 1.5)
    want = a
    for ax in range(3):
        want = ndimage.correlate1d(want, w, axis=ax, mode="nearest")
    assert np.array_equal(filters.gaussian_blur(a, 9), want)
    assert np.array_equal(filters.gaussian_blur(a, 1), a)


# ---- gather (Wyman & Davis 2006 via Chaudhari §2.3.2 / §4.1): mirror folding -------------------

def reference_gather(E, window):
    """The gather, loop for loop in plain Python (IEEE doubles, the kernels' order of terms)."""
    a = np.asarray(E, dtype=np.float64)
    w = filters.gather_taps(window)
    r = min((len(w) - 1) // 2, min(a.shape[0], a.shape[1]) - 1)
    if r < (len(w) - 1) // 2:
        w = w[(len(w) - 1) // 2 - r: (len(w) - 1) // 2 + r + 1]
        w = w / w.sum()
    H, N, C = a.shape
    tmp = np.zeros(a.shape)
    for i in range(H):
        for j in range(N):
            for c in range(C):
                s = 0.0
                for t in range(-r, r + 1):
                    for src in (j - t, -1 - j - t, 2 * N - 1 - j - t):
                        if 0 <= src < N:
                            s += w[t + r] * a[i, src, c]
                tmp[i, j, c] = s
    out = np.zeros(a.shape)
    for i in range(H):
        for j in range(N):
            for c in range(C):
                s = 0.0
                for t in range(-r, r + 1):
                    for src in (i - t, -1 - i - t, 2 * H - 1 - i - t):
                        if 0 <= src < H:
                            s += w[t + r] * tmp[src, j, c]
                out[i, j, c] = s
    return out


@pytest.mark.parametrize("shape,window", [((9, 11, 2), 7), ((5, 4, 1), 7), ((12, 10, 3), 3)])
def test_gather_equals_the_reference_loops_bit_for_bit(shape, window):
    E = np.random.default_rng(2).random(shape)
    assert np.array_equal(filters.gather_gaussian(E, window), reference_gather(E, window))
    assert np.array_equal(filters.gather_gaussian(E[..., 0], window), reference_gather(E[..., :1], window)[..., 0])


def test_gather_keeps_a_constant_map_and_the_flux():
    out = filters.gather_gaussian(np.full((10, 9), 2.5), 7)
    assert np.allclose(out, 2.5, rtol=1e-15, atol=0)  # every tap lands once, directly or mirrored
    E = np.zeros((10, 9))
    E[0, 0] = 1.0  # in the corner: the weight leaving the map is folded back
    assert abs(filters.gather_gaussian(E, 7).sum() - 1.0) < 1e-15
    assert np.array_equal(filters.gather_gaussian(E, 1), E)


def test_gather_of_a_delta_is_the_documented_kernel():
    E = np.zeros((15, 15))
    E[7, 7] = 1.0
    w = filters.gather_taps(7)
    want = np.zeros_like(E)
    want[4:11, 4:11] = np.outer(w, w)
    assert np.array_equal(filters.gather_gaussian(E, 7), want)


# ---- the quality metric's blur: zero outside --------------------------------------------------

@pytest.mark.parametrize("sigma", [0.5, 1.0, 2.0])
def test_zero_filter_equals_scipy_constant_bit_for_bit(sigma):
    a = np.random.default_rng(3).random((23, 31))
    assert np.array_equal(filters.gaussian_filter_zero(a, sigma), ndimage.gaussian_filter(a, sigma, mode="constant"))


def test_zero_filter_edge_rule_and_delta():
    out = filters.gaussian_filter_zero(np.ones((20, 20)), 1.0)  # radius 4
    assert np.allclose(out[4:-4, 4:-4], 1.0, rtol=1e-15, atol=0)  # a constant kept away from the border
    fw = filters.scipy_gaussian_taps(1.0)
    half = fw[4:].sum()
    assert abs(out[0, 0] - half * half) < 1e-15  # zero outside: the corner keeps a quarter of the kernel
    d = np.zeros((11, 11))
    d[5, 5] = 1.0
    want = np.zeros_like(d)
    want[1:10, 1:10] = fw[:, None] * fw[None, :]
    assert np.array_equal(filters.gaussian_filter_zero(d, 1.0), want)


def test_relative_l1_blurs_with_the_zero_filter():
    rng = np.random.default_rng(4)
    a, b = rng.random((16, 18)), rng.random((16, 18))
    ab, bb = ndimage.gaussian_filter(a, 1.0, mode="constant"), ndimage.gaussian_filter(b, 1.0, mode="constant")
    assert relative_l1(a, b) == float(np.abs(ab - bb).sum() / np.abs(bb).sum())
    assert relative_l1(a, a) == 0.0
