"""Run results: the output half of ``docs/oracle.md`` (one ``.npz`` plus a PNG)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from .files import NotNpzError, OutputError, atomic_path, check_out_file, load_npz

__all__ = ["Result", "tonemap", "load_result", "output_paths", "check_writable"]


def tonemap(image):
    """Clamp linear RGB to [0, 1] and apply the sRGB transfer curve; uint8 (H, W, 3).

    Parameters
    ----------
    image : (H, W, 3) array_like
        Linear RGB radiance; NaN is shown black.

    Returns
    -------
    (H, W, 3) uint8 ndarray
        sRGB-encoded 8-bit image.

    References
    ----------
    .. [1] IEC 61966-2-1:1999, Multimedia systems and equipment - Colour
       measurement and management - Default RGB colour space - sRGB (the
       transfer function).
    """
    x = np.clip(np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0), 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return np.round(s * 255.0).astype(np.uint8)


@dataclass
class Result:
    """Arrays with the docs/oracle.md names plus ``meta`` (scene, parameters, timings, plan)."""

    arrays: dict
    meta: dict = field(default_factory=dict)

    def __getitem__(self, k):
        return self.arrays[k]

    def save(self, prefix, overwrite=False, png=True):
        """Write ``PREFIX.npz`` (arrays + ``meta`` as a JSON string) and ``PREFIX.png``.

        Refuses to overwrite existing files unless ``overwrite`` is true.
        Each file is written under a temporary name and renamed into place
        when complete, so an interrupted save leaves no partial file.
        Returns the paths written.

        Parameters
        ----------
        prefix : str or os.PathLike
            Output prefix; a trailing ``.npz`` is dropped.
        overwrite : bool
            Replace existing files.
        png : bool
            Also write the tone-mapped ``image`` array as a PNG (when there is one).

        Returns
        -------
        list of str
            ``[PREFIX.npz]`` or ``[PREFIX.npz, PREFIX.png]``.

        Raises
        ------
        FileExistsError
            An output exists and ``overwrite`` is false.
        OutputError
            An output that cannot be written.
        """
        paths = output_paths(prefix, png and "image" in self.arrays)
        check_writable(paths, overwrite)
        with atomic_path(paths[0]) as tmp:
            np.savez_compressed(tmp, meta=np.array(json.dumps(self.meta, default=_json_default)), **self.arrays)
        if len(paths) > 1:
            import imageio.v3 as iio

            with atomic_path(paths[1]) as tmp:
                iio.imwrite(tmp, tonemap(self.arrays["image"]))
        return paths


def output_paths(prefix, png=True):
    """The files :meth:`Result.save` writes for ``prefix``: ``PREFIX.npz`` (and ``PREFIX.png``).

    Parameters
    ----------
    prefix
        As :meth:`Result.save`.
    png : bool
        Include the PNG.

    Returns
    -------
    list of str

    Raises
    ------
    OutputError
        An empty prefix or one without a file name.
    """
    prefix = os.fspath(prefix)
    if prefix.endswith(".npz"):
        prefix = prefix[:-4]
    name = os.path.basename(prefix)
    if not prefix.strip():
        raise OutputError("the output prefix (--out) is empty; give one such as out/render "
                          "(writes out/render.npz and out/render.png)")
    if name in ("", ".", ".."):
        raise OutputError(f"the output prefix (--out) '{prefix}' has no file name"
                          f"{' (it ends in a folder separator)' if not name else ''}; give a prefix such as "
                          f"{os.path.join(os.path.dirname(prefix), 'render')} (writes render.npz and render.png)")
    return [prefix + ".npz"] + ([prefix + ".png"] if png else [])


def check_writable(paths, overwrite=False, cli=False):
    """Refuse, before any work, outputs that cannot be written (:class:`~refraction_ref.files.OutputError`: a
    folder that is a file or not writable) or that exist, unless ``overwrite`` (``FileExistsError``).
    Nothing is left on disk.

    Parameters
    ----------
    paths : iterable of str
        Output files (:func:`output_paths`).
    overwrite : bool
        Existing files may be replaced.
    cli : bool
        Word the message for the command line (``--out``, ``--force``) rather than for Python.

    Returns
    -------
    None
    """
    for p in paths:
        if not overwrite and os.path.exists(p):
            raise FileExistsError(f"'{p}' exists; choose another {'--out prefix' if cli else 'prefix'} or "
                                  f"{'pass --force to replace it' if cli else 'pass overwrite=True'}")
        check_out_file(p, "the output")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def load_result(path):
    """Read a ``.npz`` written by :meth:`Result.save`.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.npz`` file.

    Returns
    -------
    Result
        Every array but ``meta``, and ``meta`` decoded from JSON (empty when absent).

    Raises
    ------
    NotNpzError
        A file that is not a ``.npz``.
    FileNotFoundError
        No such file.
    """

    path = os.fspath(path)
    with load_npz(path) as z:  # a PNG or a text file: NotNpzError naming it, not NumPy's pickle advice
        arrays = {}
        for k in z.files:
            try:
                arrays[k] = z[k]
            except Exception as e:  # noqa: BLE001 - object arrays (pickles), a broken zip member
                why = ("an object array, which is read only by unpickling" if "pickle" in str(e)
                       else f"{type(e).__name__}: {str(e)[:60]}")
                raise NotNpzError(f"{path}: the array '{k}' cannot be read ({why}); write plain numeric arrays "
                                  "(numpy.savez) and meta as a JSON string") from None
    meta = {}
    if "meta" in arrays:
        m = arrays.pop("meta")
        try:
            meta = json.loads(str(m)) if m.dtype.kind in "US" and m.ndim == 0 else None
        except ValueError:
            meta = None
        if not isinstance(meta, dict):
            raise NotNpzError(f"{path}: its 'meta' is not a JSON object (a {m.dtype} array of shape {m.shape}); "
                              "write meta as numpy.array(json.dumps(meta)), or leave it out")
    return Result(arrays, meta)
