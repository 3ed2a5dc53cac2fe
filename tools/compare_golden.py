"""Compare two golden suites key by key: are the outputs bit-identical?

``python tools/compare_golden.py BEFORE AFTER [--out FILE.md]`` reads each
suite's ``manifest.json`` and compares, for every case and every key, the
sha256 of the array (``golden build`` hashes each array's dtype, shape and
bytes). It prints one line per case and exits 1 when any key differs, is
missing on one side or a case is missing; with ``--out`` it writes the
comparison as a Markdown table (what a refactoring commits as proof that its
outputs did not change).
"""

from __future__ import annotations

import argparse
import json
import os
import sys


def compare(before, after):
    """Per-case comparison rows of two golden suites' manifests.

    Parameters
    ----------
    before, after : str
        Folders written by ``refraction-ref golden build``.

    Returns
    -------
    list of dict
        One row per case: ``case``, ``keys`` (compared), ``equal``,
        ``differ``, ``only_before``, ``only_after`` (lists of key names).
    """
    ma = json.load(open(os.path.join(before, "manifest.json")))["cases"]
    mb = json.load(open(os.path.join(after, "manifest.json")))["cases"]
    rows = []
    for case in sorted(set(ma) | set(mb)):
        ka = ma.get(case, {}).get("keys", {})
        kb = mb.get(case, {}).get("keys", {})
        common = sorted(set(ka) & set(kb))
        differ = [k for k in common if ka[k]["sha256"] != kb[k]["sha256"]]
        rows.append({"case": case, "keys": len(common), "equal": len(common) - len(differ), "differ": differ,
                     "only_before": sorted(set(ka) - set(kb)), "only_after": sorted(set(kb) - set(ka))})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--out", help="write the comparison as a Markdown table")
    ap.add_argument("--title", default="Golden suite before and after")
    a = ap.parse_args(argv)
    rows = compare(a.before, a.after)
    ok = all(not r["differ"] and not r["only_before"] and not r["only_after"] for r in rows)
    lines = [f"# {a.title}", "",
             f"{sum(r['keys'] for r in rows)} keys in {len(rows)} cases compared by sha256: "
             + ("**all bit-identical**." if ok else "**differences found**."), "",
             "| case | keys | identical | differ | only before | only after |", "|---|---:|---:|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['keys']} | {r['equal']} | {', '.join(r['differ']) or '-'} | "
                     f"{', '.join(r['only_before']) or '-'} | {', '.join(r['only_after']) or '-'} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        with open(a.out, "w") as f:
            f.write(text)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
