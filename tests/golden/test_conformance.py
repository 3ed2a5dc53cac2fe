"""The conformance kit catches the bugs backend authors make, names the key and the stage, and passes the oracle.

A subset of the golden catalogue is built once (module fixture); each test
writes a candidate folder from the oracle's own outputs, applies one bug, and
runs ``check``.
"""

from __future__ import annotations

import json
import os
import shutil

import numba
import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref import cli
from refraction_ref.camera import Camera
from refraction_ref.golden import build, catalogue, check
from refraction_ref.golden.check import CheckError
from refraction_ref.optics import refract

SUBSET = ("is_diamond_2_4", "is_caustics_sphere", "exact_caustics_sphere")


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    d = str(tmp_path_factory.mktemp("golden"))
    build(d, only=SUBSET, log=lambda *a: None)
    return d


def _candidate(suite, tmp_path, case, mutate=None, keys=None):
    """A candidate folder holding the oracle's own arrays of ``case`` (optionally only ``keys``), mutated."""
    with np.load(os.path.join(suite, case, "golden.npz")) as z:
        arrays = {k: z[k].copy() for k in z.files if keys is None or k in keys}
    if mutate is not None:
        mutate(arrays)
    d = tmp_path / "cand"
    (d / case).mkdir(parents=True, exist_ok=True)
    np.savez(d / case / "result.npz", **arrays)
    return str(d)


def _judge(suite, cand, case):
    out = check(cand, suite, cases=[case], panels=False)
    return out["cases"][case]


def _failing(res):
    return {k for k, j in res["keys"].items() if not j["ok"]}


def test_the_catalogue_spans_every_method():
    cases = catalogue()
    assert {c["method"] for c in cases} == {"imagespace", "exact", "levelmap", "volumetric"}
    assert len(cases) >= 20 and all(c["purpose"] for c in cases)


def test_the_oracle_passes_itself(suite, tmp_path):
    for case in SUBSET:
        res = _judge(suite, _candidate(suite, tmp_path / case, case), case)
        assert res["ok"], (case, _failing(res), res["problems"])


def test_two_builds_give_identical_hashes(suite, tmp_path):
    d = str(tmp_path / "again")
    build(d, only=["is_diamond_2_4"], log=lambda *a: None)
    a = json.load(open(os.path.join(suite, "manifest.json")))["cases"]["is_diamond_2_4"]["keys"]
    b = json.load(open(os.path.join(d, "manifest.json")))["cases"]["is_diamond_2_4"]["keys"]
    assert {k: v["sha256"] for k, v in a.items()} == {k: v["sha256"] for k, v in b.items()}


def test_another_thread_count_passes(suite, tmp_path):
    case = "is_caustics_sphere"
    scene = rr.load_scene(os.path.join(suite, case, "scene.json"))
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        res = rr.render(scene, keep="stages")
    finally:
        numba.set_num_threads(before)
    d = tmp_path / "cand" / case
    d.mkdir(parents=True)
    np.savez(d / "result.npz", **res.arrays)
    assert _judge(suite, str(tmp_path / "cand"), case)["ok"]


def test_another_photon_seed_passes_the_z_test(suite, tmp_path):
    case = "exact_caustics_sphere"
    scene = rr.load_scene(os.path.join(suite, case, "scene.json"), {"exact.photon_seed": 101})
    res = rr.render(scene, method="exact")
    d = tmp_path / "cand" / case
    d.mkdir(parents=True)
    np.savez(d / "result.npz", caustic_map_0=res["caustic_map_0"])
    r = _judge(suite, str(tmp_path / "cand"), case)
    assert r["ok"] and r["keys"]["caustic_map_0"]["kind"] == "ztest"


# --------------------------------------------------------------------- the bugs
def _half_pixel(suite):
    scene = rr.load_scene(os.path.join(suite, "is_diamond_2_4", "scene.json"))
    cam = Camera.from_dict(scene.data["camera"])
    H, W = cam.shape
    jj, ii = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))  # corners, not centres
    x = (jj / W * 2 - 1) * cam.sx
    y = (1 - ii / H * 2) * cam.sy
    b = cam.basis
    d = x[..., None] * b[0] + y[..., None] * b[1] - b[2]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)

    def m(a):
        a["ray_dir"] = d

    return m


def _eta_inverted_at_exit(a):
    # the sphere (IOR 2.4, radius 0.5 at the origin): refract the last inside direction with 1/eta
    ex = (a["status"] == 1) & (a["interfaces"] == 2)
    p = a["exit_pos"][ex]
    n = p / np.linalg.norm(p, axis=1, keepdims=True)
    d_in = a["stage.trace.path_dir"][ex][:, 0]
    t, tir = refract(d_in, n, 1.0 / 2.4)  # the bug: n_out / n_in instead of n_in / n_out = 2.4
    t = np.where(tir[:, None], np.nan, t)
    a["exit_dir"][ex] = t


def _normals_not_renormalised(a):
    rng = np.random.default_rng(0)
    n = a["stage.normals.normals"]
    a["stage.normals.normals"] = n * rng.uniform(0.8, 1.2, n.shape[:-1] + (1,))


def _float16_depths(a):
    a["stage.peel.ldi"] = a["stage.peel.ldi"].astype(np.float16).astype(np.float32)


def _off_by_one_slice(a):
    b = a["stage.voxelize.bits"].astype(np.uint64)
    carry = np.concatenate([np.zeros(b.shape[:-1] + (1,), np.uint64), b[..., :-1] >> np.uint64(31)], axis=-1)
    a["stage.voxelize.bits"] = (((b << np.uint64(1)) | carry) & np.uint64(0xFFFFFFFF)).astype(np.uint32)


def _layers_swapped(a):
    ldi = a["stage.peel.ldi"]
    a["stage.peel.ldi"] = ldi[[1, 0] + list(range(2, ldi.shape[0]))]


def _tir_marked_exited(a):
    a["status"] = np.where(a["status"] == 3, 1, a["status"]).astype(a["status"].dtype)


def _caustic_transposed(a):
    a["caustic_map_0"] = np.ascontiguousarray(a["caustic_map_0"].T)


def _frame_axis_flipped(a):
    f = a["caustic_frame_0"].copy()
    f[1] = -f[1]
    a["caustic_frame_0"] = f


def _flux_not_divided(a):
    a["caustic_map_0"] = a["caustic_map_0"] * np.float32(128 * 128)


BUGS = [  # (bug, case, keys the candidate supplies, the key that must fail, the stage that must be named)
    ("half-pixel offset in the primary rays", "is_diamond_2_4", ["ray_dir", "status"], "ray_dir", "rays"),
    ("relative index inverted at exits", "is_diamond_2_4", None, "exit_dir", "trace"),
    ("normals not renormalised", "is_diamond_2_4", None, "stage.normals.normals", "normals"),
    ("float16 depths", "is_diamond_2_4", None, "stage.peel.ldi", "peel"),
    ("off-by-one slice in the bitmask", "is_diamond_2_4", None, "stage.voxelize.bits", "voxelize"),
    ("two LDI layers swapped", "is_diamond_2_4", None, "stage.peel.ldi", "peel"),
    ("TIR rays marked as exited", "is_diamond_2_4", None, "status", "trace"),
    ("caustic map transposed", "is_caustics_sphere", None, "caustic_map_0", "gather"),
    ("frame axis flipped", "is_caustics_sphere", None, "caustic_frame_0", "gather"),
    ("photon flux not divided by the photon count", "exact_caustics_sphere", ["caustic_map_0"], "caustic_map_0",
     "gather"),
]
_MUT = {"half-pixel offset in the primary rays": None, "relative index inverted at exits": _eta_inverted_at_exit,
        "normals not renormalised": _normals_not_renormalised, "float16 depths": _float16_depths,
        "off-by-one slice in the bitmask": _off_by_one_slice, "two LDI layers swapped": _layers_swapped,
        "TIR rays marked as exited": _tir_marked_exited, "caustic map transposed": _caustic_transposed,
        "frame axis flipped": _frame_axis_flipped,
        "photon flux not divided by the photon count": _flux_not_divided}


@pytest.mark.parametrize("bug,case,keys,key,stage", BUGS, ids=[b[0] for b in BUGS])
def test_each_bug_is_caught_with_its_key_and_stage(suite, tmp_path, bug, case, keys, key, stage):
    mutate = _MUT[bug] or _half_pixel(suite)
    res = _judge(suite, _candidate(suite, tmp_path, case, mutate, keys), case)
    assert not res["ok"]
    assert key in _failing(res), (bug, _failing(res))
    assert res["earliest_failing_stage"] == stage, (bug, res["earliest_failing_stage"], _failing(res))


# --------------------------------------------------------------------- bad candidates
def test_bad_candidates_get_a_message_each_never_a_traceback(suite, tmp_path, capsys):
    cand = tmp_path / "bad"
    (cand / "is_diamond_2_4").mkdir(parents=True)
    with np.load(os.path.join(suite, "is_diamond_2_4", "golden.npz")) as z:
        status, ldi, exit_dir = z["status"], z["stage.peel.ldi"], z["exit_dir"]
    nan_dir = exit_dir.copy()
    nan_dir[status == 1] = np.nan
    np.savez(cand / "is_diamond_2_4" / "result.npz", status=status[:-1], **{"stage.peel.ldi": np.nan_to_num(ldi, posinf=0).astype(np.int32)},
             exit_dir=nan_dir)
    (cand / "is_caustics_sphere").mkdir()
    (cand / "is_caustics_sphere" / "result.npz").write_bytes(b"not a zip")
    assert cli.main(["check", str(cand), "--golden", suite, "--require", "image", "--no-panels"]) == 1
    out = capsys.readouterr()
    assert "Traceback" not in out.out + out.err
    summary = json.load(open(cand / "report" / "summary.json"))["cases"]
    keys = summary["is_diamond_2_4"]["keys"]
    assert "shape" in keys["status"]["detail"]
    assert "dtype" in keys["stage.peel.ldi"]["detail"]
    assert not keys["exit_dir"]["ok"]                      # NaN where the oracle exited
    assert any("required key 'image'" in p for p in summary["is_diamond_2_4"]["problems"])
    assert any("is not a .npz" in p for p in summary["is_caustics_sphere"]["problems"])  # not NumPy's pickle talk
    assert any("missing" in p for p in summary["exact_caustics_sphere"]["problems"])
    report = (cand / "report" / "report.md").read_text()
    assert "FAIL" in report and "earliest failing stage" in report.lower()


def test_a_suite_of_another_contract_version_is_refused(suite, tmp_path, capsys):
    other = tmp_path / "old"
    shutil.copytree(suite, other)
    m = json.load(open(other / "manifest.json"))
    m["contract_version"] = 0
    json.dump(m, open(other / "manifest.json", "w"))
    assert cli.main(["check", str(tmp_path), "--golden", str(other)]) == 2
    assert "contract_version 0" in capsys.readouterr().err
    with pytest.raises(CheckError):
        check(str(tmp_path), str(tmp_path / "nowhere"))


def test_report_rows_and_panels_show_what_failed(suite, tmp_path):
    """A rotated exit direction and a flipped bitmask bit: the report's rows keep their columns
    (a ``|c|`` in a detail is escaped) and the panels show the angle and the differing bits."""
    import imageio.v3 as iio

    from refraction_ref.golden.masks import popcount
    from refraction_ref.golden.panels import failure_panel

    case = "is_diamond_2_4"

    def bug(a):
        d = a["exit_dir"]
        ok = np.all(np.isfinite(d), axis=-1)
        d[ok] = d[ok][:, [1, 2, 0]]  # every exiting direction turned
        w = a["stage.voxelize.bits"]
        w[w.shape[0] // 2, w.shape[1] // 2, 0] ^= np.uint32(1)

    cand = _candidate(suite, tmp_path, case, bug)
    out = check(cand, suite, cases=[case], report=str(tmp_path / "rep"))
    keys = out["cases"][case]["keys"]
    assert not keys["exit_dir"]["ok"] and keys["exit_dir"]["panel"]
    md = (tmp_path / "rep" / "report.md").read_text()
    row = next(line for line in md.splitlines() if line.startswith("| `exit_dir`"))
    assert row.count(" | ") == 6 and "\\|" in row  # seven cells (the rationale last), the |c| escaped
    with np.load(os.path.join(suite, case, "golden.npz")) as z:
        g_dir, g_bits = z["exit_dir"], z["stage.voxelize.bits"]
    with np.load(os.path.join(cand, case, "result.npz")) as z:
        c_dir, c_bits = z["exit_dir"], z["stage.voxelize.bits"]
    # the bit panel's difference is the popcount of the XOR: one bit, in one pixel
    diff = popcount(c_bits ^ g_bits)
    assert diff.sum() == 1 and diff[g_bits.shape[0] // 2, g_bits.shape[1] // 2] == 1
    p = failure_panel(str(tmp_path / "dir.png"), "exit_dir", c_dir, g_dir, None, "angle")
    assert iio.imread(p).ndim == 3
