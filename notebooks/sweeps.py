"""The committed sweeps of ``benchmarks/`` read for plotting (``error_vs_time.ipynb``).

A checkout's ``benchmarks/results/*.csv`` (made by ``refraction-ref sweep
benchmarks/specs/*.json`` and the older ``benchmarks/sweep_*.py`` scripts) with
their specs: :func:`committed` returns a sweep's rows, error and time columns and
families; :func:`plot_families` draws error against time per family;
:func:`plot_knob` draws error and time against the value of the knob a family
varies; :func:`pareto` picks the settings no other beats on both axes. Kept out of the
notebook so that its first plot comes early; nothing here computes an error.
"""

from __future__ import annotations

import csv
import json
import os

import numpy as np

#: marker and dash of the n-th line :func:`plot_families` draws (with colour C{n % 10})
MARKERS = "osD^vP*Xh<>"
DASHES = ["-", "--", ":"]

#: where :func:`load` and :func:`committed` read; set by the notebook (``RESULTS_DIR``) or :func:`results_dir`
RESULTS = None


def results_dir():
    """benchmarks/results of this checkout (the notebook's folder's sibling, or beside the package)."""
    import refraction_ref as rr

    for base in (os.getcwd(), os.path.dirname(os.path.dirname(os.path.abspath(rr.__file__)))):
        for d in (os.path.join(base, "..", "benchmarks", "results"), os.path.join(base, "benchmarks", "results")):
            if os.path.isdir(d):
                return os.path.abspath(d)
    raise FileNotFoundError("benchmarks/results not found: run this notebook from a checkout of the repository")


def load(name):
    """A CSV as a list of dicts, numbers converted."""
    def conv(v):
        try:
            return float(v)
        except ValueError:
            return v
    with open(os.path.join(RESULTS, name)) as f:
        return [{k: conv(v) for k, v in r.items()} for r in csv.DictReader(f)]


def pareto(points):
    """Indices of the points (time, error) that no other point beats on both: the settings worth choosing."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], np.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def _old_rows(name, rows):
    """Rows of a sweep CSV written before the benchmarks ran as `refraction-ref sweep` specs, in the spec's columns."""
    out = []
    for r in rows:
        if name == "sweep_imagespace":
            d = {"family": r["family"], "camera.width": r["res"], "total_ms": r["pipeline_ms"],
                 "exit_dir_median_deg": r["err_median"]}
            d.update({f"imagespace.{k}": r[k] for k in ("iterations", "delta", "slices", "layers", "depth", "normals",
                                                         "bounds", "slicing")})
            out.append(d)
        elif name == "sweep_caustics":
            out.append({"family": r["knob"], f"imagespace.{r['knob']}": r["value"], "total_ms": r["photon_ms"],
                        "caustic_map_0_rel_l1": r["rel_l1"], "reference_noise": r["reference_noise"]})
        elif name == "sweep_volumetric":
            out.append({"family": r["varied"], **{k: r[k] for k in ("integrator", "N", "M", "ds_min", "eps",
                                                                     "median_miss_vox", "seconds")}})
        elif name == "levelmap_sweep":
            d = {"levelmap.variant": r["variant"], "levelmap.planes": r["planes"], "levelmap.map_size": r["map_size"],
                 "water.resolution": r["resolution"], "total_ms": 1e3 * r["time_s"],
                 "caustic_map_0_rel_l1": r["error_floor"]}
            default = r["map_size"] == 512 and r["resolution"] == 128
            if default:
                out.append(dict(d, family={"levelmap": "planes, level map", "per_ray": "planes, per ray",
                                           "volumetric": "planes, volumetric"}[r["variant"]]))
            if r["variant"] != "volumetric" and r["planes"] == 50 and not default:
                out.append(dict(d, family="map size" if r["resolution"] == 128 else "water resolution"))
    return out


def committed(spec_file):
    """A committed sweep: its spec (benchmarks/specs), rows (benchmarks/results), error and time columns."""
    with open(os.path.join(RESULTS, "..", "specs", spec_file)) as f:
        spec = json.load(f)
    rows = load(spec["name"] + ".csv")
    tim = spec.get("time", "total_ms")
    if not (rows and "family" in rows[0] and tim in rows[0]) or "status" not in rows[0]:
        rows = _old_rows(spec["name"], rows)            # the CSV predates the spec: same numbers, older columns
    rows = [r for r in rows if r.get("status", "ok") == "ok"]
    err = spec.get("error") or next(k for k in ("exit_dir_median_deg", "image_rmse") if k in rows[0])
    fams = {}
    for fm in spec["families"]:
        g = {x: (vals if "," not in k else [v[i] for v in vals]) for k, vals in fm["grid"].items()
             for i, x in enumerate(k.split(","))}
        multi = [k for k, v in g.items() if len(v) > 1 and not k.startswith("camera.")]
        plain = [k for k in g if not k.startswith("camera.")]
        fams[fm["name"]] = {"label": multi[-1] if multi else plain[-1], "keys": list(g)}
    return {"spec": spec, "rows": rows, "err": err, "time": tim, "families": fams}


def plot_families(ax, S, families=None, split=None, annotate=True, logx=True, logy=True):
    """Error against time per family (one line per value of the family's other keys), labels: the knob's values."""
    n = 0
    for fam, info in S["families"].items():
        if families is not None and fam not in families:
            continue
        rr_ = [r for r in S["rows"] if r.get("family") == fam and S["err"] in r and S["time"] in r]
        others = [k for k in info["keys"] if k != info["label"] and k != split and not k.startswith("camera.height")]
        series = {}
        for r in rr_:
            series.setdefault(tuple(r.get(k) for k in others), []).append(r)
        for sk, pts in series.items():
            pts = sorted(pts, key=lambda r: str(r.get(info["label"])) if isinstance(r.get(info["label"]), str)
                         else r.get(info["label"], 0))
            extra = ", ".join(f"{k.split('.')[-1]}={v:g}" if isinstance(v, float) else f"{k.split('.')[-1]}={v}"
                              for k, v in zip(others, sk) if len({r.get(k) for r in rr_}) > 1)
            x = [r[S["time"]] for r in pts]
            y = [r[S["err"]] for r in pts]
            # one colour, marker and dash per series, so that overlapping lines stay apart
            ax.plot(x, y, marker=MARKERS[n % len(MARKERS)], ls=DASHES[(n // 10) % len(DASHES)], ms=5, lw=1.4,
                    color=f"C{n % 10}", alpha=0.85, label=fam + (f" ({extra})" if extra else ""))
            if annotate:
                for r in pts:
                    v = r.get(info["label"])
                    ax.annotate(f"{v:g}" if isinstance(v, float) else str(v), (r[S["time"]], r[S["err"]]), fontsize=8,
                                xytext=(3, 3), textcoords="offset points", color=f"C{n % 10}")
            n += 1
    if logx:
        ax.set_xscale("log")
        plain_log_ticks(ax.xaxis)
    if logy:
        ax.set_yscale("log")
        plain_log_ticks(ax.yaxis)
    ax.set_xlabel(S["time"].replace("_", " ")); ax.set_ylabel(S["err"].replace("_", " "))


def plain_log_ticks(axis):
    """Ticks of a log axis at 1, 2, 5 x 10^k (more under a decade) written as plain numbers (0.5, 2, 20)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax = axis.axes
    lo, hi = sorted(ax.get_ylim() if axis is ax.yaxis else ax.get_xlim())   # (get_ylim settles the autoscaling)
    span = hi / lo if lo > 0 else np.inf      # under a decade: more ticks, so that at least two are labelled
    subs = ((1.0, 1.2, 1.4, 1.6, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0) if span < 3 else
            (1.0, 1.5, 2.0, 3.0, 5.0, 7.0) if span < 10 else (1.0, 2.0, 5.0))
    axis.set_major_locator(LogLocator(subs=subs))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def _order(v):
    return (0, v, "") if isinstance(v, (int, float)) else (1, 0, str(v))


def plot_knob(ax_err, ax_time, S, families, split=None):
    """Error (``ax_err``) and time (``ax_time``, or None) against the value of the knob the families vary.

    One line per family and value of ``split`` (a column, e.g. ``"integrator"``); the families must vary the same
    knob. A numeric knob spanning more than a factor 20 gets a log axis ticked at its values; a text knob one tick per
    value.
    """
    labs = {S["families"][f]["label"] for f in families}
    if len(labs) != 1:
        raise ValueError(f"families {families} vary different knobs: {sorted(labs)}")
    lab = labs.pop()
    rows = [r for r in S["rows"] if r.get("family") in families and S["err"] in r and S["time"] in r and lab in r]
    vals = sorted({r[lab] for r in rows}, key=_order)
    numeric = all(isinstance(v, (int, float)) for v in vals)
    groups = {}
    for r in rows:
        groups.setdefault((r["family"], r.get(split) if split else None), []).append(r)
    for n, ((fam, g), rs) in enumerate(sorted(groups.items(), key=lambda t: (families.index(t[0][0]), str(t[0][1])))):
        rs = sorted(rs, key=lambda r: _order(r[lab]))
        x = [r[lab] if numeric else vals.index(r[lab]) for r in rs]
        name = (fam if len(families) > 1 else "") + (f"{', ' if len(families) > 1 else ''}{g}" if split else "")
        # lines that coincide (equal errors) stay visible: the first widest, the next dashed and thinner on top
        kw = dict(marker=MARKERS[n % len(MARKERS)], color=f"C{n % 10}", lw=2.6 - 0.8 * (n % 3), ms=7 - 2 * (n % 3),
                  ls=DASHES[n % len(DASHES)], label=name or None)
        ax_err.plot(x, [r[S["err"]] for r in rs], **kw)
        if ax_time is not None:
            ax_time.plot(x, [r[S["time"]] for r in rs], **kw)
    from matplotlib.ticker import FuncFormatter

    for a in (ax_err, ax_time):
        if a is None:
            continue
        if numeric and min(vals) > 0 and max(vals) / min(vals) > 20:
            a.set_xscale("log")
            a.set_xticks(vals)
            a.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            a.minorticks_off()
        elif not numeric:
            a.set_xticks(range(len(vals)), [str(v) for v in vals])
        a.set_xlabel(lab.split(".")[-1])
    return lab
