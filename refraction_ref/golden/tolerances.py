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
    ``slope=s`` (rasterized depths) adds ``s * step(g)``, ``step(g)`` the
    largest ``|g(p) - g(q)|`` over the finite 8 neighbours ``q`` of the
    element in its picture (:func:`neighbour_step`): the depth sampled
    ``s`` pixels away along x and y. :data:`SNAP_SLOPE` = 1/512 admits a
    rasterizer that does not snap vertices to the oracle's 1/256 pixel
    grid, or casts rays analytically (``docs/oracle.md``, "Conformance").
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

Every kind first says which elements fail; the verdict then *locates* them
(``docs/oracle.md``, "Conformance"):

``over``
    The elements a fraction is counted over, the ones that carry
    information: ``all``; ``nonzero`` (either array non-zero: non-empty
    bitmask words, covered pixels, lit texels); ``finite`` (either array
    finite: present layers, recorded interfaces).
``locate``
    Differences are allowed only inside an **ambiguity mask** computed from
    the golden (by :mod:`.check`, per case): for arrays over the camera's
    pixels the silhouettes (within one pixel of a change of the depth
    complexity, of ``hit`` or of the status), for arrays over a map's
    texels the texels beside a depth discontinuity of the position map or
    the edge of the lit region, and for ``own_edges`` keys (codes) also
    where the golden key itself changes. A failing element outside the
    mask is *located*; ``fraction`` is the share of the informative
    elements that may be located failures (0 for codes: a wrong value in
    the interior fails however few pixels carry it). Arrays with no pixel
    or texel axes (photons, volumes, frames) count every failure.
``inside``
    The share of the informative elements that may differ inside the mask
    (:data:`INSIDE`, 2 % for codes): the mask explains ties along edges, not
    a region decided wrongly (TIR pixels marked exited are thin slivers,
    all beside a status change, and 7 % of the diamond's covered pixels).
``why``
    The tolerance's rationale, printed beside each verdict.

"""

from __future__ import annotations

import fnmatch

import numpy as np

__all__ = ["TOLERANCES", "tolerance_for", "judge", "informative", "nonfinite_mismatch", "finiteness",
           "FINITENESS", "SNAP_SLOPE", "neighbour_step"]

_TIE = ("a fragment exactly on a slice boundary rounds either way: one bit moves by one slice, anywhere "
        "(counted over the non-empty words); fragments appear or vanish at silhouettes (edge ties)")
_CODE = ("a code is a decision: it may differ only where the golden's own decision changes nearby "
         "(silhouettes, status boundaries); a wrong value in the interior fails")
_DIR = ("unit vectors: float64 arithmetic in another order moves them by ~1e-12 rad; differences follow "
        "slice ties and silhouettes (1 % of the covered pixels elsewhere: a tie moves an interface by a slice)")
_POS = ("positions and lengths: another order of float64 arithmetic; differences follow slice ties and "
        "silhouettes (0.5 % of the informative elements elsewhere)")
_MAP = ("maps of deterministic photons: another summation order; photons landing on the lit region's edge or "
        "beside a depth discontinuity of the receivers (1 % of the lit texels elsewhere)")
_EXACT_F = "set-up arithmetic (frames, cameras, boxes): float64 rounding only"

#: the sample shift, in pixels per axis, that a rasterizer without the oracle's 1/256 snap (or a ray caster)
#: may have: rounding a vertex to 1/256 moves it by at most 1/512 per axis, and an attribute interpolated
#: at a pixel centre of the snapped triangle is the unsnapped triangle's at a point moved by a convex
#: combination of the vertices' moves, so by at most 1/512 per axis as well
SNAP_SLOPE = 1.0 / 512.0
_SLOPE = ("a rasterizer without the 1/256 vertex snap, or a ray caster, samples each depth up to 1/512 pixel "
          "per axis from the snapped triangle's point: |c - g| may add (1/512) x the largest step to the 8 "
          "neighbours; coverage differs only at silhouettes")
_DEPTH = "rasterized depths: another order of float64 arithmetic; " + _SLOPE + " (0.5 % elsewhere)"

#: (pattern on the key, spec): the first match wins. Stage buffers are ``stage.<stage>.<buffer>``.
TOLERANCES = [
    ("stage.voxelize.bits", {"kind": "exact", "fraction": 0.002, "over": "nonzero", "locate": True,
                             "silhouette": "counts", "why": _TIE}),
    ("stage.peel.depth_complexity", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True,
                                     "why": "layer counts change only where fragments appear or vanish "
                                            "(silhouettes); judged against the candidate's own bitmask"}),
    ("depth_complexity", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True,
                          "why": "as stage.peel.depth_complexity"}),
    ("stage.receiver_depth.triangle", {"kind": "exact", "fraction": 0.0, "over": "all", "locate": True,
                                       "own_edges": True, "why": "triangle ids tie on shared edges"}),
    ("stage.receiver_hit.hit_face_*", {"kind": "exact", "fraction": 0.01, "over": "all",
                                       "why": "photons on a shared edge of two receiver triangles"}),
    ("*photon_status", {"kind": "exact", "fraction": 0.005, "over": "all",
                        "why": "photons grazing the volume's box or a receiver's edge"}),
    ("*status", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True, "own_edges": True,
                 "inside": 0.02, "why": _CODE}),
    ("*interfaces", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True, "own_edges": True,
                     "inside": 0.02, "why": _CODE}),
    ("*hit", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True, "own_edges": True,
              "inside": 0.02, "why": _CODE}),
    ("*object_mask*", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True, "own_edges": True,
                       "inside": 0.02, "why": _CODE}),
    ("*.octree.level", {"kind": "exact", "fraction": 0.0, "over": "all",
                        "why": "the leaf test on the golden's own index volume: no ambiguity"}),
    ("*plane_index*", {"kind": "exact", "over": "all", "why": "the planes drawn: a decision of smart slicing"}),
    ("*planes_used*", {"kind": "exact", "over": "all", "why": "the planes drawn: a decision of smart slicing"}),
    ("*path_dir", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite",
                   "locate": True, "split_first": True, "why": _DIR + "; interface 0 judged apart from the rest"}),
    ("*path_pos", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.005, "over": "finite",
                   "locate": True, "split_first": True, "why": _POS + "; interface 0 judged apart from the rest"}),
    ("*_dir", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite", "locate": True,
               "why": _DIR}),
    ("*_dir_*", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite", "why": _DIR}),
    ("*normals", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite", "locate": True,
                  "why": "unit normals: differences follow slice ties and silhouettes (1 % elsewhere)"}),
    ("*normal_*", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite", "locate": True,
                   "why": "unit normals of the receivers: faces tie on shared edges"}),
    ("*direction", {"kind": "close", "atol": 1e-4, "rtol": 1e-3, "fraction": 0.01, "over": "all",
                    "why": "smoothed photon directions: deposition order"}),
    ("*caustic_frame_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all", "why": _EXACT_F}),
    ("*frame_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all", "why": _EXACT_F}),
    ("*camera_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all", "why": _EXACT_F}),
    ("*box_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all", "why": _EXACT_F}),
    ("stage.caustics.planes_[0-9]*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all",
                                      "why": "plane offsets from the box (eqs. 4-1..4-9): float64 rounding only"}),
    ("*caustic_map*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01,
                       "over": "nonzero", "locate": True, "why": _MAP}),
    ("*caustic_rgb*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01,
                       "over": "nonzero", "locate": True, "why": _MAP}),
    ("*splat_*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01, "over": "nonzero",
                  "locate": True, "why": _MAP}),
    ("*plane_maps*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01,
                      "over": "nonzero", "locate": True,
                      "why": _MAP + "; counted over each plane's lit texels, not diluted over the planes"}),
    ("*radiance", {"kind": "close", "atol": 1e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01, "over": "nonzero",
                   "why": "photon radiance in the volume: deposition order (1 % of the lit voxels)"}),
    ("*image*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "fraction": 0.01, "over": "all", "locate": True,
                 "why": "colours: 8-bit-level differences; silhouettes free, 1 % of the pixels elsewhere "
                        "(slice ties move a path)"}),
    ("*diffuse_*", {"kind": "close", "atol": 1e-6, "rtol": 1e-6, "fraction": 0.0, "over": "nonzero",
                    "locate": True, "why": "albedo per texel: differs only beside a depth discontinuity"}),
    ("*ldi*", {"kind": "close", "atol": 1e-5, "rtol": 1e-5, "slope": SNAP_SLOPE, "fraction": 0.0, "over": "finite",
               "locate": True,
               "why": "layer depths are slice centres: they differ only where the bitmask does (judged against "
                      "the candidate's own bitmask) or at silhouettes; " + _SLOPE}),
    ("stage.minmax.z*", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "slope": SNAP_SLOPE, "fraction": 0.005,
                         "over": "finite", "locate": True, "why": _DEPTH}),
    ("stage.voxelize.z*", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "slope": SNAP_SLOPE, "fraction": 0.005,
                           "over": "finite", "locate": True, "why": _DEPTH}),
    ("stage.receiver_depth.depth", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "slope": SNAP_SLOPE,
                                    "fraction": 0.005, "over": "finite", "locate": True, "why": _DEPTH}),
    ("stage.level_map.position_*", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "slope": SNAP_SLOPE,
                                    "fraction": 0.005, "over": "finite", "locate": True, "why": _DEPTH}),
    ("*", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.005, "over": "finite", "locate": True,
           "why": _POS}),
]

#: the share of the informative elements that may differ inside the ambiguity mask, unless a spec says
INSIDE = 0.05

#: keys of maps from jittered photons, judged by the Z-test when the oracle stored batches
NOISY = ("caustic_map_*",)
ZTEST = {"kind": "ztest", "alpha": 1e-3, "atol": 1e-3, "over": "all",
         "why": "jittered photons: a Z-test against the oracle's K independent batches, Bonferroni-corrected"}


def tolerance_for(key, noisy=False):
    """The tolerance spec of an array key (a copy of the first matching :data:`TOLERANCES` entry).

    Parameters
    ----------
    key : str
        An array key.
    noisy : bool
        The case is judged statistically: keys matching :data:`NOISY` get the
        :data:`ZTEST` spec.

    Returns
    -------
    dict
        The spec (``kind``, tolerances, ``over``, ...), a copy.

    Raises
    ------
    KeyError
        No pattern matches ``key``.
    """
    if noisy and any(fnmatch.fnmatchcase(key, p) for p in NOISY):
        return dict(ZTEST)
    for pat, spec in TOLERANCES:
        if fnmatch.fnmatchcase(key, pat):
            return dict(spec)
    raise KeyError(key)


#: the categories of :func:`finiteness`, by code
FINITENESS = ("NaN", "+inf", "-inf", "finite")


def finiteness(a):
    """Per element of a float array its :data:`FINITENESS` code: 0 NaN, 1 +inf, 2 -inf, 3 finite.

    Parameters
    ----------
    a : ndarray
        A float array.

    Returns
    -------
    int ndarray
        Codes with the shape of ``a``.
    """
    return np.where(np.isnan(a), 0, np.where(a == np.inf, 1, np.where(a == -np.inf, 2, 3)))


def nonfinite_mismatch(c, g):
    """Counts of NaN / inf / finite mismatches by category (``{"NaN where the golden has +inf": n, ...}``).

    Parameters
    ----------
    c : ndarray
        Candidate array.
    g : ndarray
        Golden array, same shape.

    Returns
    -------
    dict of str to int
        Only the categories that occur; empty for non-float arrays.
    """
    if c.dtype.kind not in "fc" or g.dtype.kind not in "fc":
        return {}
    names = FINITENESS
    cc, gc = finiteness(c), finiteness(g)
    out = {}
    for i in range(4):
        for j in range(4):
            if i != j:
                n = int(np.count_nonzero((cc == i) & (gc == j)))
                if n:
                    out[f"{names[i]} where the golden has {names[j]}"] = n
    return out


def informative(c, g, over):
    """The elements a fraction counts over (``over``: all, nonzero, finite), per element of the judged array.

    Parameters
    ----------
    c : ndarray
        Candidate array.
    g : ndarray
        Golden array, same shape.
    over : {'all', 'nonzero', 'finite'}
        ``nonzero``: where either is nonzero (NaN counts); ``finite``: where
        either is finite (for float arrays); otherwise every element.

    Returns
    -------
    bool ndarray
        Mask with the shape of ``g``.
    """
    if over == "nonzero":
        with np.errstate(invalid="ignore"):
            m = (np.nan_to_num(c, nan=1.0) != 0) | (np.nan_to_num(g, nan=1.0) != 0)
    elif over == "finite" and g.dtype.kind in "fc":
        m = np.isfinite(c) | np.isfinite(g) if c.dtype.kind in "fc" else np.isfinite(g)
    else:
        m = np.ones(g.shape, bool)
    return m


def _elementwise(c, g, spec, batches):
    """Per element: failing mask (over the array's elements, or its vectors for ``angle``), error, detail."""
    kind = spec["kind"]
    if kind == "exact":
        bad = (c != g) if g.dtype.kind not in "fc" else ~((c == g) | (np.isnan(c) & np.isnan(g)))
        err = {"differing": int(np.count_nonzero(bad))}
        detail = f"{err['differing']} of {bad.size} elements differ"
    elif kind == "close":
        c64, g64 = c.astype(np.float64), g.astype(np.float64)
        fin = np.isfinite(g64)
        scale = float(np.max(np.abs(g64[fin]))) if spec.get("scale") == "max" and fin.any() else 1.0
        tol = spec["atol"] * scale + spec["rtol"] * np.abs(np.where(fin, g64, 0.0))
        slope = float(spec.get("slope", 0.0))
        if slope:
            tol = tol + slope * neighbour_step(g64)
        with np.errstate(invalid="ignore"):
            diff = np.abs(c64 - g64)
            bad = (np.isnan(c64) != np.isnan(g64)) | (fin & ~(diff <= tol)) | (np.isinf(g64) & (c64 != g64))
        d = diff[fin & np.isfinite(c64)]
        err = {"max_abs": float(d.max()) if d.size else 0.0, "scale": scale}
        detail = (f"max |c - g| {err['max_abs']:.3g} over the finite pairs (tolerance {spec['atol']:g} x "
                  f"{scale:.3g} + {spec['rtol']:g} |g|" + (f" + {slope:.3g} step(g)" if slope else "") + ")")
    elif kind == "angle":
        c64, g64 = c.astype(np.float64), g.astype(np.float64)
        if c64.shape[-1] != 3:
            raise ValueError("angle tolerance on an array whose last axis is not 3")
        fin = np.all(np.isfinite(g64), axis=-1)
        cfin = np.all(np.isfinite(c64), axis=-1)
        both = fin & cfin
        ang = np.zeros(fin.shape)
        nrm = np.linalg.norm(np.where(np.isfinite(c64), c64, 0.0), axis=-1)
        gn = np.linalg.norm(np.where(np.isfinite(g64), g64, 0.0), axis=-1)
        dots = np.sum(np.where(both[..., None], c64 * g64, 0.0), axis=-1)
        crs = np.linalg.norm(np.cross(np.where(both[..., None], c64, 0.0), np.where(both[..., None], g64, 0.0)),
                             axis=-1)
        ang[both] = np.degrees(np.arctan2(crs[both], dots[both]))
        unit = both & (gn > 0.5)  # zero vectors (no photon passed, no surface) must stay zero
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
        t = _z_threshold(spec["alpha"] / n)  # two-sided Bonferroni threshold: P(|Z| > t) = alpha / n
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(has, (c64 - mean) / np.sqrt(np.where(has, var_t, 1.0)), 0.0)
        bad = (has & ~(np.abs(z) <= t)) | (~has & ~(np.abs(c64 - mean) <= spec["atol"] * scale))
        err = {"max_abs_z": float(np.abs(z[has]).max()) if has.any() else 0.0, "threshold": t, "batches": K}
        detail = f"max |z| {err['max_abs_z']:.3g} (threshold {t:.3g}: alpha {spec['alpha']:g} over {n} texels, K = {K})"
    else:
        raise ValueError(f"unknown tolerance kind {kind!r}")
    return bad, err, detail


def neighbour_step(g):
    """Per element, the largest ``|g(p) - g(q)|`` over its finite 8 neighbours ``q`` in the picture.

    The picture is the last two axes (rows and columns: (H, W), or (L, H, W) per layer); 0 where the
    element or all its neighbours are not finite. Diagonal neighbours count, so ``step >= |g_x| + |g_y|``
    on a plane: a sample moved by ``s`` pixels along both axes moves the value by at most ``s * step``.

    References
    ----------
    docs/oracle.md, "Conformance" (the ``slope`` term of ``close``).
    """
    g = np.asarray(g, np.float64)
    if g.ndim < 2:
        raise ValueError("a slope tolerance needs an array with picture axes (..., H, W)")
    H, W = g.shape[-2:]
    fin = np.isfinite(g)
    p = np.pad(np.where(fin, g, 0.0), [(0, 0)] * (g.ndim - 2) + [(1, 1), (1, 1)])
    pf = np.pad(fin, [(0, 0)] * (g.ndim - 2) + [(1, 1), (1, 1)])
    out = np.zeros(g.shape)
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            if di == dj == 1:
                continue
            ok = fin & pf[..., di:di + H, dj:dj + W]
            d = np.abs(p[..., di:di + H, dj:dj + W] - np.where(fin, g, 0.0))
            out = np.where(ok, np.maximum(out, d), out)
    return out


def _fold(a, shape):
    """Reduce a per-element mask to ``shape`` (the failing mask's: vectors fold their last axis) with any()."""
    while a.ndim > len(shape):
        a = a.any(axis=-1)
    return np.broadcast_to(a, shape)


def judge(cand, gold, spec, batches=None, ambiguous=None):
    """Judge one array against the golden.

    Parameters
    ----------
    cand, gold : ndarray
        Same shape (checked by the caller).
    spec : dict
        A :data:`TOLERANCES` spec (or :data:`ZTEST`).
    batches : (K, ...) ndarray, optional
        The oracle's independent batches, for ``ztest``.
    ambiguous : bool ndarray, optional
        The ambiguity mask (broadcastable to the failing mask), for ``locate`` specs.

    Returns
    -------
    dict
        ``ok``, ``failing`` (located failures over informative elements), ``allowed``, ``counts``
        (failing, inside the ambiguity mask, located, informative), ``nonfinite`` (mismatch counts by
        category), ``error`` (measured), ``detail``, ``why``, ``parts`` (``split_first``: interface 0 and
        the rest judged apart) and ``bad`` (the located failing elements, for the mask file).
    """
    allowed = float(spec.get("fraction", 0.0))
    c = np.asarray(cand)
    g = np.asarray(gold)
    bad, err, detail = _elementwise(c, g, spec, batches)
    info = _fold(informative(c, g, spec.get("over", "all")), bad.shape) | bad
    amb = np.zeros(bad.shape, bool) if ambiguous is None else _fold(np.asarray(ambiguous, bool), bad.shape)
    located = bad & ~amb
    nonfinite = nonfinite_mismatch(c, g)

    inside = float(spec.get("inside", INSIDE)) if ambiguous is not None else 1.0

    def verdict(loc, inf, b, a):
        n_info = int(np.count_nonzero(inf))
        n_loc = int(np.count_nonzero(loc))
        frac = n_loc / max(n_info, 1)
        n_in = int(np.count_nonzero(b & a))
        return {"ok": frac <= allowed and n_in <= inside * max(n_info, 1), "failing": frac, "counts": {
            "failing": int(np.count_nonzero(b)), "inside_ambiguity": int(np.count_nonzero(b & a)),
            "located": n_loc, "informative": n_info}}

    parts = None
    if spec.get("split_first") and bad.ndim >= 3 and bad.shape[2] > 1:  # (H, W, K): interface k on axis 2
        parts = {name: verdict(located[:, :, sl], info[:, :, sl], bad[:, :, sl], amb[:, :, sl])
                 for name, sl in (("interface 0", slice(0, 1)), ("interfaces 1+", slice(1, None)))}
        v = verdict(located, info, bad, amb)
        v["ok"] = all(p["ok"] for p in parts.values())
        v["failing"] = max(p["failing"] for p in parts.values())
    else:
        v = verdict(located, info, bad, amb)
    cn = v["counts"]
    detail += (f"; {cn['located']} failing outside the ambiguity mask of {cn['informative']} informative "
               f"({cn['inside_ambiguity']} more inside it, {100 * inside:.3g} % allowed there)")
    if parts:
        detail += "; " + ", ".join(f"{n}: {p['counts']['located']} of {p['counts']['informative']}"
                                   f"{'' if p['ok'] else ' FAIL'}" for n, p in parts.items())
    if nonfinite:
        detail += "; " + ", ".join(f"{n} {k}" for k, n in nonfinite.items())
    return dict(v, allowed=allowed, inside_allowed=inside, error=err, detail=detail, why=spec.get("why", ""), nonfinite=nonfinite,
                parts=parts, bad=located)


def _z_threshold(p):
    """``t`` with ``P(|Z| > t) = p`` for a standard normal Z."""
    from scipy.stats import norm

    return float(norm.isf(p / 2.0))
