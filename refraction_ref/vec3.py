"""Products of many 3-vectors with one small matrix or vector, without BLAS.

``points @ M`` on an (N, 3) array goes to the BLAS library NumPy was built
with. Two reasons keep the oracle off it:

* **Speed.** OpenBLAS starts its own worker threads for a large product and
  lets them spin after it returns; they then take the cores Numba's parallel
  kernels need. On the 2-core CI machine one such product before the
  caustics' final pass made every later parallel stage of the render run on
  one core (the whole caustics render 0.88x with 2 threads against 1; 1.48x
  with these kernels).
* **Bits.** BLAS picks its kernel by CPU (``DYNAMIC_ARCH``), with or without
  fused multiply-adds, so ``p @ M`` may differ in the last bit between
  machines. These kernels sum ``x m0 + y m1 + z m2`` in that order,
  unfused, on every machine and thread count.

Kernels are parallel over the rows.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["affine", "dot", "readonly"]


def readonly(a):
    """A read-only view of ``a`` (no copy), for a kernel's input arrays.

    Numba compiles one version per argument type, and a read-only array (the
    mesh cache freezes its arrays) is another type than a writable one: passing
    every input as read-only gives each kernel one signature, not two.

    Parameters
    ----------
    a : ndarray
        Any array; it is not modified.

    Returns
    -------
    ndarray
        A view of ``a`` with the writeable flag cleared.
    """
    a = a.view()
    a.flags.writeable = False
    return a


@nb.njit(cache=True, parallel=True)
def _affine_kernel(p, m, t, out):
    for k in nb.prange(p.shape[0]):
        x, y, z = p[k, 0], p[k, 1], p[k, 2]
        for c in range(m.shape[1]):
            out[k, c] = x * m[0, c] + y * m[1, c] + z * m[2, c] + t[c]


@nb.njit(cache=True, parallel=True)
def _dot_kernel(p, v, out):
    for k in nb.prange(p.shape[0]):
        out[k] = p[k, 0] * v[0] + p[k, 1] * v[1] + p[k, 2] * v[2]


def affine(p, m, t=None):
    """``p @ m + t`` for points ``p`` (..., 3), ``m`` (3, C), ``t`` (C,) (default 0).

    Parameters
    ----------
    p : (..., 3) array_like
        Points (or vectors), converted to float64.
    m : (3, C) array_like
        Matrix applied on the right; each output column is
        ``x m[0, c] + y m[1, c] + z m[2, c]`` summed in that order.
    t : (C,) array_like, optional
        Offset added last; zero when None.

    Returns
    -------
    ndarray (..., C) float64
    """
    p = np.asarray(p, dtype=np.float64)
    m = np.ascontiguousarray(m, dtype=np.float64)
    if p.shape[-1] != 3 or m.ndim != 2 or m.shape[0] != 3:
        raise ValueError(f"affine: p (..., 3) and m (3, C) expected, got {p.shape} and {m.shape}")
    t = np.zeros(m.shape[1]) if t is None else np.ascontiguousarray(np.broadcast_to(t, (m.shape[1],)),
                                                                      dtype=np.float64)
    flat = np.ascontiguousarray(p).reshape(-1, 3)
    out = np.empty((len(flat), m.shape[1]))
    _affine_kernel(readonly(flat), readonly(m), readonly(t), out)  # one signature (see readonly)
    return out.reshape(p.shape[:-1] + (m.shape[1],))


def dot(p, v):
    """``p @ v`` for vectors ``p`` (..., 3) and one vector ``v`` (3,).

    Parameters
    ----------
    p : (..., 3) array_like
        Vectors, converted to float64.
    v : (3,) array_like
        The one vector; each result is ``x v0 + y v1 + z v2`` in that order.

    Returns
    -------
    ndarray (...) float64
    """
    p = np.asarray(p, dtype=np.float64)
    v = np.ascontiguousarray(v, dtype=np.float64).reshape(3)
    if p.shape[-1] != 3:
        raise ValueError(f"dot: p (..., 3) expected, got {p.shape}")
    flat = np.ascontiguousarray(p).reshape(-1, 3)
    out = np.empty(len(flat))
    _dot_kernel(readonly(flat), readonly(v), out)
    return out.reshape(p.shape[:-1])
