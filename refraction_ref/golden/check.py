"""``refraction-ref check CANDIDATE_DIR --golden DIR``: judge a backend's outputs against the golden suite.

A candidate folder has the suite's layout: ``CANDIDATE_DIR/<case>/result.npz``
holding the keys the backend produces (final keys such as ``exit_dir`` and
stage buffers such as ``stage.peel.ldi``), with the golden shapes and
dtypes. Every key the candidate supplies is judged by its tolerance
(:mod:`.tolerances`, recorded per key in the manifest); ``require`` makes a
key mandatory. Per case the report names the **earliest failing stage**:
walking the method's stages in order, the first whose buffers fail; that
is the pass to fix.

Writes ``report.md`` (per case and key: pass or fail, the measured error
beside the tolerance, the earliest failing stage), ``summary.json`` and a
PNG panel (candidate, golden, difference) per failing key into the report
folder. Never a traceback for a bad candidate: a missing case, a file that
cannot be read, a wrong shape or dtype, NaN where the contract forbids it,
and a suite from another contract version each get a clear message.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from ..contract import CONTRACT_VERSION
from ..files import atomic_open, savefig_atomic
from .tolerances import judge

__all__ = ["check", "CheckError"]


class CheckError(ValueError):
    """The golden suite itself cannot be used (missing, unreadable, another contract version)."""


def _load_manifest(golden):
    p = os.path.join(golden, "manifest.json")
    if not os.path.isfile(p):
        raise CheckError(f"check: '{golden}' is not a golden suite (no manifest.json); build one with "
                         f"'refraction-ref golden build {golden}'")
    with open(p) as f:
        m = json.load(f)
    if m.get("contract_version") != CONTRACT_VERSION:
        raise CheckError(f"check: the golden suite '{golden}' follows contract_version {m.get('contract_version')}, "
                         f"this refraction_ref follows {CONTRACT_VERSION} (docs/oracle.md, changelog); rebuild it "
                         "with 'refraction-ref golden build'")
    return m


def _dtype_problem(c, spec):
    g = np.dtype(spec["dtype"])
    if c.dtype.kind != g.kind and not (g.kind in "iu" and c.dtype.kind in "iu"):
        return f"dtype {c.dtype} where the contract has {g}"
    if g.kind == "f" and c.dtype.itemsize < min(g.itemsize, 4):
        return f"dtype {c.dtype} (under 32 bits) where the contract has {g}"
    return None


def _popcount(words):
    """Set bits per pixel of (H, W, K) unsigned words."""
    w = np.ascontiguousarray(words)
    return np.unpackbits(w.view(np.uint8).reshape(w.shape[:-1] + (-1,)), axis=-1).sum(axis=-1)


def _panel(path, key, c, g, bad, kind=None):
    """Candidate, golden and their difference for a failing array (2D pictures of what can be shown).

    Bit words (H, W, K) show the set bits per pixel and the bits that differ
    (popcount of XOR); unit vectors (``kind == 'angle'``, (..., 3)) show the
    directions as colours and the angle between them in degrees; anything
    else its middle 2D slice (vectors by their norm) and ``|c - g|``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    c, g = np.asarray(c), np.asarray(g)
    if c.shape != g.shape or c.ndim < 2:
        return None

    def img(a):
        a = np.asarray(a, np.float64)
        while a.ndim > 3 or (a.ndim == 3 and a.shape[-1] not in (3,)):
            a = a[a.shape[0] // 2] if a.ndim > 3 or a.shape[0] > 3 else a[0]
        if a.ndim == 3:
            a = np.linalg.norm(np.nan_to_num(a), axis=-1)
        return np.atleast_2d(a)

    rgb = None
    if np.issubdtype(c.dtype, np.unsignedinteger) and c.ndim == 3:
        ci, gi, diff = _popcount(c), _popcount(g), _popcount(c ^ g)
        names = ("set bits per pixel", "bits that differ")
    elif kind == "angle" and c.shape[-1] == 3 and c.ndim in (2, 3):
        cf, gf = np.asarray(c, np.float64), np.asarray(g, np.float64)
        if c.ndim == 2:  # (N, 3): a strip
            cf, gf = cf[None], gf[None]
        unit = lambda a: a / np.maximum(np.linalg.norm(np.nan_to_num(a), axis=-1, keepdims=True), 1e-300)  # noqa: E731
        cos = np.clip(np.sum(unit(np.nan_to_num(cf)) * unit(np.nan_to_num(gf)), axis=-1), -1.0, 1.0)
        diff = np.degrees(np.arccos(cos))
        diff[~(np.all(np.isfinite(cf), -1) & np.all(np.isfinite(gf), -1))] = np.nan
        rgb = [np.clip(0.5 + 0.5 * np.nan_to_num(unit(a)), 0.0, 1.0) for a in (cf, gf)]
        ci = gi = None
        names = ("direction as colour", "angle between them (deg)")
    else:
        ci, gi = img(c), img(g)
        if ci.ndim != 2 or ci.shape != gi.shape:
            return None
        diff = np.abs(ci - gi)
        names = ("", "|candidate - golden|")
    fig = Figure(figsize=(12, 4))
    FigureCanvasAgg(fig)
    ax = fig.subplots(1, 3)
    if rgb is not None:
        for x, a, t in ((ax[0], rgb[0], "candidate"), (ax[1], rgb[1], "golden")):
            x.imshow(a, interpolation="nearest")
            x.set_title(f"{t}: {key}\n{names[0]}", fontsize=9)
    else:
        fin = np.isfinite(gi)
        lo, hi = (float(np.min(gi[fin])), float(np.max(gi[fin]))) if fin.any() else (0.0, 1.0)
        for x, a, t in ((ax[0], ci, "candidate"), (ax[1], gi, "golden")):
            im = x.imshow(a, vmin=lo, vmax=hi if hi > lo else lo + 1, cmap="viridis", interpolation="nearest")
            x.set_title(f"{t}: {key}" + (f"\n{names[0]}" if names[0] else ""), fontsize=9)
            fig.colorbar(im, ax=x, fraction=0.046)
    im = ax[2].imshow(diff, cmap="magma", interpolation="nearest")
    ax[2].set_title(names[1], fontsize=9)
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    for x in ax:
        x.set_xticks([])
        x.set_yticks([])
    fig.tight_layout()
    return savefig_atomic(fig, path, dpi=70)


def check(candidate, golden, require=(), report=None, panels=True, cases=None):
    """Judge a candidate folder against a golden suite.

    Parameters
    ----------
    candidate, golden : str
        Folders (see the module docstring).
    require : sequence of str
        Keys every case must supply (a missing one fails the case).
    report : str, optional
        Folder for ``report.md``, ``summary.json`` and panels (default:
        ``candidate/report``).
    panels : bool
        Write a PNG panel per failing key.
    cases : sequence of str, optional
        Judge only these cases of the suite.

    Returns
    -------
    dict
        ``ok`` (bool), ``cases`` (per case: ``ok``, ``earliest_failing_stage``,
        ``problems``, ``keys`` with the judgement of each), ``seconds``.

    Raises
    ------
    CheckError
        When the golden suite cannot be used.
    """
    t0 = time.perf_counter()
    man = _load_manifest(golden)
    report = report or os.path.join(candidate, "report")
    if not os.path.isdir(candidate):
        raise CheckError(f"check: the candidate folder '{candidate}' does not exist")
    names = list(man["cases"]) if not cases else list(cases)
    out = {"ok": True, "golden": os.path.abspath(golden), "candidate": os.path.abspath(candidate),
           "contract_version": CONTRACT_VERSION, "cases": {}}
    for name in names:
        entry = man["cases"].get(name)
        res = {"ok": True, "problems": [], "keys": {}, "earliest_failing_stage": None, "method": None}
        out["cases"][name] = res
        if entry is None:
            res["ok"] = False
            res["problems"].append(f"the suite has no case '{name}'")
            continue
        res["method"] = entry["method"]
        cpath = os.path.join(candidate, name, "result.npz")
        if not os.path.isfile(cpath):
            res["ok"] = False
            res["problems"].append(f"missing: {os.path.join(name, 'result.npz')} (the backend did not run this case)")
            continue
        try:
            with np.load(cpath, allow_pickle=False) as z:
                cand = {k: z[k] for k in z.files if k != "meta"}
        except Exception as e:  # any unreadable file is a problem of the candidate, reported, not raised
            res["ok"] = False
            res["problems"].append(f"{cpath} could not be read ({type(e).__name__}: {e})")
            continue
        with np.load(os.path.join(golden, name, "golden.npz"), allow_pickle=False) as z:
            gold = {k: z[k] for k in z.files}
        batches = {}
        if "batches" in entry:
            with np.load(os.path.join(golden, name, "batches.npz"), allow_pickle=False) as z:
                batches = {k: z[k] for k in z.files}
        for k in require:
            if k not in cand:
                res["ok"] = False
                res["problems"].append(f"required key '{k}' is missing")
        unknown = sorted(k for k in cand if k not in entry["keys"])
        if unknown:
            res["problems"].append(f"keys the contract does not have (ignored): {', '.join(unknown[:8])}"
                                   + (" ..." if len(unknown) > 8 else ""))
        for k, spec in entry["keys"].items():
            if k not in cand:
                continue
            c, g = cand[k], gold[k]
            j = {"stage": spec["stage"], "kind": spec["tolerance"]["kind"], "tolerance": spec["tolerance"]}
            res["keys"][k] = j
            if tuple(c.shape) != tuple(spec["shape"]):
                j.update(ok=False, detail=f"shape {tuple(c.shape)} where the golden has {tuple(spec['shape'])}")
            elif _dtype_problem(c, spec):
                j.update(ok=False, detail=_dtype_problem(c, spec))
            else:
                try:
                    r = judge(c, g, spec["tolerance"], batches.get(k))
                except ValueError as e:
                    r = {"ok": False, "detail": str(e), "failing": 1.0, "allowed": 0.0, "error": {}, "bad": None}
                bad = r.pop("bad")
                j.update(r)
                if not r["ok"] and panels and bad is not None:
                    os.makedirs(report, exist_ok=True)
                    pp = _panel(os.path.join(report, f"{name}__{k}.png"), k, c, g, bad, j["kind"])
                    if pp:
                        j["panel"] = os.path.basename(pp)
            if not j["ok"]:
                res["ok"] = False
        order = entry["stages"]
        failing = [j["stage"] for j in res["keys"].values() if not j["ok"]]
        if failing:
            res["earliest_failing_stage"] = min(failing, key=lambda s: order.index(s) if s in order else len(order))
        out["ok"] &= res["ok"]
    out["seconds"] = time.perf_counter() - t0
    os.makedirs(report, exist_ok=True)
    with atomic_open(os.path.join(report, "summary.json"), "w") as f:
        json.dump(out, f, indent=1, default=float)
    with atomic_open(os.path.join(report, "report.md"), "w") as f:
        f.write(format_report(out))
    out["report"] = os.path.join(report, "report.md")
    return out


def format_report(out):
    """The Markdown report of a :func:`check`."""
    n_ok = sum(1 for c in out["cases"].values() if c["ok"])
    lines = [f"# Conformance report: {'PASS' if out['ok'] else 'FAIL'}", "",
             f"{n_ok} of {len(out['cases'])} cases pass; candidate `{out['candidate']}` against the golden suite "
             f"`{out['golden']}` (contract_version {out['contract_version']}).", "",
             "| case | method | result | earliest failing stage | keys judged |", "|---|---|---|---|---|"]
    for name, c in out["cases"].items():
        lines.append(f"| {name} | {c['method'] or ''} | {'pass' if c['ok'] else '**FAIL**'} | "
                     f"{c['earliest_failing_stage'] or ''} | {len(c['keys'])} |")
    for name, c in out["cases"].items():
        lines += ["", f"## {name}: {'pass' if c['ok'] else 'FAIL'}"]
        if c["earliest_failing_stage"]:
            lines.append(f"\nEarliest failing stage: **{c['earliest_failing_stage']}** (fix this pass first).")
        for p in c["problems"]:
            lines.append(f"\n- {p}")
        if c["keys"]:
            lines += ["", "| key | stage | tolerance | measured | failing / allowed | result |", "|---|---|---|---|---|---|"]
            for k, j in c["keys"].items():
                frac = (f"{100 * j['failing']:.3g}% / {100 * j['allowed']:.3g}%" if "failing" in j else "")
                panel = f" ([panel]({j['panel']}))" if j.get("panel") else ""
                detail = j.get("detail", "").replace("|", "\\|")  # |c| in a detail must not split the row
                lines.append(f"| `{k}` | {j['stage']} | {j['kind']} | {detail} | {frac} | "
                             f"{'pass' if j['ok'] else '**FAIL**'}{panel} |")
    return "\n".join(lines) + "\n"
