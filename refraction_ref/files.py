"""Atomic writes: every file the package writes appears complete or not at all.

A run killed while saving must not leave a truncated ``.npz`` that later
runs refuse to overwrite and readers fail on. So every writer (renders,
plots, CSV and JSON tables, golden suites, reports) writes to a temporary
name in the destination folder and renames it into place when complete
(:func:`os.replace` is atomic within one file system).
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile

__all__ = ["atomic_path", "atomic_open", "savefig_atomic", "OutputError", "check_out_file", "check_out_folder",
           "NotNpzError", "load_npz", "file_kind"]


class OutputError(ValueError):
    """An output path that cannot be written, found before any work (the message names it and the fix)."""


def _missing_folders(folder):
    """The folders :func:`os.makedirs` would create for ``folder``, outermost first; raises OutputError when a
    part of the path is a file."""
    missing = []
    f = os.path.abspath(folder)
    while not os.path.exists(f):
        missing.append(f)
        parent = os.path.dirname(f)
        if parent == f:
            break
        f = parent
    if not os.path.isdir(f):
        raise OutputError(f"cannot write under '{folder}': '{f}' is a file, not a folder; choose another path")
    return missing[::-1]


def _probe_folder(folder, what):
    """Check that files can be created in ``folder`` by creating (and removing) one, and the missing folders
    on the way; leaves nothing behind."""
    missing = _missing_folders(folder or ".")
    made = []
    try:
        for m in missing:
            os.mkdir(m)
            made.append(m)
        fd, probe = tempfile.mkstemp(prefix=".probe", dir=folder or ".")
        os.close(fd)
        os.remove(probe)
    except OSError as e:
        f = folder or "."
        if os.path.isdir(f) and not made and e.errno in (errno.ENOENT, errno.EROFS, errno.EACCES, errno.EPERM):
            # the folder exists (/proc, /sys, a read-only mount): "No such file or directory" alone misleads
            why = ("read-only" if e.errno == errno.EROFS else "no permission" if e.errno in (errno.EACCES, errno.EPERM)
                   else "it is a virtual or special file system, such as /proc or /sys")
            raise OutputError(f"cannot create files for {what} in '{f}': the folder exists but new files cannot be "
                              f"made there ({why}); choose a folder you can write to") from None
        raise OutputError(f"cannot write {what} in '{f}' ({e.strerror or e}); choose a folder you "
                          "can write to") from None
    finally:
        for m in reversed(made):
            with contextlib.suppress(OSError):
                os.rmdir(m)


def check_out_file(path, what="the output"):
    """Refuse, before any work, a file path that cannot be written (:class:`OutputError`).

    Refused: an empty path, a path ending in a folder separator or naming an existing folder, a hidden or
    extension-only file name (``out/.npz``), a folder that is a file or where files cannot be created.
    Nothing is left on disk.

    Parameters
    ----------
    path : str or os.PathLike
        The output file (or file prefix) to check.
    what : str
        What the path is, for the message.

    Returns
    -------
    None

    Raises
    ------
    OutputError
        Naming the path and the fix.
    """
    path = os.fspath(path)
    folder, name = os.path.split(path)
    stem = os.path.splitext(name)[0]
    if not path.strip():
        raise OutputError(f"{what} path is empty; give a path such as out/render")
    if not name or os.path.isdir(path):
        raise OutputError(f"{what} '{path}' is a folder; give a file prefix inside it, e.g. "
                          f"{os.path.join(path, 'render')}")
    if stem in ("", ".", ".."):
        raise OutputError(f"{what} '{path}' has no file name; give one such as {os.path.join(folder, 'render')}")
    _check_name_length(path, what)
    _probe_folder(folder, what)


#: Characters :func:`atomic_path` adds to a file name for its temporary file (``.NAME.tmpPID``).
_TMP_EXTRA = len(".") + len(".tmp") + 10


def _name_max(folder):
    """The longest file name the file system of ``folder`` (or its nearest existing parent) takes."""
    f = os.path.abspath(folder or ".")
    while not os.path.exists(f) and os.path.dirname(f) != f:
        f = os.path.dirname(f)
    try:
        return os.pathconf(f, "PC_NAME_MAX"), os.pathconf(f, "PC_PATH_MAX")
    except (OSError, ValueError, AttributeError):  # no pathconf (Windows) or no answer: the common limits
        return 255, 4096


def _check_name_length(path, what):
    """Refuse a file name (or a folder name on the way) longer than the file system takes, counting the
    temporary name the atomic write uses, so that the failure comes before the work and not when saving."""
    folder, name = os.path.split(path)
    name_max, path_max = _name_max(folder)
    for part in [p for p in os.path.normpath(folder).split(os.sep) if p] if folder else []:
        if len(part.encode("utf-8", "surrogateescape")) > name_max:
            raise OutputError(f"{what} '{path[:60]}...': the folder name '{part[:40]}...' has {len(part)} "
                              f"characters, more than the {name_max} this file system takes; shorten it")
    n = len(name.encode("utf-8", "surrogateescape")) + _TMP_EXTRA
    if n > name_max:
        raise OutputError(f"{what} file name '{name[:40]}...' has {len(name)} characters; this file system takes "
                          f"{name_max} (with the {_TMP_EXTRA} of the temporary name written first, at most "
                          f"{name_max - _TMP_EXTRA}); give a shorter --out")
    if len(os.path.abspath(path).encode("utf-8", "surrogateescape")) + _TMP_EXTRA > path_max:
        raise OutputError(f"{what} path has {len(os.path.abspath(path))} characters; this file system takes at "
                          f"most {path_max - _TMP_EXTRA}; give a shorter --out")


def check_out_folder(path, what="the output folder"):
    """Refuse, before any work, a folder that cannot hold our outputs (:class:`OutputError`): an empty path,
    an existing file, or a place where files cannot be created. Nothing is left on disk.

    Parameters
    ----------
    path : str or os.PathLike
        The output folder (it may not exist yet).
    what : str
        What the folder is, for the message.

    Raises
    ------
    OutputError
        Naming the folder and the fix.
    """
    path = os.fspath(path)
    if not path.strip():
        raise OutputError(f"{what} is empty; give a folder such as out/golden")
    if os.path.exists(path) and not os.path.isdir(path):
        raise OutputError(f"{what} '{path}' is a file, not a folder; give a new or existing folder")
    _probe_folder(path, what)


class NotNpzError(ValueError):
    """A file given as a ``.npz`` result that is not one (a PNG, a text file, a truncated file)."""


def load_npz(path, what="result"):
    """``numpy.load(path, allow_pickle=False)`` for a ``.npz``, or :class:`NotNpzError` naming the file.

    NumPy reads any non-zip file as a pickle and, refused one, says "load it unsafely"; a user who
    gave the wrong file should instead hear that it is not a ``.npz`` and what it looks like.
    A missing file raises :class:`FileNotFoundError` with the path.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.npz`` file.
    what : str
        What the file should be, for the messages (``"result"``).

    Returns
    -------
    numpy.lib.npyio.NpzFile
        Use as a context manager.

    Raises
    ------
    NotNpzError
        A folder, a file that is not a zip archive, or an unreadable archive.
    FileNotFoundError
        No such file.
    """
    import zipfile

    import numpy as np

    path = os.fspath(path)
    if os.path.isdir(path):
        raise NotNpzError(f"{path} is a folder, not a .npz {what}")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{what} file '{path}' does not exist")
    if not zipfile.is_zipfile(path):
        raise NotNpzError(f"{path} is not a .npz {what} ({file_kind(path)}); give a .npz written by "
                          "refraction-ref render or by a backend (numpy.savez)")
    try:
        z = np.load(path, allow_pickle=False)
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as e:
        raise NotNpzError(f"{path} is not a readable .npz {what} ({type(e).__name__}: {e})") from None
    return z


def file_kind(path):
    """A few words on what a file is, from its first bytes.

    Parameters
    ----------
    path : str or os.PathLike
        An existing, readable file (its first 512 bytes are read).

    Returns
    -------
    str
        E.g. ``"a PNG image"``, ``"an empty file"``, ``"a text file, JSON"``.
    """
    with open(path, "rb") as f:
        head = f.read(512)
    for magic, kind in ((b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"#?RADIANCE", "an HDR image"),
                        (b"\x93NUMPY", "a .npy array"), (b"PK\x03\x04", "a zip archive"), (b"\x80", "a pickle"),
                        (b"ply", "a PLY mesh")):
        if head.startswith(magic):
            return kind
    if not head:
        return "an empty file"
    try:
        head.decode("utf-8")
    except UnicodeDecodeError:
        return f"{os.path.getsize(path)} bytes of binary data"
    return "a text file" + (", JSON" if head.lstrip()[:1] in (b"{", b"[") else "")


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` (same extension); rename it to ``path`` on success.

    On an exception the temporary file is removed, and so are the folders this call created,
    and ``path`` is untouched.

    Parameters
    ----------
    path : str or os.PathLike
        The final file; its folder is created when missing.

    Yields
    ------
    str
        The temporary path (hidden, in the same folder) to write to.

    Examples
    --------
    >>> with atomic_path("out/plot.png") as tmp:   # doctest: +SKIP
    ...     fig.savefig(tmp)
    """
    path = os.fspath(path)
    folder, name = os.path.split(path)
    made = _missing_folders(folder) if folder else []
    if folder:
        os.makedirs(folder, exist_ok=True)
    stem, ext = os.path.splitext(name)
    tmp = os.path.join(folder, f".{stem}.tmp{os.getpid()}{ext}")
    ok = False
    try:
        yield tmp
        os.replace(tmp, path)
        ok = True
    finally:
        for t in (tmp, tmp + ".npz"):  # numpy.savez adds .npz to a name without it
            if os.path.exists(t):
                os.remove(t)
        if not ok:
            for m in reversed(made):
                with contextlib.suppress(OSError):
                    os.rmdir(m)  # only if empty


@contextlib.contextmanager
def atomic_open(path, mode="w", **kwargs):
    """:func:`open` for writing, atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : str or os.PathLike
        The final file.
    mode : str
        Mode for :func:`open` (a writing mode, ``"w"`` or ``"wb"``).
    **kwargs
        Passed to :func:`open` (``encoding``, ``newline``).

    Yields
    ------
    file object
        Open on the temporary file; renamed to ``path`` after the block.
    """
    with atomic_path(path) as tmp:
        with open(tmp, mode, **kwargs) as f:
            yield f


def savefig_atomic(fig, path, **kwargs):
    """``fig.savefig(path, **kwargs)``, atomically; returns ``path``.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure to save.
    path : str or os.PathLike
        The image file; the format follows its extension.
    **kwargs
        Passed to ``fig.savefig`` (``dpi``, ``bbox_inches``).

    Returns
    -------
    str or os.PathLike
        ``path``.
    """
    with atomic_path(path) as tmp:
        fig.savefig(tmp, **kwargs)
    return path
