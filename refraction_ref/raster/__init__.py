"""The one triangle rasterizer shared by every method.

A CPU stand-in for the GPU's raster stage with its blend units: no culling,
no hidden-surface removal, one fragment per covered pixel centre, the
perspective-correct view-space depth of that fragment, and a per-pixel blend
operation. Every blend mode the three papers use is one call:

========== ============================================================
``op``     per-pixel result
========== ============================================================
``min``    smallest fragment depth (``+inf`` where nothing is drawn)
``minmax`` both in one pass, as the thesis's R/G max-blend trick does
``nearest`` the nearest depth and the index of its triangle (a visibility
           buffer; used by the orthographic maps of the level-map method)
``max``    largest fragment depth (``-inf`` where nothing is drawn)
``count``  number of fragments (the depth complexity)
``or``     bitmask occupancy: slice bit set with logical OR
``add``    bitmask occupancy with *additive* blending (a 32-bit add per
           word, so two fragments in one slice carry into the next bit,
           exactly as on a GPU without logical-OR blending)
``collect`` the ``capacity`` nearest fragment depths, sorted, plus the
           total count (an A-buffer / k-buffer of exact float depths)
========== ============================================================

Coverage is decided with exact integer edge functions on vertices snapped
to 1/256 pixel (as GPUs do) and a top-left tie rule, so a pixel centre on an
edge shared by two triangles yields exactly one fragment: closed meshes
give an even fragment count per pixel, and additive blending never sees a
spurious duplicate. Triangles crossing the near plane are clipped; zero-area
triangles produce no fragments. The image is split into bands of rows and
each band is rasterized by one thread, triangles in index order, so every
result is bit-identical whatever the thread count.

The stages, one module each, as a GPU's pipeline orders them:

======================= ==============================================================
module                  stage
======================= ==============================================================
:mod:`.snap`            triangle set-up: near-plane clipping, projection, snapping to
                        1/256 pixel, rows per triangle, binning into bands
                        (:func:`raster_setup`, :func:`ortho_setup`, :func:`bin_bands`)
:mod:`.coverage`        edge functions and the top-left rule: the pixels a triangle
                        covers, row by row (:func:`row_span` and its helpers)
:mod:`.blend`           the band kernels: every fragment blended into its pixel with
                        one of the ops above; recorded :class:`Fragments`
:mod:`.draw`            the entry points: :func:`rasterize`, :func:`rasterize_ortho`,
                        :func:`ortho_fragments`
======================= ==============================================================

Public toolkit
--------------
Kernels elsewhere that draw their own triangles or splat their own points
(with a blend the ops above do not cover) reuse the rasterizer's pieces, so
that they inherit its coverage rule and its determinism:

========================== ==========================================================
name                       used by
========================== ==========================================================
:data:`SUBPIXEL`           the 1/256-pixel fixed point the helpers below assume
:data:`BAND`               :mod:`~refraction_ref.caustics.splat`,
                           :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray` (rows per band)
:data:`MAX_COORD`          :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray` (guard band)
:func:`bin_bands`          :mod:`~refraction_ref.caustics.splat` (photons),
                           :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray` (beams)
:func:`oriented_triangle`  :mod:`~refraction_ref.levelmap.caustics_map`
:func:`pixel_span`         :mod:`~refraction_ref.levelmap.caustics_map`
:func:`edge_setup`         :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray`
:func:`edge_values`        :mod:`~refraction_ref.levelmap.caustics_map`,
                           :mod:`~refraction_ref.levelmap.per_ray`
:func:`row_span`           :mod:`~refraction_ref.levelmap.caustics_map` (the scanline
                           step: the covered run of a row, as the band kernel walks it)
========================== ==========================================================

:func:`bin_bands` is a parallel kernel called from Python. The five coverage
helpers are ``numba.njit(inline="always")`` functions meant to be called
from other njit kernels, into which they are inlined; changing one does not
invalidate the Numba caches of kernels in *other* files that inline it
(Numba keys a cache on the caller's source file only): clear them with
``find refraction_ref -name '*.nb[ic]' -delete``.

References
----------
.. [1] J. Pineda, "A Parallel Algorithm for Polygon Rasterization",
   SIGGRAPH 1988 (edge functions).
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.3 (min/max pass with max blending,
   bitmask voxelization with additive blending).
.. [3] E. Eisemann, X. Décoret, "Fast Scene Voxelization and Applications",
   I3D 2006 (slicing by bitwise blending).
"""

from __future__ import annotations

from .blend import FRAGMENT_LIMIT, OPS, Fragments
from .coverage import SUBPIXEL, edge_setup, edge_values, oriented_triangle, pixel_span, row_span
from .draw import ortho_fragments, rasterize, rasterize_ortho
from .snap import (BAND, MAX_COORD, RasterSetup, SnappedVertices, bin_bands, clip_near, ortho_setup, raster_setup,
                   raster_stats)

__all__ = ["rasterize", "raster_setup", "raster_stats", "RasterSetup", "SnappedVertices", "Fragments",
           "FRAGMENT_LIMIT", "clip_near", "OPS", "ortho_setup", "rasterize_ortho", "ortho_fragments",
           # public toolkit (see the module docstring)
           "SUBPIXEL", "BAND", "MAX_COORD", "bin_bands", "oriented_triangle", "pixel_span", "edge_setup", "row_span",
           "edge_values"]
