"""Warming up: compile (or load from Numba's cache) the kernels a scene's plan needs, once per process.

One warm-up for every method: a method registers ``warm=warmer(name)``
(:class:`~refraction_ref.graph.Method`), and :func:`warm` renders a tiny copy
of the scene itself: the same objects, knobs, environment, lights and
receivers, at the few pixels and photons of the method's
:attr:`~refraction_ref.graph.Method.tiny` overrides. It therefore compiles
exactly the kernels the real render calls, with the argument types the real
render passes (one signature per kernel), and no variant the scene does not
use (the lookup-table peeling, the float A-buffer, the other integrator ...).
The render's own ``total_ms`` then excludes JIT time; ``jit_ms`` holds it. A
second scene with other knobs warms again, which costs a tiny render once its
kernels are cached.

Kernels are compiled with ``cache=True``: in a later process the warm-up only
loads them from Numba's on-disk cache. :func:`kernels_cached` looks at that
cache kernel by kernel (the list per method is ``data/kernels.json``, written
by ``benchmarks/bench_first_run.py``), and :func:`compile_report` shows
compilation as it happens: a bar of kernels done of the expected total on a
terminal, one line per method otherwise. ``refraction-ref warmup`` runs them.

This module imports no method: it asks :mod:`refraction_ref.graph` for them by name.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import sys
import time

from .graph import Method, get_method, method_blocks, run_graph
from .scene import load_scene

__all__ = ["warm", "warmer", "tiny_scene", "kernels_cached", "expected_kernels", "compile_report", "dispatcher",
           "plan_key"]

_done = set()

#: the scene inputs that choose kernels by their kind only (array ranks and dtypes, not sizes or values)
_INPUTS = ("objects", "lights", "environment", "volume", "water")


def _method(method):
    return method if isinstance(method, Method) else get_method(method)


def tiny_scene(method, scene):
    """``scene`` shrunk for ``method``'s warm-up: same knobs and inputs, a few pixels.

    Parameters
    ----------
    method : str or Method
        Its :attr:`~refraction_ref.graph.Method.tiny` overrides shrink the scene.
    scene : Scene
        A validated scene.

    Returns
    -------
    Scene
        A new scene; ``scene`` is unchanged.
    """
    m = _method(method)
    return load_scene(scene, dict(m.tiny(scene)) if m.tiny is not None else {})


def _kind(v):
    """A value as far as it can choose a kernel or its argument types: arrays by shape rank and dtype."""
    if hasattr(v, "dtype"):
        return ["array", getattr(v, "ndim", 0), str(v.dtype)]
    if isinstance(v, dict):
        return {k: _kind(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_kind(x) for x in v]
    return v if isinstance(v, (str, bool)) or v is None else type(v).__name__


def plan_key(method, scene):
    """What decides which kernels a render runs and their argument types (not sizes, positions or counts).

    Two scenes with equal keys compile the same kernels: :func:`warm` warms once per key.

    Parameters
    ----------
    method : str or Method
    scene : Scene

    Returns
    -------
    str
        A JSON text of the method, its knob blocks and the kinds of the scene's inputs.
    """
    d = scene.data
    name = _method(method).name
    return json.dumps([name, {b: d.get(b) for b in method_blocks()}, _kind({k: d.get(k) for k in _INPUTS}),
                       bool(d.get("receivers")), sorted(scene.callables)], sort_keys=True, default=str)


def warm(method, scene=None):
    """Compile (or load) the kernels ``method`` needs for ``scene``, once per process and plan.

    Parameters
    ----------
    method : str or Method
    scene : Scene, optional
        Default: the method's :attr:`~refraction_ref.graph.Method.default_scene`
        (the bundled default scene when that is None).

    Returns
    -------
    bool
        Whether it rendered the tiny scene (False: this plan was warm already).
    """
    m = _method(method)
    if scene is None:
        scene = load_scene(m.default_scene)
    key = plan_key(m, scene)
    if key in _done:
        return False
    run_graph(m, tiny_scene(m, scene), warm=False)
    _done.add(key)
    return True


def warmer(name):
    """The :attr:`~refraction_ref.graph.Method.warm` of the method called ``name``: :func:`warm` bound to it.

    Parameters
    ----------
    name : str
        The method's registered name.

    Returns
    -------
    callable
        ``warm(scene=None) -> bool``, as :func:`warm`.
    """

    def warm_method(scene=None):
        return warm(name, scene)

    warm_method.__name__ = warm_method.__qualname__ = f"warm_{name}"
    warm_method.__doc__ = (f"Compile (or load) the kernels the {name} method needs for ``scene`` "
                           "(:func:`refraction_ref.warm.warm`).")
    return warm_method


# ------------------------------------------------------------- the cache, kernel by kernel
def _manifest():
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "kernels.json")
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return {}


def expected_kernels(method):
    """Qualified names of the kernels a default render of ``method`` compiles (``data/kernels.json``).

    Parameters
    ----------
    method : str

    Returns
    -------
    list of str
        ``module.function`` names; empty for a method the manifest does not list.
    """
    return list(_manifest().get(method, []))


def dispatcher(qualname):
    """The Numba kernel named ``module.function`` (``data/kernels.json``'s names), or None.

    Parameters
    ----------
    qualname : str

    Returns
    -------
    CPUDispatcher or None
    """
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

    Parameters
    ----------
    method : str

    Returns
    -------
    bool
        False as well for a method the manifest does not list.
    """
    names = expected_kernels(method)
    if not names:
        return False
    for q in names:
        d = dispatcher(q)
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
