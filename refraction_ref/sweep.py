"""``refraction-ref sweep SPEC.json``: error against run time over a grid of knobs, on ``dask.distributed``.

A spec (JSON) names scenes, methods, a grid of dotted overrides and a
number of repeats; every combination is one task. Tasks run on a
``LocalCluster`` by default (worker processes and threads per worker
settable) or on an existing cluster (``--scheduler tcp://HOST:PORT``). Each
task pins its Numba thread count (``threads``, default 1), so timings stay
comparable whatever the worker, renders once to warm up and ``repeats``
times, and measures its error against the exact reference of the same scene
and camera (rendered once per scene and camera, as a task of its own). A
task that fails is reported in its row; the sweep goes on.

Spec::

    {"name": "iterations",
     "scenes": {"bunny": null, "pool": "refraction_ref/data/levelmap_default.json"},
     "methods": ["imagespace"],
     "grid": {"imagespace.iterations": [1, 5, 10], "camera.width": [128]},
     "base": {"camera.height": 128},
     "repeats": 3, "threads": 1, "reference": "exact"}

``scenes`` maps a name to a scene file (relative to the spec), a scene dict,
or null for the bundled default. ``grid`` keys are dotted overrides whose
values are listed; ``base`` overrides apply to every task. A ``camera.*``
key in the grid changes the reference too.

Optional keys (one knob at a time, references of their own, measurements
that are not renders):

``families``
    In place of ``grid``: a list of ``{"name": ..., "grid": {...}}``, each
    its own product of values around ``base``; the tasks are the families'
    in order and every row has a ``family`` column (e.g. iterations 1..10,
    then slices 64..512, each with the other knobs at their defaults).
linked keys
    A grid key naming several dotted keys joined by ``,`` takes lists of
    as many values, which vary together: ``"camera.width,camera.height":
    [[256, 256], [512, 512]]``. The row gets one column per key.
``reference_base``
    Overrides of the reference render only (e.g. ``{"exact.photons": 1536}``).
``reference_follows``
    Grid keys besides ``camera.*`` that the reference follows (it is
    rendered once per distinct value: e.g. ``["levelmap.map_size"]``, so
    the maps compared have one size).
``task``
    ``"FILE.py:FUNCTION"`` (FILE relative to the spec): each grid point
    calls ``FUNCTION(**params)`` (``params``: ``base`` with the point's
    values, keys as written) instead of rendering, and its returned dict
    (scalars only) is the row (no ``scenes``, ``methods`` or reference). A
    worker process's first call is repeated, the first one untimed (it
    compiles the kernels). The file must be readable at the same path on
    every worker.
``error``, ``time``
    The row columns the plot shows (default: the first of
    ``exit_dir_median_deg``, ``image_rmse``, ``*_rel_l1`` the rows have,
    against ``total_ms``). For render sweeps ``error`` is one of
    :data:`ERROR_METRICS` or ``caustic_map_<k>_rel_l1`` and ``time`` is
    ``total_ms`` or ``t_<stage>``; anything else is refused (docs/sweep.md).

Output (``--out DIR``; existing files are refused without ``--force``): ``NAME.csv`` (one row per task: scene, method, the
grid's values, error statistics, median stage timings, total, worker, thread
count, status), ``NAME.parquet`` where pyarrow is installed (it is not a
dependency), and ``NAME.png`` (error against time: one line per scene and
method, or family, each point labelled with the knob values that vary).
"""

from __future__ import annotations

import csv
import itertools
import json
import os
import time

from .validation import show

__all__ = ["load_spec", "tasks_of", "run_task", "run_function", "run_reference", "sweep", "SweepError",
           "ERROR_METRICS", "output_files"]

#: The error columns of a render sweep's rows (each against the reference of the same scene and camera):
#: the median and 90th percentile of the exit-direction angle where both exit (degrees), the fraction of
#: pixels hit in the reference whose status agrees, the image RMSE (linear RGB); and, per receiver,
#: ``caustic_map_<k>_rel_l1`` (relative L1 of the caustic maps, both blurred one texel).
ERROR_METRICS = ("exit_dir_median_deg", "exit_dir_p90_deg", "status_agree", "image_rmse")


class SweepError(ValueError):
    """A spec that cannot be run, with the key to fix."""


def _check_columns(spec):
    """Refuse an ``error`` or ``time`` column a render sweep never writes (the plot would be empty)."""
    import re

    err, tim = spec.get("error"), spec.get("time")
    if err is not None and not (isinstance(err, str) and (err in ERROR_METRICS
                                                          or re.fullmatch(r"caustic_map_\d+_rel_l1", err))):
        raise SweepError(f"sweep: 'error' is {str(err)[:60]!r}; choose one of {', '.join(ERROR_METRICS)} or "
                         "caustic_map_<k>_rel_l1 (docs/sweep.md), or leave it out for the first the rows have")
    if tim is not None and not (isinstance(tim, str) and (tim == "total_ms" or re.fullmatch(r"t_\w+", tim))):
        raise SweepError(f"sweep: 'time' is {str(tim)[:60]!r}; choose total_ms or t_<stage> (a stage's median "
                         "time, e.g. t_trace), or leave it out")


def output_files(spec, out):
    """The files a sweep writes in ``out``: ``NAME.csv``, ``NAME.png`` and ``NAME.parquet``.

    Parameters
    ----------
    spec : dict
        A spec from :func:`load_spec`.
    out : str
        The output folder.

    Returns
    -------
    list of str
    """
    return [os.path.join(out, f"{spec['name']}.{ext}") for ext in ("csv", "png", "parquet")]


def load_spec(src):
    """Read and check a sweep spec (a path or a dict); relative scene paths resolve against the spec's folder.

    Parameters
    ----------
    src : str, os.PathLike or dict
        A JSON spec file, or the spec itself (module docstring).

    Returns
    -------
    dict
        The spec with its defaults filled in.

    Raises
    ------
    SweepError
        Naming the key that is unknown or wrong.
    """
    base_dir = "."
    if isinstance(src, (str, os.PathLike)):
        path = os.fspath(src)
        if not os.path.isfile(path):
            raise SweepError(f"sweep: spec file '{path}' does not exist")
        try:
            with open(path, encoding="utf-8-sig") as f:
                spec = json.load(f)
        except json.JSONDecodeError as e:
            raise SweepError(f"sweep: spec file '{path}' is not valid JSON: {e}") from None
        except (ValueError, RecursionError) as e:  # not UTF-8, a 5,000-digit number, deep nesting
            raise SweepError(f"sweep: spec file '{path}' cannot be read as JSON ({type(e).__name__}: "
                             f"{str(e)[:60]})") from None
        base_dir = os.path.dirname(os.path.abspath(path))
    elif isinstance(src, dict):
        spec = dict(src)
    else:
        raise SweepError(f"sweep: the spec must be a JSON file path or a dict, got {type(src).__name__}")
    if not isinstance(spec, dict):
        raise SweepError("sweep: the spec must be a JSON object {\"name\": ..., \"scenes\": ..., ...} (docs/sweep.md)")
    known = {"name", "scenes", "methods", "grid", "base", "repeats", "threads", "reference", "families",
             "reference_base", "reference_follows", "task", "error", "time"}
    bad = sorted(set(spec) - known)
    if bad:
        raise SweepError(f"sweep: unknown spec key {', '.join(repr(b) for b in bad)}; known: {', '.join(sorted(known))}")
    from .graph import method_names

    spec.setdefault("name", "sweep")
    spec.setdefault("scenes", {"default": None})
    spec.setdefault("methods", ["imagespace"])
    spec.setdefault("grid", {})
    spec.setdefault("base", {})
    spec.setdefault("repeats", 3)
    spec.setdefault("threads", 1)
    spec.setdefault("reference", "exact")
    spec.setdefault("reference_base", {})
    spec.setdefault("reference_follows", [])
    if not isinstance(spec["name"], str) or not spec["name"].strip() or os.sep in spec["name"] \
            or spec["name"].startswith(".") or len(spec["name"]) > 200:
        raise SweepError(f"sweep: 'name' is {str(spec['name'])[:60]!r}; give a short file name without a "
                         "folder separator (the outputs are NAME.csv and NAME.png)")
    for k, typ in (("scenes", dict), ("methods", list), ("grid", dict), ("base", dict), ("reference_base", dict),
                   ("reference_follows", list)):
        if not isinstance(spec[k], typ):
            raise SweepError(f"sweep: '{k}' must be a {'JSON object' if typ is dict else 'list'}, got "
                             f"{type(spec[k]).__name__} (docs/sweep.md)")
    for k in ("repeats", "threads"):
        if isinstance(spec[k], bool) or not isinstance(spec[k], int) or not 1 <= spec[k] <= 1000:
            raise SweepError(f"sweep: '{k}' is {show(spec[k], 30)}; give a whole number from 1 to 1000")
    if not spec.get("task"):
        _check_columns(spec)
    if "families" in spec:
        if spec["grid"]:
            raise SweepError("sweep: give either 'grid' or 'families', not both")
        fams = spec["families"]
        if not isinstance(fams, list) or not all(isinstance(f, dict) and set(f) <= {"name", "grid"}
                                                 and isinstance(f.get("grid", {}), dict) for f in fams):
            raise SweepError("sweep: 'families' must be a list of "
                             "{\"name\": ..., \"grid\": {...}}")
        for k, f in enumerate(fams):
            f.setdefault("name", f"family {k}")
            f.setdefault("grid", {})
    grids = [f["grid"] for f in spec["families"]] if "families" in spec else [spec["grid"]]
    for g in grids:
        if not isinstance(g, dict):
            raise SweepError(f"sweep: 'grid' must map dotted keys to non-empty lists of values, got {show(g, 40)}")
        for k, vals in g.items():
            if not (isinstance(vals, list) and vals):
                raise SweepError(f"sweep: grid key {json.dumps(k)} is {show(vals, 40)}; give a non-empty list of "
                                 f"values, e.g. {json.dumps({k: [vals] if not isinstance(vals, list) else [1]})}")
        for k, vals in g.items():
            n = len(k.split(","))
            if n > 1 and not all(isinstance(v, list) and len(v) == n for v in vals):
                raise SweepError(f"sweep: the linked grid key {k!r} takes lists of {n} values")
    if spec.get("task") is not None:
        t = str(spec["task"])
        if ":" not in t:
            raise SweepError("sweep: 'task' must be 'FILE.py:FUNCTION'")
        f, fn = t.rsplit(":", 1)
        f = f if os.path.isabs(f) else os.path.normpath(os.path.join(base_dir, f))
        if not os.path.isfile(f):
            raise SweepError(f"sweep: the task file '{f}' does not exist")
        spec["task"] = f"{f}:{fn}"
        spec["scenes"] = {"-": None}
        spec["methods"] = ["task"]
        spec["reference"] = None
    for m in ([] if spec.get("task") else spec["methods"]):
        if m not in method_names():
            raise SweepError(f"sweep: methods lists {m!r}; choose from {', '.join(method_names())}")
    if int(spec["repeats"]) < 1 or int(spec["threads"]) < 1:
        raise SweepError("sweep: 'repeats' and 'threads' must be at least 1")
    scenes = {}
    for name, s in spec["scenes"].items():
        if isinstance(s, str) and not os.path.isabs(s):
            s = os.path.join(base_dir, s)
        scenes[name] = s
    spec["scenes"] = scenes
    from .validation import SceneError
    from .scene import load_scene

    if spec.get("task"):
        return spec
    for name, s in scenes.items():  # refuse a bad scene or override before any task is sent
        for _, combo in _family_combos(spec):
            try:
                load_scene(s, {**spec["base"], **combo})
            except SceneError as e:
                raise SweepError(f"sweep: scene '{name}' with {combo}: {e}") from None
    return spec


def _combos(grid):
    """The grid's points in order; a linked key ``"a,b"`` sets ``a`` and ``b`` together."""
    keys = list(grid)
    out = []
    for vals in itertools.product(*(grid[k] for k in keys)):
        c = {}
        for k, v in zip(keys, vals):
            if "," in k:
                c.update(zip(k.split(","), v))
            else:
                c[k] = v
        out.append(c)
    return out or [{}]


def _family_combos(spec):
    """(family name or None, point) of every grid point, families in order."""
    if "families" in spec:
        return [(f["name"], c) for f in spec["families"] for c in _combos(f["grid"])]
    return [(None, c) for c in _combos(spec["grid"])]


def _grid_keys(spec):
    """Every dotted key a grid point may set (linked keys split)."""
    grids = [f["grid"] for f in spec["families"]] if "families" in spec else [spec["grid"]]
    return list(dict.fromkeys(x for g in grids for k in g for x in k.split(",")))


def _ref_key(combo, follows=()):
    return json.dumps({k: v for k, v in sorted(combo.items()) if k.startswith("camera.") or k in follows},
                      sort_keys=True)


def tasks_of(spec):
    """Every (scene, method, overrides) of the grid, in a fixed order (``family`` set with ``families``).

    Parameters
    ----------
    spec : dict
        A spec from :func:`load_spec`.

    Returns
    -------
    list of dict
        ``scene_name``, ``scene``, ``method``, ``overrides`` (and ``family``) per task.
    """
    return [{"scene_name": sn, "scene": s, "method": m, "overrides": combo,
             **({"family": fam} if fam is not None else {})}
            for sn, s in spec["scenes"].items() for m in spec["methods"] for fam, combo in _family_combos(spec)]


def _load_task(task):
    """The function of ``"FILE.py:FUNCTION"`` (its folder on ``sys.path`` for its own imports)."""
    import importlib.util
    import sys

    f, fn = task.rsplit(":", 1)
    d = os.path.dirname(f)
    if d not in sys.path:
        sys.path.insert(0, d)
    name = "_sweep_task_" + os.path.splitext(os.path.basename(f))[0]
    mod = sys.modules.get(name)
    if mod is None or getattr(mod, "__file__", None) != f:
        sp = importlib.util.spec_from_file_location(name, f)
        mod = importlib.util.module_from_spec(sp)
        sp.loader.exec_module(mod)
        sys.modules[name] = mod
    return getattr(mod, fn)


_WARM = set()  # task functions already called in this process


def _worker_address():
    """The dask worker running this task, or ``"local"`` outside a worker."""
    try:
        import distributed

        return distributed.get_worker().address
    except (ImportError, ValueError):
        return "local"


def run_function(task, fn, base, threads):
    """A grid point of a ``task`` spec: ``fn(**{**base, **overrides})``'s dict is the row.

    Parameters
    ----------
    task : dict
        One of :func:`tasks_of`.
    fn : str
        ``"FILE.py:FUNCTION"``; called once untimed first in each process.
    base : dict
        Keyword arguments every call gets; the task's overrides win.
    threads : int
        Numba threads.

    Returns
    -------
    dict
        The CSV row: the overrides, ``status`` (``ok`` or ``failed: ...``),
        ``worker``, ``threads`` and the function's scalar outputs.
    """
    row = {**({"family": task["family"]} if "family" in task else {}), **task["overrides"], "status": "ok"}
    row["worker"] = _worker_address()
    try:
        row["threads"] = _pin_threads(threads)
        f = _load_task(fn)
        params = {**base, **task["overrides"]}
        if fn not in _WARM:  # the first call in a process compiles: called once more, untimed
            f(**params)
            _WARM.add(fn)
        out = f(**params)
        row.update({k: v for k, v in out.items() if not isinstance(v, (list, dict))})
    except Exception as e:  # a failed task is a row, not the end of the sweep
        row["status"] = f"failed: {type(e).__name__}: {e}"
    return row


def _pin_threads(n):
    import numba

    n = max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(n)
    return n


def run_reference(scene, method, overrides, threads=1):
    """The exact reference's arrays of a scene at the task's camera (a task of its own).

    Parameters
    ----------
    scene : Scene, dict, str or None
        As :func:`refraction_ref.render`.
    method : str
        The reference method (the spec's ``reference``).
    overrides : dict
        Dotted keys (the task's camera and the ``reference_base``).
    threads : int
        Numba threads.

    Returns
    -------
    dict
        ``status``, ``hit``, ``exit_dir``, ``interfaces``, ``image`` and the
        ``caustic_map_*`` arrays it has.
    """
    import refraction_ref as rr

    _pin_threads(threads)
    res = rr.render(scene, method=method, overrides=overrides)
    keep = ("status", "hit", "exit_dir", "interfaces", "image")
    return {k: v for k, v in res.arrays.items() if k in keep or k.startswith("caustic_map_")}


def run_task(task, base, repeats, threads, reference=None):
    """Render one grid point ``repeats`` times after a warm-up; the row of the CSV.

    A failure becomes the row's ``status`` (``failed: <message>``); nothing is raised.

    Parameters
    ----------
    task : dict
        One of :func:`tasks_of`.
    base : dict
        Dotted overrides every task gets; the task's own win.
    repeats : int
        Timed renders; the row holds their median.
    threads : int
        Numba threads.
    reference : dict, optional
        :func:`run_reference`'s arrays, to measure the error against.

    Returns
    -------
    dict
        The CSV row.
    """
    import statistics

    import refraction_ref as rr

    from .compare import compare_arrays

    row = {"scene": task["scene_name"], "method": task["method"],
           **({"family": task["family"]} if "family" in task else {}), **task["overrides"], "status": "ok"}
    row["worker"] = _worker_address()
    try:
        row["threads"] = _pin_threads(threads)
        sc = rr.load_scene(task["scene"], {**base, **task["overrides"]})
        rr.render(sc, method=task["method"])  # warm-up: kernels, caches, first touch of memory
        per, totals, res = {}, [], None
        for _ in range(int(repeats)):
            res = rr.render(sc, method=task["method"])
            totals.append(res.meta["total_ms"])
            for k, v in res.meta["timings_ms"].items():
                if "." not in k:
                    per.setdefault(k, []).append(v)
        row["total_ms"] = statistics.median(totals)
        for k, v in per.items():
            row[f"t_{k}"] = statistics.median(v)
        if reference is not None:
            c = compare_arrays(res.arrays, reference)
            if "exit_dir_deg" in c:
                row["exit_dir_median_deg"] = c["exit_dir_deg"]["median"]
                row["exit_dir_p90_deg"] = c["exit_dir_deg"]["p90"]
                row["status_agree"] = c["status_agree"]
            for k, v in c.get("caustic_rel_l1", {}).items():
                row[f"{k}_rel_l1"] = v
            if "image_rmse" in c:
                row["image_rmse"] = c["image_rmse"]
    except Exception as e:  # a failed task is a row, not the end of the sweep
        row["status"] = f"failed: {type(e).__name__}: {e}"
    return row


def sweep(spec, out=".", scheduler=None, workers=2, threads_per_worker=1, progress=False, client=None,
          force=False):
    """Run a spec on dask.distributed; returns (rows, paths written).

    Parameters
    ----------
    spec : dict or str
        A spec or its path (:func:`load_spec`).
    out : str
        Folder of the CSV (Parquet) and PNG.
    scheduler : str, optional
        Address of an existing cluster (``tcp://HOST:PORT``); default: a
        ``LocalCluster`` of ``workers`` processes with ``threads_per_worker``
        threads each.
    client : distributed.Client, optional
        Use this client (tests).
    force : bool
        Replace existing ``NAME.csv``/``NAME.png``/``NAME.parquet`` (else refused before any work).
    """
    from distributed import as_completed

    from .cluster import dask_client
    from .files import check_out_folder

    spec = load_spec(spec) if not isinstance(spec, dict) or "scenes" not in spec or "name" not in spec else spec
    tasks = tasks_of(spec)
    if client is None and not scheduler and int(workers) < 1:
        raise SweepError(f"sweep: workers is {workers}; give at least 1 worker process (or a scheduler)")
    check_out_folder(out, "the sweep's output folder (--out)")  # before any work, not after it
    there = [p for p in output_files(spec, out) if os.path.exists(p)]
    if there and not force:
        raise FileExistsError(f"'{there[0]}' exists; choose another --out folder or spec name, or pass --force "
                              "to replace it")
    t0 = time.perf_counter()
    with dask_client(scheduler, workers, threads_per_worker, client) as client:
        refs = {}
        futures = []
        follows = tuple(spec.get("reference_follows", ()))
        for t in tasks:
            if spec.get("task"):
                futures.append(client.submit(run_function, t, spec["task"], spec["base"], spec["threads"],
                                             pure=False))
                continue
            ref = None
            if spec["reference"] and t["method"] != spec["reference"]:
                rk = (t["scene_name"], _ref_key(t["overrides"], follows))
                if rk not in refs:
                    cam = {k: v for k, v in t["overrides"].items() if k.startswith("camera.") or k in follows}
                    refs[rk] = client.submit(run_reference, t["scene"], spec["reference"],
                                             {**spec["base"], **cam, **spec.get("reference_base", {})},
                                             spec["threads"], pure=False)
                ref = refs[rk]
            futures.append(client.submit(run_task, t, spec["base"], spec["repeats"], spec["threads"], ref,
                                         pure=False))
        rows = []
        it = as_completed(futures)
        if progress:
            from tqdm.auto import tqdm

            it = tqdm(it, total=len(futures), desc=f"sweep {spec['name']}", unit="task")
        for f in it:
            try:
                rows.append(f.result())
            except Exception as e:  # the reference task failed: its dependants land here
                rows.append({"status": f"failed: {type(e).__name__}: {e}"})
    keys = _grid_keys(spec)
    fn = bool(spec.get("task"))
    order = {json.dumps([None if fn else t["scene_name"], None if fn else t["method"], t.get("family"),
                         t["overrides"]], sort_keys=True): i for i, t in enumerate(tasks)}
    rows.sort(key=lambda r: order.get(json.dumps([r.get("scene"), r.get("method"), r.get("family"),
                                                  {k: r[k] for k in keys if k in r}], sort_keys=True), 1e9))
    wall = time.perf_counter() - t0
    paths = write_rows(rows, out, spec["name"], spec.get("error"), spec.get("time") or "total_ms", knobs=keys)
    return rows, paths, wall


def plot_series(rows, err_key, time_key="total_ms", knobs=()):
    """The plot's series: one per scene, method and family, its points in the rows' (the grid's) order.

    Parameters
    ----------
    rows : list of dict
        The sweep's rows (failed ones are left out).
    err_key, time_key : str
        The columns on the y and x axes.
    knobs : sequence of str
        Grid keys whose values label the points where they vary along a series.

    Returns
    -------
    list of (label, points, notes)
        ``label`` names the series (``"bunny, imagespace"``); ``points`` are
        ``(time, error)`` pairs; ``notes`` label each point with the values
        of the grid keys that vary along the series (``"iterations=5"``).
    """
    ok = [r for r in rows if r.get("status") == "ok" and time_key in r and err_key in r]
    parts = [k for k in ("scene", "method", "family") if any(r.get(k) is not None for r in ok)]
    out = []
    for key in dict.fromkeys(tuple(r.get(k) for k in parts) for r in ok):
        pts = [r for r in ok if tuple(r.get(k) for k in parts) == key]
        varying = [k for k in knobs if len({json.dumps(r.get(k)) for r in pts}) > 1]
        notes = [", ".join(f"{k.rsplit('.', 1)[-1]}={r.get(k)}" for k in varying) for r in pts]
        label = ", ".join(str(x) for x in key if x is not None) or "runs"
        out.append((label, [(r[time_key], r[err_key]) for r in pts], notes))
    return out


def write_rows(rows, out, name, err_key=None, time_key="total_ms", knobs=()):
    """The sweep's CSV (and Parquet where pyarrow is installed) and its error-against-time plot.

    The plot draws ``err_key`` against ``time_key``: one line per scene,
    method and family, each point labelled with the values of the grid keys
    ``knobs`` that vary along it (:func:`plot_series`).

    Parameters
    ----------
    rows : list of dict
    out : str
        The folder (created if missing).
    name : str
        File stem: ``NAME.csv``, ``NAME.parquet``, ``NAME.png``.
    err_key : str, optional
        Default: ``exit_dir_median_deg`` or else ``image_rmse``, whichever the rows have.
    time_key : str
    knobs : sequence of str

    Returns
    -------
    list of str
        The paths written.
    """
    from .files import atomic_open, atomic_path, savefig_atomic

    os.makedirs(out, exist_ok=True)
    cols = list(dict.fromkeys(k for r in rows for k in r))
    paths = []
    p = os.path.join(out, f"{name}.csv")
    with atomic_open(p, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow(r)
    paths.append(p)
    try:
        import pyarrow  # noqa: F401
        import pyarrow.csv
        import pyarrow.parquet

        p = os.path.join(out, f"{name}.parquet")
        with atomic_path(p) as tmp:
            pyarrow.parquet.write_table(pyarrow.csv.read_csv(paths[0]), tmp)
        paths.append(p)
    except ImportError:
        pass
    ok = [r for r in rows if r.get("status") == "ok" and time_key in r]
    if not err_key:
        err_key = next((k for k in ("exit_dir_median_deg", "image_rmse") if any(k in r for r in ok)), None)
    if not err_key:
        err_key = next((k for r in ok for k in r if k.endswith("_rel_l1")), None)
    if ok and err_key:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(7, 4.5))
        FigureCanvasAgg(fig)
        ax = fig.subplots()
        for label, pts, notes in plot_series(rows, err_key, time_key, knobs):
            ax.plot(*zip(*pts), "o-", label=label, ms=4, lw=0.8)
            for (x, y), note in zip(pts, notes):
                if note:
                    ax.annotate(note, (x, y), xytext=(3, 3), textcoords="offset points", fontsize=6)
        ax.set_xlabel("median render time (ms)" if time_key == "total_ms" else time_key)
        ax.set_ylabel(err_key.replace("_", " "))
        ax.set_title(f"sweep {name}: error against the exact reference versus run time" if time_key == "total_ms"
                     else f"sweep {name}: {err_key} against {time_key}")
        ax.legend(fontsize=7)
        fig.tight_layout()
        paths.append(savefig_atomic(fig, os.path.join(out, f"{name}.png"), dpi=90))
    return paths
