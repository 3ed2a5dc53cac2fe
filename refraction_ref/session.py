"""``Session``: keep every stage's output between renders and re-run only what changed.

>>> import refraction_ref as rr
>>> s = rr.Session({"camera": {"width": 64, "height": 64}, "volumetric": {"resolution": 32, "photons": 64}})
>>> first = s.render("volumetric")                       # every stage runs
>>> s.update({"camera.eye": [0.5, 0.0, 2.6]})
>>> again = s.render("volumetric")                       # only the viewing pass runs
>>> [p["stage"] for p in again.meta["plan"] if p["ran"]]
['view']

The volumetric method (Sun et al. 2008, §3) is staged: a camera change
re-runs the viewing pass only; a light change photon generation, marching,
smoothing and viewing; a geometry or material change everything.
``meta["plan"]`` says, for each stage, whether it ran or was reused and why.
Other methods are rendered afresh each time.
"""

from __future__ import annotations

import time

import numba

from .render import METHODS, render
from .result import Result
from .scene import Scene, SceneError, load_scene

__all__ = ["Session"]


class Session:
    """An interactive session on one scene.

    Parameters
    ----------
    scene : Scene, dict, str or None
        Anything :func:`~refraction_ref.scene.load_scene` accepts.
    overrides : dict, optional
        Dotted keys applied once at the start.

    Attributes
    ----------
    scene : Scene
        The current (validated) scene.
    """

    def __init__(self, scene=None, overrides=None):
        self.scene = scene if isinstance(scene, Scene) and not overrides else load_scene(scene, overrides)
        self._cache = {}

    def update(self, overrides):
        """Change dotted keys, e.g. ``{"camera.eye": [0, 0, 3]}``; the scene is re-validated.

        Returns the session, so calls chain. On a bad value the scene is left
        unchanged and :class:`SceneError` is raised.
        """
        self.scene = load_scene(self.scene, overrides)
        return self

    def clear(self):
        """Forget every cached stage."""
        self._cache.clear()

    def render(self, method="volumetric", progress=False):
        """Render the current scene; for ``volumetric``, reuse every stage whose inputs did not change.

        Returns
        -------
        Result
            As :func:`refraction_ref.render`, with ``meta["plan"]`` naming
            each stage as ran or reused, and why.
        """
        if method not in METHODS:
            raise SceneError(f"Session.render: unknown method {method!r}; choose one of {', '.join(METHODS)}")
        if method != "volumetric":
            return render(self.scene, method=method, progress=progress)
        from . import __version__
        from .volumetric.pipeline import render_volumetric

        t0 = time.perf_counter()
        arrays, info = render_volumetric(self.scene, cache=self._cache)
        meta = {"method": method, "scene": self.scene.data, "params": self.scene.data["volumetric"],
                "version": __version__, "numba_threads": int(numba.get_num_threads()),
                "total_ms": (time.perf_counter() - t0) * 1e3}
        meta.update(info)
        return Result(arrays, meta)
