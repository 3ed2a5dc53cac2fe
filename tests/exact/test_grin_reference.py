"""The graded-index reference (:mod:`refraction_ref.exact.grin`): the ray equation by DOP853.

Numerical truths:

* the Numba integrator is scipy's DOP853: on the same rays ``solve_ivp``
  (with a terminal event at the box) gives the same exits;
* on the closed-form Luneburg lens (``refraction_ref.analytic.luneburg_lens``)
  the integrator meets the closed form to 1e-9 world units and 1e-6 rad;
* on the method's sampled lens it meets the closed form to within the
  field's own discretization (rays with impact parameter below 0.9 R);
* tightening the tolerance moves the exits less and less (convergence), and
  by less than 1e-5 world units from the default rtol 1e-10 to 1e-12;
* a uniform index bends nothing: straight exits, no drift.
"""

from __future__ import annotations

import os
import re

import numpy as np
import pytest

from refraction_ref.analytic import luneburg_lens
from refraction_ref.exact import grin
from refraction_ref.status import EXITED
from refraction_ref.volumetric.gradient import gradient_field
from refraction_ref.volumetric.photons import generate_photons

BOUNDS = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
R = 0.8
OBLIQUE = [{"type": "directional", "direction": [0.3, -0.2, -1.0], "radiance": [1, 1, 1]}]


def luneburg(N, radius=R):
    """The catalogue's lens (``golden/build.py``): n = sqrt(2 - r^2 / R^2) at voxel centres inside R, 1 outside."""
    c = (np.arange(N) + 0.5) / N * 2.0 - 1.0
    X, Y, Z = np.meshgrid(c, c, c, indexing="ij")
    r2 = (X ** 2 + Y ** 2 + Z ** 2) / radius ** 2
    return np.where(r2 < 1, np.sqrt(np.maximum(2 - r2, 1.0)), 1.0)


def _box_exit(p, u):
    t = np.full(len(p), np.inf)
    for a in range(3):
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = np.where(u[:, a] > 0, (BOUNDS[1, a] - p[:, a]) / u[:, a],
                          np.where(u[:, a] < 0, (BOUNDS[0, a] - p[:, a]) / u[:, a], np.inf))
        t = np.minimum(t, ta)
    return p + t[:, None] * u


def _closed_form_exits(pos, dirs):
    """Where photons starting on the box leave it: straight to the lens, its closed form, straight on."""
    L = luneburg_lens(pos, dirs, (0.0, 0.0, 0.0), R)
    start = np.where(L["hit"][:, None], L["exit_pos"], pos)
    u = np.where(L["hit"][:, None], L["exit_dir"], dirs)
    return _box_exit(start, u), u


def _impact(pos, dirs):
    return np.linalg.norm(np.cross(pos, dirs), axis=1) / R


def _angle(a, b):
    return np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0))


def test_numba_dop853_is_scipys_dop853():
    """The same rays through ``scipy.integrate.solve_ivp(method='DOP853')`` end at the same exits."""
    N = 16
    field = gradient_field(luneburg(N), BOUNDS)
    pos = np.array([[0.3, 0.2, 1.0], [-0.5, 0.1, 1.0], [0.05, -0.6, 1.0], [0.9, 0.9, 1.0]])
    dirs = np.tile([0.0, 0.0, -1.0], (4, 1))
    volume = grin.GrinVolume(field, BOUNDS)
    ours = grin.trace_rays(volume, pos, dirs, tolerances=grin.GrinTolerances(max_step=1e9))
    ref = grin.trace_rays_scipy(volume, pos, dirs)
    assert np.all(ours["status"] == EXITED) and np.all(ref["status"] == EXITED)
    assert np.abs(ours["end_pos"] - ref["end_pos"]).max() < 1e-7
    assert _angle(ours["end_dir"], ref["end_dir"]).max() < 1e-7
    # scipy's controller, step for step: the accepted steps differ only by the last one cut at the face
    np.testing.assert_allclose(ours["length"], ref["length"], rtol=0, atol=1e-7)


def test_closed_form_luneburg_lens_to_solver_precision():
    """The lens given in closed form (no sampling): every photon leaves at the closed form's point and direction."""
    N = 32
    pos, dirs, _, _, _ = generate_photons(OBLIQUE, BOUNDS, (N, N, N), 24)
    lens = grin.GrinVolume(np.zeros((N, N, N, 4), np.float32), BOUNDS, analytic=("luneburg", (0.0, 0.0, 0.0), R))
    res = grin.trace_rays(lens, pos, dirs, tolerances=grin.GrinTolerances(rtol=1e-12, atol=1e-14))
    cp, cu = _closed_form_exits(pos, dirs)
    b = _impact(pos, dirs)
    assert np.all(res["status"] == EXITED)
    assert np.count_nonzero(b < 1) > 150
    assert np.linalg.norm(res["end_pos"] - cp, axis=1).max() < 1e-9
    assert _angle(res["end_dir"], cu).max() < 1e-6


def test_sampled_luneburg_lens_meets_the_closed_form():
    """The method's 48^3 lens (trilinear n, central-difference gradient): rays with impact parameter below
    0.9 R leave within a voxel and a degree of the closed form (median 0.1 voxel and 0.2 deg); rays that miss
    the lens by 2 % of R go straight to 1e-12."""
    N = 48
    h = 2.0 / N
    field = gradient_field(luneburg(N), BOUNDS)
    pos, dirs, _, _, _ = generate_photons(OBLIQUE, BOUNDS, (N, N, N), 24)
    res = grin.trace_rays(grin.GrinVolume(field, BOUNDS), pos, dirs)
    cp, cu = _closed_form_exits(pos, dirs)
    b = _impact(pos, dirs)
    assert np.all(res["status"] == EXITED)
    lens = b < 0.9
    dp = np.linalg.norm(res["end_pos"] - cp, axis=1) / h
    dd = np.degrees(_angle(res["end_dir"], cu))
    assert lens.sum() > 100
    assert dp[lens].max() < 1.0 and np.median(dp[lens]) < 0.1, (dp[lens].max(), np.median(dp[lens]))
    assert dd[lens].max() < 1.0 and np.median(dd[lens]) < 0.2, (dd[lens].max(), np.median(dd[lens]))
    far = b > 1.0 + 2 * h / R  # beyond the voxels the lens's surface is smeared over
    assert far.sum() > 100
    assert dp[far].max() < 1e-10


def test_tightening_the_tolerance_converges():
    """rtol 1e-6 -> 1e-8 -> 1e-10 -> 1e-12 (atol 1e-2 rtol): each step moves the exits less, and the
    default (1e-10) is within 1e-5 world units (2e-4 voxel) and 1e-5 rad of 1e-12 on every photon."""
    N = 32
    field = gradient_field(luneburg(N), BOUNDS)
    pos, dirs, _, _, _ = generate_photons(OBLIQUE, BOUNDS, (N, N, N), 24)
    rows = grin.tolerance_sweep(grin.GrinVolume(field, BOUNDS), pos, dirs, rtols=(1e-6, 1e-8, 1e-10, 1e-12))
    d = [r["dpos_max"] for r in rows[:-1]]
    assert d[0] > d[1] > d[2], d
    assert rows[2]["rtol"] == grin.RTOL and rows[2]["atol"] == pytest.approx(grin.ATOL)
    assert rows[2]["dpos_max"] < 1e-5 and rows[2]["ddir_max"] < 1e-5
    assert all(r["status_changed"] == 0 for r in rows[:-1])


def test_uniform_index_goes_straight():
    """n = 1.3 everywhere: photons and viewing rays leave along their start direction, where a line leaves."""
    N = 8
    ior = np.full((N, N, N), 1.3)
    field = gradient_field(ior, BOUNDS)
    rng = np.random.default_rng(1)
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    pos = rng.uniform(-0.9, 0.9, (50, 3))
    res = grin.trace_photons(grin.GrinVolume(field, BOUNDS), pos, d, outside_ior=1.0)
    assert np.all(res["status"] == EXITED)
    np.testing.assert_allclose(res["exit_pos"], _box_exit(pos, d), atol=1e-12)
    np.testing.assert_allclose(res["exit_dir"], d, atol=1e-14)
    assert res["touched"].all() and res["drift_max"] < 1e-6
    eye = np.tile([0.2, 0.1, 3.0], (50, 1))
    target = rng.uniform(-0.8, 0.8, (50, 3))
    u = (target - eye) / np.linalg.norm(target - eye, axis=1)[:, None]
    vw = grin.trace_view(grin.GrinVolume(field, BOUNDS), eye, u, outside_ior=1.0)
    assert np.all(vw["status"] == EXITED) and vw["hit"].all()
    np.testing.assert_allclose(vw["exit_pos"], _box_exit(target, u), atol=1e-12)
    chord = np.linalg.norm(vw["exit_pos"] - (eye + ((1.0 - eye[:, 2]) / u[:, 2])[:, None] * u), axis=1)
    np.testing.assert_allclose(vw["path_length"], chord, rtol=1e-9)


def _lens_scene(N=16, receivers=True):
    sc = {"camera": {"width": 12, "height": 12, "eye": [0.0, 0.6, 3.0], "target": [0, -0.2, 0], "fov_y": 40},
          "objects": [], "volume": {"ior": luneburg(N, 0.6), "bounds": BOUNDS.tolist()},
          "lights": [{"type": "directional", "direction": [0.0, -1.0, 0.0], "radiance": [1, 1, 1]}],
          "volumetric": {"photons": 16}}
    if receivers:
        sc["receivers"] = [{"mesh": "plane", "size": [1.6, 1.6], "transform": {"translate": [0.0, -1.4, 0.0]}}]
    return sc


def _doc_buffers(text, title):
    """stage -> buffer names of the oracle's Stage buffers table under the heading starting with ``title``."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(title))
    out, stage = {}, None
    for ln in lines[start + 1:]:
        if ln.startswith("#"):
            break
        cells = [c.strip() for c in ln.split("|")[1:-1]]
        if len(cells) < 2 or (cells[0] and set(cells[0]) <= {"-"}):
            continue
        if cells[0]:
            names = re.findall(r"`([a-z_]+)`", cells[0])
            stage = names[0] if names else None
        for name in re.findall(r"`([a-z_]+)`", cells[1]):
            out.setdefault(stage, set()).add(re.sub(r"(_[rl])+$", "", name))
    return out


def test_method_exact_on_a_volume_scene_is_the_reference():
    """``render(scene, method="exact")`` on a volume scene runs the graded-index graph: the volumetric method's
    photons (same starts, same count), converged exits on the box, per-pixel keys, caustic maps of the photons
    that met the lens; the method's paths agree with it on most photons."""
    import refraction_ref as rr

    sc = _lens_scene()
    ref = rr.render(sc, method="exact", keep="stages")
    vol = rr.render(sc, method="volumetric")
    assert ref.meta["stages"] == ["voxelize", "gradient", "photons", "receivers", "photon_trace", "caustics",
                                  "trace", "shade"]
    final = {k for k in ref.arrays if not k.startswith("stage.")}
    assert set(vol.arrays) - final == {"radiance", "direction", "photon_steps"}
    assert final <= set(vol.arrays)
    # every stage buffer is in docs/oracle.md: the volumetric method's stages in its table, ours in ours
    doc = open(os.path.join(os.path.dirname(__file__), "..", "..", "docs", "oracle.md")).read()
    ours, theirs = _doc_buffers(doc, "### `exact` (volume scenes)"), _doc_buffers(doc, "### `volumetric` (Sun")
    for key in (k for k in ref.arrays if k.startswith("stage.")):
        _, stage, buf = key.split(".", 2)
        table = ours if stage in ("photon_trace", "caustics", "trace", "shade") else theirs
        assert re.sub(r"(_\d+)+$", "", buf) in table.get(stage, ()), key
    st = ref.arrays["photon_status"]
    assert len(st) == len(vol.arrays["photon_status"])
    assert np.all((st == EXITED) | (st == grin.RECEIVED))
    ex = st == EXITED
    p = ref.arrays["photon_exit_pos"][ex]
    assert np.all(np.isclose(np.abs(p), 1.0, atol=1e-12).any(axis=1))  # on a face of the box
    np.testing.assert_allclose(np.linalg.norm(ref.arrays["photon_exit_dir"][ex], axis=1), 1.0, atol=1e-12)
    assert np.isnan(ref.arrays["photon_exit_pos"][~ex]).all()
    assert np.mean(st == vol.arrays["photon_status"]) > 0.9
    m = ref.arrays["caustic_map_0"]
    assert m.sum() > 0 and np.isfinite(m).all()
    s = ref.arrays["status"]
    assert set(np.unique(s)) <= {0, 1} and (s == 1).any()
    np.testing.assert_array_equal(np.isnan(ref.arrays["exit_pos"]).any(axis=-1), s != 1)
    assert ref.arrays["image"].dtype == np.float32 and np.isfinite(ref.arrays["image"]).all()
