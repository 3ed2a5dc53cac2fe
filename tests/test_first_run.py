"""The first run (refraction_ref.warm): the warm-up compiles the scene's own plan, the cache is checked
kernel by kernel, and compilation is shown while it happens."""

from __future__ import annotations

import io

import numba
import numpy as np
import pytest
from numba.core.registry import CPUDispatcher

from refraction_ref import warm as warmup
from refraction_ref.scene import load_scene

POOL = "refraction_ref/data/levelmap_default.json"


@numba.njit(cache=True)
def _called(x):
    return x + 1


@numba.njit(cache=True)
def _never_called(x):  # its cache index is never written: a kernel missing from a part-filled cache
    return x + 1


def test_every_listed_kernel_is_a_kernel_of_the_package():
    for method in ("imagespace", "exact", "levelmap", "volumetric"):
        names = warmup.expected_kernels(method)
        assert names, f"data/kernels.json lists no kernel for {method}"
        for q in names:
            assert isinstance(warmup.dispatcher(q), CPUDispatcher), f"{method}: {q} is not a Numba kernel"


def test_the_cache_is_checked_kernel_by_kernel(monkeypatch):
    assert _called(2) == 3  # compiled (or loaded) now: on disk
    names = [f"{__name__}._called"]
    monkeypatch.setattr(warmup, "expected_kernels", lambda method: names)
    assert warmup.kernels_cached("imagespace")
    names.append(f"{__name__}._never_called")
    assert not warmup.kernels_cached("imagespace")  # one kernel missing: not cached, whatever the others


@pytest.mark.parametrize("method,src,block", [("imagespace", None, "imagespace"),
                                              ("levelmap", POOL, "levelmap"),
                                              ("volumetric", None, "volumetric")])
def test_the_warm_up_renders_the_scene_s_own_knobs_small(method, src, block):
    knobs = {"imagespace": {"imagespace.peeling": "lut", "imagespace.tir": True},
             "levelmap": {"levelmap.variant": "per_ray"},
             "volumetric": {"volumetric.integrator": "rk4"}}[method]
    scene = load_scene(src, knobs)
    tiny = warmup.tiny_scene(method, scene)
    assert tiny.data["camera"]["width"] * tiny.data["camera"]["height"] <= 256
    for k, v in knobs.items():  # the variant the scene asks for, not every variant
        b, key = k.split(".")
        assert tiny.data[b][key] == v
    assert tiny.data["objects"] == scene.data["objects"] and tiny.data["environment"] == scene.data["environment"]
    same_plan = load_scene(scene, {"camera.width": 100})
    assert warmup.plan_key(method, same_plan) == warmup.plan_key(method, scene)  # a size does not warm again
    assert warmup.plan_key(method, load_scene(src)) != warmup.plan_key(method, scene)  # another variant does


def test_compilation_is_reported_once_each_way_off_a_terminal():
    @numba.njit
    def fresh(x):
        return x * 2

    out = io.StringIO()
    with warmup.compile_report("imagespace", stream=out):
        assert fresh(3) == 6
    lines = out.getvalue().splitlines()
    assert len(lines) == 2 and "compiling the imagespace kernels" in lines[0]
    assert lines[1].startswith("refraction-ref: compiled 1 imagespace kernels in ")
    out = io.StringIO()
    with warmup.compile_report("imagespace", stream=out):
        assert fresh(4) == 8  # compiled already: nothing to say
    assert out.getvalue() == ""


def test_read_only_and_writable_inputs_share_one_signature():
    from refraction_ref import meshes, optics, vec3

    rng = np.random.default_rng(3)
    p = rng.normal(size=(40, 3))
    frozen = p.copy()
    frozen.flags.writeable = False  # as the mesh cache hands out its arrays
    m, t = rng.normal(size=(3, 3)), rng.normal(size=3)
    d = p / np.linalg.norm(p, axis=1, keepdims=True)
    for f, args in ((vec3.affine, (m, t)), (vec3.dot, (t,)), (meshes.bounds, ()),
                    (optics.refract, (d[::-1].copy(), 0.8))):
        a, b = f(p, *args), f(frozen, *args)
        for x, y in zip(a, b) if isinstance(a, tuple) else ((a, b),):
            assert np.array_equal(x, y)
    for q in ("vec3._affine_kernel", "vec3._dot_kernel", "meshes._bounds_kernel", "optics._refract_many"):
        k = warmup.dispatcher(f"refraction_ref.{q}")  # the kernels by the names data/kernels.json uses
        assert len(k.signatures) == 1, f"{q}: {k.signatures}"


def test_warmup_verb_compiles_or_loads_and_says_which(capsys, monkeypatch):
    from refraction_ref import cli

    assert _called(1) == 2
    names = [f"{__name__}._called"]  # the verb's wording follows the kernel-by-kernel check
    monkeypatch.setattr(warmup, "expected_kernels", lambda method: names)
    assert cli.main(["warmup", "--method", "imagespace"]) == 0
    names.append(f"{__name__}._never_called")
    assert cli.main(["warmup", "--method", "imagespace"]) == 0
    first, second = capsys.readouterr().out.splitlines()
    assert first.startswith("imagespace: kernels already cached (")
    assert second.startswith("imagespace: kernels compiled and cached (")
