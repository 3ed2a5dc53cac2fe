"""A knob is declared once (``refraction_ref/<method>/knobs.py``), and everything about it follows.

* ``docs/oracle.md``'s and the README's knob tables are written from the declarations
  (``python tools/knob_tables.py``): they must not drift;
* every block of the scene declares its knobs;
* no function of the package gives a parameter named for a knob a default other than the knob's
  (``trace_layers(delta=1)`` against the block's 2 was such a contradiction).
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys

import pytest

from refraction_ref.graph import load_builtin_blocks
from refraction_ref.knobs import Knob, allowed_text, check_knob, knob_table
from refraction_ref.validation import SceneError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: the package whose functions read each block
PACKAGE_OF = {"imagespace": "imagespace", "exact": "exact", "volumetric": "volumetric", "volume": "volumetric",
              "levelmap": "levelmap", "water": "levelmap", "caustics": "caustics"}


def test_tables_follow_the_declarations():
    r = subprocess.run([sys.executable, os.path.join(ROOT, "tools", "knob_tables.py"), "--check"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_every_block_is_declared():
    blocks = load_builtin_blocks()
    assert set(PACKAGE_OF) <= set(blocks)
    for name, blk in blocks.items():
        assert blk.knobs, f"block {name} declares no Knob"
        if blk.defaults is not None:
            assert blk.defaults == {k.name: k.default for k in blk.knobs}
        for k in blk.knobs:
            assert k.doc and k.section, f"{name}.{k.name}: doc and section"


def _literal_defaults(path):
    tree = ast.parse(open(path, encoding="utf-8").read(), path)
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            pos = a.posonlyargs + a.args
            pairs = list(zip(pos[len(pos) - len(a.defaults):], a.defaults))
            pairs += [(x, d) for x, d in zip(a.kwonlyargs, a.kw_defaults) if d is not None]
            for arg, d in pairs:
                try:
                    yield node.name, node.lineno, arg.arg, ast.literal_eval(d)
                except ValueError:
                    continue


def test_no_function_default_contradicts_its_knob():
    blocks = load_builtin_blocks()
    bad = []
    for block, pkg in PACKAGE_OF.items():
        knobs = {k.name: k.default for k in blocks[block].knobs}
        folder = os.path.join(ROOT, "refraction_ref", pkg)
        for f in sorted(os.listdir(folder)):
            if not f.endswith(".py"):
                continue
            for fn, line, name, value in _literal_defaults(os.path.join(folder, f)):
                if name in knobs and value is not None and value != knobs[name]:
                    bad.append(f"{pkg}/{f}:{line} {fn}({name}={value!r}) but {block}.{name} = {knobs[name]!r}")
    assert bad == []


def test_a_declaration_checks_and_documents():
    k = Knob("slices", 256, "bitmask slices", "§3.3", kind="int", lo=32, hi=4096, multiple_of=32)
    assert allowed_text(k) == "integer 32..4096, multiple of 32"
    assert check_knob(k, 64, "imagespace.slices") == 64
    for bad in (48, 16, 8192, 1.5, True, "64"):
        with pytest.raises(SceneError, match="imagespace.slices"):
            check_knob(k, bad, "imagespace.slices")
    c = Knob("normals", "central", "the rule", "§3.5", kind="choice", choices=("forward", "central"))
    assert allowed_text(c) == '"forward", "central"'
    with pytest.raises(SceneError, match="choose one of forward, central"):
        check_knob(c, "sobel", "imagespace.normals")

    class _Block:
        knobs = (k, c)
        defaults = {"slices": 256, "normals": "central"}

    table = knob_table(_Block).splitlines()
    assert table[2] == "| `slices` | 256 | integer 32..4096, multiple of 32 | bitmask slices | §3.3 |"
    assert table[3] == '| `normals` | "central" | "forward", "central" | the rule | §3.5 |'
