"""Per-stage scaling before and after a change, from interleaved ``bench_scaling.py --samples`` runs.

    python benchmarks/scaling_compare.py OUT.md before1.json after1.json before2.json after2.json ...

The files alternate (odd: before, even: after: run them in turn, so that a
slow spell of the machine weighs on both trees); the samples of each side
are pooled and every stage's median taken at each thread count. Writes a
Markdown table: per method and stage, before and after at 1 and 2 threads,
the 2-thread speed-up of each, and the after/before ratio at 1 thread; a
stage's share of its one-thread frame (``total``) marks those over 5 %.
"""

from __future__ import annotations

import json
import statistics
import sys


def pool(paths):
    out, meta = {}, None
    for p in paths:
        with open(p) as f:
            d = json.load(f)
        meta = meta or d
        for method, per in d["samples"].items():
            for thr, stages in per.items():
                for stage, vals in stages.items():
                    out.setdefault(method, {}).setdefault(thr, {}).setdefault(stage, []).extend(vals)
    return out, meta


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    out_md, files = argv[0], argv[1:]
    before, mb = pool(files[0::2])
    after, ma = pool(files[1::2])
    lines = [f"before: rev {mb['rev']}; after: rev {ma['rev']}; {ma['machine']}; "
             f"{len(files) // 2} interleaved runs per side, medians of "
             f"{len(next(iter(next(iter(after.values()))['1'].values())))} renders per side and thread count", "",
             "| method | stage | share of 1-thr frame | before 1 thr (ms) | before 2 thr | before speed-up "
             "| after 1 thr | after 2 thr | after speed-up | after/before at 1 thr |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for method in after:
        b, a = before.get(method, {}), after[method]
        frame = statistics.median(a["1"]["total"])
        for stage in a["1"]:
            if "." in stage:
                continue
            med = {(side, t): statistics.median(d[t][stage]) if stage in d.get(t, {}) else float("nan")
                   for side, d in (("b", b), ("a", a)) for t in ("1", "2")}
            share = med[("a", "1")] / frame if stage != "total" else 1.0
            sb = med[("b", "1")] / med[("b", "2")]
            sa = med[("a", "1")] / med[("a", "2")]
            mark = " **" if share > 0.05 and stage != "total" else ""
            lines.append(f"| {method} | {stage}{mark} | {100 * share:.0f} % | {med[('b', '1')]:.1f} | "
                         f"{med[('b', '2')]:.1f} | {sb:.2f}x | {med[('a', '1')]:.1f} | {med[('a', '2')]:.1f} | "
                         f"{sa:.2f}x | {med[('a', '1')] / med[('b', '1')]:.2f} |")
    with open(out_md, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
