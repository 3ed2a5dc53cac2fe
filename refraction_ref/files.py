"""Atomic writes: every file the package writes appears complete or not at all.

A run killed while saving must not leave a truncated ``.npz`` that later
runs refuse to overwrite and readers fail on. So every writer (renders,
plots, CSV and JSON tables, golden suites, reports) writes to a temporary
name in the destination folder and renames it into place when complete
(:func:`os.replace` is atomic within one file system).
"""

from __future__ import annotations

import contextlib
import os

__all__ = ["atomic_path", "atomic_open", "savefig_atomic"]


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` (same extension); rename it to ``path`` on success.

    On an exception the temporary file is removed and ``path`` is untouched.

    Examples
    --------
    >>> with atomic_path("out/plot.png") as tmp:   # doctest: +SKIP
    ...     fig.savefig(tmp)
    """
    path = os.fspath(path)
    folder, name = os.path.split(path)
    if folder:
        os.makedirs(folder, exist_ok=True)
    stem, ext = os.path.splitext(name)
    tmp = os.path.join(folder, f".{stem}.tmp{os.getpid()}{ext}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


@contextlib.contextmanager
def atomic_open(path, mode="w", **kwargs):
    """:func:`open` for writing, atomically (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        with open(tmp, mode, **kwargs) as f:
            yield f


def savefig_atomic(fig, path, **kwargs):
    """``fig.savefig(path, **kwargs)``, atomically; returns ``path``."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, **kwargs)
    return path
