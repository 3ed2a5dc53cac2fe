"""Photon buffers of another count judged photon by photon: the candidate's photons matched to the golden's.

Keys of one photon set share their leading axis (one row per photon, in the
order the contract gives: light texel order for the mesh methods, photon
index for the volumetric). When a candidate's count differs, its photons are
matched to the golden's along the first anchor key it supplies, in order
(:func:`align_photons`), and each key is judged on the matched photons, the
others named (:func:`judge_photons`).

References
----------
docs/oracle.md, "Conformance" (photon buffers).
"""

from __future__ import annotations

import re

import numpy as np

from .tolerances import judge

__all__ = ["align_photons", "judge_photons", "photon_set", "ALIGN_WINDOW"]


#: photon buffers: (key pattern, set name, anchor keys in the order they are tried)
_PHOTON_SETS = (
    (re.compile(r"stage\.(?:photon_trace|receiver_hit)\.(?:exit_pos|exit_dir|hit_pos|hit_face)_(\d+)"),
     "light {0}", ("stage.photon_trace.exit_pos_{0}", "stage.photon_trace.exit_dir_{0}",
                   "stage.receiver_hit.hit_pos_{0}")),
    (re.compile(r"stage\.photons\.start_(?:pos|dir|radiance)|stage\.march\.(?:exit_pos|exit_dir|photon_status|"
                r"hit_pos|hit_receiver)|photon_(?:exit_pos|exit_dir|status)"),
     "photons", ("stage.photons.start_pos", "stage.photons.start_dir", "photon_exit_pos", "stage.march.exit_pos",
                 "photon_exit_dir", "stage.march.exit_dir")),
)
#: how far ahead (photons) the matching looks for the next match
ALIGN_WINDOW = 256


def photon_set(key):
    """(set name, anchor keys) of a photon buffer, or None.

    Parameters
    ----------
    key : str
        A contract key.

    Returns
    -------
    tuple or None
        The set's name (``"light 0"``, ``"photons"``) and the keys its photons may be matched along.
    """
    for rx, nm, anchors in _PHOTON_SETS:
        m = rx.fullmatch(key)
        if m:
            g = m.groups()
            return nm.format(*g), tuple(a.format(*g) for a in anchors)
    return None


def _rows_match(c_row, g_rows):
    """Which golden rows (n, ...) a candidate row equals within 1e-6 + 1e-5 |g| (NaN meets NaN)."""
    c = np.asarray(c_row, np.float64).reshape(1, -1)
    g = np.asarray(g_rows, np.float64).reshape(len(g_rows), -1)
    with np.errstate(invalid="ignore"):
        ok = (np.abs(c - g) <= 1e-6 + 1e-5 * np.abs(g)) | (np.isnan(c) & np.isnan(g))
    return ok.all(axis=1)


def _row_matches(cand, gold):
    """For each candidate row, the sorted golden rows it equals (:func:`_rows_match`), found through a sort.

    The golden rows are sorted on their first component; a candidate row is compared only with those
    whose first component lies within the tolerance's reach of its own (a binary search), and rows whose
    first component is not finite only with each other: O(n log n) for rows that match few others.
    """
    c = np.asarray(cand, np.float64)
    g = np.asarray(gold, np.float64)
    if len(c) == 0 or len(g) == 0:
        return [np.zeros(0, np.int64) for _ in range(len(c))]
    c, g = c.reshape(len(c), -1), g.reshape(len(g), -1)
    g0 = g[:, 0] if g.shape[1] else np.zeros(len(g))
    fin = np.isfinite(g0)
    order = np.flatnonzero(fin)[np.argsort(g0[fin], kind="stable")]
    keys = g0[order]
    odd = np.flatnonzero(~fin)
    out = []
    for i in range(len(c)):
        c0 = c[i, 0] if c.shape[1] else 0.0
        if np.isfinite(c0):
            # |c0 - g0| <= 1e-6 + 1e-5 |g0| implies |g0| <= (|c0| + 1e-6) / (1 - 1e-5): the reach, widened a hair
            reach = (1e-6 + 1e-5 * (abs(c0) + 1e-6) / (1.0 - 1e-5)) * (1.0 + 1e-9) + 1e-300
            lo, hi = np.searchsorted(keys, c0 - reach, "left"), np.searchsorted(keys, c0 + reach, "right")
            idx = order[lo:hi]
        else:
            idx = odd
        if len(idx):
            idx = np.sort(idx[_rows_match(c[i], g[idx])])
        out.append(idx)
    return out


def align_photons(cand, gold, window=ALIGN_WINDOW):
    """Match two photon lists kept in one order: pairs (golden index, candidate index), in order.

    Walks both lists: equal rows (within float64 rounding) pair; otherwise the nearer of the next
    candidate row equal to the golden's and the next golden row equal to the candidate's (within
    ``window``) skips the photons between as unmatched; when neither exists the two rows pair anyway (the
    same photon, computed differently: judged, and failing, as such). Which rows equal which is found
    once, through a sort on the first component (:func:`_row_matches`), so the walk is O(n log n).

    Parameters
    ----------
    cand, gold : (P', ...), (P, ...) ndarray
        The anchor key's rows.

    Returns
    -------
    gi, ci : int ndarrays
        Indices of the matched golden and candidate photons.
    """
    nc, ng = len(cand), len(gold)
    c_to_g = _row_matches(cand, gold)
    pairs = [(int(j), i) for i, js in enumerate(c_to_g) for j in js]
    g_to_c = [[] for _ in range(ng)]
    for j, i in pairs:
        g_to_c[j].append(i)
    g_to_c = [np.asarray(x, np.int64) for x in g_to_c]

    def first_after(sorted_idx, at, limit):
        k = np.searchsorted(sorted_idx, at, "right")
        return int(sorted_idx[k]) if k < len(sorted_idx) and sorted_idx[k] < limit else None

    gi, ci = [], []
    i = j = 0
    while i < nc and j < ng:
        m = c_to_g[i]
        k = np.searchsorted(m, j, "left")
        if k < len(m) and m[k] == j:
            gi.append(j), ci.append(i)
            i, j = i + 1, j + 1
            continue
        ng_next = first_after(m, j, j + window)
        nc_next = first_after(g_to_c[j], i, min(nc, i + window))
        kg = None if ng_next is None else ng_next - j
        kc = None if nc_next is None else nc_next - i
        if kg is not None and (kc is None or kg <= kc):
            j += kg
        elif kc is not None:
            i += kc
        else:
            gi.append(j), ci.append(i)
            i, j = i + 1, j + 1
    return np.asarray(gi, np.int64), np.asarray(ci, np.int64)


def _index_list(idx, n=8):
    idx = [int(x) for x in idx]
    return ", ".join(f"#{x}" for x in idx[:n]) + (f", ... ({len(idx)} in all)" if len(idx) > n else "")


def judge_photons(key, c, g, tol, cand, gold, cache):
    """Judge a photon buffer whose count differs from the golden's, photon by photon; None if it cannot.

    Parameters
    ----------
    key : str
        The photon buffer.
    c, g : ndarray
        The candidate's and the golden's arrays of ``key``.
    tol : dict
        Its tolerance.
    cand, gold : dict of str to ndarray
        Every array of the case (the anchors).
    cache : dict
        The matchings found so far in the case (one per set, anchor and count), filled here.

    Returns
    -------
    dict or None
        :func:`~refraction_ref.golden.tolerances.judge`'s verdict over the matched photons, the unmatched
        ones counted as failing, and ``photons`` (matched, missing, extra, anchor).
    """
    ps = photon_set(key)
    if ps is None or c.ndim != g.ndim or c.shape[1:] != g.shape[1:]:
        return None
    nm, anchors = ps
    a = next((a for a in anchors if a in cand and a in gold and np.asarray(cand[a]).shape[0] == c.shape[0]
              and np.asarray(cand[a]).shape[1:] == np.asarray(gold[a]).shape[1:]), None)
    if a is None:
        return None
    if (nm, a, c.shape[0]) not in cache:
        cache[(nm, a, c.shape[0])] = align_photons(np.asarray(cand[a]), np.asarray(gold[a]))
    gi, ci = cache[(nm, a, c.shape[0])]
    r = judge(c[ci], g[gi], tol)
    missing = np.setdiff1d(np.arange(g.shape[0]), gi)
    extra = np.setdiff1d(np.arange(c.shape[0]), ci)
    bad = np.zeros(g.shape[:1], bool)
    bad_m = np.asarray(r["bad"])
    while bad_m.ndim > 1:
        bad_m = bad_m.any(axis=-1)
    bad[gi] = bad_m
    bad[missing] = True
    n_info = max(g.shape[0], c.shape[0])
    n_loc = int(np.count_nonzero(bad_m)) + len(missing) + len(extra)
    frac = n_loc / max(n_info, 1)
    ok = r["ok"] and frac <= r["allowed"]
    ca = np.asarray(cand[a], np.float64)[ci].reshape(len(ci), -1)
    ga = np.asarray(gold[a], np.float64)[gi].reshape(len(gi), -1)
    with np.errstate(invalid="ignore"):
        n_eq = int(np.count_nonzero(((np.abs(ca - ga) <= 1e-6 + 1e-5 * np.abs(ga)) | (np.isnan(ca) & np.isnan(ga)))
                                    .all(axis=1)))
    detail = (f"{c.shape[0]} photons where the golden has {g.shape[0]} ({nm}): {len(gi)} paired in order along "
              f"`{a}` ({n_eq} of them equal there, the rest paired where no equal row lies within "
              f"{ALIGN_WINDOW} photons); {len(missing)} golden photons with no counterpart "
              f"({_index_list(missing) or 'none'}); {len(extra)} candidate photons with none ({_index_list(extra) or 'none'}); on the paired "
              f"photons: {r['detail']}")
    counts = dict(r["counts"], located=n_loc, informative=n_info,
                  failing=int(r["counts"]["failing"]) + len(missing) + len(extra))
    return dict(r, ok=ok, failing=frac, counts=counts, detail=detail, bad=bad,
                photons={"matched": len(gi), "missing": [int(x) for x in missing],
                         "extra": [int(x) for x in extra], "anchor": a})
