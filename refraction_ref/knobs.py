"""A knob declared once: its type, range or choices, default, doc line and paper section.

Each method's knobs module declares its block as a tuple of :class:`Knob` and
registers it with :func:`declare_block`. Everything else is derived from those
declarations:

* the block's defaults (:attr:`KnobBlock.defaults`), which the scene loader
  merges under a scene file;
* the block's checks: each knob's type and range or choices
  (:func:`check_knob`), then the block's own cross-key rules (``extra``);
* the knob tables of ``docs/oracle.md`` and the README (:func:`knob_table`,
  written by ``python tools/knob_tables.py``; ``tests/test_knob_tables.py``
  fails when a table drifts from its declarations).

The typed value a method's kernels take (``TraceKnobs``, ``MarchKnobs``, ...)
is built in the same knobs module from the checked block, with its codes
resolved there, so that no stage validates or translates a knob a second time.

Importing this module is cheap (no kernels): scene loading reads it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Callable

from .graph import KnobBlock, register_block

__all__ = ["Knob", "declare_block", "check_knob", "knob_table", "allowed_text", "code_of"]


@dataclass(frozen=True)
class Knob:
    """One knob of a block.

    Attributes
    ----------
    name : str
        The key inside its block (``"iterations"``); never renamed (a rename
        keeps the old name as an alias, ``KnobBlock.aliases``).
    default : object
        The paper's own setting where it states one.
    doc : str
        What it means (the ``meaning`` column of the knob tables).
    section : str
        The paper's section or equation (``"§3.6"``, ``"eq. 3.2"``); ``"—"``
        for a knob beyond the paper.
    kind : str
        ``"int"``, ``"float"``, ``"bool"``, ``"choice"`` or ``"other"`` (checked
        by ``check`` alone; ``allowed`` then says what is accepted).
    lo, hi : float, optional
        Inclusive bounds of a number (``lo`` exclusive with ``lo_open``).
    lo_open : bool
        The number must be strictly greater than ``lo``.
    choices : tuple of str
        The accepted values of a ``"choice"`` knob.
    multiple_of : int, optional
        An integer knob must be a multiple of this.
    nullable : bool
        ``null`` (``None``) is accepted besides the kind's values.
    allowed : str, optional
        The table's ``allowed`` column where the derived text
        (:func:`allowed_text`) does not say it all.
    check : callable, optional
        ``check(value, where, data)``: a rule of this knob beyond its kind
        and range (raising :class:`~refraction_ref.validation.SceneError`).
    summary : str, optional
        One line for the README's table of the main knobs (``None``: the
        knob is in ``docs/oracle.md``'s table only).
    read_by : str, optional
        The methods that read it, for a service's block read by several
        (the table's ``read by`` column).
    items : tuple of Knob
        For a list of objects (``water.waves``): the keys of each item,
        checked by ``check`` and listed as ``waves[k].<key>`` rows.
    """

    name: str
    default: Any
    doc: str
    section: str = "—"
    kind: str = "other"
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple = ()
    multiple_of: int | None = None
    nullable: bool = False
    allowed: str | None = None
    check: Callable | None = None
    summary: str | None = None
    read_by: str | None = None
    items: tuple = ()


def _fmt_number(x):
    return f"{x:g}" if isinstance(x, float) else str(x)


def allowed_text(knob):
    """The ``allowed`` column of a knob's table row, derived from its kind and range.

    Parameters
    ----------
    knob : Knob

    Returns
    -------
    str
    """
    if knob.allowed is not None:
        return knob.allowed
    if knob.kind == "bool":
        text = "true, false"
    elif knob.kind == "choice":
        text = ", ".join(json.dumps(c) for c in knob.choices)
    elif knob.kind in ("int", "float"):
        lead = "integer " if knob.kind == "int" else ""
        if knob.lo is not None and knob.hi is not None:
            text = f"{lead}{_fmt_number(knob.lo)}..{_fmt_number(knob.hi)}"
        elif knob.lo is not None:
            text = f"{lead}{'>' if knob.lo_open else '>='} {_fmt_number(knob.lo)}"
        elif knob.hi is not None:
            text = f"{lead}<= {_fmt_number(knob.hi)}"
        else:
            text = lead.strip() or "number"
        if knob.multiple_of:
            text += f", multiple of {knob.multiple_of}"
    else:
        text = "see meaning"
    return f"null, or {text}" if knob.nullable else text


def check_knob(knob, value, where, data=None):
    """Check one knob's value by its declaration; raise :class:`SceneError` naming ``where``.

    Parameters
    ----------
    knob : Knob
    value : object
        The value in the merged scene.
    where : str
        Its dotted key (``"imagespace.layers"``), for the message.
    data : dict, optional
        The whole merged scene, for a ``check`` that needs other blocks.

    Returns
    -------
    object
        ``value``, unchanged.
    """
    from .validation import SceneError, check_number

    if value is None and knob.nullable:
        return value
    if knob.kind == "choice":
        if not isinstance(value, str) or value not in knob.choices:
            raise SceneError(f"scene: '{where}' is {value!r}; choose one of {', '.join(knob.choices)}")
    elif knob.kind == "bool":
        if not isinstance(value, bool):
            raise SceneError(f"scene: {where} must be true or false, got {value!r}")
    elif knob.kind in ("int", "float"):
        check_number(value, where, knob.lo, knob.hi, lo_open=knob.lo_open, integer=knob.kind == "int")
        if knob.multiple_of and int(value) % knob.multiple_of:
            raise SceneError(f"scene: {where} is {value}; it must be a multiple of {knob.multiple_of}")
    if knob.check is not None:
        knob.check(value, where, data)
    return value


def declare_block(name, knobs, owner, extra=None, aliases=None, merge=None, present=True):
    """Register a block whose defaults, checks and table come from its :class:`Knob` declarations.

    Parameters
    ----------
    name : str
        The top-level scene key.
    knobs : tuple of Knob
        The block's knobs, in table order.
    owner : str
        The method that reads it.
    extra : callable, optional
        ``extra(data, base_dir)``: the block's rules across keys or blocks,
        run after every knob's own check.
    aliases : dict, optional
        Old key -> new key (``KnobBlock.aliases``).
    merge : callable, optional
        ``KnobBlock.merge``, for a block that is absent unless given.
    present : bool
        False for a block that is absent unless the scene gives it (``water``,
        ``volume``): its defaults are then filled by ``merge`` and its checks
        run only when it is there.

    Returns
    -------
    KnobBlock
        The registered block, with :attr:`KnobBlock.knobs`.
    """
    knobs = tuple(knobs)
    names = [k.name for k in knobs]
    if len(set(names)) != len(names):
        raise ValueError(f"block {name}: a knob is declared twice")

    def validate(data, base_dir="."):
        blk = data.get(name)
        if blk is None and not present:
            return data
        for k in knobs:
            check_knob(k, blk[k.name], f"{name}.{k.name}", data)
        if extra is not None:
            extra(data, base_dir)
        return data

    defaults = {k.name: k.default for k in knobs} if present else None
    return register_block(KnobBlock(name, defaults, validate, owner=owner, aliases=dict(aliases or {}),
                                    merge=merge, knobs=knobs))


def knob_table(block):
    """The Markdown table of a block's knobs (``docs/oracle.md``), from their declarations.

    Columns: key, default (left out for a block whose every key defaults to
    null), allowed, meaning, read by (only where a knob names its readers)
    and section; a list-of-objects knob is followed by one row per item key
    (``waves[k].amplitude``).

    Parameters
    ----------
    block : KnobBlock
        A block registered by :func:`declare_block`.

    Returns
    -------
    str
        Header, separator and one row per knob, newline-terminated.
    """
    rows = [(k.name, k) for k in block.knobs]
    rows = [r for name, k in rows for r in [(name, k)] + [(f"{name}[k].{i.name}", i) for i in k.items]]
    with_default = block.defaults is not None or any(k.default is not None for _, k in rows)
    with_readers = any(k.read_by for _, k in rows)
    head = ["key"] + (["default"] if with_default else []) + ["allowed", "meaning"]
    head += (["read by"] if with_readers else []) + ["section"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, k in rows:
        cells = [f"`{name}`"] + ([json.dumps(k.default)] if with_default else []) + [allowed_text(k), k.doc]
        cells += ([k.read_by or ""] if with_readers else []) + [k.section]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def code_of(knob, value):
    """The integer code of a choice (its index in ``knob.choices``): what kernels take for a string.

    Parameters
    ----------
    knob : Knob
        A ``"choice"`` knob.
    value : str

    Returns
    -------
    int
    """
    return knob.choices.index(value)
