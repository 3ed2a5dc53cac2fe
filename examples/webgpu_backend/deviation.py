"""Per-key deviation of a candidate folder from the golden suite: max, p99, share beyond the float64 tolerance.

    python examples/webgpu_backend/deviation.py CAND_DIR GOLDEN_DIR [--cases a,b] [--md OUT.md]

For each key the candidate supplies, pooled over the cases: the largest and the
99th-percentile difference (``|c - g|`` for values, the angle in degrees for
directions and normals, "differs" for codes and bit words), and the share of
the compared elements beyond the key's own tolerance taken element by element
(``atol + rtol |g|``, plus ``slope step(g)`` for the rasterized depths; the
angle bound for directions; equality for codes), **without** `check`'s
ambiguity masks and fractions: what a float32 backend moves, not check's verdict.
"""
from __future__ import annotations

import argparse
import json
import os

import numpy as np


def _step(g):
    """The largest |g(p) - g(q)| over the finite 8 neighbours q, per 2D picture (leading axes are layers)."""
    a = np.asarray(g, np.float64)
    pic = a.reshape((-1,) + a.shape[-2:])
    out = np.zeros_like(pic)
    H, W = pic.shape[1:]
    pad = np.full((pic.shape[0], H + 2, W + 2), np.nan)
    pad[:, 1:-1, 1:-1] = pic
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == dj == 0:
                continue
            nb = pad[:, 1 + di:1 + di + H, 1 + dj:1 + dj + W]
            d = np.abs(nb - pic)
            d[~np.isfinite(d)] = 0.0
            out = np.maximum(out, d)
    return out.reshape(a.shape)


def key_deviation(c, g, tol):
    """(differences, beyond-tolerance flags) of one key's compared elements, or None if not comparable."""
    if c.shape != g.shape:
        return None
    kind = tol.get("kind")
    if kind == "angle":
        c3, g3 = c.reshape(-1, 3).astype(np.float64), g.reshape(-1, 3).astype(np.float64)
        ok = np.all(np.isfinite(c3), 1) & np.all(np.isfinite(g3), 1) & (np.linalg.norm(g3, axis=1) > 0)
        a, b = c3[ok], g3[ok]
        cr = np.linalg.norm(np.cross(a, b), axis=1)
        ang = np.degrees(np.arctan2(cr, np.sum(a * b, 1)))
        return ang, ang > float(tol.get("deg", 0.05))
    if kind == "exact" or not np.issubdtype(g.dtype, np.floating):
        d = (c != g).ravel().astype(np.float64)
        return d, d > 0
    a, b = c.astype(np.float64), g.astype(np.float64)
    ok = np.isfinite(a) & np.isfinite(b)
    d = np.abs(a - b)
    bound = float(tol.get("atol", 1e-6)) + float(tol.get("rtol", 1e-5)) * np.abs(b)
    if tol.get("scale") == "max":
        bound = float(tol.get("atol", 0.002)) * np.nanmax(np.abs(b)) + float(tol.get("rtol", 1e-3)) * np.abs(b)
    if tol.get("slope"):
        bound = bound + float(tol["slope"]) * _step(b)
    return d[ok], (d > bound)[ok]


def deviations(cand, golden, cases=None):
    """key -> dict(n, max, p99, beyond, cases) pooled over the cases."""
    with open(os.path.join(golden, "manifest.json")) as fh:
        man = json.load(fh)
    cases = cases or sorted(n for n in man["cases"] if os.path.exists(os.path.join(cand, n, "result.npz")))
    pooled = {}
    for case in cases:
        keys = man["cases"][case]["keys"]
        with np.load(os.path.join(cand, case, "result.npz")) as C, np.load(os.path.join(golden, case, "golden.npz")) as G:
            for k in C.files:
                if k not in G.files or k not in keys:
                    continue
                r = key_deviation(C[k], G[k], keys[k].get("tolerance") or {})
                if r is None or r[0].size == 0:
                    continue
                name = k
                for suffix in ("_0", "_1", "_2", "_3"):       # one row per light / receiver pattern
                    if k.endswith(suffix):
                        name = k[:-len(suffix)] + "_l" if "photon_trace" in k or "receiver_hit" in k \
                            or "shadow" in k else k[:-len(suffix)] + "_r"
                p = pooled.setdefault(name, {"d": [], "b": [], "cases": 0, "kind": (keys[k].get("tolerance") or {}).get("kind")})
                p["d"].append(r[0])
                p["b"].append(r[1])
                p["cases"] += 1
    out = {}
    for k, p in pooled.items():
        d = np.concatenate(p["d"])
        b = np.concatenate(p["b"])
        out[k] = {"n": int(d.size), "max": float(d.max()), "p99": float(np.percentile(d, 99)),
                  "beyond": float(b.mean()), "kind": p["kind"], "cases": p["cases"]}
    return out


def markdown(dev):
    lines = ["| key | kind | cases | elements | max | p99 | beyond the float64 tolerance |", "|---|---|---|---|---|---|---|"]
    for k in sorted(dev):
        v = dev[k]
        unit = " deg" if v["kind"] == "angle" else ""
        if v["kind"] == "exact":
            mx, p99 = ("differs" if v["max"] > 0 else "equal"), ""
        else:
            mx, p99 = f"{v['max']:.3g}{unit}", f"{v['p99']:.3g}{unit}"
        lines.append(f"| `{k}` | {v['kind']} | {v['cases']} | {v['n']} | {mx} | {p99} | "
                     f"{v['beyond'] * 100:.3g} % |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cand")
    ap.add_argument("golden")
    ap.add_argument("--cases", default=None)
    ap.add_argument("--md", default=None)
    a = ap.parse_args()
    md = markdown(deviations(a.cand, a.golden, a.cases.split(",") if a.cases else None))
    print(md)
    if a.md:
        with open(a.md, "w") as fh:
            fh.write(md)
