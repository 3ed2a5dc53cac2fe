"""Command line: ``refraction-ref render | compare | scene | golden build | check | sweep``."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

__all__ = ["main"]


class _Parser(argparse.ArgumentParser):
    """argparse with one error prefix for every verb: ``refraction-ref: error: render: ...``, exit 2."""

    def error(self, message):
        self.print_usage(sys.stderr)
        verb = self.prog.partition(" ")[2]
        self.exit(2, f"refraction-ref: error: {verb + ': ' if verb else ''}{message}\n")


class UsageError(ValueError):
    """A command line that cannot run as given (exit 2 with the error prefix, like argparse's own)."""


def _parse_sets(items):
    out = {}
    for it in items or []:
        if "=" not in it:  # a usage error: exit 2 with the error prefix, like argparse's own
            raise UsageError(f"--set expects KEY=VALUE, got {it!r}; e.g. --set camera.width=64")
        k, v = it.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def _check_workers(n):
    """A LocalCluster of ``n`` worker processes: refuse ``n < 1`` (Dask would wait for workers forever)."""
    if n is not None and n < 1:
        raise UsageError(f"--workers is {n}; give at least 1 worker process (or --scheduler for an existing "
                         "cluster)")


def _check_keep(keep):
    """``--keep`` naming no stage (``''``, ``','``) would keep nothing without a word: refuse it."""
    if keep is not None and not [x for x in keep.split(",") if x.strip()]:
        raise UsageError(f"--keep {keep!r} names no stage; give 'stages' for every stage or a comma list of "
                         "stage names, e.g. --keep peel,trace (docs/oracle.md, Stage buffers)")


def _cmd_render(a):
    from . import load_scene, render

    from .result import check_writable, output_paths
    from .scene import ignored_content

    _check_keep(a.keep)
    scene = load_scene(a.scene, _parse_sets(a.set))
    check_writable(output_paths(a.out), overwrite=a.force, cli=True)  # before any work, not after it
    if a.keep:  # the stage names against the method's plan now, before its kernels are compiled or loaded
        from .graph import _keep_names, get_method

        m = get_method(a.method)
        if m.check is not None:
            m.check(scene)
        _keep_names(m.name, tuple(m.stages(scene)), a.keep)
    why = ignored_content(scene.data, a.method)
    if why:
        print(f"refraction-ref: warning: {why}", file=sys.stderr, flush=True)
    from .warm import compile_report

    with compile_report(a.method):  # kernels done of total on a terminal, one line each way in logs
        res = render(scene, method=a.method, progress=not a.quiet and sys.stderr.isatty(), keep=a.keep)
    paths = res.save(a.out, overwrite=a.force)
    if a.quiet:  # the files written, nothing else (the stage report is in the .npz's meta)
        print("wrote " + ", ".join(paths))
        return 0
    import numpy as np

    from .status import LABELS

    t = res.meta["timings_ms"]
    print(f"{a.method}: {scene.data['camera']['width']}x{scene.data['camera']['height']}, "
          f"{res.meta.get('triangles', 0)} triangles, {res.meta['total_ms']:.0f} ms to render"
          + (f" (and {res.meta['jit_ms'] / 1e3:.1f} s compiling or loading the kernels)"
             if res.meta.get("jit_ms", 0) > 500 else ""))
    print("stages (ms): " + ", ".join(f"{k} {v:.1f}" for k, v in t.items() if "." not in k))
    kept = sorted(k for k in res.arrays if k.startswith("stage."))
    if kept:
        print(f"kept {len(kept)} stage buffers: " + ", ".join(kept[:8]) + (" ..." if len(kept) > 8 else ""))
    if "status" in res.arrays:
        hist = np.bincount(res.arrays["status"].ravel().astype(np.int64), minlength=len(LABELS))
        print("status " + " / ".join(LABELS[k] for k in sorted(LABELS)) + ": " + " / ".join(str(int(x)) for x in hist))
    if "planes_used" in res.meta:
        print(f"planes: {res.meta['planes_requested']} requested, {res.meta['planes_used']} used")
    for p in res.meta.get("plan", []):
        print(f"  [{'ran ' if p['ran'] else 'skip'}] {p['stage']}: {p['why']}")
    print("wrote " + ", ".join(paths))
    return 0


def _run_name(path, res):
    """A run's name in plots: its file name and method, e.g. ``bunny_is.npz (imagespace)``."""
    method = res.meta.get("method")
    return os.path.basename(path) + (f" ({method})" if method else "")


def _cmd_compare(a):
    from .compare import check_comparable, compare_arrays, format_comparison
    from .result import load_result

    if a.plot:  # before reading the runs: an existing PNG is replaced only with --force, like render's --out
        from .files import check_out_file

        if os.path.exists(a.plot) and not a.force:
            raise FileExistsError(f"'{a.plot}' exists; choose another --plot file or pass --force to replace it")
        check_out_file(a.plot, "--plot")
    A = load_result(a.a)
    B = load_result(a.b)
    diff = check_comparable(A.meta, B.meta, force=a.force)
    if diff:
        print(f"refraction-ref: warning: the runs are of different scenes ('{diff}' differs); compared anyway "
              "(--force)", file=sys.stderr)
    c = compare_arrays(A.arrays, B.arrays)
    if a.json:
        print(json.dumps(c, indent=1))
    else:
        print(format_comparison(c, a.a, a.b))
    if a.plot:
        from .compare import plot_comparison

        print("wrote " + plot_comparison(A.arrays, B.arrays, a.plot, _run_name(a.a, A), _run_name(a.b, B)))
    return 0


def _cmd_scene(a):
    from . import load_scene

    scene = load_scene(a.scene, _parse_sets(a.set))
    if getattr(a, "to", None):
        fmt, path = a.to
        if fmt != "mitsuba":
            from .validation import SceneError

            raise SceneError(f"scene --to: unknown format {fmt!r}; the one known is 'mitsuba'")
        from .interop.mitsuba import write_xml

        spec = write_xml(scene, path, bsdf=a.bsdf, force=a.force)
        files = sorted(v["file"] for v in spec.values() if isinstance(v, dict) and "file" in v)
        print(f"wrote {path} and beside it {', '.join(files)} (load with mitsuba.load_file)")
        return 0
    print(scene.to_json())
    return 0


def _cmd_crosscheck(a):
    from .interop.crosscheck import run
    from .interop.report import failed_targets

    _check_workers(a.workers)
    parts = tuple(x for x in a.parts.split(",") if x)
    res = run(a.out, only=a.only, parts=parts, workers=a.workers, scheduler=a.scheduler,
              log=(lambda m: None) if a.quiet else print, report=a.report, merge=a.merge)
    print(f"{len(res['cases'])} cases; wrote {a.report or os.path.join(a.out, 'crosscheck.md')}")
    return 1 if any(failed_targets(name, e) for name, e in res["cases"].items()) else 0


def _cmd_golden_build(a):
    from .files import check_out_folder
    from .golden.build import build

    _check_workers(a.workers)
    check_out_folder(a.dir, "the golden suite folder")  # before any work: an existing file, a read-only place
    print(f"building the golden suite in {a.dir}" + (f" (cases {a.only})" if a.only else ""))
    t0 = time.perf_counter()
    m = build(a.dir, only=a.only, progress=not a.quiet and sys.stderr.isatty(), scheduler=a.scheduler,
              workers=a.workers)
    size = sum(os.path.getsize(os.path.join(r, f)) for r, _, fs in os.walk(a.dir) for f in fs)
    print(f"{len(m['cases'])} cases in {a.dir} ({size / 2**20:.1f} MiB), {time.perf_counter() - t0:.1f} s")
    return 0


def _cmd_check(a):
    from .golden.check import check

    out = check(a.candidate, a.golden, require=a.require or (), report=a.report, panels=not a.no_panels,
                cases=[c for c in a.cases.split(",") if c] if a.cases else None, allow_extra=a.allow_extra)
    for name, c in out["cases"].items():
        why = ("" if c["ok"] else f"  earliest failing stage: {c['earliest_failing_stage']}"
               if c["earliest_failing_stage"] else "  " + "; ".join(c["problems"][:2]))
        extra = f"  (extra keys, not judged: {', '.join(c['extra'])})" if c["extra"] else ""
        print(f"  {'pass' if c['ok'] else 'FAIL'}  {name}{why}{extra}")
    n_ok = sum(c["ok"] for c in out["cases"].values())
    print(f"{'PASS' if out['ok'] else 'FAIL'}: {n_ok} of {len(out['cases'])} cases pass; report in {out['report']} "
          f"({out['seconds']:.1f} s)")
    return 0 if out["ok"] else 1


def _cmd_sweep(a):
    from .sweep import load_spec, sweep, tasks_of

    from .sweep import output_files

    spec = load_spec(a.spec)
    _check_workers(a.workers if not a.scheduler else None)
    there = [p for p in output_files(spec, a.out) if os.path.exists(p)]
    if there and not a.force:  # before the cluster starts (sweep() checks again for Python callers)
        raise FileExistsError(f"'{there[0]}' exists; choose another --out folder or spec name, or pass --force "
                              "to replace it")
    n = len(tasks_of(spec))
    where = a.scheduler or f"a LocalCluster of {a.workers} worker process(es) x {a.threads_per_worker} thread(s)"
    print(f"sweep {spec['name']}: {n} tasks on {where}", flush=True)
    rows, paths, wall = sweep(spec, out=a.out, scheduler=a.scheduler, workers=a.workers,
                              threads_per_worker=a.threads_per_worker, progress=not a.quiet and sys.stderr.isatty(),
                              force=a.force)
    failed = [r for r in rows if r.get("status") != "ok"]
    print(f"{len(rows) - len(failed)} tasks ok, {len(failed)} failed, {wall:.1f} s; wrote " + ", ".join(paths))
    for r in failed[:5]:
        print(f"  failed: {r.get('scene')} {r.get('method')}: {r['status']}")
    return 0 if not failed else 1


def _cmd_tables(a):
    from .tables.report import run_tables, summary_line, unreliable

    log = (lambda m: print(m, file=sys.stderr, flush=True)) if not a.quiet else (lambda m: None)
    only = [k for k in a.only.split(",") if k] if a.only else None
    reports = run_tables(a.out, quick=a.quick, only=only, log=log)
    bad = sum(unreliable(r, c) for r in reports for c in r.claims)
    if bad:  # shown under --quiet too: the verdicts below it are not to be trusted
        print(f"refraction-ref: warning: the machine was busy (other processes used up to "
              f"{100 * max(r.other_load for r in reports):.0f}% of the CPUs); {bad} timing verdicts are marked "
              "unreliable in claims.csv and tables.md", file=sys.stderr, flush=True)
    print(f"{summary_line(reports)}; wrote {os.path.join(a.out, 'tables.md')}")
    return 0


def _cmd_warmup(a):
    from .graph import method_names
    from .warm import compile_report, kernels_cached, warm

    from .scene import load_scene

    for m in a.method or method_names():
        t0, before = time.perf_counter(), kernels_cached(m)
        with compile_report(m):  # a bar of kernels on terminals, a line each way in logs
            warm(m)
        print(f"{m}: kernels {'already cached' if before else 'compiled and cached'} "
              f"({time.perf_counter() - t0:.1f} s)", flush=True)
        for path in a.scene or ():
            # a scene's own plan (e.g. caustics: the light-view trace, splat, gather) compiles kernels the
            # default scene's plan does not use; warming it here keeps later processes from compiling them
            t0 = time.perf_counter()
            warm(m, load_scene(path))
            print(f"{m}: {os.path.basename(path)}'s kernels ready ({time.perf_counter() - t0:.1f} s)", flush=True)
    return 0


def _method_help(argv):
    """``--method``'s help: each method with its :attr:`~refraction_ref.graph.Method.label`.

    The labels need the methods' modules (a second or more to import), so
    they are listed only when help is asked for; otherwise the names.
    """
    from .graph import load_builtin_methods, method_names

    args = sys.argv[1:] if argv is None else argv
    if not any(x in ("-h", "--help") for x in args):
        return "one of " + ", ".join(method_names())
    return ", ".join(f"{m.name} ({m.label or m.doc})" for m in load_builtin_methods().values())


def main(argv=None):
    """The ``refraction-ref`` command line.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit status: 0 success, 1 a check or sweep that failed, 2 a
        usage error or an input that cannot be used (the message names it).
    """
    p = _Parser(prog="refraction-ref",
                description="CPU reference renderer for refraction through transparent objects.")
    from . import __version__

    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render", help="render a scene (default: the bundled glass bunny)")
    r.add_argument("scene", nargs="?", default=None, help="scene JSON (docs/oracle.md); omit for the default scene")
    from .graph import method_names

    r.add_argument("--method", default="imagespace", choices=list(method_names()), help=_method_help(argv))
    r.add_argument("--out", default="out/render", help="output prefix: PREFIX.npz and PREFIX.png")
    r.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scene key, e.g. --set imagespace.iterations=10 (repeatable)")
    r.add_argument("--force", action="store_true", help="overwrite existing output files")
    r.add_argument("--quiet", action="store_true",
                   help="no progress bar and no stage report: the output is the line of files written")
    r.add_argument("--keep", metavar="STAGES", default=None,
                   help="also write stage buffers as stage.<stage>.<buffer> (docs/oracle.md): 'stages' for "
                        "every stage, or a comma list of stage names, e.g. --keep peel,trace")
    r.set_defaults(fn=_cmd_render)
    c = sub.add_parser("compare", help="diff two runs: exit-direction error, interfaces, status, image RMSE")
    c.add_argument("a", help="run to test (.npz)")
    c.add_argument("b", help="reference run (.npz), e.g. --method exact")
    c.add_argument("--json", action="store_true", help="print the statistics as JSON")
    c.add_argument("--plot", metavar="PNG", help="also write images, error map and status maps to PNG "
                   "(water runs: images and caustic maps)")
    c.add_argument("--force", action="store_true",
                   help="compare runs of different scenes anyway (by default refused, naming the first key that "
                        "differs), and replace an existing --plot PNG")
    c.set_defaults(fn=_cmd_compare)
    s = sub.add_parser("scene", help="print the resolved scene (defaults filled in) as JSON")
    s.add_argument("scene", nargs="?", default=None, help="scene JSON (docs/oracle.md); omit for the default scene")
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scene key, e.g. --set camera.width=64 or a whole block, --set "
                        "'objects.0={\"mesh\": \"sphere\"}' (repeatable)")
    s.add_argument("--to", nargs=2, metavar=("FORMAT", "OUT"),
                   help="export instead of printing: 'mitsuba OUT.xml' writes a Mitsuba 3 scene (meshes and "
                        "environment bitmap beside it; needs the crosscheck extra)")
    s.add_argument("--bsdf", default="dielectric", choices=("dielectric", "refract"),
                   help="with --to mitsuba: Mitsuba's dielectric (default) or the Fresnel-free refraction of "
                        "the exact references (plugin refraction_ref_refract, registered from Python)")
    s.add_argument("--force", action="store_true", help="with --to: replace existing files")
    s.set_defaults(fn=_cmd_scene)
    x = sub.add_parser("crosscheck", help="the exact references against Mitsuba 3, per golden case (Markdown report)")
    x.add_argument("--out", default="out/crosscheck", help="folder for crosscheck.md, crosscheck.json, figures")
    x.add_argument("--only", metavar="NAME,...", help="only these golden cases")
    x.add_argument("--parts", default="paths,images,caustics", help="paths, images, caustics (default all)")
    x.add_argument("--report", metavar="FILE.md", help="write the Markdown report here (default OUT/crosscheck.md; "
                                                     "figure links relative to it)")
    x.add_argument("--workers", type=int, metavar="N", help="run the cases on a LocalCluster of N worker processes")
    x.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="run the cases on this Dask cluster")
    x.add_argument("--merge", metavar="FILE.json", help="keep the cases of this earlier crosscheck.json that this "
                                                        "run does not redo (the report then lists them all)")
    x.add_argument("--quiet", action="store_true", help="no progress lines")
    x.set_defaults(fn=_cmd_crosscheck)
    g = sub.add_parser("golden", help="the conformance kit's golden suite")
    gsub = g.add_subparsers(dest="golden_cmd", required=True)
    gb = gsub.add_parser("build", help="render the catalogue with the oracle into DIR (arrays, manifest)")
    gb.add_argument("dir", help="folder of the suite (created if missing)")
    gb.add_argument("--only", metavar="NAME,...", help="only these cases (the others in DIR are kept)")
    gb.add_argument("--quiet", action="store_true", help="no progress bar (it shows only on terminals)")
    gb.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                    help="build the cases as tasks of this Dask cluster (the suite is the same as a local build's)")
    gb.add_argument("--workers", type=int, metavar="N",
                    help="build the cases on a LocalCluster of N single-thread worker processes")
    gb.set_defaults(fn=_cmd_golden_build)
    k = sub.add_parser("check", help="judge a backend's outputs against a golden suite; exit 1 on any failure")
    k.add_argument("candidate", help="folder with <case>/result.npz per case")
    k.add_argument("--golden", required=True, help="the golden suite (refraction-ref golden build)")
    k.add_argument("--require", action="append", metavar="KEY", help="a key every case must supply (repeatable)")
    k.add_argument("--report", help="folder for report.md, summary.json and panels (default CANDIDATE/report)")
    k.add_argument("--cases", metavar="NAME,...", help="judge only these cases")
    k.add_argument("--no-panels", action="store_true", help="no PNG panels for failures")
    k.add_argument("--allow-extra", action="store_true",
                   help="accept keys the contract does not have (listed in the report, not judged); by default "
                        "they fail the case, so a typo'd key cannot pass unjudged")
    k.set_defaults(fn=_cmd_check)
    w = sub.add_parser("sweep", help="run a grid of scenes x methods x knobs on dask.distributed (error vs time)")
    w.add_argument("spec", help="sweep spec (JSON; see docs/sweep.md)")
    w.add_argument("--out", default="out/sweep",
                   help="folder for NAME.csv and NAME.png (and NAME.parquet where pyarrow is installed)")
    w.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="an existing dask cluster (default: a LocalCluster)")
    w.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes (default 2)")
    w.add_argument("--threads-per-worker", type=int, default=1, help="threads per LocalCluster worker (default 1)")
    w.add_argument("--quiet", action="store_true", help="no progress bar (it shows only on terminals)")
    w.add_argument("--force", action="store_true", help="replace an existing NAME.csv, NAME.png, NAME.parquet")
    w.set_defaults(fn=_cmd_sweep)
    t = sub.add_parser("tables", help="reproduce every paper's tables and check their claims (Markdown report)")
    t.add_argument("--out", default="out/tables", help="folder for tables.md, claims.csv, one CSV per table, plots")
    t.add_argument("--quick", action="store_true", help="reduced sizes (the CI smoke run, about 1.5 min)")
    t.add_argument("--only", metavar="PAPER,...", help="chaudhari, sun, tipprasert (default: all)")
    t.add_argument("--quiet", action="store_true", help="no progress lines")
    t.set_defaults(fn=_cmd_tables)
    u = sub.add_parser("warmup", help="compile every method's kernels for its default scene now (first run only; "
                                      "later runs load them from Numba's cache)")
    u.add_argument("--method", action="append", choices=list(method_names()),
                   help="only this method (repeatable; default: every method)")
    u.add_argument("--scene", action="append", metavar="SCENE",
                   help="also the kernels this scene's plan needs, for each method named (repeatable)")
    u.set_defaults(fn=_cmd_warmup)
    a = p.parse_args(argv)
    from .compare import CompareError
    from .files import NotNpzError, OutputError
    from .golden.check import CheckError
    from .validation import SceneError
    from .sweep import SweepError
    from .tables.report import TablesError

    try:
        return a.fn(a)
    except (SceneError, CompareError, CheckError, SweepError, TablesError, FileExistsError,
            FileNotFoundError, OutputError, NotNpzError, UsageError) as e:
        # one line whatever the user typed: a control character in a key or path is shown escaped
        msg = "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in str(e))
        print(f"refraction-ref: error: {msg}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # the reader left (`refraction-ref scene | head`): stop quietly, as a shell tool does; stdout goes to
        # devnull so that the interpreter's own flush at exit does not raise again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
