"""docs/oracle.md's porting rules for the image-space caustic stages reproduce the oracle's buffers.

The NumPy blocks of "Porting rules: image-space" ("Camera scalars",
"Rasterization", "`normals`" and "Caustic stages (§4.1)") are executed as
written and fed the oracle's upstream buffers of small versions of the two
catalogue caustic cases (a non-square eye image, a photon texture whose side
is not a power of two) and of the slanted case lit by a point light; every
caustic stage buffer must come out bit for bit. The photons' path lengths and
the light view's ``zmin`` are not buffers: they come from the oracle's own
light pass (``layered_trace``). Two planted bugs show that the slanted case
exposes what it was added for: a splat without ``|n . V|`` and a shadow test
read one light texel off.

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §4.1.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref.imagespace.pipeline import layered_trace, scene_geometry
from refraction_ref.lights import light_camera as oracle_light_camera

ROOT = Path(__file__).resolve().parents[2]
DOC = (ROOT / "docs" / "oracle.md").read_text(encoding="utf-8")
GOLDEN = ROOT / "refraction_ref" / "data" / "golden"
SMALL = {"camera.width": 48, "camera.height": 40, "imagespace.photons": 40, "caustics.map_size": 32}


def _blocks(heading):
    """The ```python blocks under a heading of docs/oracle.md, up to the next heading of level 2 or 3."""
    k = DOC.index(heading)
    rest = DOC[k + len(heading):]
    m = re.search(r"\n###? ", rest)
    return re.findall(r"```python\n(.*?)```", rest[:m.start()] if m else rest, re.S)


def _doc_namespace(scene):
    ns = {"np": np, "cam": scene.data["camera"], "env_block": scene.data["environment"]}
    for h in ("### Camera scalars", "### Rasterization", "### `normals`", "### Caustic stages (§4.1)\n"):
        blocks = _blocks(h)
        assert blocks, h
        for b in blocks:
            exec(b, ns)  # noqa: S102 -- the documented rules, as written
    return ns


def _scene(case, point_light=False, edge=False):
    data = json.loads((GOLDEN / f"{case}.json").read_text())["scene"]
    if edge:  # a narrow floor whose edge cuts the caustic: photons cross from no receiver to behind one
        data["receivers"][0]["size"] = [1.2, 3]
        data["receivers"][0]["transform"]["translate"] = [-0.75, -0.5, 0]
    for old, new in (("caustic_map", "map_size"), ("gather", "gather")):  # the old names, moved to their block
        if old in data.get("imagespace", {}):
            data.setdefault("caustics", {})[new] = data["imagespace"].pop(old)
    if point_light:
        data["lights"] = [{"type": "point", "position": [-1.2, 2.5, 0.6], "radiance": [1.0, 0.9, 0.8]}]
    return rr.load_scene(data, dict(SMALL))


def _same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


class _Port:
    """Every caustic stage of one scene, computed by the documented rules from the oracle's buffers."""

    def __init__(self, scene):
        self.scene = scene
        self.res = rr.render(scene, method="imagespace", keep="stages")
        self.ns = ns = _doc_namespace(scene)
        d = scene.data
        self.N = N = int(d["imagespace"]["photons"])
        self.Hc = Hc = int(d["caustics"]["map_size"])
        mat = d["objects"][0]["material"]
        self.ior, self.outside = float(mat["ior"]), float(d["outside_ior"])
        self.absorption = np.asarray(mat["absorption"], np.float64)
        self.lights = d["lights"]
        geom = scene_geometry(scene)
        self.cams = [ns["light_camera"](geom.vertices, lt, N) for lt in self.lights]
        self.tris = np.concatenate([ns["plane_triangles"](rc) for rc in d["receivers"]])
        self.owner = np.repeat(np.arange(len(d["receivers"])), 2)
        self.normals = ns["face_normals"](self.tris)
        self.albedo = np.stack([np.asarray(rc["albedo"], np.float64) for rc in d["receivers"]])
        self.boxes = [ns["map_box"](self.tris[self.owner == r].reshape(-1, 3), self.lights[0])
                      for r in range(len(d["receivers"]))]
        self.depth, self.triangle = ns["receiver_depth"](self.tris)
        cam = d["camera"]
        self.hits = [ns["receiver_hits"](self.buf(f"photon_trace.exit_pos_{l}"), self.buf(f"photon_trace.exit_dir_{l}"),
                                         self.depth, self.triangle, cam["near"], cam["far"])
                     for l in range(len(self.lights))]
        # not buffers: the photons' path lengths (flux) and the light view's zmin (shadow map)
        self.flux, self.lzmin = [], []
        for l, lt in enumerate(self.lights):
            tv = layered_trace(geom, oracle_light_camera(lt, geom.vertices, N), d["imagespace"], self.ior,
                               self.outside, {}, [])
            ex = np.flatnonzero(tv["trace"]["status"].ravel() == 1)
            _, _, sx, sy, ortho, _, _ = self.cams[l]
            self.flux.append(ns["photon_flux"](sx, sy, N, ortho, ex // N, ex % N, self.absorption,
                                               tv["trace"]["path_length"].ravel()[ex], self.ior))
            self.lzmin.append(tv["zmin"])

    def buf(self, name):
        return self.res.arrays[f"stage.{name}"]

    def splats(self, cosine=True):
        """Per light, per receiver, the (Hc, Wc, 3) float64 splat; cosine=False plants the missing |n . V|."""
        normals = self.normals
        if not cosine:  # every normal along its map's V: |n . V| = 1
            normals = np.tile(self.boxes[0][2], (len(self.normals), 1))
        return [[self.ns["splat_light"](P, face, self.flux[l], r, box, self.owner, normals, self.Hc, self.Hc)
                 for r, box in enumerate(self.boxes)] for l, (P, face) in enumerate(self.hits)]

    def gathered(self, per_light):
        g = int(self.scene.data["caustics"]["gather"])
        unit, rgb = [], []
        for r in range(len(self.boxes)):
            u, c = np.zeros((self.Hc, self.Hc)), np.zeros((self.Hc, self.Hc, 3))
            for l, lt in enumerate(self.lights):
                m = self.ns["gather"](per_light[l][r], g)
                u += (m[..., 0] + m[..., 1] + m[..., 2]) / 3
                c += m * np.asarray(lt["radiance"], np.float64)
            unit.append(np.nan_to_num(u, nan=0.0, posinf=0.0, neginf=0.0))
            rgb.append(np.nan_to_num(c, nan=0.0, posinf=0.0, neginf=0.0))
        return unit, rgb

    def final(self, rgb, texel_shift=0):
        ns, N = self.ns, self.N
        vis = []
        for l in range(len(self.lights)):
            leye, LB, lsx, lsy, lortho, lnear, lfar = self.cams[l]
            bias = 1e-3 * (lfar - lnear) + 2.0 * 2.0 * lsy / N
            z = np.roll(self.lzmin[l], texel_shift, axis=1)
            vis.append(lambda P, c=self.cams[l], b=bias, z=z: ns["shadow_vis"](P, c[0], c[1], c[2], c[3], c[4], N, z, b))

        def shade_pts(P, face, dirs):
            return ns["shade_receiver"](P, face, dirs, self.normals, self.owner, self.albedo, self.lights, vis, rgb,
                                        self.boxes, self.Hc, self.Hc)

        tr = {k: self.buf(f"trace.{k}") for k in ("status", "exit_pos", "exit_dir", "last_dir", "path_length")}
        cam = self.scene.data["camera"]
        return ns["caustic_final"](self.buf("minmax.zmin"), self.depth, self.triangle, self.buf("rays.ray_dir"), tr,
                                   shade_pts, self.ior, self.outside, self.absorption,
                                   int(self.scene.data["imagespace"]["delta"]), cam["near"], cam["far"])


@pytest.fixture(scope="module", params=[("is_caustics_sphere", False, False), ("is_caustics_slanted", False, False),
                                        ("is_caustics_slanted", True, False), ("is_caustics_slanted", False, True)],
                ids=["sphere", "slanted", "slanted_point_light", "slanted_floor_edge"])
def port(request):
    return _Port(_scene(*request.param))


def test_light_camera_receivers_and_depth_image_are_the_oracles(port):
    for l, (eye, LB, sx, sy, ortho, near, far) in enumerate(port.cams):
        mine = np.array([eye, *LB, [sx, sy, float(ortho)], [near, far, float(port.N)]])
        assert _same(mine, port.buf(f"photon_trace.camera_{l}"))
    for r, box in enumerate(port.boxes):
        assert _same(port.ns["map_frame"](box), port.buf(f"receivers.frame_{r}"))
        assert _same(port.ns["map_frame"](box), port.res.arrays[f"caustic_frame_{r}"])
    assert _same(port.depth, port.buf("receiver_depth.depth"))
    assert _same(port.triangle, port.buf("receiver_depth.triangle"))
    assert np.isin([0, 1], port.triangle).all()  # both halves of the plane are seen: the diagonal matters


def test_the_march_is_the_oracles(port):
    for l, (P, face) in enumerate(port.hits):
        assert _same(P, port.buf(f"receiver_hit.hit_pos_{l}"))
        assert _same(face, port.buf(f"receiver_hit.hit_face_{l}"))
        assert 0 < np.count_nonzero(face >= 0) < len(face)  # hits, and lost photons


def test_splat_gather_and_final_images_are_the_oracles(port):
    per_light = port.splats()
    for r in range(len(port.boxes)):
        sp = np.sum([(m[r][..., 0] + m[r][..., 1] + m[r][..., 2]) / 3 for m in per_light], axis=0)
        assert _same(sp.astype(np.float32), port.buf(f"splat.splat_{r}"))
    unit, rgb = port.gathered(per_light)
    for r in range(len(port.boxes)):
        assert unit[r].max() > 0
        assert _same(unit[r].astype(np.float32), port.buf(f"gather.caustic_map_{r}"))
        assert _same(rgb[r].astype(np.float32), port.buf(f"gather.caustic_rgb_{r}"))
    full, single = port.final(rgb)
    assert _same(full, port.buf("caustic_final.image_caustics"))
    assert _same(single, port.buf("caustic_final.image_caustics_single"))


def test_the_slanted_case_exposes_the_cosine_and_the_shadow():
    p = _Port(_scene("is_caustics_slanted"))
    face = p.hits[0][1]
    cos = np.abs(p.normals[face[face >= 0]] @ p.boxes[0][2])
    assert np.median(cos) < 0.75  # the floor is 33 degrees off the light: |n . V| = 0.685
    good = p.buf("splat.splat_0").astype(np.float64)
    bad = np.sum([m[0] for m in p.splats(cosine=False)], axis=0).mean(axis=2)
    # without the cosine every texel is 1 / |n . V| = 1.46 times too bright: far beyond 1 %
    assert abs(bad.sum() / good.sum() * np.median(cos) - 1.0) < 1e-5
    _, rgb = p.gathered(p.splats())
    full, _ = p.final(rgb, texel_shift=1)
    moved = np.any(full != p.buf("caustic_final.image_caustics"), axis=2)
    assert moved.sum() >= 10  # a shadow map read one light texel off moves the shadow's edge


def test_a_crossing_after_a_hole_is_the_sample_itself():
    # the march's hole rule (no secant when the previous sample's texel had no receiver) is
    # exercised by the floor-edge scene and reproduced there bit for bit
    p = _Port(_scene("is_caustics_slanted", edge=True))
    ns = dict(p.ns)
    src = [b for b in _blocks("### Caustic stages (§4.1)\n") if "def march" in b][0]
    rule = "f = -gap_prev / (gap - gap_prev) if np.isfinite(gap_prev) else 1.0"
    assert rule in src
    ns["AFTER_HOLE"] = []
    exec(src.replace(rule, rule + "\n            AFTER_HOLE.append(not np.isfinite(gap_prev))"), ns)  # noqa: S102
    cam = p.scene.data["camera"]
    P, face = ns["receiver_hits"](p.buf("photon_trace.exit_pos_0"), p.buf("photon_trace.exit_dir_0"), p.depth,
                                  p.triangle, cam["near"], cam["far"])
    assert sum(ns["AFTER_HOLE"]) >= 5
    assert _same(P, p.buf("receiver_hit.hit_pos_0")) and _same(face, p.buf("receiver_hit.hit_face_0"))
