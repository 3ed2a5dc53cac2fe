"""Shared test helpers."""

from __future__ import annotations

import os

import numba
import numpy as np
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


def _same_arrays(a, b, keys=None):
    """Arrays of ``a`` and ``b`` equal bit for bit (dtype, shape, NaN where NaN): the keys ``keys``, or
    every key, when the two hold the same keys."""
    if keys is None:
        assert sorted(a) == sorted(b)
        keys = a
    for k in keys:
        x, y = np.asarray(a[k]), np.asarray(b[k])
        assert x.dtype == y.dtype and x.shape == y.shape, k
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), k


@pytest.fixture
def same_arrays():
    """Assert two dicts of arrays equal bit for bit (determinism and before/after tests)."""
    return _same_arrays


#: the test folders that mirror the package, each with its marker (``pytest -m volumetric``
#: runs one method's tests alone; ``pytest tests/volumetric`` does the same by folder)
FOLDER_MARKERS = ("imagespace", "caustics", "volumetric", "levelmap", "exact", "golden", "interop",
                  "tables", "backends")


def pytest_collection_modifyitems(config, items):
    here = os.path.dirname(os.path.abspath(__file__))
    for item in items:
        rel = os.path.relpath(str(item.path), here)
        folder = rel.split(os.sep)[0]
        if folder in FOLDER_MARKERS:
            item.add_marker(getattr(pytest.mark, folder))
