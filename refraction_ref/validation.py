"""The scene's error type and value checks: the bottom of the package, imported by every knob block.

Every check raises :class:`SceneError` with a message that names the key
(``where``), the value given and what to give instead. Knob blocks
(``<method>/knobs.py``), lights, meshes and the scene loader import these
checks; this module imports nothing of the package, so no module needs the
scene loader (or a method) to validate its own keys.
"""

from __future__ import annotations

import copy
import json
import math

import numpy as np

__all__ = ["SceneError", "check_number", "check_vector", "check_dict", "merge_defaults", "show", "LIMIT",
           "INT_LIMIT", "MAX_DEPTH", "check_depth", "printable"]

#: The largest magnitude of a scene number that has no range of its own (positions, sizes, radiances,
#: intensities, amplitudes): beyond it the float32 buffers and the products of the shading (radiance x
#: photon density, eye distance squared) overflow or lose every digit, so it is refused, not rendered.
LIMIT = 1e6
#: The largest whole number without a range of its own (seeds, counts): the kernels take int32.
INT_LIMIT = 2**31 - 1
#: The deepest nesting of lists and objects a scene may have (a real scene nests five levels).
MAX_DEPTH = 32


class SceneError(ValueError):
    """A scene that cannot be rendered, with a message saying what to change."""


def show(x, n=60):
    """``x`` as JSON (``true``, ``null``, ``"abc"``: as the user typed it in a scene file or ``--set``), cut to
    ``n`` characters, so that a 5,000-digit number stays a one-line message; ``repr`` for what JSON cannot hold."""
    try:
        r = json.dumps(x, allow_nan=True)
    except (TypeError, ValueError, RecursionError):
        try:
            r = repr(x)
        except ValueError:  # an int beyond Python's int-string limit
            return "a number of more than 4,300 digits"
    if len(r) > 4300 and isinstance(x, int) and not isinstance(x, bool):
        return "a number of more than 4,300 digits"
    return r if len(r) <= n else r[: n - 4] + " ..."


def printable(text):
    """``text`` with every non-printable character (a newline, a carriage return) escaped: one line."""
    return "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in str(text))


def check_depth(x, where="scene", limit=MAX_DEPTH):
    """Refuse lists and objects nested deeper than ``limit`` (walked without recursion).

    Parameters
    ----------
    x : object
        A parsed JSON value.
    where : str
        What it is, for the message.
    limit : int
        The deepest nesting allowed.

    Returns
    -------
    object
        ``x``, unchanged.
    """
    stack = [(x, 1)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, (dict, list, tuple)):
            if d > limit:
                raise SceneError(f"{where} nests lists or objects {limit + 1} or more levels deep; a scene needs "
                                 "at most a few levels: fix the brackets")
            stack.extend((c, d + 1) for c in (v.values() if isinstance(v, dict) else v))
    return x


def check_dict(x, where, nullable=False):
    """``x`` if it is an object (a dict), else a :class:`SceneError` naming ``where``.

    Parameters
    ----------
    x : object
        The value given.
    where : str
        Its dotted key, for the message.
    nullable : bool
        None is allowed (and returned).

    Returns
    -------
    dict or None
    """
    if x is None and nullable:
        return x
    if not isinstance(x, dict):
        got = "null" if x is None else type(x).__name__
        tail = "give one object per item" if where.endswith("]") else "give an object or leave the key out for its defaults"
        raise SceneError(f"scene: '{where}' must be an object (a JSON dict), got {got}; {tail}")
    return x


def merge_defaults(default, given, path):
    """Merge ``given`` over ``default``; unknown keys are errors naming the key.

    Parameters
    ----------
    default : dict or None
        The block's defaults; a nested dict is merged key by key, anything
        else (None, an empty dict, a list) is replaced by ``given`` whole.
    given : dict or None
        The block as the scene gives it; None keeps the defaults.
    path : str
        The block's dotted key, for messages (``"levelmap"``, ``""`` for the top).

    Returns
    -------
    dict
        A deep copy: neither input is modified.
    """
    if default is None or not isinstance(default, dict) or not default:
        return copy.deepcopy(given)
    if given is None:
        return copy.deepcopy(default)
    if not isinstance(given, dict):
        raise SceneError(f"scene: '{path}' must be an object (a JSON dict), got {type(given).__name__}")
    out = copy.deepcopy(default)
    for k, v in given.items():
        if k not in default:
            name = f"{path}.{k}" if path else k
            raise SceneError(f"scene: unknown key '{name}'; known keys here: {', '.join(sorted(default))}")
        sub = default[k]
        if isinstance(sub, dict) and sub and v is None:  # null is not "the defaults": say so, not a TypeError
            name = f"{path}.{k}" if path else k
            raise SceneError(f"scene: '{name}' is null; give an object (or leave the key out for its defaults)")
        if isinstance(sub, dict) and sub and v is not None:
            out[k] = merge_defaults(sub, v, f"{path}.{k}" if path else k)
        else:
            out[k] = copy.deepcopy(v)
    return out


def check_vector(x, n, where, finite=True, limit=LIMIT):
    """``x`` as a float64 vector of ``n`` numbers, or a :class:`SceneError` naming ``where``.

    Parameters
    ----------
    x : sequence of float
        The value given.
    n : int
        The length it must have.
    where : str
        Its dotted key, for the message.
    finite : bool
        Refuse NaN and infinite components.
    limit : float or None
        Refuse components of magnitude above it (:data:`LIMIT`; None for no bound).

    Returns
    -------
    ndarray, shape (n,), float64
    """
    items = x if isinstance(x, (list, tuple)) else None
    if items is None or len(items) != n or not all(_is_number(v) for v in items):
        raise SceneError(f"scene: '{where}' must be a list of {n} numbers, got {show(x)}"
                         + ("; true and false are not numbers" if items and any(isinstance(v, bool) for v in items)
                            else ""))
    try:
        a = np.array([float(v) for v in items], dtype=np.float64)
    except OverflowError:
        raise SceneError(f"scene: '{where}' holds a number too large for a float ({show(x)}); "
                         f"give numbers within +-{LIMIT:g}") from None
    if finite and not np.all(np.isfinite(a)):
        raise SceneError(f"scene: '{where}' holds a NaN or infinite value ({show(x)}); give finite numbers")
    if limit is not None and np.any(np.abs(a) > limit):
        raise SceneError(f"scene: '{where}' is {show(x)}; give numbers within +-{limit:g} (larger ones overflow "
                         "the float32 buffers)")
    return a


def _is_number(v):
    return not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating))


def check_number(x, where, lo=None, hi=None, lo_open=False, integer=False, limit=None):
    """``x`` itself if it is a finite number in range, else a :class:`SceneError` naming ``where``.

    Parameters
    ----------
    x : int or float
        The value given (a bool is refused: JSON ``true`` is not a number).
    where : str
        Its dotted key, for the message.
    lo, hi : float, optional
        Inclusive bounds (``lo`` exclusive with ``lo_open``).
    lo_open : bool
        ``x`` must be strictly greater than ``lo``.
    integer : bool
        ``x`` must be a whole number.
    limit : float, optional
        The largest magnitude; by default :data:`LIMIT` (:data:`INT_LIMIT` for whole numbers) where no
        ``hi`` is given, so that no number reaches the kernels large enough to overflow.

    Returns
    -------
    int or float
        ``x``, unchanged.
    """
    if not _is_number(x):
        raise SceneError(f"scene: '{where}' must be a number, got {show(x)}")
    try:
        f = float(x)
    except OverflowError:
        f = math.inf
    if math.isnan(f) or (math.isinf(f) and not isinstance(x, (int, np.integer))):
        raise SceneError(f"scene: '{where}' is {show(x)}; give a finite number")
    if integer and (math.isinf(f) or int(x) != x):
        if math.isinf(f):
            raise SceneError(f"scene: '{where}' is a whole number too large to use ({show(x)}); it must be "
                             f"<= {hi if hi is not None else INT_LIMIT}")
        raise SceneError(f"scene: '{where}' must be a whole number, got {show(x)}")
    if lo is not None and (x <= lo if lo_open else x < lo):
        raise SceneError(f"scene: '{where}' is {show(x)}; it must be {'>' if lo_open else '>='} {lo}")
    if hi is not None and x > hi:
        raise SceneError(f"scene: '{where}' is {show(x)}; it must be <= {hi}")
    if limit is None and hi is None:
        limit = INT_LIMIT if integer else LIMIT
    if limit is not None and abs(f) > limit:
        raise SceneError(f"scene: '{where}' is {show(x)}; give a number within +-{limit:g} (larger ones overflow "
                         "the float32 buffers)")
    return x
