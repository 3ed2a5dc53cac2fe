"""Image metrics: the thesis's average CIE Luv difference (eq. 2-9) and the
relative L1 error of caustic maps used against the exact reference.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §2.7 (eq. 2-9).
.. [2] CIE 15:2004, Colorimetry (CIE 1976 L*u*v*); IEC 61966-2-1 (sRGB
   primaries, D65 white).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .filters import gaussian_filter_zero
from .vec3 import affine

__all__ = ["rgb_to_luv", "luv_difference", "relative_l1"]

_RGB2XYZ = np.array([[0.4124564, 0.3575761, 0.1804375],
                     [0.2126729, 0.7151522, 0.0721750],
                     [0.0193339, 0.1191920, 0.9503041]])
_WHITE = _RGB2XYZ.sum(axis=1)  # D65, Y = 1


def rgb_to_luv(rgb):
    """CIE L*u*v* of linear RGB (sRGB primaries, D65), clamped to [0, 1] first.

    Parameters
    ----------
    rgb : (..., 3) array_like
        Linear RGB; NaN counts as 0.

    Returns
    -------
    (..., 3) float64
        ``L`` in [0, 100]; black has ``u = v = 0``.

    References
    ----------
    CIE 15:2004 (CIE 1976 L*u*v*); Tipprasert (2006), §2.7 (eq. 2-9).
    """
    c = np.clip(np.nan_to_num(np.asarray(rgb, dtype=np.float64)), 0.0, 1.0)
    xyz = affine(c, _RGB2XYZ.T)
    X, Y, Z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    yr = Y / _WHITE[1]
    L = np.where(yr > (6 / 29) ** 3, 116.0 * np.cbrt(yr) - 16.0, (29 / 3) ** 3 * yr)
    den = X + 15 * Y + 3 * Z
    dn = _WHITE[0] + 15 * _WHITE[1] + 3 * _WHITE[2]
    un, vn = 4 * _WHITE[0] / dn, 9 * _WHITE[1] / dn
    with np.errstate(invalid="ignore", divide="ignore"):
        up = np.where(den > 0, 4 * X / den, un)
        vp = np.where(den > 0, 9 * Y / den, vn)
    return np.stack([L, 13 * L * (up - un), 13 * L * (vp - vn)], axis=-1)


def luv_difference(img1, img2, mask=None):
    """Average intensity difference of two images over the object pixels (eq. 2-9).

    Parameters
    ----------
    img1, img2 : (H, W, 3) array_like
        Linear RGB.
    mask : (H, W) bool, optional
        The object pixels; all pixels by default.

    Returns
    -------
    float
        Mean Euclidean distance in CIE L*u*v*, 0 for identical images; 0
        when the mask is empty.

    References
    ----------
    Tipprasert (2006), §2.7 (eq. 2-9), Table 5-5.
    """
    d = np.linalg.norm(rgb_to_luv(img1) - rgb_to_luv(img2), axis=-1)
    if mask is not None:
        d = d[np.asarray(mask, bool)]
    return float(d.mean()) if d.size else 0.0


def relative_l1(test, ref, mask=None, blur=1.0):
    """Relative L1 error ``sum |A - B| / sum |B|`` after blurring both by ``blur`` texels.

    Parameters
    ----------
    test, ref : (H, W) array_like
        Caustic maps.
    mask : (H, W) bool, optional
        Texels to compare (e.g. the receiver's own texels); both maps are
        zeroed outside it before blurring.
    blur : float
        Standard deviation of the Gaussian blur in texels (0: none).

    Returns
    -------
    float
        The relative L1 error; when ``ref`` is zero everywhere, 0 if ``test``
        is too and 1 otherwise.

    Notes
    -----
    The blur is SciPy's ``gaussian_filter(.., mode="constant")``, computed by
    :func:`refraction_ref.filters.gaussian_filter_zero` (a parallel kernel with
    SciPy's operations in SciPy's order: the same bits whatever the thread
    count); the sums are NumPy's.
    """
    a = np.nan_to_num(np.asarray(test, dtype=np.float64))
    b = np.nan_to_num(np.asarray(ref, dtype=np.float64))
    if mask is not None:
        m = np.asarray(mask, bool)
        a, b = np.where(m, a, 0.0), np.where(m, b, 0.0)
    if blur > 0:
        if a.ndim == 2 and b.ndim == 2:
            a, b = gaussian_filter_zero(a, blur), gaussian_filter_zero(b, blur)
        else:
            from scipy.ndimage import gaussian_filter

            a, b = gaussian_filter(a, blur, mode="constant"), gaussian_filter(b, blur, mode="constant")
    if mask is not None:
        a, b = a[m], b[m]
    if a.ndim == 2 and a.shape == b.shape and a.dtype == b.dtype == np.float64:
        # |a - b|, |b| and |a| on every thread; their sums NumPy's (pairwise, in its order)
        d, ab, aa = np.empty(a.shape), np.empty(a.shape), np.empty(a.shape)
        _abs_kernel(np.ascontiguousarray(a), np.ascontiguousarray(b), d, ab, aa)
        den = ab.sum()
        return float(d.sum() / den) if den > 0 else float(aa.sum() > 0)
    den = np.abs(b).sum()
    return float(np.abs(a - b).sum() / den) if den > 0 else float(np.abs(a).sum() > 0)


@nb.njit(cache=True, parallel=True)
def _abs_kernel(a, b, d, ab, aa):
    for i0 in nb.prange(a.shape[0]):
        i = np.int64(i0)
        for j in range(a.shape[1]):
            d[i, j] = abs(a[i, j] - b[i, j])
            ab[i, j] = abs(b[i, j])
            aa[i, j] = abs(a[i, j])
