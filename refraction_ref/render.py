"""``render``: one entry point for every registered method (``docs/oracle.md`` keys)."""

from __future__ import annotations

import time

import numba
import numpy as np

from . import warm
from .contract import CONTRACT_VERSION, software_versions
from .graph import get_method, method_names, run_graph
from .result import Result
from .validation import SceneError
from .scene import Scene, load_scene

__all__ = ["render", "METHODS", "run_method", "kernels_cached"]

METHODS = method_names()


def kernels_cached(method):
    """Whether Numba's on-disk cache holds every kernel a default render of ``method`` compiles.

    Checked kernel by kernel (:func:`refraction_ref.warm.kernels_cached`): a
    cache filled in part by the tests or an interrupted run counts as not cached.

    Parameters
    ----------
    method : str

    Returns
    -------
    bool
    """
    return warm.kernels_cached(method)


def run_method(scene, method, cache=None, keep=None, progress=False):
    """Run a method's stage graph and wrap the outputs as a :class:`Result` with the full ``meta``.

    The method's warm-up (:attr:`~refraction_ref.graph.Method.warm`) runs
    first, outside ``total_ms`` (its time is ``jit_ms``).

    Parameters
    ----------
    scene : Scene
        A validated scene.
    method : str
        A registered method.
    cache : dict, optional
        Stage cache (:class:`~refraction_ref.session.Session` keeps one).
    keep : None, 'stages', str or list of str
        As :func:`render`.
    progress : bool
        Show a progress bar on long work.

    Returns
    -------
    Result
        ``meta["params"]`` holds the knob blocks the method names for this
        scene (:meth:`~refraction_ref.graph.Method.param_blocks`): the block
        itself when it is one, else ``{block: values}``.
    """
    m = get_method(method)
    t0 = time.perf_counter()
    if m.warm is not None:  # JIT compilation (or loading the cache) stays out of total_ms
        m.warm(scene)
    jit_ms = (time.perf_counter() - t0) * 1e3
    t0 = time.perf_counter()
    arrays, info = run_graph(m, scene, cache=cache, keep=keep, progress=progress, warm=False)
    total = (time.perf_counter() - t0) * 1e3
    blocks = m.param_blocks(scene)
    meta = {
        "method": method,
        "scene": scene.data,
        "params": scene.data[blocks[0]] if len(blocks) == 1 else {b: scene.data[b] for b in blocks},
        "version": software_versions()["refraction_ref"],
        "contract_version": CONTRACT_VERSION,
        "versions": software_versions(),
        "numba_threads": int(numba.get_num_threads()),
        "total_ms": total,
        "jit_ms": jit_ms,
    }
    meta.update(info)
    meta["contract_version"] = CONTRACT_VERSION
    for k in ("exit_pos", "exit_dir"):
        if k in arrays and arrays[k].dtype != np.float64:
            raise AssertionError(f"{method}: {k} must be float64 (docs/oracle.md)")
    return Result(arrays, meta)


def render(scene=None, method="imagespace", overrides=None, progress=False, keep=None):
    """Render a scene with one method.

    Parameters
    ----------
    scene : Scene, dict, str or None
        A scene, anything :func:`~refraction_ref.scene.load_scene` accepts,
        or None for the bundled default scene.
    method : {'imagespace', 'exact', 'levelmap', 'volumetric'}
        ``imagespace``: Chaudhari (2008); ``exact``: multi-interface Snell
        tracing through the actual triangles with Embree (for a scene with a
        ``water`` block: the exact water-caustics reference,
        :mod:`refraction_ref.exact.water`; for a scene with a ``volume``: the
        ray equation integrated to convergence by DOP853 on the volumetric
        method's field, :mod:`refraction_ref.exact.volume`); ``levelmap``: water
        caustics, Tipprasert (2006); ``volumetric``: photon tracing through an
        index volume, Sun et al. (2008).
    overrides : dict, optional
        Dotted keys, e.g. ``{"imagespace.iterations": 10}``.
    progress : bool
        Show a progress bar on long work.
    keep : None, 'stages', str or list of str
        Stages whose buffers to add to the result as ``stage.<stage>.<buffer>``
        (``docs/oracle.md``, "Stage buffers"): ``'stages'`` for every stage,
        or a comma list of stage names.

    Returns
    -------
    Result
        ``arrays`` with the ``docs/oracle.md`` keys, ``meta`` with the
        resolved scene, the parameters used, versions (package, contract,
        libraries, CPU), thread count, ``timings_ms`` (one entry per stage
        that ran) and ``plan``.
    """
    if method not in method_names():
        raise SceneError(f"render: unknown method {method!r}; choose one of {', '.join(method_names())}")
    if overrides or not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    return run_method(scene, method, keep=keep, progress=progress)
