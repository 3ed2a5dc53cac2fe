"""Small Numba helpers every method's kernels share: one home for each, so none is copied.

* :func:`dot3` and :func:`unit3`, inlined into the kernels that call them;
* :func:`take_rows`, :func:`put_rows` and :func:`copy_rows`: ``a[idx]``,
  ``a[idx] = vals`` and ``out[at:at + n] = src`` on (N, C) arrays, parallel
  over rows (NumPy's fancy indexing runs on one thread); :func:`take_values`,
  ``out[:] = a[idx]`` of a 1-D array.

Each returns exactly what the NumPy expression it stands for returns (the same
bits): the row helpers copy, and :func:`dot3` sums in the order NumPy's
``einsum('ij,ij->i')`` does, so kernels that replaced an ``einsum`` keep its
results.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["dot3", "unit3", "take_rows", "take_values", "put_rows", "copy_rows"]


@nb.njit(cache=True, inline="always")
def dot3(ax, ay, az, bx, by, bz):
    """``a . b`` of two 3-vectors, summed as ``(ax bx + az bz) + ay by``.

    That is the order in which NumPy's ``einsum('ij,ij->i')`` sums a row
    (measured, NumPy 2.x on x86-64), so a kernel that replaced an ``einsum``
    keeps its bits.

    Parameters
    ----------
    ax, ay, az, bx, by, bz : float

    Returns
    -------
    float
    """
    return (ax * bx + az * bz) + ay * by


@nb.njit(cache=True, inline="always")
def unit3(x, y, z):
    """``v / |v|`` of a 3-vector, its length as ``sqrt(x x + y y + z z)`` (a zero vector gives NaN).

    Parameters
    ----------
    x, y, z : float

    Returns
    -------
    tuple of float
    """
    n = np.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


@nb.njit(cache=True, parallel=True)
def _take_rows_kernel(a, idx, out):
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        for c in range(a.shape[1]):
            out[k, c] = a[idx[k], c]


def take_rows(a, idx):
    """``a[idx]`` of an (N, C) float64 array, on every thread.

    Parameters
    ----------
    a : (N, C) array_like
    idx : (M,) array_like of int
        Rows to take, in order.

    Returns
    -------
    (M, C) float64
    """
    a = np.ascontiguousarray(a, dtype=np.float64)
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    out = np.empty((idx.shape[0], a.shape[1]), np.float64)
    _take_rows_kernel(a, idx, out)
    return out


@nb.njit(cache=True, parallel=True)
def take_values(a, idx, out):
    """``out[:] = a[idx]`` of a 1-D array, on every thread.

    Parameters
    ----------
    a : (N,) array
    idx : (M,) int64
        Entries to take, in order.
    out : (M,) array
        Written in place (``a``'s values cast to its dtype).
    """
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        out[k] = a[idx[k]]


@nb.njit(cache=True, parallel=True)
def _put_rows_kernel(a, idx, vals):
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        i = idx[k]
        for c in range(a.shape[1]):
            a[i, c] = vals[k, c]


def put_rows(a, idx, vals):
    """``a[idx] = vals`` (rows of an (N, C) float64 array), on every thread.

    Parameters
    ----------
    a : (N, C) float64
        Written in place.
    idx : (M,) array_like of int
        Distinct rows (a repeated row would be written by two threads).
    vals : (M, C) array_like

    Returns
    -------
    (N, C) float64
        ``a``.
    """
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    vals = np.ascontiguousarray(vals, dtype=np.float64)
    _put_rows_kernel(a, idx, vals)
    return a


@nb.njit(cache=True, parallel=True)
def _copy_rows_kernel(src, out, at):
    for k0 in nb.prange(src.shape[0]):
        k = np.int64(k0)
        for c in range(src.shape[1]):
            out[at + k, c] = src[k, c]


def copy_rows(src, out, at=0):
    """``out[at:at + len(src)] = src`` for (N, C) arrays, on every thread.

    Parameters
    ----------
    src : (N, C) array
        Any strides; cast to ``out``'s dtype as NumPy's assignment casts.
    out : (M, C) array
        Written in place, rows ``at`` to ``at + N - 1``.
    at : int
        First row of ``out`` written.

    Returns
    -------
    (M, C) array
        ``out``.
    """
    _copy_rows_kernel(src, out, np.int64(at))
    return out
