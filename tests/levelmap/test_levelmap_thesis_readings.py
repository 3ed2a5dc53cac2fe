"""The thesis's level map read as the thesis means it (Tipprasert 2006).

* eq. 4-3's box read per axis (``caustics.placement = "component"``): a flat
  floor's box is its own extent about its origin, where the literal reading
  (``"thesis"``, the whole vector's length) is larger by a closed-form factor;
* smart slicing re-slices each sub-box (``levelmap.smart_spacing =
  "respace"``, eqs. 4-21/4-22) with ``n_i`` counting planes, so the thesis's
  sphere of Table 5-4 draws 3 -> 1 and 101 -> 50 planes;
* both are the defaults, and the other readings stay reachable by name.
"""

import numpy as np
import pytest

from refraction_ref.caustics.boxes import reference_box
from refraction_ref.contract import CONTRACT_VERSION
from refraction_ref.scene import load_scene


def test_component_box_of_a_flat_floor_under_a_slanted_light_closed_form():
    """Square floor of half-side a in the x-z plane, T0 = (sin t, -cos t, 0): the axes of eq. 4-1 are
    U = (cos t, sin t, 0), V = -T0, W = z, so the corners' largest components are a cos t, a sin t and a:
    the component box is the tight box (w, h, d) = 2a (cos t, sin t, 1); the literal reading takes a
    corner's whole length a sqrt(2) on every axis, larger by sqrt(2)/cos t, sqrt(2)/sin t and sqrt(2)."""
    a, t = 2.0, np.radians(20.0)
    T0 = np.array([np.sin(t), -np.cos(t), 0.0])
    floor = np.array([[x, -1.0, z] for x in (-a, a) for z in (-a, a)])
    origin = np.array([0.0, -1.0, 0.0])
    comp = reference_box(floor, T0, 64, "component", origin)
    tight = reference_box(floor, T0, 64, "tight")
    full = reference_box(floor, T0, 64, "thesis", origin)
    ext = lambda b: np.array([b.w, b.h, b.d])  # noqa: E731
    assert np.allclose(ext(comp), 2 * a * np.array([np.cos(t), np.sin(t), 1.0]), rtol=1e-12)
    assert np.allclose(ext(comp), ext(tight), rtol=1e-12) and np.allclose(comp.center, tight.center)
    assert np.allclose(ext(full) / ext(comp), np.sqrt(2) / np.array([np.cos(t), np.sin(t), 1.0]), rtol=1e-12)
    # the component box is centred on P_0 and encloses every vertex along U, V, W (its stated purpose)
    off = origin + np.array([0.5, 0.0, 0.0])
    c2 = reference_box(floor, T0, 64, "component", off)
    loc = (floor - off) @ np.stack([c2.U, c2.V, c2.W]).T
    assert np.allclose(c2.center, off) and np.all(np.abs(loc) <= ext(c2) / 2 + 1e-12)
    assert np.isclose(np.abs(loc[:, 0]).max(), c2.w / 2)


def test_defaults_are_component_box_and_respaced_smart_slicing():
    from refraction_ref.levelmap import default_scene

    d = default_scene().data
    assert CONTRACT_VERSION >= 5
    assert d["caustics"]["placement"] == "component" and d["levelmap"]["smart_spacing"] == "respace"
    # the other readings stay reachable, under the old alias too
    old = load_scene(default_scene(), {"levelmap.placement": "thesis", "levelmap.smart_spacing": "lattice"}).data
    assert old["caustics"]["placement"] == "thesis" and old["levelmap"]["smart_spacing"] == "lattice"


@pytest.mark.parametrize("planes, expected", [(3, 1), (101, 50)])
def test_respace_gives_table_5_4_sphere_counts(planes, expected):
    """Table 5-4, sphere column: 3 -> 1, 101 -> 50. The sphere lit from above shows the light its upper half:
    16 of 32 depth levels hold texels (hr = 1/2), n_i = hr (planes - 1) planes (eq. 4-22 with eps = s / (2 h));
    read as slices (n_i + 1 planes) it gave 2 and 51."""
    from refraction_ref.levelmap.pipeline import render_levelmap
    from refraction_ref.tables.tipprasert import model_scene

    sc = model_scene("sphere", planes, overrides={"caustics.map_size": 96, "water.resolution": 32,
                                                  "camera.width": 16, "camera.height": 16})
    assert sc.data["levelmap"]["smart_slicing"] and sc.data["levelmap"]["smart_spacing"] == "respace"
    _, info = render_levelmap(sc)
    (sub,) = info["stats"][0]["smart"]["sub_boxes"]
    assert sub[1] == 0.5 and sub[2] == expected
    assert info["planes_used"] == expected
