"""BLAS-free 3-vector products: the same bits as the unfused sum in a fixed order, on any thread count."""

import numba
import numpy as np
import pytest

from refraction_ref.vec3 import affine, dot


def _unfused(p, m, t):
    # x m0 + y m1 + z m2 + t, each product rounded on its own (numpy's elementwise ops never fuse)
    return ((p[..., 0:1] * m[0] + p[..., 1:2] * m[1]) + p[..., 2:3] * m[2]) + t


@pytest.mark.parametrize("threads", [1, 2])
def test_affine_and_dot_are_the_unfused_fixed_order_sums(threads):
    rng = np.random.default_rng(3)
    p = rng.normal(size=(4, 1001, 3)) * 10.0 ** rng.integers(-8, 8, size=(4, 1001, 1))
    m = rng.normal(size=(3, 3))
    t = rng.normal(size=3)
    before = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        a = affine(p, m, t)
        d = dot(p, m[:, 0])
    finally:
        numba.set_num_threads(before)
    assert a.shape == (4, 1001, 3) and d.shape == (4, 1001)
    assert np.array_equal(a, _unfused(p, m, t))
    assert np.array_equal(d, _unfused(p, m[:, :1], 0.0)[..., 0])
    # and it is the matrix product, to rounding
    assert np.allclose(a, p @ m + t, rtol=1e-12, atol=1e-300)


def test_shapes_are_checked():
    with pytest.raises(ValueError, match=r"p \(\.\.\., 3\) and m \(3, C\)"):
        affine(np.zeros((5, 2)), np.eye(3))
    with pytest.raises(ValueError, match=r"p \(\.\.\., 3\)"):
        dot(np.zeros((5, 4)), np.ones(3))
    assert affine(np.zeros((0, 3)), np.eye(3)).shape == (0, 3)
    assert affine(np.ones((2, 3)), np.ones((3, 1)), [1.0]).tolist() == [[4.0], [4.0]]
