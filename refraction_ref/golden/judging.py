"""One case of a check judged key by key: the contract's keys, each by its tolerance, located and explained.

The keys are judged in the method's stage order (recorded in the manifest);
each by its tolerance (:mod:`.tolerances`) over the golden's ambiguity mask and
ties (:mod:`.masks`), a photon buffer of another count photon by photon
(:mod:`.photons`), an image-space key that fails against the golden also
against the oracle's pass replayed on the candidate's own passing upstream
buffers (:mod:`.replay`). A failing key leaves its mask of located failures
and a panel (:mod:`.panels`).
"""

from __future__ import annotations

import difflib
import json
import os
from typing import NamedTuple

import numpy as np

from ..files import NotNpzError, atomic_path, load_npz
from .masks import ambiguity, ambiguity_context, face_ties, margin_ties, stopped_strict, weight_mask
from .panels import failure_panel
from .photons import judge_photons, photon_set
from .replay import replay, replay_group
from .tolerances import judge, tolerance_for

__all__ = ["CheckSettings", "judge_case", "read_result"]


class CheckSettings(NamedTuple):
    """What one check reads, where it writes, and what it accepts (:func:`~refraction_ref.golden.check.check`)."""

    #: the candidate's folder (``<case>/result.npz``)
    candidate: str
    #: the golden suite's folder
    golden: str
    #: keys every case must supply
    require: tuple
    #: the report's folder (masks, panels)
    report: str
    #: write a PNG panel per failing key
    panels: bool
    #: accept keys the contract does not have
    allow_extra: bool


def read_result(path):
    """The candidate's arrays, or a problem sentence (missing, not a zip, unreadable).

    Parameters
    ----------
    path : str
        The candidate's ``result.npz``.

    Returns
    -------
    arrays : dict of str to ndarray or None
        Every array but ``meta``; None when the file cannot be read.
    problem : str or None
        ``"missing"``, or why the file cannot be read; None when it was read.
    """
    try:
        with load_npz(path, "candidate result") as z:
            return {k: z[k] for k in z.files if k != "meta"}, None
    except FileNotFoundError:
        return None, "missing"
    except NotNpzError as e:
        return None, str(e)
    except Exception as e:  # noqa: BLE001 - a broken member of the zip: a problem of the candidate, reported
        return None, f"{path} could not be read ({type(e).__name__}: {e})"


def _dtype_problem(c, key_entry):
    """Dtypes are judged as documented: the golden's dtype exactly (byte order aside)."""
    g = np.dtype(key_entry["dtype"])
    if c.dtype.newbyteorder("=") != g.newbyteorder("="):
        return (f"dtype {c.dtype} where the contract has {g.newbyteorder('=')} (docs/oracle.md); write it as "
                f"{g.newbyteorder('=')}")
    return None


def _same_bytes(a, b):
    """Two arrays with the same dtype, shape and bytes."""
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and np.ascontiguousarray(a).tobytes() == \
        np.ascontiguousarray(b).tobytes()


def _safe(name):
    return "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in name)


class _Case:
    """One case's arrays and what its judging has found so far (the keys passed, the replays and the photon
    matchings computed once, the first key of each golden hash)."""

    def __init__(self, name, entry, cand, settings):
        golden = settings.golden
        with np.load(os.path.join(golden, name, "golden.npz"), allow_pickle=False) as z:
            self.gold = {k: z[k] for k in z.files}
        self.batches = {}
        if "batches" in entry:
            with np.load(os.path.join(golden, name, "batches.npz"), allow_pickle=False) as z:
                self.batches = {k: z[k] for k in z.files}
        self.name, self.entry, self.cand, self.settings = name, entry, cand, settings
        self.method = entry["method"]
        self.pics = ambiguity_context(self.gold)
        self.passed = {}
        self.explained = {}  # (replay group, light) -> {key: the oracle's pass run on the candidate's upstream}
        self.judged_as = {}  # (golden sha256, tolerance) -> the key judged: a byte-identical copy is judged once
        self.photon_cache = {}


def _contract_problems(res, cand, entry, settings):
    """The required keys missing and the keys the contract does not have, into ``res``; whether they fail."""
    problems = res["problems"]
    failed = False
    for k in settings.require:
        if k not in cand:
            failed = True
            problems.append(f"required key '{k}' is missing")
    unknown = sorted(k for k in cand if k not in entry["keys"])
    if unknown:
        if settings.allow_extra:
            res["extra"] = unknown
            problems.append(f"keys the contract does not have, accepted (allow_extra) and not judged: "
                            f"{', '.join(unknown)}")
        else:
            failed = True
            hints = []
            for u in unknown:
                near = difflib.get_close_matches(u, list(entry["keys"]), n=1)
                hints.append(f"'{u}'" + (f" (did you mean '{near[0]}'?)" if near else ""))
            problems.append(f"keys the contract does not have: {', '.join(hints)}; rename them, or pass "
                            "--allow-extra (allow_extra=True) for a backend's own keys")
    return failed


def _judge_reshaped(case, k, c, g, tol):
    """A key of another shape than the golden's: a photon buffer matched photon by photon, else a failure."""
    key_entry = case.entry["keys"][k]
    r = None
    if _dtype_problem(c, key_entry) is None:
        try:
            r = judge_photons(k, np.asarray(c), np.asarray(g), tol, case.cand, case.gold, case.photon_cache)
        except ValueError:
            r = None
    if r is not None:
        r.pop("bad")  # over the golden's photons, not the candidate's: no mask file
        return r
    ps = photon_set(k)
    have = [a for a in (ps[1] if ps else ()) if a in case.cand and np.shape(case.cand[a])[:1] == np.shape(c)[:1]]
    hint = ("" if not ps else
            f" (its photons could not be matched along `{have[0]}`, which has the same count)" if have else
            f" (supply one of {', '.join(f'`{a}`' for a in ps[1])} with this key's photon count, "
            f"{np.shape(c)[0]}, to have the photons matched one by one)")
    return {"ok": False, "detail": f"shape {tuple(c.shape)} where the golden has {tuple(key_entry['shape'])}" + hint}


def _ambiguous(case, k, c, g, tol):
    """The key's ambiguity mask with its ties (shared receiver edges, shadow-test margins), or None."""
    amb = ambiguity(k, g, tol, case.pics, c)
    if tol.get("face_ties"):
        ties = face_ties(case.settings.golden, case.name, case.gold, k, c)
        if ties is not None:
            amb = ties if amb is None else (np.asarray(amb, bool) | ties)
    if tol.get("margin_key"):
        ties = margin_ties(case.gold, k, tol)
        if ties is not None:
            amb = ties if amb is None else (np.asarray(amb, bool) | ties)
    return amb


def _explained(case, k, c, g, judged):
    """A failing image-space key judged against the oracle's pass replayed on the candidate's own passing
    upstream buffers (:mod:`.replay`): that verdict where it passes, else ``judged`` (``(r, tol, amb)``)."""
    r, tol, amb = judged
    how = replay_group(k) if not r["ok"] and case.method == "imagespace" else None
    if how is None:
        return r
    group, light, upstream = how
    if (group, light) not in case.explained:  # once per replay, after its upstream keys were judged
        case.explained[(group, light)] = replay(group, light, case.settings.golden, case.name, case.gold,
                                                 case.cand, case.passed)
    e = case.explained[(group, light)].get(k)
    if e is None or e.shape != g.shape:
        return r
    r2 = judge(c, e.astype(g.dtype), tol, None, amb)
    if not r2["ok"]:
        return r
    own = [u for u in upstream if u in case.cand and case.passed.get(u)]
    ups = " and ".join(own) if len(own) < 3 else ", ".join(own[:-1]) + " and " + own[-1]
    r2["detail"] = (f"differs from the golden where the candidate's own {ups} (within "
                    + ("its tolerance) does" if len(own) < 2 else "their tolerances) do")
                    + "; against the oracle's pass run on " + ("it: " if len(own) < 2 else "them: ") + r2["detail"])
    r2["explained_by"] = ups
    return r2


def _judge_located(case, k, c, g, tol):
    """A key of the golden's shape and dtype judged by its tolerance, located; (verdict, failing mask)."""
    amb = _ambiguous(case, k, c, g, tol)
    try:
        r = judge(c, g, tol, case.batches.get(k), amb, judged=weight_mask(k, tol, case.gold))
    except ValueError as e:
        r = {"ok": False, "detail": str(e), "failing": 1.0, "allowed": 0.0, "error": {}, "bad": None}
    r = _explained(case, k, c, g, (r, tol, amb))
    st = stopped_strict(k, case.method, c, g, tol, case.cand, case.gold)
    if st is not None:
        sbad, sdetail = st
        r["detail"] = r.get("detail", "") + sdetail
        if np.any(sbad):
            r["ok"] = False
            rb = r.get("bad")
            r["bad"] = sbad if rb is None or np.shape(rb) != sbad.shape else (np.asarray(rb, bool) | sbad)
    bad = r.pop("bad")
    if tol.get("default"):
        r["detail"] = "default tolerance (no rule names this key): " + r["detail"]
    return r, bad


def _save_failure(case, k, j, bad):
    """A failing key's mask of located failures (``.fail.npy``) and its panel (PNG), named in its row ``j``."""
    report = case.settings.report
    stem = os.path.join(report, f"{_safe(case.name)}__{_safe(k)}")
    if bad is not None and np.any(bad):
        os.makedirs(report, exist_ok=True)
        with atomic_path(stem + ".fail.npy") as tmp:
            with open(tmp, "wb") as f:
                np.save(f, np.asarray(bad))
        j["mask"] = os.path.basename(stem + ".fail.npy")
    if case.settings.panels and (bad is not None or j.get("detail", "").startswith("dtype")):
        os.makedirs(report, exist_ok=True)
        try:
            pp = failure_panel(stem + ".png", k, case.cand[k], case.gold[k], bad, j["kind"], case.pics)
        except (ValueError, TypeError):  # a candidate array that cannot be pictured: the row says why
            pp = None
        if pp:
            j["panel"] = os.path.basename(pp)


def _judge_key(case, k, keys_judged):
    """Judge key ``k`` of the case into its row of ``keys_judged``."""
    key_entry = case.entry["keys"][k]
    # a manifest written without a key's tolerance (by hand, or by another tool): the table's, or its default
    tol = dict(key_entry.get("tolerance") or tolerance_for(k, dtype=key_entry.get("dtype")))
    c, g = case.cand[k], case.gold[k]
    j = {"stage": key_entry["stage"], "kind": tol["kind"], "tolerance": tol, "why": tol.get("why", "")}
    keys_judged[k] = j
    sig = (key_entry.get("sha256"), json.dumps(tol, sort_keys=True, default=str))
    first = case.judged_as.get(sig) if key_entry.get("sha256") else None
    if first is not None and _same_bytes(case.cand[first], c):
        f = keys_judged[first]
        j.update(ok=f["ok"], same_as=first, kind=f["kind"], why=f"as `{first}`",
                 detail=f"same as `{first}` (byte-identical to it here and in the golden): judged once there")
        case.passed[k] = bool(j["ok"])
        return
    if key_entry.get("sha256"):
        case.judged_as.setdefault(sig, k)
    bad = None
    if tuple(c.shape) != tuple(key_entry["shape"]):
        j.update(_judge_reshaped(case, k, c, g, tol))
    elif _dtype_problem(c, key_entry):
        j.update(ok=False, detail=_dtype_problem(c, key_entry))
    else:
        r, bad = _judge_located(case, k, c, g, tol)
        j.update(r)
    case.passed[k] = bool(j["ok"])
    if not j["ok"]:
        _save_failure(case, k, j, bad)


def judge_case(res, name, entry, settings):
    """Fill one case's report (``res``: ``ok``, ``method``, ``problems``, ``keys``, ``extra``,
    ``earliest_failing_stage``) in place.

    Parameters
    ----------
    res : CaseReport
        The case's report, filled in place.
    name : str
        The case.
    entry : dict or None
        The case's manifest entry (``method``, ``stages``, ``keys``); None when the suite has no such case.
    settings : CheckSettings
        The check's folders and choices.

    Returns
    -------
    None
    """
    if entry is None:
        res["problems"].append(f"the suite has no case '{name}'")
        return
    res["method"] = entry["method"]
    cand, why = read_result(os.path.join(settings.candidate, name, "result.npz"))
    if cand is None:
        res["problems"].append(f"missing: {os.path.join(name, 'result.npz')} (the backend did not run this case)"
                               if why == "missing" else why)
        return
    case = _Case(name, entry, cand, settings)
    failed = _contract_problems(res, cand, entry, settings)
    order = list(entry["stages"])
    rank = {s: i for i, s in enumerate(order)}
    # within a stage, the keys a replay may explain after the others (the light's exit points after its LDI)
    later = (lambda k: replay_group(k) is not None) if entry["method"] == "imagespace" else (lambda k: False)
    for k in sorted((k for k in entry["keys"] if k in cand),
                    key=lambda k: (rank.get(entry["keys"][k]["stage"], len(order)), later(k), k)):
        _judge_key(case, k, res["keys"])
    if not res["keys"]:
        failed = True
        res["problems"].append("no key of the contract was judged: the result holds none of the golden's keys "
                               f"({len(cand)} keys supplied; the contract's are listed in the manifest)")
    failing = [j["stage"] for j in res["keys"].values() if not j["ok"]]
    if failing:
        res["earliest_failing_stage"] = min(failing, key=lambda s: rank.get(s, len(order)))
    res["ok"] = not (failed or failing)
