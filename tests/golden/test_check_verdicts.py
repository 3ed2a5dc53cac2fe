"""``check``'s verdicts cannot pass by accident, and its allowances locate.

One small golden case (the glass bunny, 128x128) is built once per session;
each test writes a candidate from the golden's own arrays with one change a
porter really makes (or a legitimate difference) and asserts the verdict,
the failing key and the stage named.
"""

from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref import cli
from refraction_ref.camera import Camera
from refraction_ref.golden import build
from refraction_ref.golden.build import COMPLETE
from refraction_ref.golden.check import CheckError
from refraction_ref.golden.masks import neighbour_changes
from refraction_ref.meshes import scene_geometry
from refraction_ref.raster import raster_setup, rasterize

CASE = "is_bunny_1_2"


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    d = str(tmp_path_factory.mktemp("golden"))
    build(d, only=[CASE], log=lambda *a: None)
    return d


@pytest.fixture(scope="module")
def gold(suite):
    with np.load(os.path.join(suite, CASE, "golden.npz")) as z:
        return {k: z[k] for k in z.files}


def _cand(tmp_path, arrays, name="cand"):
    d = tmp_path / name / CASE
    d.mkdir(parents=True, exist_ok=True)
    np.savez(d / "result.npz", **arrays)
    return str(tmp_path / name)


def _run(suite, cand, **kw):
    return rr.check(cand, suite, cases=[CASE], panels=False, **kw)


def _interior(gold):
    """Covered pixels whose 3x3 neighbourhood has one status and one depth complexity (no silhouette)."""
    st, dc = gold["status"], gold["depth_complexity"]
    return (st != 0) & ~neighbour_changes(st) & ~neighbour_changes(dc)


# --------------------------------------------------------------------- verdicts that cannot pass by accident
def test_the_oracle_passes_itself_and_the_manifest_orders_stages_by_the_graph(suite, gold, tmp_path):
    out = _run(suite, _cand(tmp_path, gold))
    assert out.ok and out.cases[CASE].earliest_failing_stage is None
    assert len(out.cases[CASE]["keys"]) == len(gold)
    entry = json.load(open(os.path.join(suite, "manifest.json")))["cases"][CASE]
    assert entry["stages"][0] == "rays" and "output" not in entry["stages"]
    owner = {k: v["stage"] for k, v in entry["keys"].items()}
    assert (owner["ray_dir"], owner["hit"], owner["exit_dir"], owner["image"], owner["depth_complexity"]) == \
        ("rays", "trace", "trace", "shade", "peel")


def test_an_empty_candidate_folder_fails(suite, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert cli.main(["check", str(tmp_path / "empty"), "--golden", suite, "--no-panels"]) == 1
    assert "FAIL: 0 of 1 cases pass" in capsys.readouterr().out
    s = json.load(open(tmp_path / "empty" / "report" / "summary.json"))
    assert s["ok"] is False and "missing" in s["cases"][CASE]["problems"][0]


def test_an_empty_result_fails(suite, tmp_path):
    out = _run(suite, _cand(tmp_path, {}))
    assert not out.ok and any("no key of the contract was judged" in p for p in out.cases[CASE].problems)


def test_a_typod_key_fails_and_allow_extra_lists_it(suite, gold, tmp_path, capsys):
    cand = _cand(tmp_path, {"exit_dirr": gold["exit_dir"], "status": gold["status"]})
    out = _run(suite, cand)
    assert not out.ok and any("'exit_dirr' (did you mean 'exit_dir'?)" in p for p in out.cases[CASE].problems)
    out = _run(suite, cand, allow_extra=True)
    assert out.ok and out.cases[CASE].extra == ["exit_dirr"] and list(out.cases[CASE]["keys"]) == ["status"]
    assert cli.main(["check", cand, "--golden", suite, "--allow-extra", "--no-panels"]) == 0
    assert "extra keys, not judged: exit_dirr" in capsys.readouterr().out


def test_a_suite_without_its_completion_marker_is_refused(suite, tmp_path, capsys):
    half = tmp_path / "half"
    shutil.copytree(suite, half)
    os.remove(half / COMPLETE)
    (tmp_path / "c").mkdir()
    assert cli.main(["check", str(tmp_path / "c"), "--golden", str(half)]) == 2
    err = capsys.readouterr().err
    assert "incomplete" in err and COMPLETE in err and err.count("\n") == 1
    shutil.copy(os.path.join(suite, COMPLETE), half / COMPLETE)
    m = json.load(open(half / "manifest.json"))
    m["cases"][CASE]["keys"].pop("status")  # edited after the build
    json.dump(m, open(half / "manifest.json", "w"))
    with pytest.raises(CheckError, match="changed after the build"):
        rr.check(str(tmp_path / "c"), str(half))


def test_a_result_that_is_not_a_zip_says_so(suite, tmp_path):
    d = tmp_path / "nz" / CASE
    d.mkdir(parents=True)
    np.save(d / "result.npy", np.zeros(3))
    os.replace(d / "result.npy", d / "result.npz")  # a .npy under the .npz name
    p = _run(suite, str(tmp_path / "nz")).cases[CASE].problems
    assert "is not a .npz" in p[0] and "a .npy array" in p[0] and "pickle" not in p[0]


# --------------------------------------------------------------------- bugs named with their stage
def _fragment_depths(suite):
    scene = rr.load_scene(os.path.join(suite, CASE, "scene.json"))
    geom = scene_geometry(scene)
    cam = Camera.from_dict(scene.data["camera"])
    tv = raster_setup(cam.world_to_view(geom.vertices), cam, faces=geom.faces)
    n = int(rasterize(tv, cam, "count", clip=True).max())
    d, _ = rasterize(tv, cam, "collect", capacity=n, clip=True)
    return np.asarray(d, np.float64), scene.data["imagespace"]


def _slice_words(d, zlo, zhi, S, rule):
    """Bitmask words (blend=add) from fragment depths with the slice index ``rule((d - zlo)/(zhi - zlo)(S - 1))``."""
    L, H, W = d.shape
    words = np.zeros((H, W, S // 32), np.uint64)
    ok = np.isfinite(d)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(ok & (zhi > zlo)[None], (d - zlo[None]) / (zhi - zlo)[None] * (S - 1), 0.0)
    b = np.clip(rule(t), 0, S - 1).astype(np.int64)
    for layer in range(L):
        for k in range(S // 32):
            sel = ok[layer] & (b[layer] // 32 == k)
            words[..., k] += np.where(sel, np.uint64(1) << (b[layer] % 32).astype(np.uint64), np.uint64(0))
    return (words & np.uint64(0xFFFFFFFF)).astype(np.uint32)


def test_floor_for_round_in_the_slice_map_names_voxelize(suite, gold, tmp_path):
    d, p = _fragment_depths(suite)
    args = (gold["stage.voxelize.zlo"], gold["stage.voxelize.zhi"], int(p["slices"]))
    assert p["blend"] == "add"
    np.testing.assert_array_equal(_slice_words(d, *args, np.rint), gold["stage.voxelize.bits"])  # the contract
    a = dict(gold, **{"stage.voxelize.bits": _slice_words(d, *args, np.floor)})
    res = _run(suite, _cand(tmp_path, a)).cases[CASE]
    j = res["keys"]["stage.voxelize.bits"]
    assert not res.ok and res.earliest_failing_stage == "voxelize" and res.failing_keys == ["stage.voxelize.bits"]
    assert j["failing"] > 5 * j["allowed"]  # 1.5 % of the non-empty words against 0.2 %


def test_a_y_flip_names_rays(suite, gold, tmp_path):
    H, W = gold["status"].shape
    a = {}
    for k, v in gold.items():  # a backend with row 0 at the bottom: every picture upside down
        a[k] = v[::-1] if v.shape[:2] == (H, W) else v[:, ::-1] if v.shape[1:3] == (H, W) else v
    res = _run(suite, _cand(tmp_path, {k: np.ascontiguousarray(v) for k, v in a.items()})).cases[CASE]
    assert not res.ok and res.earliest_failing_stage == "rays"
    assert res["keys"]["ray_dir"]["failing"] > 0.5


def test_a_scatter_of_wrong_interior_status_values_fails_and_is_located(suite, gold, tmp_path):
    ii, jj = np.nonzero(_interior(gold))
    pick = np.random.default_rng(0).choice(len(ii), 5, replace=False)
    st = gold["status"].copy()
    st[ii[pick], jj[pick]] = 4
    rep = tmp_path / "rep"
    out = rr.check(_cand(tmp_path, {"status": st}), suite, cases=[CASE], report=str(rep))
    j = out.cases[CASE]["keys"]["status"]
    assert not out.ok and j["counts"]["located"] == 5 and out.cases[CASE].earliest_failing_stage == "trace"
    mask = np.load(rep / j["mask"])
    assert mask.sum() == 5 and mask[ii[pick], jj[pick]].all() and (rep / j["panel"]).is_file()


def test_a_silhouette_difference_is_tolerated(suite, gold, tmp_path):
    st, hit = gold["status"].copy(), gold["hit"].copy()
    edge = (st == 0) & neighbour_changes(st != 0)  # pixels just outside the silhouette
    ii, jj = np.nonzero(edge)
    st[ii[:10], jj[:10]] = 1
    hit[ii[:10], jj[:10]] = True
    out = _run(suite, _cand(tmp_path, {"status": st, "hit": hit}))
    assert out.ok
    assert out.cases[CASE]["keys"]["status"]["counts"]["inside_ambiguity"] == 10


def test_a_tolerated_bitmask_tie_does_not_name_reduce(suite, gold, tmp_path):
    """One fragment rounded into the next slice (a tie a blend=or or another rasterizer makes), at the deepest
    first-layer pixel: the LDI and the layer's bound move with it, and are judged against the candidate's own
    bitmask (through the oracle's peel and reduce passes)."""
    from refraction_ref.imagespace.depth_bounds import global_bounds
    from refraction_ref.imagespace.pipeline import MinMax, Voxels, pass_peel, pass_reduce

    p = rr.load_scene(os.path.join(suite, CASE, "scene.json")).data["imagespace"]
    gmin, gmax = global_bounds(gold["stage.minmax.zmin"], gold["stage.minmax.zmax"])
    ldi = gold["stage.peel.ldi"]
    for layer in range(ldi.shape[0]):  # the deepest fragment of a layer whose next slice is empty
        i, j = np.unravel_index(np.argmax(np.where(np.isfinite(ldi[layer]), ldi[layer], -np.inf)), ldi[layer].shape)
        bits = gold["stage.voxelize.bits"].copy()
        flat = np.unpackbits(bits[i, j].view(np.uint8), bitorder="little")
        k = np.flatnonzero(flat)[layer]
        if k + 1 < flat.size and flat[k + 1] == 0:
            flat[k], flat[k + 1] = 0, 1
            bits[i, j] = np.packbits(flat, bitorder="little").view(np.uint32)
            vox = Voxels(bits=bits, zlo=gold["stage.voxelize.zlo"], zhi=gold["stage.voxelize.zhi"], ldi=None,
                         total=None)
            pl = pass_peel(vox, bits.shape[:2], p)
            red = pass_reduce(MinMax(tri_view=None, zmin=None, zmax=None, frags=None, gmin=gmin, gmax=gmax), pl, p)
            if red.bounds_hi[layer] > gold["stage.reduce.bounds_hi"][layer]:  # the tie moved the layer's bound
                break
    else:
        pytest.fail("no layer of the bunny has a movable deepest fragment")
    a = dict(gold, **{"stage.voxelize.bits": bits, "stage.peel.ldi": pl.ldi,
                      "stage.reduce.bounds_hi": red.bounds_hi, "stage.reduce.bounds_lo": red.bounds_lo})
    res = _run(suite, _cand(tmp_path, a)).cases[CASE]
    assert res.ok, (res.failing_keys, res.earliest_failing_stage)
    assert "candidate's own" in res["keys"]["stage.reduce.bounds_hi"]["detail"]
    for k in ("stage.voxelize.bits", "stage.peel.ldi"):  # without the buffers that explain it: reduce fails
        a[k] = gold[k]
    res = _run(suite, _cand(tmp_path, a, "unexplained")).cases[CASE]
    assert res.earliest_failing_stage == "reduce" and res.failing_keys == ["stage.reduce.bounds_hi"]


# --------------------------------------------------------------------- messages
def test_messages_name_nonfinite_categories_dtypes_and_the_first_interface(suite, gold, tmp_path):
    ldi = gold["stage.peel.ldi"].copy()
    ldi[np.isposinf(ldi)] = np.nan  # NaN for absent layers
    pd = gold["stage.trace.path_dir"].copy()
    ok = np.all(np.isfinite(pd[:, :, 0]), axis=-1)
    pd[ok, 0] = -pd[ok, 0]  # interface 0 turned round, the later ones right
    a = {"stage.peel.ldi": ldi, "exit_pos": gold["exit_pos"].astype(np.float32), "stage.trace.path_dir": pd}
    keys = _run(suite, _cand(tmp_path, a)).cases[CASE]["keys"]
    assert "NaN where the golden has +inf" in keys["stage.peel.ldi"]["detail"]
    assert "dtype float32 where the contract has float64" in keys["exit_pos"]["detail"]
    parts = keys["stage.trace.path_dir"]["parts"]
    assert not parts["interface 0"]["ok"] and parts["interfaces 1+"]["ok"]
    assert all(keys[k]["why"] for k in ("stage.peel.ldi", "stage.trace.path_dir"))


def test_the_report_object(suite, gold, tmp_path):
    out = rr.check(_cand(tmp_path, {"ray_dir": gold["ray_dir"], "status": gold["status"]}), suite,
                   cases=[CASE], require=["image"], panels=False)
    assert not out.ok and out.earliest_failing_stage == {CASE: None}
    assert {r["key"] for r in out.rows} == {"ray_dir", "status"} and all(r["ok"] for r in out.rows)
    assert "required key 'image' is missing" in out.text and repr(out).startswith("<CheckReport FAIL")
