"""The conformance kit's cost: ``golden build`` of the whole catalogue, ``check`` of the oracle against it, size.

Targets (issue "Conformance kit"): ``check`` of the full suite under 30 s on
this machine; the suite about 60 MB. Writes ``results/golden.json``.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common as C  # noqa: E402

from refraction_ref.golden import build, check  # noqa: E402


def main():
    d = tempfile.mkdtemp(prefix="golden_")
    try:
        t0 = time.perf_counter()
        m = build(os.path.join(d, "suite"), log=lambda *a: None)
        t_build = time.perf_counter() - t0
        suite = os.path.join(d, "suite")
        size = sum(os.path.getsize(os.path.join(r, f)) for r, _, fs in os.walk(suite) for f in fs)
        cand = os.path.join(d, "cand")
        for c in m["cases"]:
            os.makedirs(os.path.join(cand, c))
            shutil.copy(os.path.join(suite, c, "golden.npz"), os.path.join(cand, c, "result.npz"))
        out = check(cand, suite, panels=False)
    finally:
        shutil.rmtree(d, ignore_errors=True)
    per_case = {k: round(v["build_s"], 2) for k, v in m["cases"].items()}
    print(f"golden build: {len(m['cases'])} cases in {t_build:.1f} s, {size / 2**20:.1f} MiB; check of the oracle "
          f"against it: {out['seconds']:.1f} s (target < 30 s), {'all pass' if out['ok'] else 'FAILURES'}")
    C.write_json("golden.json", {"cases": len(m["cases"]), "build_s": t_build, "size_mib": size / 2**20,
                                 "check_s": out["seconds"], "check_ok": out["ok"], "build_s_per_case": per_case,
                                 "machine": C.machine_line(), "rev": C.git_rev()})


if __name__ == "__main__":
    main()
