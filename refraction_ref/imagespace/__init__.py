"""Image-space multiple refraction (Chaudhari 2008): one module per pass.

``depth_bounds`` (§3.3) -> ``voxelize`` (§3.3) -> ``peel`` (§3.4) ->
``normals`` (§3.5) -> ``search_bounds`` (§3.7) -> ``trace`` (§3.6-3.8), put
together by ``pipeline``.
"""

__all__ = ["render_imagespace"]


def __getattr__(name):  # lazy: scene loading imports .knobs without the kernels
    if name == "render_imagespace":
        from .pipeline import render_imagespace

        return render_imagespace
    raise AttributeError(name)
