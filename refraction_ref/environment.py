"""Environment maps: what a ray sees when it leaves the scene.

``checker``
    A procedural latitude-longitude checkerboard, ``tiles`` squares around
    the horizon and ``tiles / 2`` from pole to pole, alternating the two
    ``colors``. Its sharp edges make refraction errors visible.
``latlong``
    An equirectangular image (any format imageio reads; HDR stays linear,
    8-bit images are decoded from sRGB), sampled bilinearly.
``constant``
    One colour, ``colors[0]`` (useful for energy tests).

The lat-long parameterisation: ``u = atan2(x, -z) / (2 pi) + 1/2`` (u = 1/2
looks down -z), ``v = acos(y) / pi`` (v = 0 is straight up, +y).
"""

from __future__ import annotations

import functools
import math

import numba as nb
import numpy as np

__all__ = ["environment_lookup", "latlong_uv", "read_latlong"]


def latlong_uv(dirs):
    """Lat-long texture coordinates (u, v) in [0, 1] of unit directions (..., 3).

    Parameters
    ----------
    dirs : (..., 3) array_like
        Unit world-space directions.

    Returns
    -------
    u : (...) float64 ndarray
        ``atan2(x, -z) / (2 pi) + 1/2``; u = 1/2 looks down -z.
    v : (...) float64 ndarray
        ``acos(y) / pi``; v = 0 is straight up (+y).
    """
    d = np.asarray(dirs, dtype=np.float64)
    u = np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi) + 0.5
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return u, v


@functools.lru_cache(maxsize=4)
def _load_image(path):
    import imageio.v3 as iio

    img = np.asarray(iio.imread(path))
    if img.ndim not in (2, 3) or min(img.shape[:2]) < 1 or img.dtype.kind not in "uif":
        raise ValueError(f"not a single still image (array {img.shape}, dtype {img.dtype})")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    img = img[..., :3]
    if img.dtype.kind in "ui":
        img = img.astype(np.float64) / np.iinfo(img.dtype).max
        img = np.where(img <= 0.04045, img / 12.92, ((img + 0.055) / 1.055) ** 2.4)
    img = img.astype(np.float32)
    img.setflags(write=False)
    return img


def read_latlong(path, where="environment.path"):
    """Read a ``latlong`` image (when the scene is loaded, so a bad file is refused before any work).

    The image is cached: the shade stage's :func:`environment_lookup` reuses it.

    Parameters
    ----------
    path : str
        File of the equirectangular image (made absolute before reading).
    where : str
        Scene key named in the error message.

    Returns
    -------
    (H, W, 3) float32 ndarray
        Read-only linear RGB (8/16-bit images decoded from sRGB; grey
        images repeated to three channels, alpha dropped).

    Raises
    ------
    SceneError
        Naming the key, the file and what it holds, for a file imageio cannot read as a still image.
    """
    import os

    from .files import file_kind
    from .validation import SceneError

    try:
        return _load_image(os.path.abspath(path))
    except Exception as e:  # imageio raises many types
        raise SceneError(f"scene: {where} '{path}' is not an image imageio can read ({file_kind(path)}; "
                         f"{type(e).__name__}: {e}); give a latitude-longitude image (PNG, JPEG, EXR, HDR)") from None


@nb.njit(cache=True, parallel=True)
def _checker_kernel(d, tiles, colors, intensity, out):
    half = tiles / 2.0
    for k in nb.prange(d.shape[0]):
        x, y, z = d[k, 0], d[k, 1], d[k, 2]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            out[k, 0] = 0.0
            out[k, 1] = 0.0
            out[k, 2] = 0.0
            continue
        u = math.atan2(x, -z) / (2.0 * math.pi) + 0.5
        v = math.acos(min(1.0, max(-1.0, y))) / math.pi
        c = (np.int64(math.floor(u * tiles)) + np.int64(math.floor(v * half))) % 2
        for ch in range(3):
            out[k, ch] = colors[c, ch] * intensity


def _bilinear(img, u, v):
    H, W = img.shape[:2]
    x = u * W - 0.5
    y = v * H - 0.5
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    xa, xb = x0 % W, (x0 + 1) % W          # wraps around in longitude
    ya, yb = np.clip(y0, 0, H - 1), np.clip(y0 + 1, 0, H - 1)
    return ((img[ya, xa] * (1 - fx) + img[ya, xb] * fx) * (1 - fy)
            + (img[yb, xa] * (1 - fx) + img[yb, xb] * fx) * fy)


def environment_lookup(env, dirs, base_dir="."):
    """Linear RGB radiance seen along unit directions.

    Parameters
    ----------
    env : dict
        The scene's ``environment`` block.
    dirs : (..., 3) array_like
        World-space directions; rows holding NaN give black.
    base_dir : str
        Folder for a relative ``path``.

    Returns
    -------
    (..., 3) float32
    """
    import os

    d = np.asarray(dirs, dtype=np.float64)
    t = env.get("type", "checker")
    colors = np.asarray(env.get("colors", [[0.9, 0.9, 0.9], [0.1, 0.1, 0.1]]), dtype=np.float64)
    if t == "checker":  # the common case, in one pass
        flat = np.ascontiguousarray(d).reshape(-1, 3)
        out = np.empty(flat.shape, np.float32)
        _checker_kernel(flat, int(env.get("tiles", 48)), colors, float(env.get("intensity", 1.0)), out)
        return out.reshape(d.shape)
    bad = ~np.all(np.isfinite(d), axis=-1)
    d = np.where(bad[..., None], np.array([0.0, 0.0, -1.0]), d)
    if t == "constant":
        out = np.broadcast_to(colors[0], d.shape).astype(np.float64)
    elif t == "latlong":
        p = env["path"] if os.path.isabs(env["path"]) else os.path.join(base_dir, env["path"])
        u, v = latlong_uv(d)
        out = _bilinear(_load_image(os.path.abspath(p)), u, v)
    else:
        raise ValueError(f"environment: unknown type {t!r}")
    out = np.asarray(out, dtype=np.float64) * float(env.get("intensity", 1.0))
    out[bad] = 0.0
    return out.astype(np.float32)
