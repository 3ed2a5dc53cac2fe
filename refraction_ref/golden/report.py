"""The conformance report's Markdown (``report.md``) and the number formats of its verdicts.

:func:`format_report` writes what :func:`~refraction_ref.golden.check.check`
returns: a summary table, then per case its problems and a table of its judged
keys; :func:`fmt_share` and :func:`fmt_percent` are the shares every verdict's
detail prints (:mod:`.tolerances`).
"""

from __future__ import annotations

__all__ = ["format_report", "fmt_share", "fmt_percent"]


def fmt_percent(share, whole=False):
    """A percentage as a report prints it: two significant digits below 10, whole numbers above (never
    ``1e+02``), and more digits where a share short of all would round to 100.

    Parameters
    ----------
    share : float
        Per cent, >= 0.
    whole : bool
        The share is all of it (100 % may be printed).

    Returns
    -------
    str
    """
    if share < 10:
        return f"{share:.2g}"
    pct, digits = f"{share:.0f}", 0
    while not whole and float(pct) >= 100:
        digits += 1
        pct = f"{share:.{digits}f}"
    return pct


def fmt_share(n, total):
    """A count and its share, never rounded to zero: ``"3 of 262144 (0.0011 %)"``.

    Parameters
    ----------
    n, total : int
        Elements counted and elements they are counted over.

    Returns
    -------
    str
    """
    n, total = int(n), int(total)
    pct = "0" if n == 0 else fmt_percent(100.0 * n / max(total, 1), whole=n >= total)
    return f"{n} of {total} ({pct} %)"


def format_report(out):
    """The Markdown report of a :func:`~refraction_ref.golden.check.check`.

    Parameters
    ----------
    out : CheckReport or dict
        What :func:`~refraction_ref.golden.check.check` returns: ``ok``, ``candidate``, ``golden``,
        ``contract_version`` and per case ``ok``, ``method``,
        ``earliest_failing_stage``, ``problems`` and ``keys``.

    Returns
    -------
    str
        The report: a summary table, then per case its problems and a table of
        its judged keys.
    """
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
            lines += ["", "| key | stage | tolerance | measured | failing / allowed | result | rationale |",
                      "|---|---|---|---|---|---|---|"]
            for k, j in c["keys"].items():
                cn = j.get("counts")
                if cn and "located" in cn:
                    frac = f"{fmt_share(cn['located'], cn['informative'])} / {100 * j['allowed']:.3g} %"
                elif "failing" in j:
                    frac = f"{fmt_percent(100 * j['failing'], whole=j['failing'] >= 1)} % / {100 * j['allowed']:.3g} %"
                else:
                    frac = ""
                links = "".join(f" ([{w}]({j[w]}))" for w in ("panel", "mask") if j.get(w))
                detail = j.get("detail", "").replace("|", "\\|")  # |c| in a detail must not split the row
                why = j.get("why", "").replace("|", "\\|")
                lines.append(f"| `{k}` | {j['stage']} | {j['kind']} | {detail} | {frac} | "
                             f"{'pass' if j['ok'] else '**FAIL**'}{links} | {why} |")
    return "\n".join(lines) + "\n"
