"""raster.row_span, the one scanline step: the covered run of a row equals the pixel-by-pixel test.

The rasterizer's band kernel (refraction_ref.raster.blend), the level map's intersection triangles
(levelmap.caustics_map) and its per-ray beams (levelmap.per_ray, a run of one pixel) all walk rows with it, so it
must keep exactly the pixels, and give exactly the integer edge values, of testing every centre.
"""

from __future__ import annotations

import numba as nb
import numpy as np
import pytest

from refraction_ref.raster import edge_setup, edge_values, oriented_triangle, row_span


@nb.njit
def _spans(X, Y, rows, j0, j1):
    """(row_span's run and edge values, the brute-force run and its edge values) of triangle 0."""
    A = np.zeros((1, 3))
    x0, y0, x1, y1, x2, y2, _, _, _, area, _ = oriented_triangle(X, Y, A, 0)
    e = edge_setup(x0, y0, x1, y1, x2, y2)
    a0, a1, a2, b0, b1, b2 = e
    got = np.empty((rows.shape[0], 5), np.int64)
    want = np.empty((rows.shape[0], 5), np.int64)
    for q in range(rows.shape[0]):
        i = rows[q]
        ja, jb, w0, w1, w2 = row_span((x0, y0, x1, y1, x2, y2), e, i, j0, j1)
        got[q, 0] = ja
        got[q, 1] = jb
        got[q, 2] = w0
        got[q, 3] = w1
        got[q, 4] = w2
        found = False
        run = True
        first = 0
        last = -1
        fw = (0, 0, 0)
        v0, v1, v2 = edge_values(x0, y0, x1, y1, x2, y2, 256 * j0 + 128, 256 * i + 128)
        for j in range(j0, j1 + 1):  # the loop every copy had: step, then test each centre
            if j > j0:
                v0 -= 256 * a0
                v1 -= 256 * a1
                v2 -= 256 * a2
            if v0 + b0 < 0 or v1 + b1 < 0 or v2 + b2 < 0:
                continue
            if not found:
                found = True
                first = j
                fw = (v0, v1, v2)
            elif j != last + 1:
                run = False  # not one run
            last = j
        if not run:
            first = -1000
        elif not found:
            first = -999
        want[q, 0] = first
        want[q, 1] = last
        want[q, 2] = fw[0]
        want[q, 3] = fw[1]
        want[q, 4] = fw[2]
    return got, want, area


def _check(X, Y, j0, j1, rows):
    got, want, area = _spans(np.asarray(X, np.int64).reshape(1, 3), np.asarray(Y, np.int64).reshape(1, 3),
                             np.asarray(rows, np.int64), j0, j1)
    if area == 0:  # drawn by no caller
        return
    for g, w in zip(got, want):
        assert w[0] != -1000  # a triangle meets a row in one run
        if w[0] == -999:  # nothing covered: row_span says so
            assert g[0] > g[1]
        else:
            assert tuple(g) == tuple(w)


@pytest.mark.parametrize("seed", range(6))
def test_row_span_equals_the_pixel_by_pixel_test(seed):
    rng = np.random.default_rng(seed)
    for _ in range(300):
        # snapped to whole and half pixels often, so that edges run through centres and along rows
        scale = rng.choice([1, 128, 256])
        X = rng.integers(-4 * 256, 40 * 256, 3) // scale * scale
        Y = rng.integers(-4 * 256, 40 * 256, 3) // scale * scale
        j0, j1 = sorted(rng.integers(-2, 42, 2))
        _check(X, Y, int(j0), int(j1), np.arange(-3, 43))


def test_row_span_of_one_pixel_is_the_centre_test():
    # a right triangle whose hypotenuse passes through pixel centres: the top-left rule decides
    X = [128, 128 + 256 * 8, 128]
    Y = [128, 128, 128 + 256 * 8]
    for j in range(-1, 10):
        _check(X, Y, j, j, np.arange(-1, 10))


def test_row_span_of_a_degenerate_or_horizontal_triangle():
    _check([0, 256 * 5, 256 * 10], [0, 256 * 5, 256 * 10], 0, 12, np.arange(-1, 12))  # zero area
    _check([0, 256 * 10, 256 * 5], [384, 384, 384 + 256 * 4], 0, 12, np.arange(-1, 8))  # a top edge on centres
