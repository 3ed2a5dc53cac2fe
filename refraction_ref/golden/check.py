"""``refraction-ref check CANDIDATE_DIR --golden DIR``: judge a backend's outputs against the golden suite.

A candidate folder has the suite's layout: ``CANDIDATE_DIR/<case>/result.npz``
holding the keys the backend produces (final keys such as ``exit_dir`` and
stage buffers such as ``stage.peel.ldi``), with the golden shapes and
dtypes. Every key the candidate supplies is judged by its tolerance
(:mod:`.tolerances`, recorded per key in the manifest); ``require`` makes a
key mandatory. Per case the report names the **earliest failing stage**:
walking the method's stages in the graph's order (recorded in the
manifest), the first whose buffers fail; that is the pass to fix.

A verdict cannot pass by accident: the run fails when any case fails, when
a requested case is missing, when a case has no key of the contract to
judge, and when a key is not in the contract (``allow_extra`` accepts a
backend's own keys, listed in the report). A suite without its completion
marker (written last by ``golden build``) is refused.

Failures are *located* (:mod:`.tolerances`): differences are allowed only
inside an ambiguity mask computed from the golden (silhouettes, status
boundaries, depth discontinuities of the maps); elsewhere the allowance is a
fraction of the informative elements (non-empty words, covered pixels,
present layers, lit texels). A downstream buffer whose upstream input
differs within tolerance is judged against what that difference explains:
for the image-space method the layer counts and the LDI against the
candidate's own bitmask, the search bounds against the candidate's own LDI,
the trace's positions against the oracle's trace on the candidate's own LDI,
the photons' exits against the light's passes on its own light LDI and their
hits against the march of its own photons, each run through the oracle's pass
(float32 depths move positions beyond float64's tolerance through the
normals' central differences: docs/oracle.md, "Float32 rasterizers").

Writes ``report.md`` (per case and key: pass or fail, the measured error
beside the allowance and the tolerance's rationale, the earliest failing
stage), ``summary.json``, and per failing key the mask of located failing
elements (``<case>__<key>.fail.npy``) and a PNG panel (candidate, golden,
difference with the failures marked, naming the layer or component shown).

A case is judged by :mod:`.judging`, over the masks and ties of :mod:`.masks`,
the photon matching of :mod:`.photons` and the replays of :mod:`.replay`; the
panels are :mod:`.panels`' and the Markdown :mod:`.report`'s.
"""

from __future__ import annotations

import hashlib
import json
import os
import time

from ..contract import CONTRACT_VERSION
from ..files import atomic_open
from .build import COMPLETE
from .judging import CheckSettings, judge_case
from .report import format_report

__all__ = ["check", "CheckError", "CheckReport", "CaseReport", "format_report"]


class CheckError(ValueError):
    """The golden suite itself cannot be used (missing, incomplete, unreadable, another contract version)."""


class CaseReport(dict):
    """One case's verdict: a dict (``ok``, ``method``, ``problems``, ``keys``, ``extra``,
    ``earliest_failing_stage``) with the same names as attributes, and ``rows``: one dict per key judged."""

    ok = property(lambda self: bool(self["ok"]))
    method = property(lambda self: self["method"])
    problems = property(lambda self: self["problems"])
    earliest_failing_stage = property(lambda self: self["earliest_failing_stage"])
    extra = property(lambda self: self["extra"])

    @property
    def rows(self):
        """Per key judged: ``{key, stage, ok, kind, failing, allowed, detail, why}``."""
        return [dict(key=k, **{f: j.get(f) for f in ("stage", "ok", "kind", "failing", "allowed", "detail", "why")})
                for k, j in self["keys"].items()]

    @property
    def failing_keys(self):
        return [k for k, j in self["keys"].items() if not j["ok"]]


class CheckReport(dict):
    """What :func:`check` returns: a dict (``ok``, ``cases``, ``golden``, ``candidate``, ``seconds``,
    ``report``) with attributes ``ok``, ``cases`` (name -> :class:`CaseReport`), ``rows`` (one per case
    and key), ``earliest_failing_stage`` (name -> stage or None) and ``text`` (the Markdown report)."""

    ok = property(lambda self: bool(self["ok"]))
    cases = property(lambda self: self["cases"])

    @property
    def rows(self):
        return [dict(case=name, **r) for name, c in self["cases"].items() for r in c.rows]

    @property
    def earliest_failing_stage(self):
        return {name: c["earliest_failing_stage"] for name, c in self["cases"].items()}

    @property
    def text(self):
        return format_report(self)

    def __repr__(self):
        n_ok = sum(c.ok for c in self.cases.values())
        return f"<CheckReport {'PASS' if self.ok else 'FAIL'}: {n_ok} of {len(self.cases)} cases pass>"


def _load_manifest(golden):
    p = os.path.join(golden, "manifest.json")
    if not os.path.isfile(p):
        raise CheckError(f"check: '{golden}' is not a golden suite (no manifest.json); build one with "
                         f"'refraction-ref golden build {golden}'")
    with open(p, "rb") as f:
        raw = f.read()
    m = json.loads(raw)
    if m.get("contract_version") != CONTRACT_VERSION:
        raise CheckError(f"check: the golden suite '{golden}' follows contract_version {m.get('contract_version')}, "
                         f"this refraction_ref follows {CONTRACT_VERSION} (docs/oracle.md, changelog); rebuild it "
                         "with 'refraction-ref golden build'")
    mk = os.path.join(golden, COMPLETE)
    done = None
    if os.path.isfile(mk):
        with open(mk) as f:
            done = json.load(f)
    if done is None or done.get("manifest_sha256") != hashlib.sha256(raw).hexdigest():
        raise CheckError(f"check: the golden suite '{golden}' is incomplete: "
                         + ("it has no completion marker (" + COMPLETE + ", written last by 'golden build'), so its "
                            "build stopped or is still running" if done is None else
                            f"its manifest changed after the build completed ({COMPLETE} names another)")
                         + f"; finish it with 'refraction-ref golden build {golden}'")
    return m


def check(candidate, golden, require=(), report=None, panels=True, cases=None, allow_extra=False):
    """Judge a candidate folder against a golden suite.

    Parameters
    ----------
    candidate, golden : str
        Folders (see the module docstring).
    require : sequence of str
        Keys every case must supply (a missing one fails the case).
    report : str, optional
        Folder for ``report.md``, ``summary.json``, masks and panels (default: ``candidate/report``).
    panels : bool
        Write a PNG panel per failing key (the ``.fail.npy`` masks are written regardless).
    cases : sequence of str, optional
        Judge only these cases of the suite (each must be in the candidate folder).
    allow_extra : bool
        Accept keys the contract does not have (listed per case in ``extra``); by default they fail
        the case (a typo such as ``exit_dirr`` must not pass unjudged).

    Returns
    -------
    CheckReport
        ``ok`` (every case requested passed, and at least one was judged), ``cases`` (per case a
        :class:`CaseReport`: ``ok``, ``earliest_failing_stage``, ``problems``, ``extra``, ``keys`` with
        each key's judgement), ``seconds``, ``report`` (the path of ``report.md``).

    Raises
    ------
    CheckError
        When the golden suite cannot be used (no manifest, incomplete, another contract version) or the
        candidate folder does not exist.
    """
    t0 = time.perf_counter()
    man = _load_manifest(golden)
    report = report or os.path.join(candidate, "report")
    if not os.path.isdir(candidate):
        raise CheckError(f"check: the candidate folder '{candidate}' does not exist")
    if isinstance(cases, str):
        cases = [c for c in cases.split(",") if c.strip()]
    names = list(man["cases"]) if not cases else [c.strip() for c in cases]
    settings = CheckSettings(candidate, golden, tuple(require), report, panels, allow_extra)
    out = CheckReport(ok=False, golden=os.path.abspath(golden), candidate=os.path.abspath(candidate),
                      contract_version=CONTRACT_VERSION, cases={})
    for name in names:
        res = CaseReport(ok=False, problems=[], keys={}, extra=[], earliest_failing_stage=None, method=None)
        out["cases"][name] = res
        judge_case(res, name, man["cases"].get(name), settings)
    out["ok"] = bool(out["cases"]) and all(c["ok"] for c in out["cases"].values())
    out["seconds"] = time.perf_counter() - t0
    os.makedirs(report, exist_ok=True)
    with atomic_open(os.path.join(report, "summary.json"), "w") as f:
        json.dump(out, f, indent=1, default=float)
    with atomic_open(os.path.join(report, "report.md"), "w") as f:
        f.write(format_report(out))
    out["report"] = os.path.join(report, "report.md")
    return out
