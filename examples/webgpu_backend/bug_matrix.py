"""The planted bugs' verdicts over the golden cases: the earliest failing stage `check` names.

    python examples/webgpu_backend/bug_matrix.py GOLDEN_DIR WORK_DIR [--bugs a,b] [--cases a,b]

No key is set aside: `check` passes the correct float32 backend on every
case (docs/oracle.md, "Float32 rasterizers"), so a bug is named by the pass it
breaks; prints a Markdown table ("pass": `check` passes the case).
"""
import argparse
import importlib.util
import json
import os
import shutil

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    import refraction_ref as rr
    spec = importlib.util.spec_from_file_location("webgpu_imagespace", os.path.join(HERE, "imagespace.py"))
    be = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(be)
    ap = argparse.ArgumentParser()
    ap.add_argument("golden")
    ap.add_argument("work")
    ap.add_argument("--bugs", default=None)
    ap.add_argument("--cases", default=None)
    a = ap.parse_args()
    cases = a.cases.split(",") if a.cases else be.imagespace_cases(a.golden)
    bugs = a.bugs.split(",") if a.bugs else sorted(be.all_bugs())
    with open(os.path.join(a.golden, "manifest.json")) as fh:
        man = json.load(fh)["cases"]
    rows = []
    for bug in bugs:
        out = os.path.join(a.work, bug)
        shutil.rmtree(out, ignore_errors=True)
        be.run(a.golden, out, cases, bugs=[bug])
        rep = rr.check(out, a.golden, cases=cases, panels=False)
        cells = []
        for case in cases:
            order = {s: i for i, s in enumerate(man[case]["stages"])}
            bad = [r for r in rep.cases[case].rows if not r["ok"]]
            cells.append(min(bad, key=lambda r: order.get(r["stage"], 99))["stage"] if bad else "pass")
        rows.append(f"| `{bug}` | " + " | ".join(cells) + " |")
        print(rows[-1], flush=True)
    print("| bug | " + " | ".join(c.replace("is_", "") for c in cases) + " |")
    print("|---|" + "---|" * len(cases))
    print("\n".join(rows))


if __name__ == "__main__":
    main()
