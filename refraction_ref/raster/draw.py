"""Drawing: the rasterizer's entry points, a set-up drawn with one blend operation.

:func:`rasterize` draws view-space triangles (or a :class:`~.snap.RasterSetup`
of them) through a camera, :func:`rasterize_ortho` and
:func:`ortho_fragments` draw triangles given in texel units (the
orthographic maps of the level-map method, Tipprasert 2006 §4.2.2, and the
slice images and solid voxelization of the volumetric methods). Each picks
the buffers its blend operation writes (:data:`~.blend.OPS`) and runs one
band kernel of :mod:`.blend` over the set-up.

References
----------
Chaudhari (2008), §3.3 (the blend operations); Tipprasert (2006), §4.2.2
(the orthographic maps).
"""

from __future__ import annotations

import numpy as np

from .blend import (FRAGMENT_LIMIT, OPS, Fragments, _RasterBlend, _RasterGrid, _RasterTargets, _NO_FRAGMENTS,
                    _blend_fragments, _fragment_buffers, _minmax_kernel, _raster_kernel, _record, _tris)
from .snap import BAND, RasterSetup, ortho_setup, raster_setup

__all__ = ["rasterize", "rasterize_ortho", "ortho_fragments"]

_NO_SLAB = np.zeros(4)


def _check_slices(bounds, slices):
    """The per-pixel slice range of ops 'or' / 'add', contiguous float64; ValueError when unusable."""
    if slices % 32 or slices < 32:
        raise ValueError(f"rasterize: slices must be a positive multiple of 32, got {slices}")
    if bounds is None or bounds[0] is None or bounds[1] is None:
        raise ValueError("rasterize: op 'or'/'add' needs the per-pixel bounds=(zlo, zhi)")
    return np.ascontiguousarray(bounds[0], dtype=np.float64), np.ascontiguousarray(bounds[1], dtype=np.float64)


def _blend_recorded(fr, shape, op, bounds, slices):
    """Ops 'or' / 'add' on the fragments a min/max pass recorded (the same bits as rasterizing again)."""
    if op not in ("or", "add"):
        raise ValueError(f"rasterize: recorded fragments serve ops 'or' and 'add', not {op!r}")
    if fr.shape != shape:
        raise ValueError(f"rasterize: the fragments were recorded for {fr.shape}, the camera is {shape}")
    zlo, zhi = _check_slices(bounds, slices)
    H, W = shape
    bits = np.zeros((H, W, slices // 32), np.uint32)
    _blend_fragments(fr.offsets, fr.counts, fr.pix, fr.depth, W, OPS[op], zlo, zhi, int(slices), bits)
    return bits


def _targets(code, shape, capacity, slices):
    """The buffers op ``code`` blends into, initialised; (1, 1[, 1]) placeholders for the others."""
    H, W = shape
    fbuf = np.zeros((1, 1))
    ibuf = np.zeros((1, 1), np.int32)
    bits = np.zeros((1, 1, 1), np.uint32)
    layers = np.zeros((1, 1, 1))
    ids = np.zeros((1, 1), np.int64)
    if code in (0, 7):
        fbuf = np.full((H, W), np.inf)
    elif code == 1:
        fbuf = np.full((H, W), -np.inf)
    elif code == 2:
        ibuf = np.zeros((H, W), np.int32)
    elif code in (3, 4):
        bits = np.zeros((H, W, slices // 32), np.uint32)
    elif code == 6:
        layers = np.empty((2, H, W))  # initialised band by band in the kernel
    else:  # 'collect'
        ibuf = np.zeros((H, W), np.int32)
        layers = np.full((int(capacity), H, W), np.inf)
    if code == 7:  # a visibility buffer: no A-buffer, the nearest depth and its triangle
        ids = np.full((H, W), -1, np.int64)
    return _RasterTargets(fbuf, ibuf, bits, layers, ids)


def _result(code, out):
    """What :func:`rasterize` returns for op ``code`` from its buffers."""
    if code in (0, 1):
        return out.fbuf
    if code == 7:
        return out.fbuf, out.ids
    if code == 2:
        return out.ibuf
    if code in (3, 4):
        return out.bits
    if code == 6:
        return out.layers[0], out.layers[1]
    return out.layers, out.ibuf


def rasterize(tri_view, camera, op, *, bounds=None, slices=256, capacity=32, clip=True, keep_fragments=False):
    """Rasterize view-space triangles with one GPU-style blend operation.

    Parameters
    ----------
    tri_view : (T, 3, 3) array_like, RasterSetup or Fragments
        Triangle vertices in view space (see :class:`~refraction_ref.camera.Camera`),
        the result of :func:`~.snap.raster_setup` to skip the set-up, or
        the fragments a min/max pass recorded (``keep_fragments``), which
        ops ``or`` and ``add`` blend without rasterizing again (identical
        result).
    camera : Camera
        Image size and projection (perspective, or orthographic: the
        depth is then interpolated linearly on screen).
    op : {'min', 'max', 'minmax', 'nearest', 'count', 'or', 'add', 'collect'}
        Per-pixel blend (see :mod:`refraction_ref.raster`).
    bounds : tuple of two (H, W) ndarray, optional
        ``(zlo, zhi)``, the per-pixel depth range mapped onto the slices
        (``or`` and ``add``; what op ``minmax`` returns): slice
        ``b = round((d - zlo) / (zhi - zlo) * (S - 1))``, the inverse of
        Chaudhari's ``depth = Zmin + b / (S - 1) * (Zmax - Zmin)`` (§3.4.1).
    slices : int
        Number of slices S, a multiple of 32 (``or`` and ``add``).
    capacity : int
        Depths kept per pixel (``collect``).
    clip : bool
        Clip against the near plane first (default). Pass False when the
        triangles are already clipped.
    keep_fragments : bool
        With ``op='minmax'``: also return the :class:`~.blend.Fragments`
        (None when there would be more than :data:`~.blend.FRAGMENT_LIMIT`).

    Returns
    -------
    ndarray or tuple
        ``min``/``max``: (H, W) float64 depth; ``minmax``: a tuple of both;
        ``nearest``: a tuple (depth, triangle index, -1 where empty);
        ``count``: (H, W) int32;
        ``or``/``add``: (H, W, S // 32) uint32; ``collect``: a tuple
        ``(depths (capacity, H, W) float64 with +inf padding, count (H, W) int32)``.

    Raises
    ------
    ValueError
        For an unknown ``op``, a set-up or record made for another image
        size, or ops ``or``/``add`` without usable ``bounds`` and ``slices``.

    References
    ----------
    Chaudhari (2008), §3.3.
    """
    if op not in OPS:
        raise ValueError(f"rasterize: unknown op {op!r}; expected one of {sorted(OPS)}")
    W, H, sx, sy = camera.kernel_args()
    if isinstance(tri_view, Fragments):
        return _blend_recorded(tri_view, (H, W), op, bounds, slices)
    rs = tri_view if isinstance(tri_view, RasterSetup) else raster_setup(tri_view, camera, clip)
    if rs.shape != (H, W):
        raise ValueError(f"rasterize: the set-up was made for {rs.shape}, the camera is {(H, W)}")
    code = OPS[op]
    lo = hi = np.zeros((1, 1))
    if code in (3, 4):
        lo, hi = _check_slices(bounds, slices)
    out = _targets(code, (H, W), capacity, slices)
    fr = _fragment_buffers(rs, W) if keep_fragments and code == 6 else None
    rec = _NO_FRAGMENTS if fr is None else _record(fr)
    # depth is interpolated linearly on screen for an orthographic camera
    grid = _RasterGrid(W, H, BAND, not getattr(camera, "ortho", False))
    if code == 6:
        _minmax_kernel(_tris(rs), grid, out.layers, rec)
    else:
        _raster_kernel(code, _tris(rs), grid, _RasterBlend(lo, hi, int(slices), _NO_SLAB), out, rec)
    res = _result(code, out)
    if code == 6 and keep_fragments:
        res = res + (fr,)
    return res


def rasterize_ortho(tri_tex, shape, slab=None):
    """Orthographic rasterization keeping the nearest fragment and its triangle.

    The orthographic counterpart of :func:`rasterize` with ``op='min'``,
    with the same fixed-point coverage and top-left rule, plus the index of
    the triangle that produced the kept fragment (a visibility buffer, from
    which normals, owners and colours are looked up). Depth is interpolated
    linearly in screen space, as an orthographic projection does.

    Parameters
    ----------
    tri_tex : (T, 3, 3) array_like or RasterSetup
        Triangles as ``(col, row, depth)`` in texel units (see
        :func:`~.snap.ortho_setup`), or a set-up from it.
    shape : (H, W)
    slab : (z0, s, klo, khi), optional
        Keep only fragments whose slab index ``floor((depth - z0) / s)`` lies
        in ``[klo, khi]`` (the near and far clip planes of the slice images
        of Iwasaki et al.; written as an index so that it agrees bit for bit
        with a plane-index map computed with the same expression).

    Returns
    -------
    depth : (H, W) float64
        Nearest fragment depth, ``+inf`` where nothing is drawn.
    ids : (H, W) int64
        Triangle index of that fragment, ``-1`` where nothing is drawn. Ties
        go to the first triangle in index order.

    References
    ----------
    N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene with
    Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
    University, 2006, §4.2.2 (eqs. 4-10 to 4-13).
    """
    H, W = int(shape[0]), int(shape[1])
    rs = tri_tex if isinstance(tri_tex, RasterSetup) else ortho_setup(tri_tex, (H, W))
    if rs.shape != (H, W):
        raise ValueError(f"rasterize_ortho: the set-up was made for {rs.shape}, asked for {(H, W)}")
    z0, s, klo, khi = (0.0, 0.0, 0.0, 0.0) if slab is None else (float(v) for v in slab)
    if slab is not None and not s > 0.0:
        raise ValueError(f"rasterize_ortho: slab thickness must be > 0, got {s}")
    code = OPS["nearest"]
    out = _targets(code, (H, W), 0, 256)
    d1 = np.zeros((1, 1))
    _raster_kernel(code, _tris(rs), _RasterGrid(W, H, BAND, False),
                   _RasterBlend(d1, d1, 256, np.array([z0, s, klo, khi], dtype=np.float64)), out, _NO_FRAGMENTS)
    return _result(code, out)


def ortho_fragments(tri_tex, shape):
    """Every fragment of an orthographic rasterization, with its depth and facing.

    Parameters
    ----------
    tri_tex : (T, 3, 3) array_like or RasterSetup
        Triangles as ``(col, row, depth)`` in texel units (:func:`~.snap.ortho_setup`).
    shape : (H, W)

    Returns
    -------
    Fragments
        Grouped by band of rows, triangles in index order within a band;
        ``facing`` is -1 for triangles counter-clockwise in (col, row) and
        +1 for the others. Used by the solid voxelization of the volumetric
        method to count surface crossings along each column.

    Raises
    ------
    MemoryError
        When the fragments would exceed the recording limit.
    """
    H, W = int(shape[0]), int(shape[1])
    rs = tri_tex if isinstance(tri_tex, RasterSetup) else ortho_setup(tri_tex, (H, W))
    fr = _fragment_buffers(rs, W)
    if fr is None:
        raise MemoryError(f"ortho_fragments: more than {FRAGMENT_LIMIT} fragments; lower the resolution")
    layers = np.empty((2, H, W))
    _minmax_kernel(_tris(rs), _RasterGrid(W, H, BAND, False), layers, _record(fr))
    return fr
