"""Tables 5-1, 5-3, 5-4 and 5-5 of Tipprasert (2006) beside the thesis's figures.

    python benchmarks/levelmap_tables.py [--step 7] [--repeats 3] [--out benchmarks/results]

For the teapot (6,320 triangles), a UV sphere of 1,984 triangles (Table 5-2)
and the bunny (in place of the thesis's dolphin, whose figures are plotted
beside it), each alone in the default pool under the default waves with the
light from above: rendering time against the number of planes (3..101) for
the level map and the volumetric baseline (5-1), normal and smart slicing
(5-3), the planes smart slicing actually used (5-4) and the Luv difference
of the images with smart slicing on and off (5-5). Times are medians after
warm-up on this CPU; the thesis's are seconds on a GeForce 6800, so compare
shapes and ratios, not values. Writes ``levelmap_table5_{1,3,4,5}.csv`` and
``.png`` into the output folder.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_levelmap import mesh_arg, model_scene, timed  # noqa: E402
from refraction_ref.files import atomic_open, savefig_atomic  # noqa: E402

from refraction_ref.levelmap.metrics import luv_difference  # noqa: E402
from refraction_ref.levelmap.pipeline import warm_up  # noqa: E402
from refraction_ref.scene import load_scene  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
MESHES = (("teapot", "teapot"), ("sphere", "sphere"), ("bunny", "dolphin"))


def thesis():
    rows = {}
    with open(os.path.join(HERE, "thesis_tables_5.csv")) as f:
        lines = [ln for ln in f if not ln.startswith("#")]
    for r in csv.DictReader(lines):
        rows[int(r["planes"])] = {k: (float(v) if v else float("nan")) for k, v in r.items()}
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step", type=int, default=7, help="plane-count step from 3 to 101")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(HERE, "results"))
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    warm_up()
    th = thesis()
    planes = list(range(3, 102, a.step))
    if planes[-1] != 101:
        planes.append(101)
    rows = []
    for mesh, tname in MESHES:
        for n in planes:
            sc = model_scene(mesh_arg(mesh), n)
            t_n, (an, _) = timed(load_scene(sc, {"levelmap.smart_slicing": False}), a.repeats)
            t_s, (as_, ins) = timed(load_scene(sc, {"levelmap.smart_slicing": True}), a.repeats)
            t_v, _ = timed(load_scene(sc, {"levelmap.variant": "volumetric"}), a.repeats)
            luv = luv_difference(an["image"], as_["image"], an["object_mask"])
            t = th[n]
            rows.append({"mesh": mesh, "planes": n, "levelmap_s": t_n, "volumetric_s": t_v, "smart_s": t_s,
                         "planes_used": ins["planes_used"], "luv_smart_on_off": luv,
                         "thesis_mesh": tname, "thesis_levelmap_s": t[f"t51_{tname}_levelmap"],
                         "thesis_volumetric_s": t[f"t51_{tname}_volumetric"],
                         "thesis_smart_s": t[f"t53_{tname}_smart"], "thesis_planes_used": t[f"t54_{tname}"],
                         "thesis_luv": t[f"t55_{tname}"]})
            print(f"{mesh:7s} {n:3d} planes: level map {t_n:.3f} s, volumetric {t_v:.3f} s, smart {t_s:.3f} s, "
                  f"used {ins['planes_used']:3d} (thesis {t[f't54_{tname}']:.0f}), Luv {luv:g}", flush=True)
    tables = {
        "1": ["mesh", "planes", "levelmap_s", "volumetric_s", "thesis_mesh", "thesis_levelmap_s", "thesis_volumetric_s"],
        "3": ["mesh", "planes", "levelmap_s", "smart_s", "thesis_mesh", "thesis_levelmap_s", "thesis_smart_s"],
        "4": ["mesh", "planes", "planes_used", "thesis_mesh", "thesis_planes_used"],
        "5": ["mesh", "planes", "luv_smart_on_off", "thesis_mesh", "thesis_luv"],
    }
    for k, cols in tables.items():
        p = os.path.join(a.out, f"levelmap_table5_{k}.csv")
        with atomic_open(p, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
        print("wrote", p)
    plot(rows, a.out)


def plot(rows, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    specs = {
        "1": (("levelmap_s", "level map"), ("volumetric_s", "volumetric"),
              ("thesis_levelmap_s", "thesis level map"), ("thesis_volumetric_s", "thesis volumetric"), "seconds"),
        "3": (("levelmap_s", "normal"), ("smart_s", "smart"),
              ("thesis_levelmap_s", "thesis normal"), ("thesis_smart_s", "thesis smart"), "seconds"),
        "4": (("planes", "requested"), ("planes_used", "used (smart)"), None,
              ("thesis_planes_used", "thesis used"), "planes"),
        "5": (("luv_smart_on_off", "Luv diff."), None, None, ("thesis_luv", "thesis"), "eq. 2-9"),
    }
    for k, (a1, a2, t1, t2, ylabel) in specs.items():
        fig, axs = plt.subplots(1, 3, figsize=(13, 3.6))
        for ax, (mesh, tname) in zip(axs, MESHES):
            rs = [r for r in rows if r["mesh"] == mesh]
            x = [r["planes"] for r in rs]
            for spec, style in ((a1, "-o"), (a2, "-s")):
                if spec:
                    ax.plot(x, [r[spec[0]] for r in rs], style, ms=3, label=spec[1])
            twin = ax.twinx() if ylabel == "seconds" else ax
            for spec, style in ((t1, "--"), (t2, ":")):
                if spec:
                    twin.plot(x, [r[spec[0]] for r in rs], style, color="gray" if style == "--" else "k",
                              label=spec[1] + f" ({tname})")
            ax.set_title(f"{mesh} (thesis: {tname})")
            ax.set_xlabel("planes requested")
            ax.set_ylabel(ylabel + (" (this CPU)" if ylabel == "seconds" else ""))
            if twin is not ax:
                twin.set_ylabel("thesis seconds (GeForce 6800)")
            h1, l1 = ax.get_legend_handles_labels()
            h2, l2 = (twin.get_legend_handles_labels() if twin is not ax else ([], []))
            ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left")
        fig.suptitle(f"Tipprasert (2006) Table 5-{k}, reproduced")
        fig.tight_layout()
        p = os.path.join(out, f"levelmap_table5_{k}.png")
        savefig_atomic(fig, p, dpi=90)
        plt.close(fig)
        print("wrote", p)


if __name__ == "__main__":
    main()
