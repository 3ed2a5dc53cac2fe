"""Scene loading (refraction_ref.scene) and the shared optics (refraction_ref.optics)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

import refraction_ref as rr
from refraction_ref import optics
from refraction_ref.scene import IMAGESPACE_DEFAULTS, apply_overrides

# --------------------------------------------------------------------------
# defaults and overrides
# --------------------------------------------------------------------------


def test_defaults_are_the_seed_settings():
    s = rr.load_scene()
    im = s.data["imagespace"]
    assert im["iterations"] == 5 and im["slices"] == 256 and im["layers"] == 32
    assert im["bounds"] == "mip" and im["mip_size"] == 256 and im["normals"] == "central"
    assert im == IMAGESPACE_DEFAULTS
    c = s.data["camera"]
    assert c["width"] == 512 and c["height"] == 512 and c["fov_y"] == 30.0
    assert s.data["outside_ior"] == 1.0
    assert len(s.data["objects"]) == 1 and s.data["objects"][0]["mesh"] == "bunny"
    # a partial scene: given keys kept, the rest of the block filled in
    s = rr.load_scene({"camera": {"width": 40}, "imagespace": {"iterations": 7},
                       "objects": [{"mesh": "sphere", "material": {"ior": 1.33}}]})
    assert s.data["camera"]["width"] == 40 and s.data["camera"]["height"] == 512
    assert s.data["imagespace"]["iterations"] == 7 and s.data["imagespace"]["slices"] == 256
    o = s.data["objects"][0]
    assert o["material"] == {"ior": 1.33, "absorption": [0.0, 0.0, 0.0]}
    assert o["transform"] == {"scale": 1.0, "rotate": [0.0, 0.0, 0.0], "translate": [0.0, 0.0, 0.0]}
    # the defaults themselves were not modified by loading
    assert IMAGESPACE_DEFAULTS["iterations"] == 5


def test_overrides_with_dotted_keys_and_strings():
    s = rr.load_scene(None, {"imagespace.iterations": "10", "imagespace.tir": "true",
                             "camera.eye": "[0, 1, 3]", "objects.0.material.ior": 1.5,
                             "imagespace.normals": "mesh3x3", "camera.fov_y": "45.5"})
    im = s.data["imagespace"]
    assert im["iterations"] == 10 and isinstance(im["iterations"], int)
    assert im["tir"] is True
    assert s.data["camera"]["eye"] == [0, 1, 3]
    assert s.data["objects"][0]["material"]["ior"] == 1.5
    assert im["normals"] == "mesh3x3"  # not JSON: kept as a string
    assert s.data["camera"]["fov_y"] == 45.5
    assert rr.load_scene(None, {"imagespace.tir": "FALSE"}).data["imagespace"]["tir"] is False
    # the same through render's overrides and apply_overrides on a plain dict
    d = apply_overrides({"a": {"b": 1}}, {"a.b": "2"})
    assert d == {"a": {"b": 2}}


def test_overrides_are_validated():
    with pytest.raises(rr.SceneError, match="imagespace.iterations"):
        rr.load_scene(None, {"imagespace.iterations": "-1"})
    with pytest.raises(rr.SceneError, match="slices"):
        rr.load_scene(None, {"imagespace.slices": 100})  # not a multiple of 32
    with pytest.raises(rr.SceneError, match="imagespace.bounds"):
        rr.load_scene(None, {"imagespace.bounds": "exactish"})


@pytest.mark.parametrize("key,named", [("imagespace.itterations", "itterations"),
                                       ("camera.eyes", "eyes"),
                                       ("nonsense.iterations", "nonsense"),
                                       ("objects.3.material.ior", "3")])
def test_unknown_override_key_is_an_error_naming_it(key, named):
    with pytest.raises(rr.SceneError) as e:
        rr.load_scene(None, {key: 1})
    assert named in str(e.value) and key in str(e.value)


@pytest.mark.parametrize("scene,named", [({"camera": {"widht": 64}}, "camera.widht"),
                                         ({"imagespace": {"iteration": 3}}, "imagespace.iteration"),
                                         ({"objects": [{"mesh": "sphere", "materal": {}}]}, "objects[0].materal"),
                                         ({"colour": 1}, "colour")])
def test_unknown_scene_key_is_an_error_naming_it(scene, named):
    with pytest.raises(rr.SceneError, match=named.replace("[", r"\[").replace("]", r"\]")):
        rr.load_scene(scene)


def test_json_round_trip(tmp_path):
    s = rr.load_scene({"camera": {"width": 48, "height": 32, "eye": [0.5, 0.2, 3.0]},
                       "objects": [{"mesh": "sphere", "fit": 0.8, "material": {"ior": 1.4, "absorption": [0.1, 0, 0]}},
                                   {"mesh": "plane", "size": [1.0, 2.0],
                                    "transform": {"translate": [0, -1, 0], "rotate": [10, 0, 0]}}],
                       "imagespace": {"iterations": 9, "depth": "float"}})
    p = tmp_path / "scene.json"
    p.write_text(s.to_json())
    s2 = rr.load_scene(str(p))
    assert s2.data == s.data
    assert json.loads(s2.to_json()) == json.loads(s.to_json())
    assert s2.base_dir == str(tmp_path)
    # a relative mesh path in a scene file resolves against the file's folder
    import trimesh

    trimesh.creation.box().export(tmp_path / "box.ply")
    p2 = tmp_path / "rel.json"
    p2.write_text(json.dumps({"objects": [{"mesh": "box.ply"}]}))
    assert rr.load_scene(str(p2)).resolve_path("box.ply") == str(tmp_path / "box.ply")


def test_bad_json_file_is_refused(tmp_path):
    p = tmp_path / "broken.json"
    p.write_text("{not json")
    with pytest.raises(rr.SceneError, match="broken.json"):
        rr.load_scene(str(p))
    p.write_text("[1, 2]")
    with pytest.raises(rr.SceneError, match="broken.json"):
        rr.load_scene(str(p))


# --------------------------------------------------------------------------
# optics
# --------------------------------------------------------------------------

_unit = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(lambda v: 0.1 < np.linalg.norm(v))


def _u(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


@settings(max_examples=200, deadline=None)
@given(d=_unit, n=_unit, eta=st.floats(0.3, 3.0), flip=st.booleans())
def test_refract_obeys_snell(d, n, eta, flip):
    d, n = _u(d), _u(n)
    cos_i = -float(d @ n)
    assume(abs(cos_i) > 1e-3)
    sin_i = float(np.linalg.norm(np.cross(d, n)))  # accurate near normal incidence too
    assume(abs(eta * sin_i - 1) > 1e-9)  # away from the critical angle
    t, tir = optics.refract(d, -n if flip else n, eta)  # either normal orientation
    assert abs(np.linalg.norm(t) - 1) < 1e-12
    nf = n if cos_i > 0 else -n  # normal facing the incident ray
    assert bool(tir) == (eta * sin_i > 1)
    if tir:  # mirror direction
        np.testing.assert_allclose(t, d - 2 * (d @ nf) * nf, atol=1e-12)
        return
    sin_t = np.linalg.norm(np.cross(t, nf))
    assert abs(sin_i * eta - sin_t) < 1e-10  # n1 sin_i = n2 sin_t with eta = n1 / n2
    assert abs(np.dot(np.cross(d, nf), t)) < 1e-10  # coplanar
    assert t @ nf < 0  # transmitted to the other side


def test_refract_special_cases():
    d = _u([0.3, -0.2, -1.0])
    t, tir = optics.refract(d, [0, 0, 1], 1.0)  # index matched: unchanged
    assert not tir and np.max(np.abs(t - d)) < 1e-15
    t, tir = optics.refract([0, 0, -1.0], [0, 0, 1], 1 / 1.5)  # normal incidence
    assert not tir and np.array_equal(t, [0, 0, -1.0])
    # arrays, per-direction eta, shapes kept
    dd = np.tile(d, (4, 5, 1))
    t, tir = optics.refract(dd, [0, 0, 1.0], np.full((4, 5), 0.8))
    assert t.shape == (4, 5, 3) and tir.shape == (4, 5) and not tir.any()


@settings(max_examples=100, deadline=None)
@given(cos_i=st.floats(-1.0, 1.0), eta=st.floats(0.2, 4.0))
def test_fresnel_in_unit_interval_and_tir(cos_i, eta):
    r = float(optics.fresnel(cos_i, eta))
    assert 0.0 <= r <= 1.0
    sin2 = 1 - cos_i * cos_i
    if eta * eta * sin2 > 1 + 1e-12:
        assert r == 1.0
    # reciprocity: the reflectance is the same seen from the other side (away from
    # grazing incidence, where the reverse side sits at the critical angle: ill-conditioned)
    if eta * eta * sin2 < 1 - 1e-9 and abs(cos_i) > 1e-2:
        cos_t = math.sqrt(1 - eta * eta * sin2)
        assert abs(float(optics.fresnel(cos_t, 1 / eta)) - r) < 1e-9


@pytest.mark.parametrize("n1,n2", [(1.0, 1.5), (1.5, 1.0), (1.0, 2.4), (1.33, 1.0), (1.2, 1.2)])
def test_fresnel_at_normal_incidence(n1, n2):
    r = float(optics.fresnel(1.0, n1 / n2))
    assert abs(r - ((n1 - n2) / (n1 + n2)) ** 2) < 1e-15
    # grazing incidence reflects everything
    assert abs(float(optics.fresnel(0.0, n1 / n2)) - 1.0) < 1e-12
    # array form agrees with the scalar form
    c = np.linspace(0, 1, 7)
    np.testing.assert_array_equal(optics.fresnel(c, n1 / n2), [float(optics.fresnel(x, n1 / n2)) for x in c])


def test_beer_lambert():
    a = np.array([0.5, 0.0, 2.0])
    t = optics.beer_lambert(a, np.array([[0.0, 1.0], [2.0, 3.0]]), ior=1.5)
    assert t.shape == (2, 2, 3)
    np.testing.assert_allclose(t[1, 0], np.exp(-a * 2.0 * 1.5), rtol=1e-15)
    assert np.all(t[0, 0] == 1.0) and np.all(t[..., 1] == 1.0)
    # multiplicative along a path: T(l1 + l2) = T(l1) T(l2)
    np.testing.assert_allclose(optics.beer_lambert(a, 3.0, 1.2),
                               optics.beer_lambert(a, 1.0, 1.2) * optics.beer_lambert(a, 2.0, 1.2), rtol=1e-14)
    assert np.all(np.diff(optics.beer_lambert([1, 1, 1], np.linspace(0, 5, 10))[:, 0]) < 0)


def test_checker_environment_matches_the_latlong_formula():
    """The checker kernel's colours are (floor(u tiles) + floor(v tiles / 2)) mod 2 of the
    lat-long (u, v) computed with libm (Python's math), including directions exactly on
    the square edges and the poles, where the signs of zeros decide."""
    import math

    from refraction_ref.environment import environment_lookup

    rng = np.random.default_rng(7)
    colors = [[0.9, 0.8, 0.7], [0.1, 0.2, 0.3]]
    for tiles in (1, 2, 7, 16, 1000):
        d = rng.standard_normal((20_000, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        phi = np.linspace(-np.pi, np.pi, tiles + 1)  # meridians between squares
        theta = np.linspace(0.0, np.pi, tiles + 1)   # parallels between squares
        edges = np.concatenate([
            np.stack([np.sin(phi), np.zeros_like(phi), -np.cos(phi)], 1),
            np.stack([np.sin(theta), np.cos(theta), np.zeros_like(theta)], 1),
            [[0, 1, 0], [0, -1, 0], [0, 0, -1], [0, 0, 1], [-0.0, 0, 1], [1, 0, 0], [-1, 0, 0]]])
        d = np.concatenate([d, edges, -edges])
        env = {"type": "checker", "tiles": tiles, "colors": colors, "intensity": 1.0}
        got = environment_lookup(env, d)
        c = [(math.floor((math.atan2(x, -z) / (2 * math.pi) + 0.5) * tiles)
              + math.floor(math.acos(min(1.0, max(-1.0, y))) / math.pi * (tiles / 2.0))) % 2 for x, y, z in d]
        np.testing.assert_array_equal(got, np.asarray(colors, np.float32)[c], err_msg=f"tiles {tiles}")
