"""The light's view of the refractive objects and the photons it emits (Chaudhari 2008, §4.1).

Caustics mapping renders the refractive objects from the light (Shah et al.
2007, §2.3.2 of the thesis): a directional light sees them through an
*orthographic* camera looking along the light, a point light through a
*perspective* camera at the light. Either window is fitted to the objects'
bounding sphere, so every photon texel that can meet an object is in it.

One photon leaves through every texel of the light's layered depth images
and is traced through all layers by the eye pass's own kernels
(:func:`~refraction_ref.imagespace.pipeline.layered_trace`). Its flux, for
a light of unit strength, is the power through its texel:

* directional light (unit irradiance perpendicular to the light): the
  texel's area ``(2 sx / W) (2 sy / H)``;
* point light (unit intensity): the texel's solid angle,
  ``(2 sx / W) (2 sy / H) / (1 + x^2 + y^2)^{3/2}`` at image-plane
  coordinates ``(x, y)`` (unit depth).

Beer-Lambert absorption along the photon's path inside (§3.8) scales it
per colour channel; Fresnel reflection is not applied (as in the thesis).

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §2.3.2, §3.8, §4.1.
.. [2] M. A. Shah, J. Konttinen, S. Pattanaik, "Caustics Mapping: An
   Image-Space Technique for Real-Time Caustics", IEEE TVCG 13(2), 2007.
"""

from __future__ import annotations

import numpy as np


__all__ = ["light_camera", "texel_flux", "light_direction_at", "window_samples"]

# the light camera and directions are the shared lights service; re-exported for this package
from ..lights import light_camera, light_direction_at  # noqa: E402,F401

def texel_flux(cam, col, row):
    """Flux of one photon texel for a unit light, at continuous texel positions.

    Parameters
    ----------
    cam : Camera
        The light's camera (:func:`light_camera`).
    col, row : array_like
        Texel coordinates (centres at ``+0.5``).

    Returns
    -------
    ndarray
        Area of the texel (orthographic) or its solid angle (perspective).
    """
    W, H, sx, sy = cam.kernel_args()
    a = (2.0 * sx / W) * (2.0 * sy / H)
    col = np.asarray(col, dtype=np.float64)
    if cam.ortho:
        return np.full(col.shape, a)
    x = (col / W * 2.0 - 1.0) * sx
    y = (1.0 - np.asarray(row, dtype=np.float64) / H * 2.0) * sy
    return a / (1.0 + x * x + y * y) ** 1.5


def window_samples(cam, n, seed):
    """Jittered photons through the light's window (the exact reference's emission).

    One photon per cell of an ``n`` x ``n`` grid over the same window as the
    photon texture, at a uniformly random position inside its cell.

    Returns
    -------
    origins, dirs : (n * n, 3) float64
        World-space rays (parallel ones from the window plane, or from the
        point light).
    flux : (n * n,) float64
        :func:`texel_flux` of the cell at the sample (an unbiased estimate
        of the power through the cell).
    half : (n * n,) int8
        Checkerboard of the cells (0 / 1): two interleaved halves whose maps
        estimate the reference's own noise.
    """
    rng = np.random.default_rng(int(seed))
    jj, ii = np.meshgrid(np.arange(n), np.arange(n))
    u = (jj + rng.random((n, n))) / n
    v = (ii + rng.random((n, n))) / n
    x = (u * 2.0 - 1.0) * cam.sx
    y = (1.0 - v * 2.0) * cam.sy
    b = cam.basis
    if cam.ortho:
        o = np.asarray(cam.eye) + x[..., None] * b[0] + y[..., None] * b[1]
        d = np.broadcast_to(-b[2], o.shape).copy()
        flux = np.full(n * n, (2.0 * cam.sx / n) * (2.0 * cam.sy / n))
    else:
        d = x[..., None] * b[0] + y[..., None] * b[1] - b[2]
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        o = np.broadcast_to(np.asarray(cam.eye, dtype=np.float64), d.shape).copy()
        flux = ((2.0 * cam.sx / n) * (2.0 * cam.sy / n) / (1.0 + x * x + y * y) ** 1.5).ravel()
    half = ((ii + jj) % 2).astype(np.int8).ravel()
    return o.reshape(-1, 3), d.reshape(-1, 3), flux, half
