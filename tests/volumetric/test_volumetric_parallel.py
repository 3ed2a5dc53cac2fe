"""Every volumetric stage gives the same bits with 1 and 2 Numba threads (issue "Use every core")."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import refraction_ref as rr
from refraction_ref.volumetric.octree import build_octree
from refraction_ref.volumetric.photons import generate_photons
from refraction_ref.filters import separable_correlate

from test_volumetric import BOUNDS, luneburg


def _stage_arrays(res):
    """Every array of a render: the outputs and every stage's buffers."""
    return {k: v for k, v in res.arrays.items() if isinstance(v, np.ndarray)}


def _same(a, b):
    assert a.keys() == b.keys() and a
    for k in a:
        assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), k


@pytest.mark.parametrize("scene,overrides", [
    (None, {"volumetric.resolution": 32, "volumetric.photons": 64, "camera.width": 16, "camera.height": 16}),
    ({"camera": {"width": 16, "height": 16}, "objects": [],
      "volume": {"ior": luneburg(32), "extinction": 0.1, "scattering": [0.2, 0.2, 0.2], "bounds": BOUNDS.tolist()},
      "volumetric": {"photons": 16}}, None),
    ({"camera": {"width": 16, "height": 16}, "objects": [{"mesh": "sphere", "fit": 0.8}],
      "lights": [{"type": "directional", "direction": [0.2, -1.0, 0.1]}],
      "receivers": [{"mesh": "plane", "size": [1.6, 1.6], "transform": {"translate": [0, -0.7, 0]}}],
      "imagespace": {"caustic_map": 16},
      "volumetric": {"resolution": 24, "photons": 32, "bounds": [[-1, -1, -1], [1, 1, 1]]}}, None),
], ids=["bunny32", "luneburg", "proxy_and_receivers"])
def test_stages_identical_on_one_and_two_threads(scene, overrides, on_one_and_two_threads):
    a, b = on_one_and_two_threads(
        lambda: _stage_arrays(rr.render(scene, method="volumetric", overrides=overrides, keep="stages")))
    for stage in ("voxelize", "gradient", "octree", "photons", "smooth"):
        assert any(k.startswith(f"stage.{stage}.") for k in a), stage
    _same(a, b)


def test_separable_correlate_equals_scipy():
    rng = np.random.default_rng(3)
    x = np.arange(-4, 5, dtype=np.float64)
    g = np.exp(-0.5 * (x / 1.5) ** 2)
    g /= g.sum()
    for shape in ((7, 9, 11), (6, 5, 8, 3)):
        a = rng.random(shape) * 3
        a0 = a.copy()
        for w in (g, np.array([0.25, 0.5, 0.25])):
            ref = a
            for ax in range(3):
                ref = ndimage.correlate1d(ref, w, axis=ax, mode="nearest")
            assert np.array_equal(separable_correlate(a, w), ref)
            assert np.array_equal(a, a0)  # the input is left alone


def test_octree_and_photons_identical_on_one_and_two_threads(on_one_and_two_threads):
    ior = luneburg(33)[:, :21, :9]
    a, b = on_one_and_two_threads(lambda: build_octree(ior))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2] == b[2]
    lights = [{"type": "directional", "direction": [0.3, -1.0, 0.2], "radiance": [1, 0.5, 1]},
              {"type": "point", "position": [0.2, 3.0, 0.5], "radiance": [2, 1, 1]}]
    a, b = on_one_and_two_threads(lambda: generate_photons(lights, BOUNDS, (32, 32, 32), 33))
    for x, y in zip(a[:4], b[:4]):
        assert np.array_equal(x, y)


def test_parallel_slab_entry_matches_box_entry(on_one_and_two_threads):
    """The photon kernel's slab test gives box_entry's t_in bit for bit, edge cases included."""
    from refraction_ref.volumetric.photons import box_entry, slab_entry

    rng = np.random.default_rng(3)
    o = rng.uniform(-3, 3, (4000, 3))
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[::7, 0] = 0.0                                  # rays parallel to a slab
    d[::11, 1] = -0.0
    o[::13, 0] = 1.0                                 # origins on a face
    o[::19, 1] = -1.0
    o[::17] = 0.0                                    # origins inside
    t_ref, _ = box_entry(o, d, BOUNDS)

    def run():
        t = np.empty(len(o))
        slab_entry(o, d, BOUNDS, t)
        return t

    a, b = on_one_and_two_threads(run)
    assert np.array_equal(a, t_ref) and np.array_equal(b, t_ref)
    assert np.array_equal(np.signbit(a), np.signbit(t_ref))


def test_parallel_slab_exit_and_entry_points_match_numpy(on_one_and_two_threads):
    """The photon kernels' exit parameter and texel entry points equal box_entry's NumPy, bit for bit."""
    from refraction_ref.volumetric.photons import box_entry, entry_points, slab_both

    rng = np.random.default_rng(5)
    o = rng.uniform(-3, 3, (4000, 3))
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[::7, 0] = 0.0
    d[::11, 1] = -0.0
    o[::13, 0] = 1.0
    o[::19, 1] = -1.0
    o[::23, 2] = -0.0
    o[::17] = 0.0
    t_in_ref, t_out_ref = box_entry(o, d, BOUNDS)
    _, back = box_entry(o, -d, BOUNDS)
    e_ref = o - np.where(np.isfinite(back), np.maximum(back, 0.0), 0.0)[:, None] * d

    def run():
        t_in = np.empty(len(o))
        t_out = np.empty(len(o))
        slab_both(o, d, BOUNDS, t_in, t_out, True)
        e = np.empty_like(o)
        entry_points(o, d, BOUNDS, e)
        return t_in, t_out, e

    for got in on_one_and_two_threads(run):
        for x, y in zip(got, (t_in_ref, t_out_ref, e_ref)):
            ok = ~np.isnan(y)  # (a NaN's sign bit may differ: t_out is only ever compared)
            assert np.array_equal(x, y, equal_nan=True) and np.array_equal(np.signbit(x[ok]), np.signbit(y[ok]))
