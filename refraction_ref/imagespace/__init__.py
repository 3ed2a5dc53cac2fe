"""Image-space multiple refraction (Chaudhari 2008): one module per pass.

``depth_bounds`` (§3.3) -> ``voxelize`` (§3.3) -> ``peel`` (§3.4) ->
``normals`` (§3.5) -> ``search_bounds`` (§3.7) -> ``trace`` (§3.6-3.8), put
together by ``pipeline``.
"""

from .pipeline import render_imagespace

__all__ = ["render_imagespace"]
