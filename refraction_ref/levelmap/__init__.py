"""Water caustics with the level-map method (Tipprasert 2006), the thesis's
slice-image baseline (Iwasaki et al. 2003, :mod:`.slice_image_baseline`,
``levelmap.variant = "volumetric"``) and a per-ray variant, one module per pass.

>>> from refraction_ref.levelmap import default_scene, render_levelmap
>>> arrays, info = render_levelmap(default_scene())          # doctest: +SKIP

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006.
"""

# the exact water reference (render_water_exact) lives in refraction_ref.exact, which reuses this
# package's passes: it is not re-exported here, so the level map imports nothing of the exact package
__all__ = ["render_levelmap", "default_scene"]


def __getattr__(name):  # lazy: scene validation imports .knobs without the kernels
    if name in ("render_levelmap", "default_scene"):
        from . import pipeline

        return getattr(pipeline, name)
    raise AttributeError(name)
