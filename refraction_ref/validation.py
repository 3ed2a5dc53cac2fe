"""The scene's error type and value checks: the bottom of the package, imported by every knob block.

Every check raises :class:`SceneError` with a message that names the key
(``where``), the value given and what to give instead. Knob blocks
(``<method>/knobs.py``), lights, meshes and the scene loader import these
checks; this module imports nothing of the package, so no module needs the
scene loader (or a method) to validate its own keys.
"""

from __future__ import annotations

import copy
import math

import numpy as np

__all__ = ["SceneError", "check_number", "check_vector", "merge_defaults"]


class SceneError(ValueError):
    """A scene that cannot be rendered, with a message saying what to change."""


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
        if isinstance(sub, dict) and sub and v is not None:
            out[k] = merge_defaults(sub, v, f"{path}.{k}" if path else k)
        else:
            out[k] = copy.deepcopy(v)
    return out


def check_vector(x, n, where, finite=True):
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

    Returns
    -------
    ndarray, shape (n,), float64
    """
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"scene: '{where}' must be a list of {n} numbers, got {x!r}") from None
    if a.shape != (n,):
        raise SceneError(f"scene: '{where}' must be a list of {n} numbers, got {x!r}")
    if finite and not np.all(np.isfinite(a)):
        raise SceneError(f"scene: '{where}' holds a NaN or infinite value ({x!r}); give finite numbers")
    return a


def check_number(x, where, lo=None, hi=None, lo_open=False, integer=False):
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

    Returns
    -------
    int or float
        ``x``, unchanged.
    """
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise SceneError(f"scene: '{where}' must be a number, got {x!r}")
    if not math.isfinite(float(x)):
        raise SceneError(f"scene: '{where}' is {x!r}; give a finite number")
    if integer and int(x) != x:
        raise SceneError(f"scene: '{where}' must be a whole number, got {x!r}")
    if lo is not None and (x <= lo if lo_open else x < lo):
        raise SceneError(f"scene: '{where}' is {x!r}; it must be {'>' if lo_open else '>='} {lo}")
    if hi is not None and x > hi:
        raise SceneError(f"scene: '{where}' is {x!r}; it must be <= {hi}")
    return x
