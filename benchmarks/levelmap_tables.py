"""Tables 5-1, 5-3, 5-4 and 5-5 of Tipprasert (2006) beside the thesis's figures.

    python benchmarks/levelmap_tables.py [--quick] [--out benchmarks/results]

A thin wrapper of :func:`refraction_ref.tables.tipprasert.run` (what
``refraction-ref tables`` runs): writes ``levelmap_table5_{1,3,4,5}.csv`` and
``.png`` into the output folder, and prints the thesis's claims with their
verdicts.
"""

from __future__ import annotations

import argparse
import csv
import os
import pathlib
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from refraction_ref.files import atomic_open  # noqa: E402
from refraction_ref.tables.tipprasert import run  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
COLUMNS = {
    "1": ["mesh", "planes", "levelmap_s", "volumetric_s", "caustics_normal_ms", "caustics_volumetric_ms",
          "thesis_mesh", "thesis_levelmap_s", "thesis_volumetric_s"],
    "3": ["mesh", "planes", "levelmap_s", "smart_s", "respace_s", "caustics_normal_ms", "caustics_smart_ms",
          "profiling_ms", "thesis_mesh", "thesis_normal_s", "thesis_smart_s"],
    "4": ["mesh", "planes", "planes_used", "planes_respaced", "thesis_mesh", "thesis_planes_used"],
    "5": ["mesh", "planes", "luv_smart_on_off", "luv_respace_on_off", "maps_identical", "thesis_mesh", "thesis_luv"],
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="teapot and sphere, 3 plane counts, small maps")
    ap.add_argument("--out", default=os.path.join(HERE, "results"))
    a = ap.parse_args(argv)
    rep = run(a.quick, pathlib.Path(a.out))
    for k, cols in COLUMNS.items():
        p = os.path.join(a.out, f"levelmap_table5_{k}.csv")
        with atomic_open(p, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
            w.writeheader()
            w.writerows(rep.rows)
        print("wrote", p)
    for c in rep.claims:
        print(f"[{c.verdict}] {c.section}: {c.measured}. {c.why}")
    print(f"{rep.seconds:.0f} s")


if __name__ == "__main__":
    main()
