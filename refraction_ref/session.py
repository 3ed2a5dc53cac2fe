"""``Session``: keep every stage's output between renders and re-run only what changed.

>>> import refraction_ref as rr
>>> s = rr.Session({"camera": {"width": 64, "height": 64}, "volumetric": {"resolution": 32, "photons": 64}})
>>> first = s.render("volumetric")                       # every stage runs
>>> s.update({"camera.eye": [0.5, 0.0, 2.6]})            # doctest: +ELLIPSIS
<refraction_ref.session.Session object at ...>
>>> again = s.render("volumetric")                       # only the viewing pass runs
>>> [p["stage"] for p in again.meta["plan"] if p["ran"]]
['view']

Every method is a registered stage graph (:mod:`refraction_ref.graph`):
each stage declares the scene keys and knobs it reads, and re-runs when
one of them changed or an upstream stage re-ran. So for the volumetric
method (Sun et al. 2008, §3) a camera change re-runs the viewing pass
only, a light change photon generation, marching, smoothing and viewing;
for the image-space method ``imagespace.iterations`` re-runs the trace and
the shading only; for the level map a camera change re-runs the final
image only. ``meta["plan"]`` says, for each stage, whether it ran or was
reused and why.
"""

from __future__ import annotations

from .graph import method_names
from .render import run_method
from .validation import SceneError
from .scene import Scene, load_scene

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

        On a bad key or value :class:`SceneError` is raised naming it, and
        the scene and the cached stages are left as they were.

        Parameters
        ----------
        overrides : dict
            Dotted keys and their new values.

        Returns
        -------
        Session
            This session, so calls chain.
        """
        self.scene = load_scene(self.scene, overrides)
        return self

    def clear(self):
        """Forget every cached stage."""
        self._cache.clear()

    def render(self, method="volumetric", progress=False, keep=None):
        """Render the current scene, reusing every stage whose inputs did not change.

        Parameters
        ----------
        method : str
            A registered method.
        progress : bool
        keep : None, 'stages', str or list of str
            As :func:`refraction_ref.render`.

        Returns
        -------
        Result
            As :func:`refraction_ref.render`, with ``meta["plan"]`` naming
            each stage as ran or reused, and why.
        """
        if method not in method_names():
            raise SceneError(f"Session.render: unknown method {method!r}; choose one of {', '.join(method_names())}")
        return run_method(self.scene, method, cache=self._cache, keep=keep, progress=progress)
