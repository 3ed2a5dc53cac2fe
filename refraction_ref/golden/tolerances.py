"""How a candidate's array is judged against the oracle's: the tolerance kinds and their defaults.

Kinds (``docs/oracle.md``, "Conformance"):

``exact``
    Equal values (status, interfaces, hit, bitmask words, layer counts,
    triangle ids). ``fraction`` of the elements may differ: silhouette
    pixels and fragments exactly on a slice boundary are legitimate ties.
``close``
    ``|c - g| <= atol + rtol |g|`` (positions, depths, path lengths, maps
    of deterministic photons, images); NaN must meet NaN. ``scale='max'``
    makes ``atol`` relative to the largest ``|g|`` (photon maps).
``angle``
    Unit vectors (directions, normals): the angle between them at most
    ``deg`` degrees, and ``|c|`` within ``norm`` of 1 (a normal that is not
    renormalised fails even when it points the right way); NaN meets NaN.
``ztest``
    Maps of jittered photons (the exact references): per texel
    ``z = (c - mean) / sqrt(var (1 + 1/K) + p q^2)`` over the oracle's K
    independent batches, two-sided, Bonferroni-corrected for the number of
    texels tested at significance ``alpha`` (Mitsuba 3's render tests in
    spirit). ``q`` is the irradiance one photon deposits in one texel (its
    flux over the texel's area) and ``p = (hits + 1) / (K + 2)`` the
    texel's estimated chance of a hit (``hits``: batches in which it was
    hit): a texel that photons seldom reach has a sample variance of zero
    in K batches although one photon may land there, and the floor
    ``p q^2`` keeps the Gaussian test honest there.

Every kind allows a ``fraction`` of elements to fail (0 by default).
"""

from __future__ import annotations

import fnmatch

import numpy as np

__all__ = ["TOLERANCES", "tolerance_for", "judge"]

#: (pattern on the key, spec): the first match wins. Stage buffers are ``stage.<stage>.<buffer>``.
TOLERANCES = [
    ("stage.voxelize.bits", {"kind": "exact", "fraction": 0.002}),
    ("stage.peel.depth_complexity", {"kind": "exact", "fraction": 0.002}),
    ("depth_complexity", {"kind": "exact", "fraction": 0.002}),
    ("stage.receiver_depth.triangle", {"kind": "exact", "fraction": 0.01}),
    ("stage.receiver_hit.hit_face_*", {"kind": "exact", "fraction": 0.01}),
    ("*status", {"kind": "exact", "fraction": 0.005}),
    ("*interfaces", {"kind": "exact", "fraction": 0.005}),
    ("*hit", {"kind": "exact", "fraction": 0.005}),
    ("*object_mask*", {"kind": "exact", "fraction": 0.005}),
    ("*.octree.level", {"kind": "exact", "fraction": 0.0}),
    ("*plane_index*", {"kind": "exact"}),
    ("*planes_used*", {"kind": "exact"}),
    ("*_dir", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01}),
    ("*_dir_*", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01}),
    ("*path_dir", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01}),
    ("*normals", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01}),
    ("stage.normals.normals", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01}),
    ("*normal_*", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01}),
    ("*direction", {"kind": "close", "atol": 1e-4, "rtol": 1e-3, "fraction": 0.01}),
    ("*caustic_frame_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7}),
    ("*frame_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7}),
    ("*camera_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7}),
    ("*box_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7}),
    ("*caustic_map*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01}),
    ("*caustic_rgb*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01}),
    ("*splat_*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01}),
    ("*plane_maps*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01}),
    ("*radiance", {"kind": "close", "atol": 1e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01}),
    ("*image*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "fraction": 0.01}),
    ("*diffuse_*", {"kind": "close", "atol": 1e-6, "rtol": 1e-6, "fraction": 0.005}),
    ("*ldi*", {"kind": "close", "atol": 1e-5, "rtol": 1e-5, "fraction": 0.002}),
    ("*", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.005}),
]

#: keys of maps from jittered photons, judged by the Z-test when the oracle stored batches
NOISY = ("caustic_map_*",)
ZTEST = {"kind": "ztest", "alpha": 1e-3, "atol": 1e-3}


def tolerance_for(key, noisy=False):
    """The tolerance spec of an array key (a copy of the first matching :data:`TOLERANCES` entry)."""
    if noisy and any(fnmatch.fnmatchcase(key, p) for p in NOISY):
        return dict(ZTEST)
    for pat, spec in TOLERANCES:
        if fnmatch.fnmatchcase(key, pat):
            return dict(spec)
    raise KeyError(key)


def _nan_mismatch(c, g):
    if c.dtype.kind not in "fc" or g.dtype.kind not in "fc":
        return np.zeros(g.shape, bool)
    return np.isnan(c) != np.isnan(g)


def judge(cand, gold, spec, batches=None):
    """Judge one array; returns a dict ``ok``, ``failing`` (fraction), ``allowed``, ``error`` (measured), ``detail``.

    Parameters
    ----------
    cand, gold : ndarray
        Same shape (checked by the caller).
    spec : dict
        A :data:`TOLERANCES` spec (or :data:`ZTEST`).
    batches : (K, ...) ndarray, optional
        The oracle's independent batches, for ``ztest``.
    """
    kind = spec["kind"]
    allowed = float(spec.get("fraction", 0.0))
    c = np.asarray(cand)
    g = np.asarray(gold)
    if kind == "exact":
        bad = (c != g) if g.dtype.kind not in "fc" else ~((c == g) | (np.isnan(c) & np.isnan(g)))
        err = {"differing": int(np.count_nonzero(bad))}
        detail = f"{err['differing']} of {bad.size} elements differ"
    elif kind == "close":
        c64, g64 = c.astype(np.float64), g.astype(np.float64)
        fin = np.isfinite(g64)
        scale = float(np.max(np.abs(g64[fin]))) if spec.get("scale") == "max" and fin.any() else 1.0
        tol = spec["atol"] * scale + spec["rtol"] * np.abs(np.where(fin, g64, 0.0))
        with np.errstate(invalid="ignore"):
            diff = np.abs(c64 - g64)
            bad = _nan_mismatch(c64, g64) | (fin & ~(diff <= tol)) | (np.isinf(g64) & (c64 != g64))
        d = diff[fin & np.isfinite(c64)]
        err = {"max_abs": float(d.max()) if d.size else 0.0, "scale": scale}
        detail = f"max |c - g| {err['max_abs']:.3g} (tolerance {spec['atol']:g} x {scale:.3g} + {spec['rtol']:g} |g|)"
    elif kind == "angle":
        c64, g64 = c.astype(np.float64), g.astype(np.float64)
        if c64.shape[-1] != 3:
            raise ValueError("angle tolerance on an array whose last axis is not 3")
        fin = np.all(np.isfinite(g64), axis=-1)
        cfin = np.all(np.isfinite(c64), axis=-1)
        both = fin & cfin
        ang = np.zeros(fin.shape)
        nrm = np.linalg.norm(c64, axis=-1)
        gn = np.linalg.norm(g64, axis=-1)
        dots = np.sum(c64 * g64, axis=-1)
        crs = np.linalg.norm(np.cross(c64, g64), axis=-1)
        ang[both] = np.degrees(np.arctan2(crs[both], dots[both]))
        # zero vectors (no photon passed, no surface) must stay zero
        unit = both & (gn > 0.5)
        bad = (fin != cfin) | (unit & ((ang > spec["deg"]) | (np.abs(nrm - 1.0) > spec["norm"]))) \
            | (both & (gn <= 0.5) & (nrm > 1e-9))
        a = ang[unit]
        err = {"max_deg": float(a.max()) if a.size else 0.0,
               "max_norm_error": float(np.abs(nrm[unit] - 1.0).max()) if unit.any() else 0.0}
        detail = (f"max angle {err['max_deg']:.3g} deg (tolerance {spec['deg']:g}), max | |c| - 1 | "
                  f"{err['max_norm_error']:.2g} (tolerance {spec['norm']:g})")
    elif kind == "ztest":
        if batches is None:
            raise ValueError("a ztest tolerance needs the oracle's batches")
        b = np.asarray(batches, np.float64)
        K = b.shape[0]
        mean = b.mean(axis=0)
        var = b.var(axis=0, ddof=1) if K > 1 else np.zeros_like(mean)
        c64 = c.astype(np.float64)
        scale = float(np.abs(mean).max()) or 1.0
        q = float(spec.get("quantum", 0.0))
        p = (np.count_nonzero(b != 0, axis=0) + 1.0) / (K + 2.0)
        var_t = var * (1.0 + 1.0 / K) + p * q * q
        has = var_t > 0
        n = max(int(np.count_nonzero(has)), 1)
        # two-sided Bonferroni threshold: P(|Z| > t) = alpha / n
        t = _z_threshold(spec["alpha"] / n)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(has, (c64 - mean) / np.sqrt(np.where(has, var_t, 1.0)), 0.0)
        bad = (has & ~(np.abs(z) <= t)) | (~has & ~(np.abs(c64 - mean) <= spec["atol"] * scale))
        err = {"max_abs_z": float(np.abs(z[has]).max()) if has.any() else 0.0, "threshold": t, "batches": K}
        detail = f"max |z| {err['max_abs_z']:.3g} (threshold {t:.3g}: alpha {spec['alpha']:g} over {n} texels, K = {K})"
    else:
        raise ValueError(f"unknown tolerance kind {kind!r}")
    failing = float(np.count_nonzero(bad)) / max(bad.size, 1)
    return {"ok": failing <= allowed, "failing": failing, "allowed": allowed, "error": err, "detail": detail,
            "bad": bad}


def _z_threshold(p):
    """``t`` with ``P(|Z| > t) = p`` for a standard normal Z."""
    from scipy.stats import norm

    return float(norm.isf(p / 2.0))
