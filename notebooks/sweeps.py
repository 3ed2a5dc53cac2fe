"""The committed sweeps of ``benchmarks/`` read for plotting (``error_vs_time.ipynb``).

A checkout's ``benchmarks/results/*.csv`` (made by ``refraction-ref sweep
benchmarks/specs/*.json`` and the older ``benchmarks/sweep_*.py`` scripts) with
their specs: :func:`committed` returns a sweep's rows, error and time columns and
families; :func:`plot_families` draws error against time per family;
:func:`pareto` picks the settings no other beats on both axes. Kept out of the
notebook so that its first plot comes early; nothing here computes an error.
"""

from __future__ import annotations

import csv
import json
import os

import numpy as np

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
            ax.plot(x, y, "o-", ms=3, lw=0.7, color=f"C{n % 10}", label=fam + (f" ({extra})" if extra else ""))
            if annotate:
                for r in pts:
                    v = r.get(info["label"])
                    ax.annotate(f"{v:g}" if isinstance(v, float) else str(v), (r[S["time"]], r[S["err"]]), fontsize=6)
            n += 1
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(S["time"].replace("_", " ")); ax.set_ylabel(S["err"].replace("_", " "))
