"""The image-space method's exit-direction error against the exact reference, view by view.

    python benchmarks/error_vs_view.py [--res 512] [--quick]

For the bunny and Igea (each fit 1.0, eye at distance 2.6, fov 30) over a ring
of 8 views every 45 degrees around the vertical axis (``chaudhari.RING``;
az000 is the default front view), at IOR 1.2, 1.33 and 1.5: the median and
p90 exit-direction error over the pixels where both methods exit, the
fraction of hit pixels whose image-space ray exits (the rest end mostly in
total internal reflection, which the thesis's method does not follow), and
the fraction of hit pixels that exit within 5 degrees of the exact direction;
for the seed defaults and for each option (``chaudhari.ERROR_OPTIONS``:
``tir``, ``depth=float``, normals, iterations, blend, end point, filter, the
former defaults, and the three beyond-the-thesis options together).

Also the seed defaults against the former ones (``blend='or'``,
``endpoint='bracket'``, ``filter='nearest'``) on the default bunny against the
exact reference and on the sphere against the closed form.

The table code is :mod:`refraction_ref.tables.chaudhari`. Writes
``benchmarks/results/error_vs_view.csv`` (one row per model, IOR, view and
option), ``error_vs_view.md`` (the pooled tables) and ``error_vs_view.png``
(error and exit fraction against the view); ``--quick`` writes ``*_quick.*``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common as C  # noqa: E402
from refraction_ref.files import atomic_open  # noqa: E402
from refraction_ref.tables import chaudhari as T  # noqa: E402

FIELDS = ("model", "ior", "view", "azimuth", "elevation", "option", "hit", "median", "p90", "exit", "within5", "tir",
          "lost", "limit", "exact_exit")


def plot(rows, path, options=("seed defaults", "tir", "normals=mesh3x3")):
    import matplotlib

    matplotlib.use("Agg")  # a script: no display needed
    import matplotlib.pyplot as plt

    models = list(dict.fromkeys(r["model"] for r in rows))
    iors = sorted({r["ior"] for r in rows})
    fig, axes = plt.subplots(2, len(models), figsize=(6.0 * len(models), 8.0), squeeze=False)
    styles = {"seed defaults": "-", "tir": "--", "normals=mesh3x3": ":"}
    colors = dict(zip(iors, ("tab:blue", "tab:orange", "tab:green", "tab:red")))
    for c, m in enumerate(models):
        for ior in iors:
            for opt in options:
                rs = sorted((r for r in rows if r["model"] == m and r["ior"] == ior and r["option"] == opt),
                            key=lambda r: r["azimuth"])
                if not rs:
                    continue
                az = [r["azimuth"] for r in rs]
                lab = f"IOR {ior}, {opt}"
                axes[0, c].plot(az, [r["p90"] for r in rs], styles.get(opt, "-"), color=colors[ior], marker="o",
                                ms=3, label=lab)
                axes[1, c].plot(az, [100 * r["exit"] for r in rs], styles.get(opt, "-"), color=colors[ior],
                                marker="o", ms=3, label=lab)
        axes[0, c].set_title(f"{m}: p90 exit-direction error")
        axes[0, c].set_ylabel("p90 error (deg), pixels where both exit")
        axes[1, c].set_title(f"{m}: hit pixels that exit")
        axes[1, c].set_ylabel("% of hit pixels with status 1")
        for ax in axes[:, c]:
            ax.set_xlabel("view azimuth (deg; 0 = default front view)")
            ax.set_xticks(range(0, 360, 45))
            ax.grid(alpha=0.3)
    axes[0, -1].legend(fontsize=7, ncol=2)
    fig.suptitle("Chaudhari 2008 image-space method against the exact reference, ring of views")
    fig.tight_layout()
    with atomic_open(path, "wb") as f:
        fig.savefig(f, format="png", dpi=90)
    plt.close(fig)


def _pct(x):
    return f"{100 * x:.1f}%"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=512, help="image (and voxel grid) texels a side (the thesis's 512)")
    ap.add_argument("--quick", action="store_true", help="bunny, 128x128, 4 views, IOR 1.33, 4 options")
    ap.add_argument("--models", default="bunny,igea")
    ap.add_argument("--plot-only", action="store_true", help="redraw the PNG from the CSV")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    csv_path = C.results_path(f"error_vs_view{suffix}.csv")
    if args.plot_only:
        with open(csv_path) as f:
            rows = [{k: (float(v) if k not in ("model", "view", "option") else v) for k, v in r.items()}
                    for r in csv.DictReader(f)]
        plot(rows, C.results_path(f"error_vs_view{suffix}.png"))
        return 0
    t_start = time.perf_counter()
    out = []

    def say(s=""):
        print(s, flush=True)
        out.append(s)

    res = 128 if args.quick else args.res
    names = ["bunny"] if args.quick else [m.strip() for m in args.models.split(",") if m.strip()]
    models = {}
    for n in names:
        mesh = C.model_path("igea.ply") if n == "igea" else n
        models[n] = T.Model([C._obj(mesh)], 2.6, n)
    ring = T.RING[::2] if args.quick else T.RING
    iors = (1.33,) if args.quick else (1.2, 1.33, 1.5)
    options = T.ERROR_OPTIONS[:3] + (T.ERROR_OPTIONS[9],) if args.quick else T.ERROR_OPTIONS
    say(f"# Exit-direction error against the exact reference ({C.machine_line()}; git {C.git_rev()})")
    say(f"{res}x{res}, {len(ring)} views (azimuth {', '.join(str(int(v.azimuth)) for v in ring)}; elevation 0), "
        f"distance 2.6, fov 30, IOR {', '.join(map(str, iors))}; models {', '.join(names)}")

    say("\n## The seed defaults against the former ones\n")
    ba = T.defaults_before_after(res=res if not args.quick else 128, log=say)
    md = [[r["scene"], r["option"], f"{r['median']:.3f}", f"{r['p90']:.3f}", _pct(r["exit"]), _pct(r["within5"]),
           _pct(r["tir"]), _pct(r["lost"])] for r in ba]
    say("")
    say(C.md_table(["scene", "defaults", "median deg", "p90 deg", "exit", "within 5 deg", "TIR (3)", "lost (4)"], md))

    say("\n## Per view (measuring) ...")
    rows = T.error_vs_view(models, iors=iors, ring=ring, options=options, res=res, log=say)
    with atomic_open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{r[k]:.5f}" if isinstance(r[k], float) else r[k]) for k in FIELDS})

    summ = T.summarize_error(rows)
    say("\n## Pooled over the ring: every option, per model and IOR\n")
    say("median / p90: over every pixel of the ring where both methods exit; exit, within 5 deg, TIR: fractions of "
        "the hit pixels (exact hits); exit range: the lowest and highest view.")
    for n in names:
        for ior in iors:
            say(f"\n### {n}, IOR {ior}\n")
            tab = [[s["option"], f"{s['median']:.2f}", f"{s['p90']:.2f}", f"{s['p90_min']:.1f}-{s['p90_max']:.1f}",
                    _pct(s["exit"]), f"{100 * s['exit_min']:.0f}-{100 * s['exit_max']:.0f}%", _pct(s["within5"]),
                    _pct(s["tir"]), _pct(s["lost"]), _pct(s["exact_exit"])]
                   for s in summ if s["model"] == n and s["ior"] == ior]
            say(C.md_table(["option", "median deg", "p90 deg", "p90 range (views)", "exit", "exit range (views)",
                            "within 5 deg", "TIR (3)", "lost (4)", "exact exits"], tab))
    say("\n## The seed defaults view by view, IOR 1.33\n")
    d133 = [r for r in rows if r["option"] == "seed defaults" and abs(r["ior"] - 1.33) < 1e-9]
    tab = [[r["model"], r["view"], f"{r['median']:.2f}", f"{r['p90']:.2f}", _pct(r["exit"]), _pct(r["within5"]),
            _pct(r["tir"]), _pct(r["lost"])] for r in d133]
    say(C.md_table(["model", "view", "median deg", "p90 deg", "exit", "within 5 deg", "TIR (3)", "lost (4)"], tab))

    plot(rows, C.results_path(f"error_vs_view{suffix}.png"))
    say(f"\nscript took {time.perf_counter() - t_start:.0f} s")
    with atomic_open(C.results_path(f"error_vs_view{suffix}.md"), "w") as f:
        f.write("\n".join(out) + "\n")
    print(f"wrote benchmarks/results/error_vs_view{suffix}.csv, .md, .png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
