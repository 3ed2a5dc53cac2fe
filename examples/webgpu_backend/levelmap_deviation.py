"""Per-key deviation of a candidate folder from a golden suite, without check's allowances.

For each key of each case: the largest and 99th-percentile deviation from the golden and the
share of elements beyond the float64 tolerance ``atol + rtol |g|`` (maps with ``scale = max``:
``atol`` times the map's largest value; angles: the key's degrees), NaN / inf placement
mismatches, and for codes the share of differing elements. This is what ``LEVELMAP.md``'s
float32 deviation table reports; ``refraction-ref check`` is the verdict (it adds the slope
term, the ambiguity masks and the fractions).

    python examples/webgpu_backend/levelmap_deviation.py GOLDEN_DIR CAND_DIR [--cases a,b] [--markdown]
"""
import json
import os
import sys

import numpy as np


def deviation(c, g, tol):
    """A dict: max, p99, beyond (share of informative elements beyond the float64 tolerance), n, mism."""
    kind = tol.get("kind", "close")
    if c.shape != g.shape:
        return {"note": f"shape {c.shape} vs {g.shape}"}
    if kind == "exact" or g.dtype.kind in "biu":
        d = (c != g)
        if g.ndim >= 3 and g.shape[-1] == 3:
            d = d.any(-1)
        return {"max": float(d.sum()), "p99": None, "beyond": float(d.mean()) if d.size else 0.0,
                "n": int(d.size), "unit": "elements"}
    c = c.astype(np.float64)
    g = g.astype(np.float64)
    if kind == "angle":
        fin = np.isfinite(g).all(-1) & np.isfinite(c).all(-1)
        gn, cn = np.linalg.norm(g, axis=-1), np.linalg.norm(c, axis=-1)
        ok = fin & (gn > 0) & (cn > 0)
        cosv = np.clip(np.sum(c[ok] * g[ok], -1) / (cn[ok] * gn[ok]), -1, 1)
        ang = np.degrees(np.arccos(cosv))
        mism = int((np.isfinite(g).all(-1) != np.isfinite(c).all(-1)).sum())
        if ang.size == 0:
            return {"max": 0.0, "p99": 0.0, "beyond": 0.0, "n": 0, "mism": mism, "unit": "deg"}
        return {"max": float(ang.max()), "p99": float(np.percentile(ang, 99)),
                "beyond": float(np.mean(ang > tol.get("deg", 0.05))), "n": int(ang.size), "mism": mism,
                "unit": "deg"}
    both = np.isfinite(g) & np.isfinite(c)
    mism = int(((np.isnan(g) != np.isnan(c)) | (np.isinf(g) != np.isinf(c))
                | (np.isinf(g) & np.isinf(c) & (np.sign(g) != np.sign(c)))).sum())
    over = tol.get("over", "finite")
    info = both & (g != 0) if over == "nonzero" else both
    if not info.any():
        return {"max": 0.0, "p99": 0.0, "beyond": 0.0, "n": 0, "mism": mism, "unit": "abs"}
    with np.errstate(invalid="ignore"):
        err = np.abs(c - g)[info]
    atol = tol.get("atol", 0.0)
    if tol.get("scale") == "max":
        atol = atol * float(np.max(np.abs(g[both])))
    lim = atol + tol.get("rtol", 0.0) * np.abs(g[info])
    out = {"max": float(err.max()), "p99": float(np.percentile(err, 99)), "beyond": float(np.mean(err > lim)),
           "n": int(info.sum()), "mism": mism, "unit": "abs"}
    if tol.get("flux"):
        sg, sc = float(np.sum(g[both])), float(np.sum(c[both]))
        out["total_rel"] = abs(sc - sg) / abs(sg) if sg else 0.0
    return out


def table(golden, cand, cases):
    man = json.load(open(os.path.join(golden, "manifest.json")))
    rows = []
    for case in cases:
        gz = np.load(os.path.join(golden, case, "golden.npz"))
        cz = np.load(os.path.join(cand, case, "result.npz"))
        keys = man["cases"][case]["keys"]
        for k in gz.files:
            if k not in cz.files or k not in keys:
                continue
            d = deviation(cz[k], gz[k], keys[k]["tolerance"])
            rows.append((case, k, keys[k]["tolerance"].get("kind"), d))
    return rows


def _fmt(x):
    if x is None:
        return ""
    if isinstance(x, float):
        return f"{x:.3g}"
    return str(x)


def family(key):
    """The key with its receiver and light indices replaced (``position_0_1`` -> ``position_r_l``)."""
    import re
    k = re.sub(r"_\d+_\d+$", "_r_l", key)
    return re.sub(r"_\d+$", "_r", k)


def summary(rows):
    """Per key family over cases and receivers: the worst max, p99 and share beyond, and where."""
    out = {}
    for case, k, kind, d in rows:
        if "max" not in d:
            continue
        f = family(k)
        if f.startswith("stage.") and f.split(".")[-1] in ("image", "object_mask", "image_direct",
                                                           "object_mask_direct"):
            continue                                            # copies of the final keys
        e = out.setdefault(f, {"kind": kind, "max": 0.0, "p99": 0.0, "beyond": 0.0, "where": "", "mism": 0,
                               "total_rel": 0.0})
        if d["max"] >= e["max"]:
            e["max"] = d["max"]
        if d.get("p99") is not None:
            e["p99"] = max(e["p99"], d["p99"])
        if d["beyond"] > e["beyond"]:
            e["beyond"], e["where"] = d["beyond"], case
        e["mism"] += d.get("mism", 0) or 0
        e["total_rel"] = max(e["total_rel"], d.get("total_rel", 0.0) or 0.0)
    return out


if __name__ == "__main__":
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("golden")
    ap.add_argument("cand")
    ap.add_argument("--cases", default=None)
    ap.add_argument("--summary", action="store_true", help="one row per key family, worst over cases")
    a = ap.parse_args()
    man = json.load(open(os.path.join(a.golden, "manifest.json")))
    cases = a.cases.split(",") if a.cases else sorted(c for c, m in man["cases"].items()
                                                      if m.get("method") == "levelmap")
    if a.summary:
        print("| key | kind | max | p99 | beyond f64 tol (worst case) | NaN/inf mismatches | total rel |")
        print("|---|---|---|---|---|---|---|")
        for f, e in summary(table(a.golden, a.cand, cases)).items():
            unit = " deg" if e["kind"] == "angle" else (" elements" if e["kind"] == "exact" else "")
            print(f"| `{f}` | {e['kind']} | {_fmt(e['max'])}{unit} | {_fmt(e['p99']) if e['kind'] != 'exact' else ''} | "
                  f"{e['beyond'] * 100:.3g} % {('(' + e['where'] + ')') if e['where'] else ''} | {e['mism']} | "
                  f"{_fmt(e['total_rel']) if e['total_rel'] else ''} |")
        sys.exit(0)
    print("| case | key | kind | max | p99 | beyond f64 tol | n | NaN/inf mismatches | total rel |")
    print("|---|---|---|---|---|---|---|---|---|")
    for case, k, kind, d in table(a.golden, a.cand, cases):
        print(f"| {case} | `{k}` | {kind} | {_fmt(d.get('max'))} | {_fmt(d.get('p99'))} | "
              f"{_fmt(d.get('beyond'))} | {d.get('n', '')} | {d.get('mism', '')} | {_fmt(d.get('total_rel'))} |")
    sys.exit(0)
