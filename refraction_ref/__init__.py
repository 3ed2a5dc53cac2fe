"""refraction_ref: a CPU reference (NumPy + Numba) for three GPU methods of
rendering light refracted through transparent objects and water.

>>> import refraction_ref as rr
>>> scene = rr.load_scene()                       # the bundled glass bunny
>>> result = rr.render(scene, method="imagespace", overrides={"imagespace.iterations": 10})
>>> result.arrays["exit_dir"].shape
(512, 512, 3)
"""

__version__ = "0.1.0"

from .camera import Camera
from .golden.check import check
from .render import METHODS, render
from .result import Result, load_result
from .validation import SceneError
from .scene import Scene, default_scene, load_scene
from .session import Session

__all__ = ["Camera", "METHODS", "Result", "Scene", "SceneError", "check", "default_scene", "load_result",
           "load_scene", "render", "Session", "__version__"]
