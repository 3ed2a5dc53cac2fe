"""The first run: a cold ``refraction-ref render`` per method (empty Numba cache), and a cold ``golden build``.

Each run happens in a private copy of the package (``refraction_ref/`` copied
without its ``__pycache__``) put first on ``PYTHONPATH``, so the Numba cache
starts empty and neither reads nor wipes the cache of the working tree. The
time is the whole command as a user sees it (interpreter start, imports,
compilation, the render, writing the files), as wall-clock seconds and as
CPU seconds of the child (user + system: on a shared, loaded machine the wall
clock measures the other load; Numba compiles on one thread, so the CPU time
of a cold run is close to its wall time on an idle machine, and an upper
bound of it for the multi-threaded render part). A second, warm run of the
same command shows what is left once the cache is filled. The child also
records the compile seconds of every kernel (exclusive of the kernels it
calls, which compile inside it) and lists every kernel that compiled, with
its number of signatures (two or more is an accidental specialisation unless
the kernel is meant to serve two types).

Usage::

    python benchmarks/bench_first_run.py                 # the four methods' default renders
    python benchmarks/bench_first_run.py imagespace exact
    python benchmarks/bench_first_run.py golden          # cold golden build (slow)
    python benchmarks/bench_first_run.py --keep DIR ...  # keep the outputs (bit-identity checks)
    python benchmarks/bench_first_run.py --manifest      # rewrite refraction_ref/data/kernels.json (warm, quick)

Writes ``results/first_run.json`` (merged with earlier runs, one row per
target); ``results/first_run.md`` is the written note.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
RESULTS = os.path.join(HERE, "results")

TARGETS = {
    "imagespace": ["render"],
    "exact": ["render", "--method", "exact"],
    "levelmap": ["render", "PKG/data/levelmap_default.json", "--method", "levelmap"],
    "volumetric": ["render", "--method", "volumetric"],
    "golden": ["golden", "build"],
}

_CHILD = r"""
import json, sys, time
from numba.core import event
spent, stack = {}, []

class _Timer(event.Listener):  # exclusive compile seconds per kernel (callees compile inside callers)
    def on_start(self, ev):
        stack.append([ev.data["dispatcher"], time.perf_counter(), 0.0])

    def on_end(self, ev):
        d, t0, inner = stack.pop()
        dt = time.perf_counter() - t0
        if stack:
            stack[-1][2] += dt
        q = d.py_func.__module__ + "." + d.py_func.__name__
        spent[q] = spent.get(q, 0.0) + dt - inner

event.register("numba:compile", _Timer())
from refraction_ref.cli import main
rc = main(sys.argv[2:])
from numba.core.registry import CPUDispatcher
sigs = {}
for name, mod in list(sys.modules.items()):
    if not name.startswith("refraction_ref"):
        continue
    for k, v in list(vars(mod).items()):
        if isinstance(v, CPUDispatcher) and v.signatures and v.py_func.__module__ == name:
            sigs[f"{name}.{k}"] = [str(s) for s in v.signatures]
with open(sys.argv[1], "w") as f:
    json.dump({"sigs": sigs, "spent": spent}, f)
sys.exit(rc)
"""

_LIST = r"""
import json, sys
import refraction_ref as rr
from numba.core.registry import CPUDispatcher
method, src = sys.argv[1], (sys.argv[2] or None)
rr.render(src, method=method, overrides={"camera.width": 24, "camera.height": 24})
names = sorted({f"{v.py_func.__module__}.{v.py_func.__name__}" for name, mod in list(sys.modules.items())
                if name.startswith("refraction_ref") for v in list(vars(mod).values())
                if isinstance(v, CPUDispatcher) and v.signatures and v.py_func.__module__ == name})
print(json.dumps(names))
"""


def _child_cpu():
    """CPU seconds (user + system) of the finished child processes: on a loaded machine, the honest measure."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _copy_package(dest):
    shutil.copytree(os.path.join(REPO, "refraction_ref"), os.path.join(dest, "refraction_ref"),
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    return os.path.join(dest, "refraction_ref")


def run(target, keep=None):
    """One cold and one warm run of ``target`` in a fresh copy of the package; a dict of the timings."""
    tmp = tempfile.mkdtemp(prefix="firstrun_")
    try:
        pkg = _copy_package(tmp)
        env = dict(os.environ, PYTHONPATH=tmp + os.pathsep + os.environ.get("PYTHONPATH", ""))
        env.pop("NUMBA_CACHE_DIR", None)
        row = {"target": target}
        for phase in ("cold", "warm"):
            out = os.path.join(keep or tmp, f"{target}_{phase}")
            argv = [a.replace("PKG", pkg) for a in TARGETS[target]]
            argv += [out] if target == "golden" else ["--out", out, "--force"]
            sig_file = os.path.join(tmp, f"sigs_{phase}.json")
            t0, c0 = time.perf_counter(), _child_cpu()
            p = subprocess.run([sys.executable, "-c", _CHILD, sig_file] + argv, env=env, cwd=tmp,
                               capture_output=True, text=True)
            row[f"{phase}_s"] = round(time.perf_counter() - t0, 1)
            row[f"{phase}_cpu_s"] = round(_child_cpu() - c0, 1)
            if p.returncode != 0:
                raise SystemExit(f"{target} ({phase}) failed:\n{p.stdout[-2000:]}\n{p.stderr[-4000:]}")
            if phase == "cold":
                with open(sig_file) as f:
                    got = json.load(f)
                sigs = got["sigs"]
                row["compile_s"] = {k: round(v, 2) for k, v in sorted(got["spent"].items(), key=lambda kv: -kv[1])}
                row["kernels"] = sorted(sigs)
                row["kernels_compiled"] = len(sigs)
                row["signatures"] = sum(len(v) for v in sigs.values())
                row["multi_signature"] = {k: v for k, v in sigs.items() if len(v) > 1}
            print(f"{target:10s} {phase}: {row[f'{phase}_s']:7.1f} s wall, {row[f'{phase}_cpu_s']:7.1f} s CPU",
                  flush=True)
        return row
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _is_kernel(qualname):
    """Whether ``module.name`` is a Numba kernel of the package now (a cold run's list may name one
    since renamed, moved or folded into its caller)."""
    import importlib

    from numba.core.registry import CPUDispatcher

    module, _, name = qualname.rpartition(".")
    try:
        return isinstance(getattr(importlib.import_module(module), name, None), CPUDispatcher)
    except ImportError:
        return False


def write_manifest():
    """``refraction_ref/data/kernels.json``: the kernels each method's default render calls.

    One fresh process per method renders the default scene small (the same
    plan, hence the same kernels) and lists every package kernel that holds a
    signature afterwards, compiled or loaded from the cache, joined with the
    kernels the last cold run of the method compiled (``first_run.json``: a
    warm process does not see the callees compiled inside their callers,
    whose code the callers' cache entries hold). ``kernels_cached``
    checks these one by one and the compile bar counts against their number:
    regenerate after adding, renaming or removing kernels.
    """
    out, cold = {}, {}
    path = os.path.join(RESULTS, "first_run.json")
    if os.path.exists(path):  # a cold run also lists the callees compiled inside their callers
        with open(path) as f:
            cold = {r["target"]: r.get("kernels", []) for r in json.load(f)["rows"]}
    for method, argv in TARGETS.items():
        if method == "golden":
            continue
        src = next((a for a in argv if a.startswith("PKG/")), "").replace("PKG", os.path.join(REPO, "refraction_ref"))
        p = subprocess.run([sys.executable, "-c", _LIST, method, src], capture_output=True, text=True, cwd=REPO)
        if p.returncode != 0:
            raise SystemExit(f"listing the {method} kernels failed:\n{p.stderr[-3000:]}")
        out[method] = sorted(set(json.loads(p.stdout.strip().splitlines()[-1]))
                             | {q for q in cold.get(method, []) if _is_kernel(q)})
        print(f"{method}: {len(out[method])} kernels", flush=True)
    path = os.path.join(REPO, "refraction_ref", "data", "kernels.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=1, sort_keys=True)
        f.write("\n")
    print(f"wrote {path}")


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--manifest" in argv:
        return write_manifest()
    keep = None
    if "--keep" in argv:
        i = argv.index("--keep")
        keep = argv[i + 1]
        del argv[i:i + 2]
        os.makedirs(keep, exist_ok=True)
    targets = argv or ["imagespace", "exact", "levelmap", "volumetric"]
    bad = [t for t in targets if t not in TARGETS]
    if bad:
        raise SystemExit(f"bench_first_run: unknown target {bad}; choose from {', '.join(TARGETS)}")
    path = os.path.join(RESULTS, "first_run.json")
    for t in targets:
        r = run(t, keep)
        print(f"  {r['kernels_compiled']} kernels, {r['signatures']} signatures; several signatures: "
              + (", ".join(f"{k} ({len(v)})" for k, v in r["multi_signature"].items()) or "none"), flush=True)
        rows = {}
        if os.path.exists(path):  # read just before writing: another run may have added its rows meanwhile
            with open(path) as f:
                rows = {r["target"]: r for r in json.load(f)["rows"]}
        rows[t] = r
        with open(path, "w") as f:
            json.dump({"cpus": os.cpu_count(), "rows": list(rows.values())}, f, indent=1)


if __name__ == "__main__":
    main()
