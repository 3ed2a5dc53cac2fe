"""The order in which ``prange`` loops visit image rows (or bands of rows).

Numba splits a ``prange`` into one contiguous block of iterations per
thread. An object rarely fills the image evenly from top to bottom (the
default bunny has twice as many fragments in the lower half as in the
upper), so contiguous blocks of rows give one thread most of the work.
Visiting the rows in a stride order instead - task ``k`` takes row
``k * s mod n`` with ``s`` coprime to ``n`` - spreads every thread's rows
over the whole image. The result does not depend on the order: each task
writes only its own rows.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["coprime_stride", "strided"]


@nb.njit(cache=True)
def coprime_stride(n):
    """A stride coprime with ``n`` (a small prime that does not divide it), so that
    ``k * s mod n`` for ``k = 0 .. n-1`` visits every index once.

    Parameters
    ----------
    n : int
        Number of tasks (rows or bands), > 0.

    Returns
    -------
    int
        The first of the primes 7 .. 47 that does not divide ``n``; 1 when all do.
    """
    for p in (7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47):
        if n % p != 0:
            return p
    return 1


@nb.njit(cache=True, inline="always")
def strided(k, s, n):
    """The index task ``k`` works on (``s = coprime_stride(n)``), as a signed integer.

    Parameters
    ----------
    k : int
        Task number, ``0 <= k < n`` (the ``prange`` index).
    s : int
        Stride from :func:`coprime_stride`.
    n : int
        Number of tasks.

    Returns
    -------
    int64
        ``k * s mod n``.
    """
    return (np.int64(k) * s) % n
