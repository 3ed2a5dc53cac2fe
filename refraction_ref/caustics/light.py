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

import numba as nb
import numpy as np

from ..embree import chunk_length, run_chunks

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

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
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

    Parameters
    ----------
    cam : Camera
        The light's camera (:func:`light_camera`): its window.
    n : int
        Cells per side of the grid (``exact.photons``).
    seed : int
        Seed of the jitter (``exact.photon_seed`` plus the light's index).

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

    Notes
    -----
    The jitter is the stream of ``np.random.default_rng(seed)``: ``u`` its
    first ``n * n`` doubles, ``v`` the next, row-major. Fixed chunks of rows
    draw theirs on ``numba.get_num_threads()`` threads, each from a copy of
    the generator advanced to its first draw (``PCG64.advance``), so the
    samples are the same bits whatever the thread count.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    n = int(n)
    N = n * n
    o = np.empty((N, 3))
    d = np.empty((N, 3))
    flux = np.empty(N)
    half = np.empty(N, np.int8)
    if N == 0:
        return o, d, flux, half
    # the stream of np.random.default_rng(seed): u's jitter is its draws [0, N), v's its draws
    # [N, 2N), row-major. Each chunk of rows jumps a copy of the generator to its own draws
    # (PCG64.advance: one draw per double; Generator.random releases the GIL): the same numbers
    # as one generator drawing them all, on every thread
    state = np.random.PCG64(int(seed)).state
    ru = np.empty(N)
    rv = np.empty(N)

    def draws(r0, r1):
        for start, out in ((r0 * n, ru), (N + r0 * n, rv)):
            bg = np.random.PCG64()
            bg.state = state
            bg.advance(start)
            a = start % N
            np.random.Generator(bg).random(out=out[a:a + (r1 - r0) * n])

    run_chunks(draws, n, chunk_length(n, 32, min_chunk=1))
    b = np.ascontiguousarray(cam.basis, dtype=np.float64)
    eye = np.asarray(cam.eye, dtype=np.float64)
    if cam.ortho:
        _ortho_samples_kernel(ru, rv, n, float(cam.sx), float(cam.sy), eye, b, o, d, half)
        flux[:] = (2.0 * cam.sx / n) * (2.0 * cam.sy / n)
        return o, d, flux, half

    def rows(r0, r1):  # the NumPy expressions on rows [r0, r1) alone (all per cell)
        m = r1 - r0
        jj, ii = np.meshgrid(np.arange(n), np.arange(r0, r1))
        sl = slice(r0 * n, r1 * n)
        u = (jj + ru[sl].reshape(m, n)) / n
        v = (ii + rv[sl].reshape(m, n)) / n
        x = (u * 2.0 - 1.0) * cam.sx
        y = (1.0 - v * 2.0) * cam.sy
        dd = x[..., None] * b[0] + y[..., None] * b[1] - b[2]
        dd /= np.linalg.norm(dd, axis=-1, keepdims=True)
        d[sl] = dd.reshape(-1, 3)
        o[sl] = eye
        flux[sl] = ((2.0 * cam.sx / n) * (2.0 * cam.sy / n) / (1.0 + x * x + y * y) ** 1.5).ravel()
        half[sl] = ((ii + jj) % 2).astype(np.int8).ravel()

    run_chunks(rows, n, chunk_length(n, 32, min_chunk=1))
    return o, d, flux, half


@nb.njit(cache=True, parallel=True)
def _ortho_samples_kernel(ru, rv, n, sx, sy, eye, b, o, d, half):
    # window_samples's NumPy expressions per cell (i, j), operation for operation:
    # u = (j + ru) / n, x = (2u - 1) sx, o = eye + x b0 + y b1, d = -b2
    for i0 in nb.prange(n):
        i = np.int64(i0)
        for j in range(n):
            k = i * n + j
            u = (j + ru[k]) / n
            vv = (i + rv[k]) / n
            x = (u * 2.0 - 1.0) * sx
            y = (1.0 - vv * 2.0) * sy
            for c in range(3):
                o[k, c] = eye[c] + x * b[0, c] + y * b[1, c]
                d[k, c] = -b[2, c]
            half[k] = (i + j) % 2
