"""Every level-map output and stage buffer is bit-identical with 1 and 2 Numba threads.

The stages split their work among threads (prange over pixels, rays, texel
rows and bands of map rows) without accumulating floats in thread order, so
the thread count changes no bit.
"""

from __future__ import annotations

import pytest

import refraction_ref as rr
from refraction_ref.scene import load_scene

SCENE = {
    "camera": {"width": 32, "height": 28, "eye": [0.2, 1.8, 2.0], "target": [0, -0.6, 0]},
    "objects": [],
    "lights": [{"type": "directional", "direction": [0.2, -1.0, 0.1]},
               {"type": "directional", "direction": [-0.1, -1.0, 0.2], "radiance": [0.5, 0.5, 0.5]}],
    "receivers": [{"mesh": "plane", "size": [1.5, 1.5], "transform": {"translate": [0, -0.6, 0]}},
                  {"mesh": "teapot", "fit": 0.5, "transform": {"translate": [0.1, -0.45, 0.0]}}],
    "water": {"size": [2.5, 2.5], "resolution": 24, "absorption": 0.2,
              "waves": [{"amplitude": 0.01, "wavelength": 0.6, "direction": [1, 0.3]},
                        {"amplitude": 0.006, "wavelength": 0.37, "direction": [-0.4, 1], "phase": 1.0}]},
    "levelmap": {"planes": 9, "map_size": 64, "exact_samples": 96},
}


@pytest.mark.parametrize("knobs", [{}, {"levelmap.smart_spacing": "respace"}, {"levelmap.culling": "bounds"},
                                   {"levelmap.placement": "tight", "levelmap.smart_slicing": False},
                                   {"levelmap.variant": "volumetric"}, {"levelmap.variant": "per_ray"}],
                         ids=["default", "respace", "bounds", "tight", "volumetric", "per_ray"])
def test_levelmap_outputs_and_stage_buffers_bit_identical(knobs, on_one_and_two_threads, same_arrays):
    sc = load_scene(SCENE, knobs)
    a, b = on_one_and_two_threads(lambda: rr.render(sc, method="levelmap", keep="stages").arrays)
    assert "stage.image.view_status" in a and "image_direct" in a
    same_arrays(a, b)


def test_exact_water_view_bit_identical(on_one_and_two_threads, same_arrays):
    sc = load_scene(SCENE)
    a, b = on_one_and_two_threads(lambda: rr.render(sc, method="exact", keep="stages").arrays)
    same_arrays(a, b)
