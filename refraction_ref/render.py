"""``render``: one entry point for every method, writing the ORACLE.md keys."""

from __future__ import annotations

import time

import numba
import numpy as np

from .result import Result
from .scene import Scene, SceneError, load_scene

__all__ = ["render", "METHODS"]

METHODS = ("imagespace", "exact", "levelmap", "volumetric")


def _version():
    from . import __version__

    return __version__


def render(scene=None, method="imagespace", overrides=None, progress=False):
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
        :mod:`refraction_ref.levelmap.exact_water`); ``levelmap``: water
        caustics, Tipprasert (2006); ``volumetric``: photon tracing through an
        index volume, Sun et al. (2008).
    overrides : dict, optional
        Dotted keys, e.g. ``{"imagespace.iterations": 10}``.
    progress : bool
        Show a progress bar on long work.

    Returns
    -------
    Result
        ``arrays`` with the ORACLE.md keys, ``meta`` with the resolved
        scene, the parameters used, version, thread count, ``timings_ms``
        and ``plan``.
    """
    if method not in METHODS:
        raise SceneError(f"render: unknown method {method!r}; choose one of {', '.join(METHODS)}")
    scene = load_scene(scene if scene is not None else None, overrides) if (overrides or not isinstance(scene, Scene)) else scene
    t0 = time.perf_counter()
    if method == "imagespace":
        from .imagespace import render_imagespace

        arrays, info = render_imagespace(scene)
        params = scene.data["imagespace"]
    elif method == "volumetric":
        from .volumetric import render_volumetric  # Sun et al. 2008 volumetric relighting

        arrays, info = render_volumetric(scene)
        params = scene.data["volumetric"]
    elif method == "levelmap":
        from .levelmap.pipeline import render_levelmap  # Tipprasert 2006 water caustics

        arrays, info = render_levelmap(scene)
        params = {"levelmap": scene.data["levelmap"], "water": scene.data["water"]}
    elif method == "exact" and scene.data.get("water") is not None:
        from .levelmap.exact_water import render_water_exact  # exact water-caustics reference

        arrays, info = render_water_exact(scene, progress=progress)
        params = {"levelmap": scene.data["levelmap"], "water": scene.data["water"]}
    else:
        from .exact_render import render_exact

        arrays, info = render_exact(scene, progress=progress)
        params = scene.data["exact"]
    total = (time.perf_counter() - t0) * 1e3
    meta = {
        "method": method,
        "scene": scene.data,
        "params": params,
        "version": _version(),
        "numba_threads": int(numba.get_num_threads()),
        "total_ms": total,
    }
    meta.update(info)
    for k in ("exit_pos", "exit_dir"):
        assert k not in arrays or arrays[k].dtype == np.float64
    return Result(arrays, meta)
