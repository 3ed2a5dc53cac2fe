"""Shared test helpers."""

from __future__ import annotations

import numba
import pytest


def _on_one_and_two_threads(fn):
    """``(fn() with 1 Numba thread, fn() with 2)``; the thread count is restored afterwards."""
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = fn()
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        b = fn()
    finally:
        numba.set_num_threads(before)
    return a, b


@pytest.fixture
def on_one_and_two_threads():
    """Run a callable with 1 and with 2 Numba threads: determinism tests compare the two results."""
    return _on_one_and_two_threads
