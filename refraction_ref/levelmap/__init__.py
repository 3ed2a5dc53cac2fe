"""Water caustics with the level-map method (Tipprasert 2006), its volumetric
baseline (Iwasaki et al.) and a per-ray variant, one module per pass.

>>> from refraction_ref.levelmap import default_scene, render_levelmap
>>> arrays, info = render_levelmap(default_scene())          # doctest: +SKIP

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006.
"""

__all__ = ["render_levelmap", "render_water_exact", "default_scene"]


def __getattr__(name):  # lazy: scene validation imports .knobs without the kernels
    if name in ("render_levelmap", "default_scene"):
        from . import pipeline

        return getattr(pipeline, name)
    if name == "render_water_exact":
        from ..exact.pipeline import render_water_exact

        return render_water_exact
    raise AttributeError(name)
