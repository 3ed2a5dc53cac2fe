"""The stage graph (refraction_ref.graph): reuse is never stale, every knob re-runs its readers, kept buffers.

The mutation test changes every knob of every method (and the scene keys
the stages share) in a :class:`~refraction_ref.Session` and checks two
truths: every stage that declares the key re-ran, and the session's result
is bit-identical to a fresh render of the changed scene. A knob missing
from a stage's ``reads`` cannot slip through: the stage would see a
projected scene without it (``UndeclaredRead``), and a stale reuse would
differ from the fresh render.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hs

import refraction_ref as rr
from refraction_ref.graph import BLOCKS, Stage, UndeclaredRead, get_method, run_graph
from refraction_ref.scene import SceneError, load_scene

CAUSTICS = {
    "camera": {"eye": [0.0, 1.2, 2.4], "target": [0.0, -0.2, 0.0], "width": 24, "height": 24},
    "objects": [{"mesh": "sphere", "fit": 0.8, "material": {"ior": 1.5}}],
    "lights": [{"type": "directional", "direction": [0.2, -1.0, 0.1]}],
    "receivers": [{"mesh": "plane", "size": [2.0, 2.0], "transform": {"translate": [0.0, -0.6, 0.0]}}],
    "imagespace": {"photons": 16},
    "caustics": {"map_size": 16, "gather": 3},
    "exact": {"photons": 16},
}
WATER = {
    "camera": {"eye": [0.0, 2.5, 2.5], "target": [0.0, -1.0, 0.0], "width": 20, "height": 20},
    "objects": [],
    "receivers": [{"mesh": "plane", "size": [2.0, 2.0], "transform": {"translate": [0.0, -1.0, 0.0]}}],
    "water": {"size": [2.0, 2.0], "resolution": 8, "waves": [{"amplitude": 0.02, "wavelength": 0.7}]},
    "lights": [{"type": "directional", "direction": [0.1, -1.0, 0.0]}],
    "levelmap": {"planes": 6},
    "caustics": {"map_size": 24},
    "exact": {"water_samples": 24},
}
VOLUME = {
    "camera": {"width": 16, "height": 16},
    "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.3}}],
    "volumetric": {"resolution": 16, "photons": 12, "padding": 2, "blur": 3, "supersample": 2},
}

#: a graded-index volume (a Luneburg lens sampled on 8^3 voxels) for the exact method's graded-index graph
_g = (np.arange(8) + 0.5) / 8 * 1.6 - 0.8
_r2 = (_g[:, None, None] ** 2 + _g[None, :, None] ** 2 + _g[None, None, :] ** 2) / 0.6 ** 2
GRIN = {
    "camera": {"width": 8, "height": 8, "eye": [0.0, 0.6, 3.0], "target": [0.0, -0.2, 0.0], "fov_y": 40},
    "objects": [], "volume": {"ior": np.where(_r2 < 1, np.sqrt(2 - np.minimum(_r2, 1)), 1.0).tolist(),
                              "bounds": [[-0.8, -0.8, -0.8], [0.8, 0.8, 0.8]]},
    "lights": [{"type": "directional", "direction": [0.0, -1.0, 0.0]}],
    "receivers": [{"mesh": "plane", "size": [1.6, 1.6], "transform": {"translate": [0.0, -1.4, 0.0]}}],
    "volumetric": {"photons": 8},
    "caustics": {"map_size": 12},
}

#: one valid, different value per knob: a knob without an entry fails test_every_knob_has_a_mutation
MUTATIONS = {
    "imagespace": {"iterations": 6, "layers": 3, "slices": 128, "bounds": "global", "mip_size": 8,
                   "bound_margin": 0.05, "blend": "or", "endpoint": "bracket", "filter": "nearest",
                   "peel_all": True, "depth": "float", "slicing": "global",
                   "peeling": "lut", "normals": "cross", "delta": 1, "exit_threshold": 2.0, "tir": True,
                   "max_interfaces": 3, "record": 2, "photons": 12, "receiver_hit": "exact",
                   "grid": [12, 12]},  # CAUSTICS's 24x24 image on a half-size grid
    "exact": {"normals": "face", "crease_deg": 30.0, "max_bounces": 2, "photons": 12, "photon_seed": 1,
              "record": 2, "water_samples": 20},
    "levelmap": {"planes": 7, "smart_slicing": False, "depth_levels": 8, "variant": "volumetric",
                 "smart_spacing": "lattice", "culling": "bounds"},  # respace is the default (contract_version 5)
    "caustics": {"map_size": 20, "gather": 5, "placement": "tight", "shadows": False, "ambient": 0.3},
    "water": {"ior": 1.4, "height": 0.05, "resolution": 6, "absorption": 0.2, "size": [2.2, 2.0],
              "waves": [{"amplitude": 0.03, "wavelength": 0.5}]},
    "volumetric": {"resolution": 14, "photons": 10, "ds_min": 0.5, "ds_max": 4.0, "eps": 0.01, "eps2": 0.03,
                   "integrator": "rk4", "phase_g": 0.3, "scattering": 0.3, "absorption": 0.1,
                   "supersample": 3, "blur": 5, "padding": 3, "bounds": [[-0.8, -0.8, -0.8], [0.8, 0.8, 0.8]],
                   "max_steps": 40, "min_radiance": 0.01, "stop_fraction": 0.01, "stiff": 0.5,
                   "stepping": "robust", "proxy": "box", "proxy_inflate": 3.0},
    "volume": {},  # the volumetric input block: covered by tests/volumetric/test_volumetric.py
}
#: scene keys shared by the methods, mutated on every (method, scene) below
SHARED = {"camera.eye": [0.1, 1.1, 2.4], "outside_ior": 1.05, "environment.tiles": 8,
          "lights.0.direction": [0.0, -1.0, 0.2], "objects.0.material.ior": 1.4}

CASES = [  # (method, base scene, blocks whose knobs it reads)
    ("imagespace", CAUSTICS, ("imagespace", "caustics")),
    ("exact", CAUSTICS, ("exact", "caustics")),
    ("levelmap", WATER, ("levelmap", "water", "caustics")),
    ("exact", WATER, ("caustics",)),
    ("volumetric", VOLUME, ("volumetric",)),
    ("exact", GRIN, ("volumetric", "caustics")),   # the graded-index reference reads the volumetric knobs
]


def _same(a, b):
    assert sorted(a.arrays) == sorted(b.arrays)
    for k in a.arrays:
        x, y = np.asarray(a.arrays[k]), np.asarray(b.arrays[k])
        assert x.shape == y.shape and x.dtype == y.dtype, k
        assert np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"), f"{k} differs from a fresh render"


def _reads_key(stage, key):
    return any(key == r or key.startswith(r + ".") or r.startswith(key + ".") for r in stage.reads)


def _mutations(scene_dict, blocks, method):
    out = [(f"{b}.{k}", v) for b in blocks for k, v in MUTATIONS[b].items()]
    if method == "exact" and "water" in scene_dict:
        out += [("exact.water_samples", 20), ("exact.photon_seed", 1)]
    for k, v in SHARED.items():
        if k == "objects.0.material.ior" and not scene_dict.get("objects", [1]):
            continue
        out.append((k, v))
    return out


def test_every_knob_has_a_mutation():
    for name, block in BLOCKS.items():
        if block.defaults is None:
            continue
        assert set(MUTATIONS[name]) == set(block.defaults), f"MUTATIONS['{name}'] must cover every knob"


def test_every_knob_is_read_by_a_stage():
    read = set()
    for method, sc, _ in CASES:
        scene = load_scene(sc)
        for st in get_method(method).stages(scene):
            read.update(st.reads)
    for name, block in BLOCKS.items():
        for k in block.defaults or {}:
            assert f"{name}.{k}" in read or name in read, f"no stage reads '{name}.{k}'"


#: one test per (method, scene, mutated key): each prints its own progress line, none runs for minutes
MUTATION_CASES = [(method, base, key, value) for method, base, blocks in CASES
                  for key, value in _mutations(base, blocks, method)]


@pytest.mark.parametrize("method,base,key,value", MUTATION_CASES,
                         ids=[f"{m}-{'water' if 'water' in b else 'volume' if 'volume' in b else 'mesh'}-{k}"
                              for m, b, k, _ in MUTATION_CASES])
def test_every_knob_reruns_its_readers_and_matches_a_fresh_render(method, base, key, value):
    s = rr.Session(base)
    s.render(method)
    s.update({key: value})
    res = s.render(method)
    ran = {p["stage"] for p in res.meta["plan"] if p["ran"]}
    readers = {st.name for st in get_method(method).stages(s.scene) if _reads_key(st, key) and not st.diagnostic}
    if readers:
        assert readers <= ran, f"{method}: after changing {key}, {sorted(readers - ran)} did not re-run"
    else:  # a key this method does not read (the exact water reference has no environment)
        assert not ran, f"{method}: {key} is read by no stage, yet {sorted(ran)} re-ran"
    _same(res, rr.render(s.scene, method=method))


def test_only_trace_and_shade_rerun_after_iterations():
    s = rr.Session({"camera": {"width": 32, "height": 32}})
    s.render("imagespace")
    s.update({"imagespace.iterations": 10})
    ran = [p["stage"] for p in s.render("imagespace").meta["plan"] if p["ran"]]
    assert ran == ["trace", "shade"]


def test_camera_change_of_water_scene_reuses_the_light_side():
    s = rr.Session(WATER)
    s.render("levelmap")
    s.update({"camera.eye": [0.3, 2.5, 2.4]})
    res = s.render("levelmap")
    assert [p["stage"] for p in res.meta["plan"] if p["ran"]] == ["image"]
    assert set(res.meta["timings_ms"]) == {"image"}


_POOL = [("camera.eye", [[0.0, 1.2, 2.4], [0.2, 1.0, 2.5]]),
         ("lights.0.direction", [[0.2, -1.0, 0.1], [0.0, -1.0, 0.3]]),
         ("objects.0.material.ior", [1.5, 1.33]),
         ("imagespace.iterations", [5, 3]),
         ("imagespace.normals", ["central", "forward"]),
         ("caustics.gather", [3, 1]),
         ("receivers.0.albedo", [[0.8, 0.8, 0.8], [0.5, 0.6, 0.7]])]


@settings(max_examples=8, deadline=None, derandomize=True)
@given(hs.lists(hs.tuples(hs.integers(0, len(_POOL) - 1), hs.integers(0, 1)), min_size=1, max_size=4))
def test_random_updates_equal_a_fresh_render(steps):
    s = rr.Session(CAUSTICS)
    s.render("imagespace")
    for k, v in steps:
        key, values = _POOL[k]
        s.update({key: values[v]})
        got = s.render("imagespace")
    _same(got, rr.render(s.scene, method="imagespace"))


def test_bad_update_leaves_the_session_intact():
    s = rr.Session({"camera": {"width": 24, "height": 24}})
    first = s.render("imagespace")
    scene = s.scene
    for bad in ({"imagespace.iterations": -1}, {"imagespace.nope": 1}, {"camera.width": "wide"}):
        with pytest.raises(SceneError, match=r"imagespace\.iterations|nope|camera\.width"):
            s.update(bad)
        assert s.scene is scene
    again = s.render("imagespace")
    assert not any(p["ran"] for p in again.meta["plan"])
    _same(first, again)


def test_unknown_stage_in_keep_is_refused_by_name():
    with pytest.raises(SceneError, match="'peeel'.*peel"):
        rr.render({"camera": {"width": 16, "height": 16}}, keep="trace,peeel")


def test_kept_buffers_are_the_pipeline_s_own():
    res = rr.render({"camera": {"width": 32, "height": 32}, "imagespace": {"record": 3}}, keep="stages")
    a = res.arrays
    assert np.array_equal(a["stage.trace.status"], a["status"])
    assert np.array_equal(a["stage.peel.depth_complexity"], a["depth_complexity"])
    ldi = a["stage.peel.ldi"]
    zmin, zmax = a["stage.minmax.zmin"], a["stage.minmax.zmax"]
    hit = np.isfinite(zmin)
    # the first layer is the front surface, within one slice of zmin; the layers are sorted
    S = res.meta["params"]["slices"]
    assert np.all(np.abs(ldi[0][hit] - zmin[hit]) <= (zmax[hit] - zmin[hit]) / S + 1e-6)
    present = np.isfinite(ldi)
    assert np.all(present[1:] <= present[:-1])  # a pixel's layers are 0..n-1, no gaps
    assert np.all((ldi[1:] >= ldi[:-1])[present[1:]])
    # depth complexity is the popcount of the bitmask words
    bits = a["stage.voxelize.bits"]
    pop = np.unpackbits(bits.view(np.uint8), axis=-1).sum(axis=-1)
    assert np.array_equal(pop, a["depth_complexity"])
    # the first recorded interface is the front surface point, the last one the exit
    pp = a["stage.trace.path_pos"]
    ex = (a["status"] == 1) & (a["interfaces"] <= 3)
    k = a["interfaces"][ex].astype(int) - 1
    assert np.allclose(pp[ex, k], a["exit_pos"][ex])


def test_undeclared_read_is_caught():
    from refraction_ref.graph import Method

    def bad(ctx):
        return {"x": ctx.scene.data["imagespace"]["iterations"]}

    m = Method("bad", blocks=(), stages=lambda sc: (Stage("s", bad, reads=("imagespace.layers",), makes=("x",)),),
               assemble=lambda sc, b, st: ({}, {}))
    with pytest.raises(UndeclaredRead, match="imagespace.iterations"):
        run_graph(m, load_scene({}))


def test_meta_records_contract_and_versions():
    res = rr.render({"camera": {"width": 16, "height": 16}})
    from refraction_ref.contract import CONTRACT_VERSION

    assert res.meta["contract_version"] == CONTRACT_VERSION
    for lib in ("numpy", "numba", "trimesh", "embreex", "cpu"):
        assert res.meta["versions"][lib]
    ran = [p["stage"] for p in res.meta["plan"] if p["ran"]]
    assert set(res.meta["timings_ms"]) == set(ran)


def test_a_moved_knob_keeps_its_old_name(monkeypatch):
    import dataclasses

    from refraction_ref import graph

    block = graph.BLOCKS["imagespace"]
    monkeypatch.setitem(graph.BLOCKS, "imagespace", dataclasses.replace(block, aliases={"steps": "iterations"}))
    assert load_scene({"imagespace": {"steps": 7}}).data["imagespace"]["iterations"] == 7
    assert load_scene({}, {"imagespace.steps": 9}).data["imagespace"]["iterations"] == 9
    with pytest.raises(SceneError, match="imagespace.stepz"):
        load_scene({"imagespace": {"stepz": 7}})
