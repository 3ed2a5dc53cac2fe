"""The volumetric method's error against its run time, measured against the converged graded-index reference.

The reference (``--method exact`` on a volume scene,
:mod:`refraction_ref.exact.grin`) integrates the ray equation by DOP853 to
convergence on the very field, photons and receivers the method uses, so
the difference between the two is the method's integration error alone
(Sun et al. 2008, §4.4-§4.5, §5.3). Two graded scenes, both [-1, 1]^3, a
sun from above, a floor receiver below the box (y = -1.2), a 96x96 camera
in front:

* ``luneburg``: the catalogue's lens (``vol_luneburg``: n = sqrt(2 - r^2 /
  R^2), R = 0.8), which also has a closed form (the continuous lens,
  :func:`refraction_ref.analytic.luneburg_lens`): its rows add the exit
  direction error against the closed form for the method and for the
  reference (photons with impact parameter below 0.9 R), which separates
  the field's own discretization from the integration;
* ``blob``: a smooth asymmetric GRIN blob, two Gaussian bumps of index
  (+0.4, sigma 0.25, and +0.25, sigma 0.18, off centre): curved paths
  everywhere, no symmetry.

Knobs swept from the defaults (``stepping = paper``, ``integrator = euler``,
``eps = 0.005``, ``eps2 = 0.02``, ``ds_min = 1``, N = 64, ``photons`` M =
128): stepping x integrator (paper / robust x Euler / RK4); ``eps`` (eps2 =
4 eps, the defaults' ratio); ``ds_min``; the resolution N (the volume
generated at N, each N against its own reference); the photon texture M
(caustic maps against the reference of the same photons, and against the
reference at the largest M, the converged map).

Errors per run: photon exits (status 1 in both; the photons are the same
photons, one for one) as the position error in voxels and the direction
error in degrees (median, p99) and the share of photons whose status
differs; the floor's caustic map as the relative L1 error with both blurred
one texel (``refraction-ref compare``'s); the viewing pass's exit
directions (status 1 in both, median and p99 degrees) and status agreement.
Run time: the method's ``timings_ms`` on one Numba thread (``--threads``;
best of ``--repeats``, after a warm-up render): the photon pass is ``octree
+ photons + march + caustics``, the viewing pass ``view``; and the CPU time
of the whole render; the reference's own time beside (every thread).

Usage: ``python benchmarks/grin_error_vs_time.py [--quick] [--repeats R]``.
Writes ``benchmarks/results/grin_error_vs_time{,_quick}.{csv,md,png}``.
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
import time

import numpy as np

import refraction_ref as rr
from refraction_ref.analytic import luneburg_lens
from refraction_ref.compare import angular_error_deg, compare_arrays
from refraction_ref.exact import grin
from refraction_ref.files import atomic_open
from refraction_ref.golden.build import _generate_volume
from refraction_ref.volumetric.gradient import gradient_field
from refraction_ref.volumetric.photons import generate_photons

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
B = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
R_LENS = 0.8
LIGHT = {"type": "directional", "direction": [0.0, -1.0, 0.0], "radiance": [1.0, 1.0, 1.0]}
DEFAULTS = {"stepping": "paper", "integrator": "euler", "eps": 0.005, "eps2": 0.02, "ds_min": 1.0}


def volume(name, N):
    """The scene's index volume at N^3 voxel centres over [-1, 1]^3."""
    if name == "luneburg":
        return _generate_volume({"generator": "luneburg", "n": N, "radius": R_LENS})
    c = (np.arange(N) + 0.5) / N * 2.0 - 1.0
    X, Y, Z = np.meshgrid(c, c, c, indexing="ij")

    def bump(cx, cy, cz, s):
        return np.exp(-((X - cx) ** 2 + (Y - cy) ** 2 + (Z - cz) ** 2) / (2 * s * s))

    return 1.0 + 0.4 * bump(-0.15, 0.1, 0.0, 0.25) + 0.25 * bump(0.3, -0.25, 0.15, 0.18)


def scene(name, N, M, knobs=None):
    """The benchmark scene: the volume, the sun, the floor, the camera; volumetric knobs over the defaults."""
    return {"camera": {"eye": [0.0, 0.3, 3.0], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y": 40, "width": 96,
                       "height": 96},
            "objects": [], "volume": {"ior": volume(name, N), "bounds": B.tolist()}, "lights": [LIGHT],
            "receivers": [{"mesh": "plane", "size": [2.4, 2.4], "transform": {"translate": [0.0, -1.2, 0.0]}}],
            "caustics": {"map_size": 64},
            "volumetric": {"photons": int(M), **DEFAULTS, **(knobs or {})}}


def _photon_time(meta):
    t = meta["timings_ms"]
    return sum(t.get(k, 0.0) for k in ("octree", "photons", "march", "caustics"))


def _lens_closed_form(pos, dirs, exit_dir):
    """Exit-direction error (deg; median, p99) against the continuous lens, photons with b < 0.9 R."""
    L = luneburg_lens(pos, dirs, (0.0, 0.0, 0.0), R_LENS)
    b = np.linalg.norm(np.cross(pos, dirs), axis=1) / R_LENS
    sel = (b < 0.9) & np.all(np.isfinite(exit_dir), axis=1)
    e = angular_error_deg(exit_dir[sel], L["exit_dir"][sel])
    return float(np.median(e)), float(np.percentile(e, 99))


def errors(res, ref, N, truth_map=None):
    """The method's errors against the reference (module docstring)."""
    a, b = res.arrays, ref.arrays
    h = 2.0 / N
    sa, sb = a["photon_status"], b["photon_status"]
    both = (sa == 1) & (sb == 1)
    dp = np.linalg.norm(a["photon_exit_pos"][both] - b["photon_exit_pos"][both], axis=1) / h
    dd = angular_error_deg(a["photon_exit_dir"][both], b["photon_exit_dir"][both])
    c = compare_arrays(a, b)
    out = {"photons": int(len(sa)), "pos_p50_vox": float(np.median(dp)), "pos_p99_vox": float(np.percentile(dp, 99)),
           "dir_p50_deg": float(np.median(dd)), "dir_p99_deg": float(np.percentile(dd, 99)),
           "status_differs_pct": 100.0 * float(np.mean(sa != sb)),
           "caustic_l1": float(c["caustic_rel_l1"]["caustic_map_0"]),
           "view_p50_deg": c["exit_dir_deg"]["median"], "view_p99_deg": c["exit_dir_deg"]["p99"],
           "view_status_agree_pct": 100.0 * c["status_agree"]}
    if truth_map is not None:
        from refraction_ref.metrics import relative_l1

        out["caustic_l1_truth"] = float(relative_l1(a["caustic_map_0"], truth_map, blur=1.0))
    return out


class _Arrays:
    """A result's arrays read back from the references' cache (``.arrays``, as a Result)."""

    def __init__(self, arrays):
        self.arrays = arrays


class References:
    """Converged references per (scene, N, M), kept on disk in ``folder`` (a rerun reuses them), rendered with a
    Session per (scene, N) (a photon change reuses the viewing rays); with the photons' starts kept."""

    def __init__(self, folder):
        self.folder = folder
        os.makedirs(folder, exist_ok=True)
        self.sessions = {}
        self.cache = {}
        self.seconds = {}

    def get(self, name, N, M):
        key = (name, N, M)
        if key in self.cache:
            return self.cache[key]
        path = os.path.join(self.folder, f"{name}_{N}_{M}_rtol{grin.RTOL:g}.npz")
        if os.path.exists(path):
            with np.load(path) as z:
                arrays = {k: z[k] for k in z.files}
            self.seconds[key] = float(arrays.pop("seconds"))
            self.cache[key] = _Arrays(arrays)
            return self.cache[key]
        s = self.sessions.get((name, N))
        if s is None:
            s = self.sessions[(name, N)] = rr.Session(scene(name, N, M))
        else:
            s.update({"volumetric.photons": int(M)})
        t0 = time.perf_counter()
        r = s.render("exact", keep="photons")
        self.seconds[key] = time.perf_counter() - t0
        with atomic_open(path, "wb") as f:
            np.savez(f, seconds=self.seconds[key], **r.arrays)
        self.cache[key] = _Arrays(dict(r.arrays))
        return self.cache[key]


def run_method(name, N, M, knobs, repeats, threads):
    """The method's render of one setting on ``threads`` Numba threads, best of ``repeats`` by the two passes'
    wall time; and its times: (photon pass ms, viewing pass ms, graph ms, CPU ms of the whole render)."""
    import numba

    best, res = None, None
    sc = rr.load_scene(scene(name, N, M, knobs))
    was = numba.get_num_threads()
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    try:
        rr.render(sc, method="volumetric")  # compiles (or loads) this setting's kernels outside the timings
        for _ in range(repeats):
            c0 = time.process_time()
            r = rr.render(sc, method="volumetric")
            cpu = (time.process_time() - c0) * 1e3
            t = (_photon_time(r.meta), r.meta["timings_ms"]["view"], r.meta["total_ms"], cpu)
            if best is None or t[0] + t[1] < best[0] + best[1]:
                best, res = t, r
    finally:
        numba.set_num_threads(was)
    return res, best


def families(quick):
    eps = (0.002, 0.005, 0.02) if quick else (0.001, 0.002, 0.005, 0.01, 0.02, 0.05)
    fam = [("stepping", f"{st}/{it}", {"stepping": st, "integrator": it}, None, None)
           for st in ("paper", "robust") for it in ("euler", "rk4")]
    fam += [("eps", f"eps={e:g}", {"eps": e, "eps2": 4 * e}, None, None) for e in eps]
    fam += [("ds_min", f"ds_min={d:g}", {"ds_min": d}, None, None) for d in ((1.0, 2.0) if quick else (0.5, 1.0, 2.0))]
    fam += [("resolution", f"N={n}", {}, n, None) for n in ((16, 32) if quick else (32, 64, 128))]
    fam += [("photons", f"M={m}", {}, None, m) for m in ((16, 32) if quick else (32, 64, 128, 256))]
    return fam


def convergence_rows(name, N, M):
    """The reference's tolerance sweep on the scene's photons (:func:`~refraction_ref.exact.grin.tolerance_sweep`)."""
    field = gradient_field(volume(name, N), B)
    pos, dirs, _, _, _ = generate_photons([LIGHT], B, (N, N, N), M)
    rows = grin.tolerance_sweep(grin.GrinVolume(field, B), pos, dirs, rtols=(1e-6, 1e-8, 1e-10, 1e-12))
    for r in rows:
        for k in ("dpos_max", "dpos_p99"):
            if r[k] is not None:
                r[k + "_vox"] = r[k] / (2.0 / N)
    return rows


def _fmt(x, nd=3):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-"
    if isinstance(x, float):
        return f"{x:.{nd}g}"
    return str(x)


COLS = ["scene", "family", "setting", "N", "M", "photons", "t_photons_ms", "t_view_ms", "t_total_ms", "cpu_ms",
        "pos_p50_vox", "pos_p99_vox", "dir_p50_deg", "dir_p99_deg", "status_differs_pct", "caustic_l1",
        "caustic_l1_truth", "view_p50_deg", "view_p99_deg", "view_status_agree_pct", "lens_cf_p50_deg",
        "lens_cf_p99_deg", "ref_lens_cf_p50_deg", "ref_lens_cf_p99_deg", "ref_s"]


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows})
    fig, ax = plt.subplots(len(scenes), 2, figsize=(11, 4.2 * len(scenes)), squeeze=False)
    marks = {"stepping": "o", "eps": "s", "ds_min": "^", "resolution": "D", "photons": "v"}
    for i, sc in enumerate(scenes):
        for fam, m in marks.items():
            rr_ = [r for r in rows if r["scene"] == sc and r["family"] == fam]
            if not rr_:
                continue
            ax[i, 0].plot([r["t_photons_ms"] for r in rr_], [max(r["dir_p50_deg"], 1e-6) for r in rr_], m + "-",
                          label=fam)
            ax[i, 1].plot([r["t_view_ms"] for r in rr_], [max(r["view_p50_deg"], 1e-6) for r in rr_], m + "-",
                          label=fam)
            for r in rr_:
                ax[i, 0].annotate(r["setting"], (r["t_photons_ms"], max(r["dir_p50_deg"], 1e-6)), fontsize=6)
        ax[i, 0].set(xscale="log", yscale="log", xlabel="photon pass (ms)",
                     ylabel="photon exit direction error, median (deg)",
                     title=f"{sc}: photons against the converged reference")
        ax[i, 1].set(xscale="log", yscale="log", xlabel="viewing pass (ms)",
                     ylabel="viewing exit direction error, median (deg)",
                     title=f"{sc}: viewing rays against the converged reference")
        ax[i, 0].legend(fontsize=7)
        ax[i, 1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grids and photon counts (a smoke run)")
    ap.add_argument("--repeats", type=int, default=3, help="method runs per setting; the fastest is kept")
    ap.add_argument("--threads", type=int, default=1,
                    help="Numba threads of the method's timed renders (1: its work, without the waits of a shared "
                         "machine's threads; the references use every thread)")
    ap.add_argument("--scenes", default="luneburg,blob")
    ap.add_argument("--refs", default=os.path.join(tempfile.gettempdir(), "grin_error_vs_time_refs"),
                    help="folder keeping the references between runs (default: in the temporary folder)")
    a = ap.parse_args(argv)
    tag = "_quick" if a.quick else ""
    N0, M0 = (32, 32) if a.quick else (64, 128)
    refs = References(a.refs)
    rows, conv = [], {}
    t_start = time.perf_counter()
    for name in a.scenes.split(","):
        conv[name] = convergence_rows(name, N0, 32 if a.quick else 64)
        fams = families(a.quick)
        m_truth = max(f[4] for f in fams if f[4])
        truth = refs.get(name, N0, m_truth).arrays["caustic_map_0"]
        for fam, label, knobs, N, M in fams:
            N = N or N0
            M = M or M0
            ref = refs.get(name, N, M)
            res, (tp, tv, tt, tc) = run_method(name, N, M, knobs, a.repeats, a.threads)
            row = {"scene": name, "family": fam, "setting": label, "N": N, "M": M, "t_photons_ms": tp,
                   "t_view_ms": tv, "t_total_ms": tt, "cpu_ms": tc, "ref_s": refs.seconds[(name, N, M)]}
            row.update(errors(res, ref, N, truth if N == N0 else None))
            if name == "luneburg":
                start = ref.arrays["stage.photons.start_pos"], ref.arrays["stage.photons.start_dir"]
                row["lens_cf_p50_deg"], row["lens_cf_p99_deg"] = _lens_closed_form(*start,
                                                                                  res.arrays["photon_exit_dir"])
                row["ref_lens_cf_p50_deg"], row["ref_lens_cf_p99_deg"] = _lens_closed_form(
                    *start, ref.arrays["photon_exit_dir"])
            rows.append(row)
            print(f"{name:9s} {label:18s} photons {tp:8.1f} ms view {tv:7.1f} ms  dir p50 {row['dir_p50_deg']:.3g} "
                  f"p99 {row['dir_p99_deg']:.3g} deg  pos p50 {row['pos_p50_vox']:.3g} vox  caustic L1 "
                  f"{row['caustic_l1']:.3g}  view p50 {row['view_p50_deg']:.3g} deg", flush=True)
    os.makedirs(OUT, exist_ok=True)
    with atomic_open(os.path.join(OUT, f"grin_error_vs_time{tag}.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in COLS})
    plot(rows, os.path.join(OUT, f"grin_error_vs_time{tag}.png"))
    with atomic_open(os.path.join(OUT, f"grin_error_vs_time{tag}.md"), "w") as f:
        f.write(report(rows, conv, refs, N0, M0, time.perf_counter() - t_start, a))
    print(f"wrote {OUT}/grin_error_vs_time{tag}.{{csv,md,png}}")


def summary(rows, conv, refs, N0, M0):
    """The findings in numbers, one bullet per scene and knob family (computed from the rows)."""
    out = []

    def row(sc, setting):
        return next((r for r in rows if r["scene"] == sc and r["setting"] == setting), None)

    for sc in sorted({r["scene"] for r in rows}, key=lambda x: x != "luneburg"):
        d = row(sc, "paper/euler")
        if d is None:
            continue
        t0 = d["t_photons_ms"]
        line = (f"**{sc}**, defaults (paper, Euler): photon exits {d['dir_p50_deg']:.3g} deg median "
                f"({d['dir_p99_deg']:.3g} p99), {d['pos_p50_vox']:.3g} voxel; floor map L1 {d['caustic_l1']:.3g}; "
                f"viewing exits {d['view_p50_deg']:.3g} deg median.")
        k = row(sc, "paper/rk4")
        if k:
            line += (f" RK4: {d['dir_p50_deg'] / max(k['dir_p50_deg'], 1e-12):.0f}x smaller photon direction error, "
                     f"{d['caustic_l1'] / max(k['caustic_l1'], 1e-12):.0f}x smaller map error, "
                     f"{d['view_p50_deg'] / max(k['view_p50_deg'], 1e-12):.0f}x smaller viewing error, for "
                     f"{k['t_photons_ms'] / t0:.1f}x the photon pass and {k['t_view_ms'] / d['t_view_ms']:.1f}x the "
                     "viewing pass.")
        rb = row(sc, "robust/euler")
        if rb:
            line += (f" Robust stepping with Euler: {rb['dir_p50_deg']:.3g} deg, map L1 {rb['caustic_l1']:.3g} "
                     f"({rb['t_photons_ms'] / t0:.1f}x the time).")
        eps = [r for r in rows if r["scene"] == sc and r["family"] == "eps"]
        if eps:
            worst = max(eps, key=lambda r: r["dir_p50_deg"])
            best = min(eps, key=lambda r: r["dir_p50_deg"])
            line += (f" eps: from {best['setting']} ({best['dir_p50_deg']:.3g} deg, map {best['caustic_l1']:.3g}, "
                     f"{best['t_photons_ms']:.0f} ms) to {worst['setting']} ({worst['dir_p50_deg']:.3g} deg, map "
                     f"{worst['caustic_l1']:.3g}, {worst['t_photons_ms']:.0f} ms).")
        ds = row(sc, "ds_min=2")
        if ds:
            line += (f" ds_min = 2 voxels: {ds['dir_p50_deg']:.3g} deg, map {ds['caustic_l1']:.3g} "
                     f"({ds['t_photons_ms'] / t0:.2f}x the time).")
        res = [r for r in rows if r["scene"] == sc and r["family"] == "resolution"]
        if res:
            line += " Resolution: " + ", ".join(f"{r['setting']} {r['dir_p50_deg']:.3g} deg / view "
                                                f"{r['view_p50_deg']:.3g} deg" for r in res) + "."
        ph = [r for r in rows
              if r["scene"] == sc and r["family"] == "photons" and r.get("caustic_l1_truth") is not None]
        if ph:
            line += " Photons (map against the converged map at the largest M): " + ", ".join(
                f"{r['setting']} {r['caustic_l1_truth']:.3g}" for r in ph) + "."
        cr = next((r for r in conv.get(sc, []) if r["rtol"] == grin.RTOL), None)
        if cr:
            line += (f" The reference moves by at most {cr['dpos_max_vox']:.2g} voxel ({cr['dpos_max']:.2g} world) "
                     f"from rtol {grin.RTOL:g} to 1e-12; it cost {refs.seconds.get((sc, N0, M0), float('nan')):.0f} s "
                     f"at N = {N0}, M = {M0}.")
        out.append("- " + line)
    lens = [r for r in rows if r["scene"] == "luneburg" and r["family"] == "resolution"]
    if lens:
        out.append("- **luneburg against the continuous lens** (b < 0.9 R): the converged reference's own error "
                   "(the field's discretization) falls with N, " + ", ".join(
                       f"{r['setting']} {r['ref_lens_cf_p50_deg']:.3g} deg" for r in lens) + "; the method's stays "
                   "near the integration error, " + ", ".join(
                       f"{r['setting']} {r['lens_cf_p50_deg']:.3g} deg" for r in lens) + " (medians).")
    return out


def report(rows, conv, refs, N0, M0, seconds, a):
    import numba

    L = [f"# The volumetric method's error against run time, against the converged graded-index reference"
         f"{' (quick)' if a.quick else ''}", "",
         "`benchmarks/grin_error_vs_time.py" + (" --quick" if a.quick else "") + "` (module docstring: scenes, knobs, "
         f"metrics). The method's renders on {a.threads} Numba thread(s) of a 2-vCPU machine shared with other jobs "
         f"(times: best of {a.repeats} after a warm-up render; still noisy, by tens of per cent), the references on "
         f"{numba.get_num_threads()}; this run took {seconds / 60:.1f} min (references read back from `--refs` "
         f"keep their first run's time, below; a run from scratch took 13 min). Times compare within a run: "
         f"another run on the same machine gave times up to 2-3x longer (other jobs). Defaults: stepping paper, Euler, eps 0.005, "
         f"eps2 0.02, ds_min 1 voxel, N = {N0}, M = {M0} (photons^2 texels), 96x96 pixels.", "",
         "The reference is `--method exact` on the same scene: the ray equation by DOP853 (rtol "
         f"{grin.RTOL:g}, atol {grin.ATOL:g}, steps <= {grin.MAX_STEP:g} voxel) on the method's own field, photons "
         "and receivers (docs/oracle.md, \"Exact reference on volume scenes\"). So every error below is the "
         "method's integration (step rule, integrator, octree shortcut), not the field's discretization; the "
         "Luneburg rows add both against the continuous lens's closed form.", ""]
    L += ["## Summary", ""] + summary(rows, conv, refs, N0, M0) + [""]
    L += ["## Convergence of the reference", "",
          "Tightening DOP853's tolerance (atol = rtol / 100) on the scene's own photons "
          f"(N = {N0}, M = {32 if a.quick else 64}): how far the exits move to the next tighter tolerance.", "",
          "| scene | rtol | steps per photon | seconds | exit moves: max (world) | max (voxels) | p99 (voxels) | "
          "direction, max (rad) | status changed |", "|---|---|---|---|---|---|---|---|---|"]
    for name, rs in conv.items():
        for r in rs:
            L.append(f"| {name} | {r['rtol']:g} | {r['steps']:.0f} | {r['seconds']:.2f} | {_fmt(r['dpos_max'])} | "
                     f"{_fmt(r.get('dpos_max_vox'))} | {_fmt(r.get('dpos_p99_vox'))} | {_fmt(r['ddir_max'])} | "
                     f"{_fmt(r['status_changed'])} |")
    L += ["", "## Reference cost", "", "| scene | N | M | photons | seconds (photons and, first time per N, the "
          "96x96 viewing rays) |", "|---|---|---|---|---|"]
    for (name, N, M), s in sorted(refs.seconds.items()):  # (a reference read back keeps its first run's time)
        L.append(f"| {name} | {N} | {M} | {len(refs.cache[(name, N, M)].arrays['photon_status'])} | {s:.1f} |")
    L += ["", "## Error against run time", "",
          "Photon exits: position (voxels) and direction (degrees) of the photons that exited in both; "
          "\"status\": photons whose status differs. Caustic: relative L1 of the floor's map against the reference "
          "of the same photons, and (\"vs truth\") against the reference at the largest M (same N only). View: exit "
          "direction of the pixels that exited in both (degrees) and status agreement.", ""]
    head = ("| scene | knob | photon pass ms | view ms | render CPU ms | pos p50 / p99 (vox) | dir p50 / p99 (deg) | "
            "status % | caustic L1 | vs truth | view p50 / p99 (deg) | view status % |")
    L += [head, "|---" * (head.count("|") - 1) + "|"]
    for r in rows:
        L.append(f"| {r['scene']} | {r['setting']} | {r['t_photons_ms']:.0f} | {r['t_view_ms']:.0f} | "
                 f"{r['cpu_ms']:.0f} | "
                 f"{_fmt(r['pos_p50_vox'])} / {_fmt(r['pos_p99_vox'])} | {_fmt(r['dir_p50_deg'])} / "
                 f"{_fmt(r['dir_p99_deg'])} | {r['status_differs_pct']:.2f} | {_fmt(r['caustic_l1'])} | "
                 f"{_fmt(r.get('caustic_l1_truth'))} | {_fmt(r['view_p50_deg'])} / {_fmt(r['view_p99_deg'])} | "
                 f"{r['view_status_agree_pct']:.1f} |")
    lens = [r for r in rows if r["scene"] == "luneburg"]
    if lens:
        L += ["", "## Luneburg: against the continuous lens", "",
              "Exit direction against the closed form (photons with impact parameter below 0.9 R), the method and "
              "the converged reference on the same field: the reference's error is the field's discretization "
              "(trilinear n, central-difference gradient), the rest is the method's.", "",
              "| knob | method p50 / p99 (deg) | reference p50 / p99 (deg) |", "|---|---|---|"]
        for r in lens:
            L.append(f"| {r['setting']} | {_fmt(r['lens_cf_p50_deg'])} / {_fmt(r['lens_cf_p99_deg'])} | "
                     f"{_fmt(r['ref_lens_cf_p50_deg'])} / {_fmt(r['ref_lens_cf_p99_deg'])} |")
    L += ["", f"![error against time](grin_error_vs_time{'_quick' if a.quick else ''}.png)", ""]
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    main()
