"""Write the knob tables of ``docs/oracle.md`` and the README from the knobs modules' declarations.

``python tools/knob_tables.py`` rewrites, in ``docs/oracle.md``, the table
under each ``### `<block>` block`` heading, and in ``README.md`` the table
under ``## Image-space knobs``, from the :class:`~refraction_ref.knobs.Knob`
declarations of each block (``refraction_ref/<method>/knobs.py``): a knob is
declared once, and its documentation follows. ``--check`` writes nothing and
exits 1 naming each table that differs from its declarations
(``tests/test_knob_tables.py`` runs it, so CI fails when a table drifts).
"""

from __future__ import annotations

import argparse
import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from refraction_ref.graph import load_builtin_blocks  # noqa: E402
from refraction_ref.knobs import knob_table  # noqa: E402

#: the README's table: the image-space knobs that declare a ``summary`` (the main ones)
README_HEADING = "## Image-space knobs"


def readme_table(block):
    """The README's table of a block: the knobs with a ``summary``, as ``knob | default | meaning``.

    Parameters
    ----------
    block : KnobBlock

    Returns
    -------
    str
    """
    rows = ["| knob | default | meaning |", "|---|---|---|"]
    for k in block.knobs:
        if k.summary:
            d = k.default
            shown = f"`{d}`" if isinstance(d, str) else json.dumps(d)
            rows.append(f"| `{k.name}` | {shown} | {k.summary} |")
    return "\n".join(rows) + "\n"


def _replace_table(text, heading, table):
    """``text`` with the first table after the line starting with ``heading`` replaced by ``table``."""
    lines = text.splitlines(keepends=True)
    h = next((i for i, ln in enumerate(lines) if ln.startswith(heading)), None)
    if h is None:
        raise KeyError(f"no heading {heading!r}")
    start = next(i for i in range(h + 1, len(lines)) if lines[i].startswith("|"))
    end = start
    while end < len(lines) and lines[end].startswith("|"):
        end += 1
    return "".join(lines[:start]) + table + "".join(lines[end:])


def expected(root=ROOT):
    """The two files as their declarations write them.

    Parameters
    ----------
    root : str
        The repository.

    Returns
    -------
    dict
        Path relative to ``root`` -> (current text, expected text, names of the tables in it).
    """
    blocks = load_builtin_blocks()
    out = {}
    path = os.path.join(root, "docs", "oracle.md")
    text = open(path, encoding="utf-8").read()
    new, names = text, []
    for name, blk in blocks.items():
        if blk.knobs:
            one = _replace_table(new, f"### `{name}` block", knob_table(blk))
            if one != new:  # the tables that drifted, by name
                names.append(name)
            new = one
    out["docs/oracle.md"] = (text, new, names)
    path = os.path.join(root, "README.md")
    text = open(path, encoding="utf-8").read()
    blk = blocks["imagespace"]
    new = _replace_table(text, README_HEADING, readme_table(blk)) if any(k.summary for k in blk.knobs) else text
    out["README.md"] = (text, new, ["imagespace"] if new != text else [])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 when a table drifts")
    a = ap.parse_args(argv)
    stale = []
    for rel, (text, new, names) in expected().items():
        if text == new:
            continue
        if a.check:
            stale.append(f"{rel}: the knob tables of {', '.join(names)} differ from their declarations "
                         "(run python tools/knob_tables.py)")
        else:
            with open(os.path.join(ROOT, rel), "w", encoding="utf-8") as f:
                f.write(new)
            print(f"wrote {rel} ({', '.join(names)})")
    for s in stale:
        print(s)
    return 1 if stale else 0


if __name__ == "__main__":
    raise SystemExit(main())
