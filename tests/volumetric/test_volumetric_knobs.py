"""The volumetric knobs, declared once: their defaults reach every function, their typed values the kernels."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import refraction_ref.volumetric as volumetric
from refraction_ref.scene import SceneError, load_scene
from refraction_ref.volumetric.knobs import (EULER, PAPER, RK4, ROBUST, VOLUMETRIC_DEFAULTS, MarchKnobs, ViewKnobs,
                                             march_knobs, octree_dilations, view_knobs)
from refraction_ref.volumetric.octree import build_octree, minmax_pyramid


def _functions():
    for info in pkgutil.iter_modules(volumetric.__path__):
        mod = importlib.import_module(f"refraction_ref.volumetric.{info.name}")
        for name, fn in vars(mod).items():
            if inspect.isfunction(fn) and fn.__module__ == mod.__name__:
                yield f"{info.name}.{name}", fn


def test_no_function_default_contradicts_its_knob():
    seen = 0
    for where, fn in _functions():
        for p in inspect.signature(fn).parameters.values():
            if p.name in VOLUMETRIC_DEFAULTS and p.default is not inspect.Parameter.empty:
                assert p.default == VOLUMETRIC_DEFAULTS[p.name], (where, p.name, p.default)
                seen += 1
    assert seen >= 3  # build_octree's eps, eps2, ds_max at least
    # the octree a function builds by default is the one the default stepping reads
    default_dilate = octree_dilations(VOLUMETRIC_DEFAULTS["stepping"])[0]
    for fn in (build_octree, minmax_pyramid):
        assert inspect.signature(fn).parameters["dilate"].default is default_dilate


def test_typed_values_resolve_the_choices_to_codes():
    assert march_knobs() == MarchKnobs(1.0, 0.25, EULER, 0, 1e-3, 1e-3, PAPER)
    assert view_knobs() == ViewKnobs(EULER, 0.0)
    k = march_knobs({"integrator": "rk4", "stepping": "robust", "ds_min": 2})
    assert (k.integrator, k.stepping, k.ds_min) == (RK4, ROBUST, 2.0) and isinstance(k.ds_min, float)
    scene = load_scene({"volumetric": {"phase_g": 0.5, "integrator": "rk4"}})
    assert view_knobs(scene.data["volumetric"]) == ViewKnobs(RK4, 0.5)
    with pytest.raises(SceneError, match="stepping"):
        march_knobs({"stepping": "fast"})


def test_each_stepping_reads_its_octree():
    assert octree_dilations("paper") == (False, True)       # §4.2 as written for photons; dilated for viewing
    assert octree_dilations("robust") == (True, True)       # one octree for both
    assert octree_dilations(ROBUST) == octree_dilations("robust")


@pytest.mark.parametrize("block,words", [
    ({"volumetric": {"ds_min": 2.0, "ds_max": 1.0}}, "ds_max .* is below volumetric.ds_min"),
    ({"volumetric": {"eps2": 0.001}}, "secondary tolerance"),
    ({"volumetric": {"blur": 8}}, "must be odd"),
    ({"volumetric": {"padding": 100, "resolution": 64}}, "leaves no voxels"),
    ({"volumetric": {"integrator": "rk2"}}, "choose one of euler, rk4"),
    ({"volumetric": {"scattering": [1, 2]}}, "finite number or a list"),
    ({"volumetric": {"bounds": [[0, 0, 0], [0, 1, 1]]}}, "every upper bound"),
    ({"volumetric": {"resolution": 1024}}, "GiB; lower it"),
    ({"volume": [1, 2]}, "must be an object"),
    ({"volume": {"bounds": [[0, 0, 0], [1, 1, 1]]}}, "volume.ior' is missing"),
    ({"volume": {"ior": [[[1.0] * 4] * 4] * 4}}, "volume.bounds' is missing"),
])
def test_bad_blocks_are_refused_with_their_messages(block, words):
    with pytest.raises(SceneError, match=words):
        load_scene(block)


def test_volume_block_is_filled_when_given():
    ior = [[[1.0] * 4] * 4] * 4
    scene = load_scene({"volume": {"ior": ior, "bounds": [[0, 0, 0], [1, 1, 1]]}})
    assert set(scene.data["volume"]) == {"ior", "bounds", "extinction", "scattering"}
    assert scene.data["volume"]["extinction"] is None
    assert load_scene().data["volume"] is None
