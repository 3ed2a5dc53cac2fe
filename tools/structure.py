"""The package's structure in numbers: import circles, arrows running back up, unit sizes, docstrings.

Run ``python tools/structure.py [--json]`` from the repository root. It reads
the source of ``refraction_ref`` (it imports nothing of the package) and reports:

- **circles**: strongly connected sets of modules in the import graph (every
  ``import``/``from ... import`` of a ``refraction_ref`` module, at any
  depth: an import inside a function ties two modules as much as one at the
  top). A package's ``__init__`` re-exporting its own modules is not counted
  as an arrow of those modules back to it.
- **rooms** and **arrows running back up**: rooms are the top-level modules
  and sub-packages of ``refraction_ref``; an arrow between two rooms runs
  *back up* when it closes a cycle of rooms: the arrows left over after the
  rooms are ordered by a depth-first topological sort (a feedback arc set;
  0 when the room graph is acyclic).
- **long functions** (more than 150 lines, decorators included) and
  **functions with more than 12 positional parameters**.
- **docstrings**: the share of public functions (module and class level,
  names and modules not starting with ``_``) whose numpydoc docstring has a
  ``Parameters`` section (functions that take no parameter count as
  documented), and with ``--passes``, every public pass function (a
  module-level public function of a pass module, ``refraction_ref.<method>.<pass>``
  for the methods' packages, knobs and pipeline modules aside) without a
  ``References`` section.

The targets (the redesign of issue "one redesign step"): 0 circles, at most
4 arrows back up, 0 long functions, 0 functions over 12 positional
parameters, at least 90 % of public functions with Parameters, every pass
with References.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import sys

PKG = "refraction_ref"
MAX_LINES = 150
MAX_POSITIONAL = 12
#: issue 35's targets: no Python function over 8 parameters, at most 10 kernels over 10, no module over 800 lines
MAX_PARAMETERS = 8
MAX_KERNEL_PARAMETERS = 10
MAX_WIDE_KERNELS = 10
MAX_MODULE_LINES = 800


def _modules(root):
    mods = {}
    for dirpath, dirnames, files in os.walk(os.path.join(root, PKG)):
        dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
        for f in sorted(files):
            if f.endswith(".py"):
                path = os.path.join(dirpath, f)
                rel = os.path.relpath(path, root)[:-3].replace(os.sep, ".")
                name = rel[: -len(".__init__")] if rel.endswith(".__init__") else rel
                mods[name] = path
    return mods


def _resolve(mod, is_pkg, node, mods):
    """The refraction_ref modules an import node names."""
    out = []
    if isinstance(node, ast.Import):
        for a in node.names:
            if a.name.split(".")[0] == PKG:
                out.append(a.name)
        return [m for m in out if m in mods]
    base = node.module or ""
    if node.level:
        parts = mod.split(".")
        if not is_pkg:
            parts = parts[:-1]
        parts = parts[: len(parts) - (node.level - 1)]
        base = ".".join(parts + ([base] if base else []))
    if base.split(".")[0] != PKG:
        return []
    for a in node.names:
        sub = f"{base}.{a.name}"
        if sub in mods:
            out.append(sub)
        elif base in mods:
            out.append(base)
    return sorted(set(out))


def import_graph(root="."):
    mods = _modules(root)
    edges = {m: set() for m in mods}
    for m, path in mods.items():
        is_pkg = path.endswith("__init__.py")
        tree = ast.parse(open(path, encoding="utf-8").read(), path)
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for t in _resolve(m, is_pkg, node, mods):
                    if t == m:
                        continue
                    # a package's __init__ importing its own modules (re-export) is not an arrow back
                    if is_pkg and t.startswith(m + "."):
                        edges[m].add(t)
                        continue
                    edges[m].add(t)
    return mods, edges


def _scc(nodes, edges):
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            out.append(sorted(comp))

    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return out


def _room(m):
    parts = m.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 else m


def _back_arrows(edges):
    """Feedback arcs of the room graph from a depth-first search (arrows to a room still on the stack)."""
    rooms = sorted({_room(m) for m in edges})
    redges = {r: set() for r in rooms}
    for m, ts in edges.items():
        for t in ts:
            a, b = _room(m), _room(t)
            if a != b and not (m == PKG or t == PKG):
                redges[a].add(b)
    state, back = {}, []

    def visit(v):
        state[v] = 1
        for w in sorted(redges[v]):
            if state.get(w) == 1:
                back.append((v, w))
            elif w not in state:
                visit(w)
        state[v] = 2

    for r in rooms:
        if r not in state:
            visit(r)
    return rooms, back


def _docstring_sections(doc):
    lines = [ln.strip() for ln in (doc or "").splitlines()]
    return {lines[i] for i in range(len(lines) - 1) if lines[i + 1] and set(lines[i + 1]) == {"-"}}


def _n_params(fn):
    a = fn.args
    names = [x.arg for x in a.posonlyargs + a.args]
    if names and names[0] in ("self", "cls"):
        names = names[1:]
    return names


def functions(root="."):
    mods = _modules(root)
    rows = []
    for m, path in mods.items():
        tree = ast.parse(open(path, encoding="utf-8").read(), path)
        public_mod = not any(p.startswith("_") and p != "__init__" for p in m.split("."))

        def walk(body, owner, public_owner):
            for node in body:
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    start = min([node.lineno] + [d.lineno for d in node.decorator_list])
                    params = _n_params(node)
                    doc = ast.get_docstring(node)
                    secs = _docstring_sections(doc)
                    all_params = params + [x.arg for x in node.args.kwonlyargs]
                    if node.args.vararg:
                        all_params.append(node.args.vararg.arg)
                    if node.args.kwarg:
                        all_params.append(node.args.kwarg.arg)
                    deco = " ".join(ast.unparse(d) for d in node.decorator_list)
                    rows.append({
                        "module": m, "name": f"{owner}{node.name}", "line": node.lineno,
                        "parameters_n": len(all_params), "kernel": "jit" in deco,
                        "lines": node.end_lineno - start + 1, "positional": len(params),
                        "public": public_mod and public_owner and not node.name.startswith("_"),
                        "has_params": bool(all_params), "parameters": "Parameters" in secs,
                        "references": "References" in secs,
                    })
                    walk(node.body, f"{owner}{node.name}.<locals>.", False)
                elif isinstance(node, ast.ClassDef):
                    walk(node.body, f"{owner}{node.name}.", public_owner and not node.name.startswith("_"))

        walk(tree.body, "", True)
    return rows


#: the method packages whose modules are passes (one module per pass) and the modules that are not
PASS_PACKAGES = ("imagespace", "levelmap", "volumetric", "caustics", "exact")
NOT_PASS_MODULES = ("knobs", "pipeline", "__init__")


def is_pass_module(module):
    """A module of one of a method's passes: ``refraction_ref.<method>.<pass>``, not knobs or pipeline."""
    parts = module.split(".")
    return len(parts) == 3 and parts[1] in PASS_PACKAGES and parts[2] not in NOT_PASS_MODULES


def _private_imports(root):
    """``tests/`` files that import a private name of the package (``from refraction_ref.x import _y``,
    ``refraction_ref.x._y``, or ``m._y`` on a name bound to a package module)."""
    out = []
    for dirpath, dirnames, files in os.walk(os.path.join(root, "tests")):
        dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
        for f in sorted(files):
            if not f.endswith(".py"):
                continue
            path = os.path.join(dirpath, f)
            tree = ast.parse(open(path, encoding="utf-8").read(), path)
            bound, hits = set(), set()
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == PKG:
                    for a in node.names:
                        if a.name.startswith("_") and not a.name.startswith("__"):
                            hits.add(f"{node.module}.{a.name}")
                        bound.add(a.asname or a.name)
                    if any(p.startswith("_") and not p.startswith("__") for p in node.module.split(".")):
                        hits.add(node.module)
                elif isinstance(node, ast.Import):
                    for a in node.names:
                        if a.name.split(".")[0] == PKG:
                            bound.add(a.asname or a.name.split(".")[0])
                            if any(p.startswith("_") and not p.startswith("__") for p in a.name.split(".")):
                                hits.add(a.name)
            for node in ast.walk(tree):
                if (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")):
                    owner = ast.unparse(node.value)
                    if ((isinstance(node.value, ast.Name) and node.value.id in bound)
                            or owner.startswith(PKG + ".")):
                        hits.add(f"{owner}.{node.attr}")
            if hits:
                out.append(f"{os.path.relpath(path, root)}: {', '.join(sorted(hits))}")
    return out


def report(root=".", passes=False):
    mods, edges = import_graph(root)
    circles = [c for c in _scc(list(mods), edges) if len(c) > 1]
    rooms, back = _back_arrows(edges)
    fns = functions(root)
    public = [f for f in fns if f["public"]]
    documented = [f for f in public if f["parameters"] or not f["has_params"]]
    out = {
        "modules": len(mods),
        "rooms": len(rooms),
        "circles": circles,
        "arrows_back_up": [f"{a} -> {b}" for a, b in back],
        "long_functions": [f"{f['module']}.{f['name']} ({f['lines']} lines)" for f in fns if f["lines"] > MAX_LINES],
        "many_positional": [f"{f['module']}.{f['name']} ({f['positional']})" for f in fns
                            if f["positional"] > MAX_POSITIONAL],
        "many_parameters": [f"{f['module']}.{f['name']} ({f['parameters_n']})" for f in fns
                            if not f["kernel"] and f["parameters_n"] > MAX_PARAMETERS],
        "wide_kernels": [f"{f['module']}.{f['name']} ({f['parameters_n']})" for f in fns
                         if f["kernel"] and f["parameters_n"] > MAX_KERNEL_PARAMETERS],
        "module_lines": sorted(((sum(1 for _ in open(p, encoding="utf-8")), m) for m, p in mods.items()),
                               reverse=True),
        "tests_importing_private": _private_imports(root),
        "public_functions": len(public),
        "with_parameters": len(documented),
        "parameters_share": round(len(documented) / max(len(public), 1), 4),
        "undocumented": [f"{f['module']}.{f['name']}" for f in public if f not in documented],
    }
    if passes:
        pf = [f for f in public if is_pass_module(f["module"]) and "." not in f["name"]]
        out["passes"] = len(pf)
        out["passes_without_references"] = [f"{f['module']}.{f['name']}" for f in pf if not f["references"]]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print the whole report as JSON")
    ap.add_argument("--passes", action="store_true", help="also check every registered stage's References")
    ap.add_argument("--list", action="store_true", help="list the undocumented public functions")
    a = ap.parse_args(argv)
    r = report(".", passes=a.passes)
    if a.json:
        print(json.dumps(r, indent=1))
        return 0
    print(f"modules {r['modules']}, rooms {r['rooms']}")
    print(f"circles: {len(r['circles'])}")
    for c in r["circles"]:
        print("  " + " <-> ".join(c))
    print(f"arrows running back up: {len(r['arrows_back_up'])}")
    for x in r["arrows_back_up"]:
        print("  " + x)
    print(f"functions over {MAX_LINES} lines: {len(r['long_functions'])}")
    for x in r["long_functions"]:
        print("  " + x)
    print(f"functions over {MAX_POSITIONAL} positional parameters: {len(r['many_positional'])}")
    for x in r["many_positional"]:
        print("  " + x)
    print(f"Python functions over {MAX_PARAMETERS} parameters: {len(r['many_parameters'])}")
    for x in r["many_parameters"]:
        print("  " + x)
    print(f"kernels over {MAX_KERNEL_PARAMETERS} parameters: {len(r['wide_kernels'])} "
          f"(at most {MAX_WIDE_KERNELS})")
    for x in r["wide_kernels"]:
        print("  " + x)
    big = [(n, m) for n, m in r["module_lines"] if n > MAX_MODULE_LINES]
    n0, m0 = r["module_lines"][0]
    print(f"modules over {MAX_MODULE_LINES} lines: {len(big)} (largest {m0}, {n0})")
    for n, m in big:
        print(f"  {m} ({n})")
    print(f"test files importing a private name: {len(r['tests_importing_private'])}")
    for x in r["tests_importing_private"]:
        print("  " + x)
    print(f"public functions with a Parameters section: {r['with_parameters']} of {r['public_functions']} "
          f"({100 * r['parameters_share']:.1f} %)")
    if a.list:
        for x in r["undocumented"]:
            print("  " + x)
    if a.passes:
        print(f"passes without References: {len(r['passes_without_references'])} of {r['passes']}")
        for x in r["passes_without_references"]:
            print("  " + x)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
