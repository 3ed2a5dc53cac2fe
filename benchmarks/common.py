"""Shared helpers of the benchmark scripts: timing, scene builders, result folder.

Everything here is plain Python on top of the public API (``rr.load_scene``,
``rr.render``, ``refraction_ref.compare.compare_arrays``); nothing in
``refraction_ref/`` is patched or monkeyed with.

Scenes
------
``bunny_scene``            the default scene (built-in bunny, 69,451 tris, IOR 1.2, eye (0,0,2.6))
``igea_scene``             Igea (268,686 tris, shipped in ``refraction_ref/data``) in the same set-up
``lowpoly_bunny_scene``    the bunny decimated to ~15,000 tris (cached PLY in ``results/``)
``two_bunnies_scene``      two bunnies side by side (fit 1.0, x = -/+0.55), camera pulled back

Every mesh the tables need ships with the package (``refraction_ref/data``); a
builder whose file is missing (a trimmed install) raises :class:`Skip` with a
message, and the scripts print it and leave the row out. Nothing is downloaded.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
RESULTS = os.path.join(HERE, "results")

if REPO not in sys.path:  # run as `python benchmarks/x.py` without installing
    sys.path.insert(0, REPO)

import refraction_ref as rr  # noqa: E402
from refraction_ref.files import atomic_open  # noqa: E402

STAGES = ("minmax", "voxelize", "peel", "reduce", "trace", "shade")
SETUP_STAGES = ("geometry", "rays")  # scene set-up, outside the per-frame passes (pipeline_ms)
IOR = 1.2                      # the default scene's glass
LOWPOLY_FACES = 15000          # thesis "Bunny-lowpoly" (Table 4.1)
TWO_BUNNY_EYE_Z = 4.8          # camera distance that frames both bunnies (fov_y 30)


class Skip(Exception):
    """A benchmark row that cannot run here (e.g. a missing model file)."""


# -- folders -----------------------------------------------------------------
def results_dir():
    """``benchmarks/results/``, created on first use."""
    os.makedirs(RESULTS, exist_ok=True)
    return RESULTS


def results_path(name):
    return os.path.join(results_dir(), name)


def write_json(name, obj):
    p = results_path(name)
    with atomic_open(p, "w") as f:
        json.dump(obj, f, indent=1, sort_keys=True, default=_json_default)
    return p


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def model_path(name):
    """Absolute path of a mesh shipped in ``refraction_ref/data``; :class:`Skip` when absent."""
    from refraction_ref.meshes import _DATA

    p = os.path.join(_DATA, name)
    if not os.path.isfile(p):
        raise Skip(f"{p} is absent (a trimmed install?); skipping rows that need it")
    return p


# -- timing ------------------------------------------------------------------
def median_time(fn, repeats=5):
    """Call ``fn`` once to warm up, then ``repeats`` times; return (median s, list of s).

    Wall time per call with :func:`time.perf_counter`.
    """
    fn()
    ts = []
    for _ in range(max(1, int(repeats))):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), ts


def pipeline_ms(result):
    """Sum of the stages' ``timings_ms`` (min/max pass to finished image).

    Sub-stage entries (``photon_trace.minmax``) are already inside their
    stage's time, and ``geometry`` (loading and placing the meshes) and
    ``rays`` (the primary rays written as outputs) are scene set-up,
    outside the thesis's per-frame passes, as before the stage graph; they
    are left out.
    """
    return float(sum(v for k, v in result.meta["timings_ms"].items() if "." not in k and k not in SETUP_STAGES))


def _cpu_jiffies():
    """(busy jiffies of the whole machine, jiffies of this process incl. its threads)."""
    try:
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
        busy = sum(v) - v[3] - (v[4] if len(v) > 4 else 0)  # minus idle, iowait
        with open("/proc/self/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        mine = int(fields[11]) + int(fields[12])  # utime + stime
        return busy, mine
    except (OSError, ValueError, IndexError):
        return None


def other_load(before, after, wall_s):
    """Fraction of the machine's CPU capacity used by other processes between two ``_cpu_jiffies``."""
    if before is None or after is None or wall_s <= 0:
        return 0.0
    hz = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    others = (after[0] - before[0]) - (after[1] - before[1])
    return max(0.0, others / hz / (wall_s * (os.cpu_count() or 1)))


#: a measurement during which other processes used more than this share of
#: the CPUs is repeated (up to ``retries`` times, after waiting for quiet)
DISTURBED = 0.15


def machine_busy(window=0.5):
    """Share of the CPUs used by other processes over ``window`` seconds (0 when unknown)."""
    c0, t0 = _cpu_jiffies(), time.perf_counter()
    time.sleep(window)
    return other_load(c0, _cpu_jiffies(), time.perf_counter() - t0)


#: total seconds one process may spend waiting for quiet (so a long busy spell
#: elsewhere costs minutes, not hours); set BENCH_WAIT_BUDGET_S=0 to never wait
WAIT_BUDGET_S = float(os.environ.get("BENCH_WAIT_BUDGET_S", "180"))
_waited = [0.0]


def wait_for_quiet(threshold=0.10, timeout=30.0):
    """Wait (at most ``timeout`` s) until other processes use less than ``threshold`` of the CPUs.

    Other sessions on this machine (a test run, a compile) may be invisible to
    ``ps`` but still show in ``/proc/stat``. The waits of one process add up to
    at most ``WAIT_BUDGET_S``. Returns the seconds waited.
    """
    timeout = min(timeout, max(0.0, WAIT_BUDGET_S - _waited[0]))
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout:
        if machine_busy(0.5) < threshold:
            break
    dt = time.perf_counter() - t0
    _waited[0] += dt
    return dt


#: warm-up renders before timing: on this virtual machine the first renders of
#: a process (and of a new scene) also pay for memory not handed out before
WARMUP = 4


def time_render(scene, repeats=5, method="imagespace", overrides=None, warmup=WARMUP, retries=2):
    """Render ``repeats`` times after ``warmup`` warm-up renders.

    ``WARMUP`` (4) warm-ups by default: on this machine the first renders
    are outliers (the first touch of the large buffers' memory).
    The machine has two vCPUs, so another busy process (a test run, a
    compile) inflates a measurement severalfold: when other processes used
    more than ``DISTURBED`` of the CPUs during the timed renders, the
    measurement is repeated after a pause (up to ``retries`` times) and the
    least disturbed one is kept.

    Returns a dict: ``pipeline_ms`` (median of the stage sums), ``total_ms``
    (median of ``meta['total_ms']``), ``stages_ms`` (per-stage medians),
    ``samples`` (every stage sum), ``other_load`` (share of the CPUs other
    processes used meanwhile), ``attempts`` and ``result`` (the last run, for
    accuracy).
    """
    t = time_interleaved(scene, repeats, (method,), warmup, retries, overrides)
    return dict(t[method], other_load=t["other_load"], attempts=t["attempts"])


def time_interleaved(scene, repeats=9, methods=("imagespace", "exact"), warmup=WARMUP, retries=2, overrides=None):
    """Time several methods on one scene in the same run, alternating them render by render.

    A slow spell of the machine then slows every method alike, so the ratio
    of their medians is what "N times faster in the same run" means. Warm-up
    and retries as in :func:`time_render`.

    Returns a dict: per method the :func:`time_render` summary
    (``pipeline_ms``, ``total_ms``, ``stages_ms``, ``samples``, ``result``),
    plus ``other_load`` and ``attempts``.
    """
    for m in methods:  # warm-up (JIT cache, allocations, BVH)
        for _ in range(max(1, int(warmup))):
            rr.render(scene, method=m, overrides=overrides)
    best = None
    for attempt in range(1 + max(0, int(retries))):
        if attempt:
            wait_for_quiet(timeout=15.0 * attempt)
        acc = {m: {"sums": [], "totals": [], "per": {}, "result": None} for m in methods}
        c0, t0 = _cpu_jiffies(), time.perf_counter()
        for _ in range(max(1, int(repeats))):
            for m in methods:
                res = rr.render(scene, method=m, overrides=overrides)
                a = acc[m]
                a["result"] = res
                a["sums"].append(pipeline_ms(res))
                a["totals"].append(float(res.meta["total_ms"]))
                for k, v in res.meta["timings_ms"].items():
                    a["per"].setdefault(k, []).append(float(v))
        load = other_load(c0, _cpu_jiffies(), time.perf_counter() - t0)
        out = {m: {"pipeline_ms": statistics.median(a["sums"]), "total_ms": statistics.median(a["totals"]),
                   "stages_ms": {k: statistics.median(v) for k, v in a["per"].items()}, "samples": a["sums"],
                   "result": a["result"]}
               for m, a in acc.items()}
        out.update(other_load=load, attempts=attempt + 1)
        if best is None or load < best["other_load"]:
            best = out
        best["attempts"] = attempt + 1
        if load <= DISTURBED:
            break
    if best["other_load"] > DISTURBED:
        print(f"  warning: other processes used {100 * best['other_load']:.0f}% of the CPUs during this "
              "measurement; its times are inflated", flush=True)
    return best


# -- scenes ------------------------------------------------------------------
def _obj(mesh, translate=(0.0, 0.0, 0.0)):
    return {"mesh": mesh, "fit": 1.0,
            "transform": {"scale": 1.0, "rotate": [0.0, 0.0, 0.0], "translate": list(map(float, translate))},
            "material": {"ior": IOR, "absorption": [0.0, 0.0, 0.0]}}


def _camera(res, eye_z=2.6):
    return {"eye": [0.0, 0.0, float(eye_z)], "width": int(res), "height": int(res)}


def _imagespace(layers=32, slices=256, iterations=5, **extra):
    d = {"layers": int(layers), "slices": int(slices), "iterations": int(iterations)}
    d.update(extra)
    return d


def make_scene(objects, res=512, eye_z=2.6, **imagespace):
    """A scene dict in the docs/oracle.md format, validated by ``rr.load_scene``."""
    # no receivers: these benchmarks time the refraction pass alone (caustics: bench_caustics.py)
    return rr.load_scene({"camera": _camera(res, eye_z), "objects": objects, "receivers": [],
                          "imagespace": _imagespace(**imagespace)})


def bunny_scene(res=512, **imagespace):
    """The default scene (built-in bunny, 69,451 tris) at ``res`` x ``res``."""
    return make_scene([_obj("bunny")], res, **imagespace)


def igea_scene(res=512, **imagespace):
    """Igea (268,686 tris, shipped with the package), same camera and glass; :class:`Skip` if absent."""
    return make_scene([_obj(model_path("igea.ply"))], res, **imagespace)


def lowpoly_bunny_scene(res=512, **imagespace):
    return make_scene([_obj(lowpoly_bunny_path())], res, **imagespace)


def two_bunnies_scene(res=512, lowpoly=False, **imagespace):
    """Two bunnies (each fit 1.0) at x = -0.55 and +0.55, eye pulled back to z = 4.8 to frame both."""
    mesh = lowpoly_bunny_path() if lowpoly else "bunny"
    return make_scene([_obj(mesh, (-0.55, 0, 0)), _obj(mesh, (0.55, 0, 0))], res, eye_z=TWO_BUNNY_EYE_Z,
                      **imagespace)


# -- the decimated bunny ------------------------------------------------------
_LOWPOLY = {}


def _bunny_arrays():
    from refraction_ref.meshes import load_mesh

    v, f = load_mesh("bunny")
    return np.array(v, np.float64, order="C"), np.array(f, np.int64, order="C")  # writable copies


def lowpoly_bunny_path(target=LOWPOLY_FACES):
    """PLY of the built-in bunny decimated to ~``target`` triangles, cached in ``results/``.

    Quadric decimation (trimesh + fast-simplification) when available, else
    grid vertex clustering; :func:`lowpoly_method` says which was used.
    """
    if target in _LOWPOLY:
        return _LOWPOLY[target][0]
    import trimesh

    for method in ("quadric", "cluster"):
        p = results_path(f"bunny_lowpoly_{target}_{method}.ply")
        if os.path.isfile(p):
            _LOWPOLY[target] = (p, method)
            return p
    from refraction_ref.tables.chaudhari_report import decimate  # quadric if installed, else clustering

    v, f = _bunny_arrays()
    nv, nf, method = decimate(v, f, target)
    p = results_path(f"bunny_lowpoly_{target}_{method}.ply")
    trimesh.Trimesh(nv, nf, process=False).export(p)
    _LOWPOLY[target] = (p, method)
    return p


def lowpoly_method(target=LOWPOLY_FACES):
    lowpoly_bunny_path(target)
    method = _LOWPOLY[target][1]
    return ("quadric decimation (trimesh.simplify_quadric_decimation, fast-simplification)"
            if method == "quadric" else "grid vertex clustering (numpy; fast-simplification not installed)")


def triangles(scene):
    from refraction_ref.meshes import scene_geometry

    return int(len(scene_geometry(scene).faces))


# -- misc --------------------------------------------------------------------
def machine_line():
    import numba

    return (f"python {sys.version.split()[0]}, numba {numba.__version__} ({numba.get_num_threads()} threads), "
            f"{os.cpu_count()} CPUs, refraction_ref {rr.__version__}")


def git_rev():
    try:
        out = subprocess.run(["git", "-C", REPO, "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", REPO, "status", "--porcelain", "--", "refraction_ref"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return out + ("+dirty" if dirty else "")
    except Exception:
        return "unknown"


def md_table(header, rows):
    """A markdown table from a header list and rows of already-formatted cells."""
    w = [max(len(str(h)), *(len(str(r[k])) for r in rows)) if rows else len(str(h)) for k, h in enumerate(header)]
    line = lambda cells: "| " + " | ".join(str(c).ljust(w[k]) for k, c in enumerate(cells)) + " |"  # noqa: E731
    out = [line(header), "|" + "|".join("-" * (x + 2) for x in w) + "|"]
    out += [line(r) for r in rows]
    return "\n".join(out)
