"""Compile (or load from Numba's cache) the kernels a scene's plan needs, once per process; report compilation.

A method's warm-up renders a tiny copy of the scene itself: the same objects,
knobs, environment, lights and receivers, at a few pixels and a few photons.
It therefore compiles exactly the kernels the real render calls, with the
argument types the real render passes (one signature per kernel), and no
variant the scene does not use (the lookup-table peeling, the float A-buffer,
the other integrator ...). The render's own ``total_ms`` then excludes JIT
time; ``jit_ms`` holds it. A second scene with other knobs warms again, which
costs a tiny render once its kernels are cached.

Kernels are compiled with ``cache=True``: in a later process the warm-up only
loads them from Numba's on-disk cache. :func:`kernels_cached` looks at that
cache kernel by kernel (the list per method is ``data/kernels.json``, written
by ``benchmarks/bench_first_run.py``), and :func:`compile_report` shows
compilation as it happens: a bar of kernels done of the expected total on a
terminal, one line per method otherwise.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import sys
import time

__all__ = ["warm", "tiny_scene", "kernels_cached", "expected_kernels", "compile_report"]

_done = set()

#: Overrides that shrink a scene to a warm-up size without changing which kernels run or their argument types.
_TINY = {
    "imagespace": {"camera.width": 16, "camera.height": 16, "imagespace.photons": 8, "imagespace.caustic_map": 8},
    "levelmap": {"camera.width": 8, "camera.height": 8, "levelmap.map_size": 8, "levelmap.exact_samples": 16,
                 "imagespace.caustic_map": 8},
    "exact": {"camera.width": 16, "camera.height": 16, "exact.photons": 8, "imagespace.caustic_map": 8},
    "volumetric": {"camera.width": 4, "camera.height": 4, "volumetric.photons": 4, "volumetric.resolution": 16,
                   "volumetric.padding": 2, "imagespace.photons": 8, "imagespace.caustic_map": 8},
}


def tiny_scene(method, scene):
    """``scene`` shrunk for ``method``'s warm-up: same knobs and inputs, a few pixels (a new Scene)."""
    from .scene import load_scene

    over = dict(_TINY.get(method, {}))
    if method in ("levelmap", "exact") and scene.data.get("water") is not None:
        over.update({"water.resolution": 4, "levelmap.map_size": 8, "levelmap.exact_samples": 16})
    return load_scene(scene, over)


def _kind(v):
    """A value as far as it can choose a kernel or its argument types: arrays by shape rank and dtype."""
    if hasattr(v, "dtype"):
        return ["array", getattr(v, "ndim", 0), str(v.dtype)]
    if isinstance(v, dict):
        return {k: _kind(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_kind(x) for x in v]
    return v if isinstance(v, (str, bool)) or v is None else type(v).__name__


def _key(method, scene):
    """What decides which kernels a render runs and their argument types (not sizes, positions or counts)."""
    d = scene.data
    return json.dumps([method, {b: d.get(b) for b in ("imagespace", "levelmap", "volumetric", "exact")},
                       _kind({k: d.get(k) for k in ("objects", "lights", "environment", "volume", "water")}),
                       bool(d.get("receivers")), sorted(scene.callables)], sort_keys=True, default=str)


def warm(method, scene=None):
    """Compile (or load) the kernels ``method`` needs for ``scene`` (the method's default scene if None)."""
    from .graph import run_graph
    from .scene import load_scene

    if scene is None:
        from .levelmap.pipeline import DEFAULT_SCENE_PATH

        scene = load_scene(DEFAULT_SCENE_PATH if method == "levelmap" else None)
    key = _key(method, scene)
    if key in _done:
        return
    run_graph(method, tiny_scene(method, scene), warm=False)
    _done.add(key)


# ------------------------------------------------------------- the cache, kernel by kernel
def _manifest():
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "kernels.json")
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return {}


def expected_kernels(method):
    """Qualified names of the kernels a default render of ``method`` compiles (``data/kernels.json``)."""
    return list(_manifest().get(method, []))


def _dispatcher(qualname):
    mod, _, name = qualname.rpartition(".")
    try:
        return getattr(importlib.import_module(mod), name)
    except (ImportError, AttributeError):
        return None


def _has_cache_entry(disp):
    """Whether Numba's on-disk index holds a compiled version of ``disp``'s current code for this machine."""
    cache = getattr(disp, "_cache", None)
    f = getattr(cache, "_cache_file", None)
    if f is None:  # cache=False: nothing on disk, ever
        return False
    try:
        index = f._load_index()  # {} when missing or stale (source file changed)
        want = cache._index_key(None, disp.targetctx.codegen())[1:]
    except Exception:  # a Numba whose private layout differs: say "not cached" (only a message depends on it)
        return False
    return any(k[1:] == want for k in index)


def kernels_cached(method):
    """Whether Numba's on-disk cache holds every kernel a default render of ``method`` compiles.

    Checked kernel by kernel against the list in ``data/kernels.json``: a cache
    that the tests or an interrupted run filled in part counts as not cached.
    """
    names = expected_kernels(method)
    if not names:
        return False
    for q in names:
        d = _dispatcher(q)
        if d is None or not _has_cache_entry(d):
            return False
    return True


# ------------------------------------------------------------- showing compilation
@contextlib.contextmanager
def compile_report(method, stream=None, bar=None):
    """Show Numba compilations while the block runs: a bar on terminals, else a line when it starts and ends.

    Parameters
    ----------
    method : str
        Named in the messages; its expected kernel count (``data/kernels.json``) is the bar's total.
    stream : file, optional
        Where to write (default ``sys.stderr``).
    bar : bool, optional
        A tqdm bar (kernels done of total); default: when ``stream`` is a terminal.
    """
    from numba.core import event

    stream = sys.stderr if stream is None else stream
    if bar is None:
        bar = hasattr(stream, "isatty") and stream.isatty()
    total = len(expected_kernels(method)) or None
    state = {"n": 0, "t0": None, "bar": None, "depth": 0}

    def start(ev):
        state["depth"] += 1
        if state["t0"] is None:
            state["t0"] = time.perf_counter()
            if bar:
                from tqdm.auto import tqdm

                state["bar"] = tqdm(total=total, desc=f"compiling {method} kernels (first run only)", unit="kernel",
                                    file=stream, leave=False)
            else:
                print(f"refraction-ref: compiling the {method} kernels with Numba"
                      + (f" (about {total})" if total else "")
                      + "; first run only, later runs load them from the cache ...", file=stream, flush=True)

    def end(ev):
        state["depth"] -= 1
        if state["depth"] > 0:  # a helper compiled inside a kernel's compilation: part of that kernel
            return
        state["n"] += 1
        b = state["bar"]
        if b is not None:
            if b.total is not None and state["n"] > b.total:
                b.total = state["n"]
            d = ev.data.get("dispatcher") if ev.data else None
            b.set_postfix_str(getattr(getattr(d, "py_func", None), "__name__", ""), refresh=False)
            b.update(1)

    class _Listener(event.Listener):
        def on_start(self, ev):
            start(ev)

        def on_end(self, ev):
            end(ev)

    try:
        with event.install_listener("numba:compile", _Listener()):
            yield
    finally:
        if state["bar"] is not None:
            state["bar"].close()
        if state["t0"] is not None:
            print(f"refraction-ref: compiled {state['n']} {method} kernels in "
                  f"{time.perf_counter() - state['t0']:.0f} s (cached for later runs)", file=stream, flush=True)
