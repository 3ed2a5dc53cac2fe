"""``refraction-ref tables``: every paper's tables and claims, measured here, in one Markdown report.

Each paper module returns a :class:`.common.Report`; this module runs them,
writes one CSV per table, ``claims.csv`` and ``tables.md`` (our numbers beside
the papers', the plots, and the claims marked held / not held / not comparable,
each with its rule). Nothing is written outside the output folder.

Other load: each paper is measured under a :class:`.common.LoadProbe`; when
other processes took more than :data:`.common.BUSY` of the CPUs meanwhile, a
warning is logged and that paper's timing verdicts are marked unreliable in
``claims.csv`` (column ``reliable``) and ``tables.md``.

References
----------
Chaudhari (2008) §4.2, Tables 4.1, 4.2; Sun et al. (2008) §6, Tables 1, 2;
Tipprasert (2006) ch. 5, Tables 5-1, 5-3, 5-4, 5-5.
"""

from __future__ import annotations

import csv
import importlib
import os
import time

from .common import (BUSY, BY_CONSTRUCTION, EVIDENCE, HELD, NOT_COMPARABLE, NOT_HELD, NOT_MEASURED, SPLIT,
                     LoadProbe, Report)

__all__ = ["TablesError", "PAPERS", "run_tables", "write_report", "markdown", "unreliable", "sentences",
           "sentence_verdict", "summary", "summary_line"]

class TablesError(ValueError):
    """A request the tables command cannot serve (an unknown paper)."""


#: name -> (module, paper); the order of the report
PAPERS = {
    "chaudhari": ("refraction_ref.tables.chaudhari_report", "Chaudhari 2008"),
    "sun": ("refraction_ref.tables.sun", "Sun et al. 2008"),
    "tipprasert": ("refraction_ref.tables.tipprasert", "Tipprasert 2006"),
}


def run_tables(out, quick=False, only=None, log=print):
    """Run each paper's tables and write the report into ``out``.

    Parameters
    ----------
    out : path-like
        Output folder (created).
    quick : bool
        Each paper's reduced run (the CI smoke run; about half a minute each).
    only : sequence of str, optional
        Keys of :data:`PAPERS` to run (default: all).
    log : callable
        Progress lines.

    Returns
    -------
    list of Report
    """
    only = list(PAPERS) if not only else list(only)
    bad = [k for k in only if k not in PAPERS]
    if bad:
        raise TablesError(f"tables: unknown paper {bad[0]!r} in --only; choose from {', '.join(PAPERS)}")
    out = os.fspath(out)
    os.makedirs(out, exist_ok=True)
    reports = []
    for key in only:
        mod_name, paper = PAPERS[key]
        t0 = time.perf_counter()
        try:
            mod = importlib.import_module(mod_name)
        except ModuleNotFoundError as e:
            if e.name != mod_name:  # a broken import inside the module is a bug, not an absence
                raise
            log(f"{paper}: not available in this build")
            reports.append(Report(paper, seconds=0.0))
            continue
        probe = LoadProbe()
        rep = mod.run(quick=quick, out=out, log=log)
        rep.other_load = probe.stop()
        rep.seconds = time.perf_counter() - t0
        log(f"{paper}: {len(rep.tables)} tables, {len(rep.claims)} claims in {rep.seconds:.0f} s")
        if rep.other_load > BUSY:
            n = sum(c.timing for c in rep.claims)
            log(f"warning: other processes used {100 * rep.other_load:.0f}% of the CPUs while {paper} was "
                f"measured (more than {100 * BUSY:.0f}%); its {n} timing verdicts are marked unreliable. "
                "Re-run on an idle machine to trust them.")
        reports.append(rep)
    write_report(reports, out, quick)
    return reports


def _cell(x):
    if x is None:
        return "—"
    if isinstance(x, float):
        return f"{x:.3g}" if abs(x) < 1e4 else f"{x:,.0f}"
    if isinstance(x, int) and not isinstance(x, bool) and abs(x) >= 1e4:
        return f"{x:,}"
    return str(x).replace("|", "\\|")


def _md_table(columns, rows):
    out = ["| " + " | ".join(_cell(c) for c in columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    out += ["| " + " | ".join(_cell(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def unreliable(report, claim):
    """Whether a claim's verdict rests on a timing taken while the machine was busy (:data:`.common.BUSY`).

    Parameters
    ----------
    report : Report
        The paper's report (its ``other_load``).
    claim : Claim
        One of its claims (its ``timing`` flag).

    Returns
    -------
    bool
    """
    return bool(claim.timing) and report.other_load > BUSY


def sentence_verdict(verdicts):
    """One quoted sentence's verdict from its rows' verdicts.

    Only :data:`.common.EVIDENCE` rows (held, not held) decide: all held is
    held, all not held is not held, both is :data:`.common.SPLIT`. A sentence
    with no evidence row takes, in this order, not comparable, not measured,
    by construction: a by-construction row is shown but never counts for or
    against the sentence.

    Parameters
    ----------
    verdicts : iterable of str
        The verdicts of the sentence's rows.

    Returns
    -------
    str
    """
    vs = list(verdicts)
    ev = {v for v in vs if v in EVIDENCE}
    if ev:
        return ev.pop() if len(ev) == 1 else SPLIT
    for v in (NOT_COMPARABLE, NOT_MEASURED, BY_CONSTRUCTION):
        if v in vs:
            return v
    raise ValueError("sentence_verdict: no rows")


def sentences(reports):
    """Each quoted sentence once, in the order of its first row, with its rows and its verdict.

    Parameters
    ----------
    reports : list of Report

    Returns
    -------
    list of dict
        ``id`` (``"S1"``, ...), ``paper``, ``quote``, ``sections`` (in row
        order, without repeats), ``rows`` (the (report, claim) pairs),
        ``verdicts`` (the rows' verdicts) and ``verdict`` (:func:`sentence_verdict`).
    """
    out, by = [], {}
    for r in reports:
        for c in r.claims:
            key = (c.paper, " ".join(c.quote.split()))
            if key not in by:
                by[key] = {"id": f"S{len(out) + 1}", "paper": c.paper, "quote": c.quote, "sections": [],
                           "rows": []}
                out.append(by[key])
            s = by[key]
            if c.section not in s["sections"]:
                s["sections"].append(c.section)
            s["rows"].append((r, c))
    for s in out:
        s["verdicts"] = [c.verdict for _, c in s["rows"]]
        s["verdict"] = sentence_verdict(s["verdicts"])
    return out


def _counts(verdicts, order):
    return {v: sum(x == v for x in verdicts) for v in order}


def summary(reports):
    """Counts of the report: rows by verdict, and each quoted sentence once by its verdict.

    Parameters
    ----------
    reports : list of Report

    Returns
    -------
    dict
        ``rows`` and ``sentences`` (the totals), ``row_counts`` (verdict ->
        rows, :data:`.common.VERDICTS`), ``sentence_counts`` (verdict ->
        sentences, with :data:`.common.SPLIT`), ``evidence_rows`` (rows that
        count for or against a sentence), ``unreliable`` and ``straddles`` (rows).
    """
    from .common import VERDICTS

    ss = sentences(reports)
    rows = [(r, c) for r in reports for c in r.claims]
    return {"rows": len(rows), "sentences": len(ss),
            "row_counts": _counts([c.verdict for _, c in rows], VERDICTS),
            "sentence_counts": _counts([s["verdict"] for s in ss], (HELD, NOT_HELD, SPLIT) + VERDICTS[2:]),
            "evidence_rows": sum(c.verdict in EVIDENCE for _, c in rows),
            "unreliable": sum(unreliable(r, c) for r, c in rows), "straddles": sum(c.straddles for _, c in rows)}


def summary_line(reports):
    """One line: the sentences by verdict, then the rows (the command's last line)."""
    s = summary(reports)
    sc, rc = s["sentence_counts"], s["row_counts"]
    return (f"{s['sentences']} quoted sentences: {sc[HELD]} held, {sc[NOT_HELD]} not held, {sc[SPLIT]} split, "
            f"{sc[NOT_COMPARABLE]} not comparable, {sc[NOT_MEASURED]} not measured, {sc[BY_CONSTRUCTION]} by "
            f"construction only; {s['rows']} rows ({rc[HELD]} held, {rc[NOT_HELD]} not held, {rc[NOT_COMPARABLE]} "
            f"not comparable, {rc[NOT_MEASURED]} not measured, {rc[BY_CONSTRUCTION]} by construction)")


def _verdict(report, claim):
    v = f"**{claim.verdict}**"
    if claim.construction and claim.verdict != BY_CONSTRUCTION:
        v += f" (partly by construction: {claim.construction})"
    if unreliable(report, claim):
        v += f" (timing unreliable: other load {100 * report.other_load:.0f}%)"
    if claim.straddles:
        v += " (single rounds on both sides of the threshold: a re-run may flip it)"
    return v


def markdown(reports, quick=False):
    """The report's Markdown text.

    Parameters
    ----------
    reports : list of Report
        One per paper.
    quick : bool
        The run used the quick (CI smoke) sizes.

    Returns
    -------
    str
    """
    from ..contract import software_versions

    v = software_versions()
    lines = ["# The papers' tables and claims, measured with refraction_ref", "",
             f"{'Quick run (CI smoke sizes)' if quick else 'Full run'}; "
             f"{v.get('cpu', '')} ({v.get('cpu_count', os.cpu_count())} CPUs), numba {v.get('numba', '')}. "
             "Our times are a CPU's and the papers' a GPU's of their day: compare ratios and trends, "
             "not absolute times.", ""]
    busy = [r for r in reports if r.other_load > BUSY]
    if busy:
        lines += ["**Warning: the machine was busy.** Other processes used "
                  + ", ".join(f"{100 * r.other_load:.0f}% of the CPUs while {r.paper} was measured" for r in busy)
                  + f" (more than {100 * BUSY:.0f}%): the timing verdicts of "
                  + ", ".join(r.paper for r in busy) + " are marked unreliable. Re-run on an idle machine.", ""]
    pairs = [(r, c) for r in reports for c in r.claims]
    if pairs:
        sm = summary(reports)
        ss = sentences(reports)
        sid = {id(c): s["id"] for s in ss for _, c in s["rows"]}
        sc, rc = sm["sentence_counts"], sm["row_counts"]
        lines += ["## Claims", "",
                  f"{sm['sentences']} quoted sentences in {sm['rows']} rows. Each sentence is counted once, from "
                  f"its rows' verdicts: {sc[HELD]} held, {sc[NOT_HELD]} not held, {sc[SPLIT]} split (held on one "
                  f"set-up or part, not held on another), {sc[NOT_COMPARABLE]} not comparable, "
                  f"{sc[NOT_MEASURED]} not measured, {sc[BY_CONSTRUCTION]} by construction only. "
                  f"Rows: {rc[HELD]} held, {rc[NOT_HELD]} not held, {rc[NOT_COMPARABLE]} not comparable, "
                  f"{rc[NOT_MEASURED]} not measured, {rc[BY_CONSTRUCTION]} by construction "
                  "(the outcome follows from how the code is built: shown with its reason, never counted as "
                  "evidence)"
                  + (f"; {sm['unreliable']} timing verdicts unreliable (busy machine)" if sm["unreliable"] else "")
                  + (f"; {sm['straddles']} timing verdicts decided by a median whose single rounds fall on both "
                     "sides of the threshold (a re-run may flip them)" if sm["straddles"] else "") + ".", "",
                  "Each claim's rule (the quantity, the threshold, the set-up) was fixed before measuring; the "
                  "set-up column says where ours differs from the paper's.", "",
                  _md_table(["#", "paper", "section", "claim", "rule", "set-up", "verdict", "measured", "why"],
                            [[sid[id(c)], c.paper, c.section, f"“{c.quote}”", c.rule or "—",
                              f"differs: {c.differs}" if c.differs else "the paper's",
                              _verdict(r, c) + (f" — {c.construction}" if c.verdict == BY_CONSTRUCTION else ""),
                              c.measured, c.why]
                             for r, c in pairs]), "",
                  "### Sentences", "",
                  "Each quoted sentence once, with its rows' verdicts (by-construction, not-comparable and "
                  "not-measured rows never decide a sentence that has a held or not-held row).", "",
                  _md_table(["#", "paper", "section", "rows' verdicts", "sentence"],
                            [[s["id"], s["paper"], ", ".join(s["sections"]), " / ".join(s["verdicts"]),
                              f"**{s['verdict']}**"] for s in ss]), ""]
    for r in reports:
        lines += [f"## {r.paper}", ""]
        if not r.tables and not r.claims:
            lines += ["Not measured in this build.", ""]
            continue
        lines += [f"Measured in {r.seconds:.0f} s; other processes used {100 * r.other_load:.0f}% of the CPUs "
                  "meanwhile.", ""]
        for t in r.tables:
            lines += [f"### {t.title}", "", _md_table(t.columns, t.rows), ""]
            if t.note:
                lines += [t.note, ""]
            lines += [f"CSV: `{t.key}.csv`", ""]
            if t.plot:
                lines += [f"![{t.title}]({t.plot})", ""]
    return "\n".join(lines) + "\n"


def write_report(reports, out, quick=False):
    """Write ``<table key>.csv`` per table, ``claims.csv`` and ``tables.md`` into ``out``.

    Parameters
    ----------
    reports : list of Report
        One per paper.
    out : str
        Existing output folder.
    quick : bool
        The run used the quick (CI smoke) sizes.
    """
    from ..files import atomic_open

    for r in reports:
        for t in r.tables:
            with atomic_open(os.path.join(out, f"{t.key}.csv"), "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(t.columns)
                w.writerows([["" if c is None else c for c in row] for row in t.rows])
    with atomic_open(os.path.join(out, "claims.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["paper", "section", "quote", "rule", "verdict", "measured", "why", "timing", "other_load",
                    "reliable", "straddles", "sentence", "sentence_verdict", "construction", "differs"])
        ss = sentences(reports)
        sent = {id(c): s for s in ss for _, c in s["rows"]}
        for r in reports:
            for c in r.claims:
                w.writerow([c.paper, c.section, c.quote, c.rule, c.verdict, c.measured, c.why,
                            "yes" if c.timing else "no", f"{r.other_load:.2f}", "no" if unreliable(r, c) else "yes",
                            "yes" if c.straddles else "no", sent[id(c)]["id"], sent[id(c)]["verdict"],
                            c.construction, c.differs])
    with atomic_open(os.path.join(out, "tables.md"), "w") as f:
        f.write(markdown(reports, quick))
