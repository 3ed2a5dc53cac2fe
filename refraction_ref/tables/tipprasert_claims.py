"""Tipprasert (2006): the thesis's claims of chs. 5 and 6 and the abstract, as rows judged on the tables' measurements.

Each :class:`~.claims.ClaimRow` quotes a sentence, states its rule and names
the judge that reads :func:`claims`' measurements (the rows of
:func:`.tipprasert.measure`, :func:`.tipprasert.culling_study`,
:func:`.tipprasert.one_plane_memory` and
:func:`.tipprasert_placement.placement_study`).

References
----------
N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene with
Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn University,
2006, §5.1, §5.2.4 (Tables 5-1 to 5-5, Figs. 5-11, 5-12, eqs. 5-1 to 5-7),
§6.1, §6.2, the abstract.
"""

from __future__ import annotations

import statistics

import numpy as np

from .claims import ClaimRow, Finding, evaluate
from .common import BY_CONSTRUCTION, NOT_COMPARABLE, NOT_MEASURED, ratio_spread, spread, straddles
from .tipprasert_placement import ONE_PLANE, READINGS
from .tipprasert_scenes import PAPER, depth_levels

__all__ = ["CLAIMS", "claims", "LITTLE"]

QUOTE_5_1 = ("From graphs and table, the result from experimental program supports our assumption; the level map "
             "algorithm outperforms volumetric algorithm in all cases.")
QUOTE_LINEAR = ("It is obvious that the processing time for illumination map creation has a direct variation with "
                "number of sample planes.")
QUOTE_SMART = ("From this reason, we can safely conclude that smart slicing algorithm can greatly reduce rendering "
               "time for level map algorithm in most situations.")
QUOTE_5_5 = "Table 5-5 shows that enabling smart slicing do not affect the quality in any cases."
QUOTE_MEMORY = ("To handle a scene mentioned above, assuming that both color and depth textures use 16 bits format, "
                "our algorithm uses only 100 MB rather than those gigantic 5000 MB required in the first algorithm.")
QUOTE_IDENTICAL = ("In term of quality, our experiments have already proven that the resulting images from level map "
                   "are per-pixel identical to volumetric based algorithm.")
QUOTE_PROFILE = ("But this additional processing time has a very little significance when compared to the processing "
                 "time used for intersection test.")
Q_ONE_PLANE = ("There is only one situation where our algorithm uses more memory than volumetric based algorithm, that "
               "is, when each object owns only one plane.")
Q_VARIES = ("When using sphere as an input, the algorithm gives the best performance, however, using with dolphin gives "
            "no difference.")
Q_EMPTY = "There is only one empty level in dolphin model while the others have several."
Q_LONGER = ("When thoroughly examining Table 5-3 and Table 5-4, we can see that at the same number of reference planes, "
            "the rendering time used when smart slicing turn on is a little bit longer.")
Q_T54 = ("Table 5-4 proves the earlier statement by showing the number of actual planes used when performing smart "
         "slicing.")
Q_CULL = "By performing early intersection test, we can reduce numerous numbers of polygons to be filled."
Q_DEPTH = ("The depth texture is used in the intensity calculation process to improve accuracy of the caustics "
           "patterns.")
#: "a little bit longer": smart slicing's time over normal slicing's at the same planes, above 1 and at most this
LITTLE = 1.2


def _linear_r2(x, y):
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < 3:
        return float("nan"), float("nan")
    a, b = np.polyfit(x, y, 1)
    res = y - (a * x + b)
    ss = float(((y - y.mean()) ** 2).sum())
    return (1.0 - float((res ** 2).sum()) / ss if ss > 0 else float("nan")), float(a)


def _plane_counts_differ(rows):
    counts = sorted({r["planes"] for r in rows})
    return (f"{len(counts)} plane counts ({', '.join(map(str, counts))}) where the thesis's tables have every count "
            "from 3 to 101; " + ("the bunny stands for the dolphin; " if any(r["thesis_mesh"] == "dolphin" for r in rows)
                                 else "no dolphin; ")
            + "times on one CPU thread, the thesis's on a GeForce 6800")


# --------------------------------------------------------------------------- ch. 5's tables
def _gap(m):
    # per cell the median of the per-round ratios (both variants timed within moments of each other) and its spread
    rows = m["rows"]
    vr = [ratio_spread(r["rounds"]["volumetric"], r["rounds"]["normal"]) for r in rows]
    ratio = [x.median for x in vr]
    worst = min(range(len(rows)), key=lambda k: ratio[k])
    w = rows[worst]
    ok = all(x > 1.0 for x in ratio)
    return Finding(ok, f"volumetric / level map >= {vr[worst].text('x')} over the rounds ({w['mesh']}, {w['planes']} "
                       f"planes); median over the cells {statistics.median(ratio):.2f}x"
                       + ("; above 1 in every cell" if ok else "; not above 1 in every cell (timing noise)"))


def _slice_images(m):
    # the falsifiable part of the thesis's argument (eqs. 5-3 to 5-7): T(DP) <= T(I), per cell
    rows = m["rows"]
    ir = [ratio_spread(r["t_i_rounds"], r["t_dp_rounds"]) for r in rows]
    k = min(range(len(rows)), key=lambda i: ir[i].median)
    return Finding(all(x.median > 1.0 for x in ir),
                   f"T(I) / T(DP) >= {ir[k].text('x')} ({rows[k]['mesh']}, {rows[k]['planes']} planes: slice images "
                   f"{rows[k]['t_i_ms']:.1f} ms against the position and diffuse maps {rows[k]['t_dp_ms']:.1f} ms); "
                   f"median over the cells {statistics.median(x.median for x in ir):.2f}x",
                   straddles=any(straddles(x.low, x.high, 1.0) for x in ir))


def _linear(m):
    rows = m["rows"]
    r2s, why, rounds_r2, slopes = [], [], [], []
    for mesh in dict.fromkeys(r["mesh"] for r in rows):
        rs = [r for r in rows if r["mesh"] == mesh]
        x = [r["planes"] for r in rs]
        r2i, slope_i = _linear_r2(x, [r["t_i_ms"] for r in rs])
        r2d, slope_d = _linear_r2(x, [r["t_dp_ms"] for r in rs])
        r2v, _ = _linear_r2(x, [r["caustics_volumetric_ms"] for r in rs])
        r2s.append(r2i)
        slopes.append(slope_i)
        # the same fit on each round alone: how far one round's verdict could stray from the medians'
        per = [_linear_r2(x, [r["t_i_rounds"][i] for r in rs])[0] for i in range(len(rs[0]["t_i_rounds"]))]
        rounds_r2 += per
        intercept = float(np.polyfit(x, [r["t_i_ms"] for r in rs], 1)[1])
        why.append(f"{mesh}: T(I) R^2 {r2i:.3f}, {slope_i:.2f} ms per plane, intercept {intercept:.1f} ms "
                   f"(single rounds R^2 >= {min(per):.3f}, n = {len(per)}); T(DP) {min(r['t_dp_ms'] for r in rs):.1f}-"
                   f"{max(r['t_dp_ms'] for r in rs):.1f} ms ({slope_d:+.2f} ms per plane); the baseline's whole "
                   f"caustics stage R^2 {r2v:.3f}")
    ok = all(x > 0.9 for x in r2s if x == x) and all(sl > 0 for sl in slopes)
    return Finding(ok, "; ".join(why), straddles=straddles(min(rounds_r2), max(rounds_r2), 0.9))


def _smart(m):
    rows = m["rows"]
    sr = [ratio_spread(r["rounds"]["normal"], r["rounds"]["respace"]) for r in rows]
    cells = [(r["mesh"], r["planes"], x.median, ratio_spread(r["rounds"]["normal"], r["rounds"]["smart"]).median)
             for r, x in zip(rows, sr)]
    fast = [c for c in cells if c[2] >= 1.2]
    # the verdict if every cell with rounds on both sides of 1.2 went the other way
    sure, maybe = sum(x.low >= 1.2 for x in sr), sum(x.high >= 1.2 for x in sr)
    top = m["top"]
    at_top = ", ".join(f"{mesh} {x:.2f}x" for mesh, n, x, _ in cells if n == top)
    few = [c for c in cells if c[1] <= 10]
    return Finding(2 * len(fast) > len(cells),
                   f"normal / smart (re-sliced, eq. 4-22) >= 1.2x in {len(fast)} of {len(cells)} (model, planes) "
                   f"cells; at {top} planes: {at_top}"
                   + (f"; at <= 10 planes {min(c[2] for c in few):.2f}-{max(c[2] for c in few):.2f}x" if few else "")
                   + f"; lattice smart slicing >= 1.2x in {sum(c[3] >= 1.2 for c in cells)} of {len(cells)}"
                   + f"; each cell's rounds {min(x.low for x in sr):.2f}-{max(x.high for x in sr):.2f}x "
                     f"({sr[0].n} per cell; every round >= 1.2x in {sure} cells, some round in {maybe})",
                   straddles=(2 * sure > len(cells)) != (2 * maybe > len(cells)))


def _quality_5_5(m):
    rows = m["rows"]
    lat = max(r["luv_smart_on_off"] for r in rows)
    rsp = max(r["luv_respace_on_off"] for r in rows)
    worst = max(rows, key=lambda r: r["luv_respace_on_off"])
    return Finding(rsp < 0.01,
                   f"max Luv difference {rsp:.3g} with the thesis's re-slicing (eq. 4-22; {worst['mesh']}, "
                   f"{worst['planes']} planes); {lat:.3g} with our lattice smart slicing (maps "
                   f"{'bit-identical' if all(r['maps_identical'] for r in rows) else 'not identical'}: "
                   "equal by construction, so no test of the claim)")


def _memory(m):
    rows, top = m["rows"], m["top"]
    top_rows = [r for r in rows if r["planes"] == top]
    mem = min(r["memory_volumetric_b"] / r["memory_levelmap_b"] for r in top_rows)
    flat = all(len({r["memory_levelmap_b"] for r in rows if r["mesh"] == k}) == 1 for k in {r["mesh"] for r in rows})
    per_obj_lm = 2 * 512 * 512 * 2 / 2 ** 20
    per_obj_vol = (101 if top < 101 else top + 1) * 512 * 512 * 2 / 2 ** 20  # the thesis's 100 planes: 101 slices
    return Finding(mem >= 10.0 and flat,
                   f"slice stack / level map's two maps = {mem:.1f}x at {top} planes (16-bit texels, "
                   f"{top_rows[0]['memory_volumetric_b'] / 2 ** 20:.2f} MiB against "
                   f"{top_rows[0]['memory_levelmap_b'] / 2 ** 20:.2f} MiB per object at our map size); the "
                   f"level map's memory {'does not change' if flat else 'changes'} with the planes; the thesis's "
                   f"scene (100 objects, 100 planes, 512^2) from our counts: {100 * per_obj_lm:.0f} MiB against "
                   f"{100 * per_obj_vol:,.0f} MiB")


def _identical(m):
    rows = m["rows"]
    lv = max(r["luv_levelmap_volumetric"] for r in rows)
    px = max(r["image_max_diff_volumetric"] for r in rows)
    same = all(r["maps_identical_volumetric"] for r in rows)
    return Finding(px < 0.5 / 255.0,
                   f"largest pixel difference {px:.3g} (Luv {lv:.3g}) between the level map's image and the "
                   f"volumetric baseline's over {len(rows)} (model, planes) cells; caustic maps "
                   f"{'bit-identical in every cell' if same else 'not bit-identical in every cell'}")


def _profiling(m):
    rows = m["rows"]
    # per cell the median over the rounds of each round's depth profiling / intersection test (thesis's smart slicing)
    frac = [spread([q / max(c, 1e-9) for q, c in zip(r["profiling_rounds"], r["intersection_rounds"])]) for r in rows]
    whole = [r["profiling_ms"] / (1e3 * r["smart_s"]) for r in rows]
    k = max(range(len(rows)), key=lambda i: frac[i].median)
    return Finding(frac[k].median < 0.05,
                   f"depth profiling / intersection test at most {100 * frac[k].median:.1f} % ({rows[k]['mesh']}, "
                   f"{rows[k]['planes']} planes; rounds {100 * frac[k].low:.1f}-{100 * frac[k].high:.1f} %), median "
                   f"over the cells {100 * statistics.median(f.median for f in frac):.1f} %; against the whole "
                   f"render at most {100 * max(whole):.1f} %",
                   straddles=any(straddles(f.low, f.high, 0.05) for f in frac))


# --------------------------------------------------------------------------- the further statements
def _one_plane(m):
    mem1 = m["mem1"]
    return Finding(None, f"at one plane ({mem1['map'][0]}^2 maps): our baseline's stack {mem1['volumetric']:,} bytes "
                         f"(two slices: the front slab and the plane's) against the level map's two maps "
                         f"{mem1['levelmap']:,}: " + ("equal" if mem1["volumetric"] == mem1["levelmap"] else "not equal")
                   + "; with the thesis's count (one slice per plane) the level map's two maps are twice the stack's one")


def _gain_by_model(m):
    return {k: statistics.median(ratio_spread(r["rounds"]["normal"], r["rounds"]["respace"]).median
                                 for r in m["rows"] if r["mesh"] == k) for k in m["meshes"]}


def _sphere_best(m):
    med = _gain_by_model(m)
    return Finding("sphere" in med and all(med["sphere"] >= v for v in med.values()),
                   "normal / smart (re-sliced), median over the plane counts: "
                   + ", ".join(f"{k} ({m['thesis_of'][k]}) {v:.2f}x" for k, v in med.items()))


def _dolphin_gain(m):
    b = m["dolphin"]
    if not b:
        return Finding(None, "—", "The quick run has no stand-in for the dolphin.", verdict=NOT_MEASURED)
    return Finding(None, f"{b} (for the dolphin): normal / smart {_gain_by_model(m)[b]:.2f}x",
                   "Our bunny stands in the dolphin's rows but is not the dolphin: its depth profile is its own (the "
                   "thesis's point is that the dolphin has one empty level).", verdict=NOT_COMPARABLE)


def _empty_levels(m):
    return {k: next(r["empty_levels"] for r in m["rows"] if r["mesh"] == k) for k in m["meshes"]}


def _others_empty(m):
    empty = _empty_levels(m)
    others = [k for k in m["meshes"] if m["thesis_of"][k] != "dolphin"]
    return Finding(all(empty[k] is not None and empty[k] >= 2 for k in others),
                   "empty depth levels of " + str(m["levels"]) + ": " + ", ".join(f"{k} {empty[k]}" for k in others))


def _dolphin_empty(m):
    b = m["dolphin"]
    if not b:
        return Finding(None, "—", "The quick run has no stand-in for the dolphin.", verdict=NOT_MEASURED)
    return Finding(None, f"{b} (for the dolphin): {_empty_levels(m)[b]} empty levels",
                   "Our bunny is not the dolphin: its count says nothing of the thesis's model.",
                   verdict=NOT_COMPARABLE)


def _longer(m):
    # "a little bit longer" at the same number of planes
    cells = []
    for k in m["meshes"]:
        rs = [r for r in m["rows"] if r["mesh"] == k]
        a, c = np.polyfit([r["planes"] for r in rs], [r["levelmap_s"] for r in rs], 1)
        cells += [(k, r["planes"], r["planes_respaced"], r["respace_s"] / (a * r["planes_respaced"] + c))
                  for r in rs if r["planes_respaced"] < r["planes"]]
    if not cells:
        return None
    x = statistics.median(c[3] for c in cells)
    ok = 1.0 < x <= LITTLE
    return Finding(ok, f"smart (re-sliced, k planes drawn) / normal slicing at k planes: median {x:.2f}x over "
                       f"{len(cells)} cells ({min(c[3] for c in cells):.2f}-{max(c[3] for c in cells):.2f}x)",
                   "" if ok else ("At equal planes smart slicing is not longer here." if x <= 1.0 else
                                  f"At equal planes smart slicing is more than {LITTLE:g}x longer here: 'a little bit' "
                                  "fails."))


def _table_5_4(m):
    rows, b, top = m["rows"], m["dolphin"], m["top"]
    dev = [(r["mesh"], r["planes"], r["planes_respaced"], r["thesis_planes_used"]) for r in rows
           if m["thesis_of"][r["mesh"]] != "dolphin"]
    bad = [d for d in dev if abs(d[2] - d[3]) > max(2.0, 0.15 * d[3])]
    return Finding(not bad,
                   f"{len(dev) - len(bad)} of {len(dev)} (model, planes) cells within max(2, 15%) of the thesis's count"
                   + ("; off: " + ", ".join(f"{k} {n}: {p} against {t:.0f}" for k, n, p, t in bad[:6]) if bad else "")
                   + (f"; {b} (dolphin): " + ", ".join(f"{r['planes']}: {r['planes_respaced']}/"
                                                       f"{r['thesis_planes_used']:.0f}"
                                                       for r in rows if r["mesh"] == b and r["planes"] in (3, top))
                      if b else ""))


def _culling(m):
    cull = m["cull"]
    fewer = {k: v["bounds"]["triangles"] / max(v["none"]["triangles"], 1) for k, v in cull.items()}
    speed = {k: statistics.median([a / b for a, b in zip(v["none"]["ms"], v["bounds"]["ms"])])
             for k, v in cull.items()}
    return Finding(all(x <= 0.5 for x in fewer.values()),
                   "; ".join(f"{k}: culling draws {100 * fewer[k]:.0f}% of the triangles, caustics stage "
                             f"{speed[k]:.2f}x faster{'' if cull[k]['identical'] else ' (maps differ)'}" for k in cull)
                   + f" ({m['top']} planes)")


def _depth_test(m):
    by = {}
    for r in m["prow"]:
        by.setdefault((r["scene"], r["receiver"]), {})[r["reading"]] = r["rel_l1"]
    comp = READINGS[1][0]
    pairs = {k: (v[comp], v[ONE_PLANE]) for k, v in by.items() if comp in v and ONE_PLANE in v}
    return Finding(bool(pairs) and all(a < c for a, c in pairs.values()),
                   "; ".join(f"{k[1]} in {k[0].split(' (')[0]}: rel L1 {a:.3f} with the depth test (50 planes) against "
                             f"{c:.3f} with one plane" for k, (a, c) in pairs.items()))


_PLANES = "{plane_counts}"
CLAIMS = (
    ClaimRow("§5.2.4, Experiment 1, Table 5-1", QUOTE_5_1, _gap, verdict=BY_CONSTRUCTION, timing=True,
             why="Shown for the size of the gap; the falsifiable part of the thesis's argument, slice images "
                 "against the one position/diffuse pass (eq. 5-6), is judged on its own times.",
             rule="Not judged: the median over interleaved repeats (after an untimed render of each, on one "
                  "thread) of each round's volumetric / level-map time in every (model, planes) cell.",
             construction=("our baseline renders the level map's position and diffuse maps too (its slices "
                           "take their triangles' set-up from that pass), then draws the same intersection "
                           "triangles over the same maps, plus one slice image per plane: it does strictly "
                           "more work than the level map, so it is slower in every cell"), differs=_PLANES),
    ClaimRow("§5.2.4, Experiment 1, Table 5-1", QUOTE_5_1, _slice_images, timing=True, differs=_PLANES,
             why=("Even at the fewest planes the baseline's slice images cost more than the level map's one pass "
                  "of position and diffuse maps (eq. 5-6), the only term in which the two differ (eqs. 5-1, 5-2).",
                  "At the fewest planes the baseline's few slice images cost less than the level map's position "
                  "and diffuse maps here, so eq. 5-6 (T(DP) <= T(I)) fails there: the level map is not faster "
                  "in all cases on the terms in which the two algorithms differ."),
             rule="The terms in which the two algorithms differ (eqs. 5-1 to 5-6): held if, in every (model, "
                  "planes) cell, the baseline's slice images T(I) (n + 1 orthographic rasterizations of the "
                  "receiver, timed alone) take longer than the level map's position and diffuse maps T(DP) "
                  "(its level_map stage): the median over interleaved repeats of each round's T(I) / T(DP) "
                  "above 1, one thread."),
    ClaimRow("§5.2.4, Experiment 1 (eqs. 5-3 to 5-6)", QUOTE_LINEAR, _linear, timing=True, differs=_PLANES,
             why=("One slice image per plane: the illumination map's creation grows in step with the sample "
                  "planes, while the level map's two maps do not change with them.",
                  "The slice images' time does not grow linearly with the planes on every model here (a loaded "
                  "machine's noise, or a fixed cost per frame larger than the per-plane work)."),
             rule="T(I) as the thesis means it (eq. 5-3): the volumetric baseline's slice-image creation, n + 1 "
                  "orthographic rasterizations of the receiver timed alone, per plane count (the median of "
                  "interleaved repeats after an untimed pass, one thread). Held if a straight line in the "
                  "plane count explains it with R^2 > 0.9 and a positive slope on every model; the level "
                  "map's position and diffuse maps T(DP) are shown beside it."),
    ClaimRow("§5.2.4, Experiment 2 (discussion of Tables 5-3, 5-4)", QUOTE_SMART, _smart, timing=True,
             why=("Smart slicing skips the planes in empty depth levels, each a full-map pass of the intersection "
                  "triangles; the gain follows the share of empty levels and the plane count (Table 5-4).",
                  "In most cells the planes smart slicing drops are too small a part of the render "
                  "here (the fixed passes dominate at few planes and small maps), or the models have few empty "
                  "depth levels (Table 5-4)."),
             rule="Smart slicing as the thesis does it (re-slicing, levelmap.smart_spacing = respace): held if "
                  "it renders at least 1.2x faster than normal slicing in more than half of the (model, plane "
                  "count) cells measured: per cell the median over interleaved repeats (after an untimed "
                  "render of each, on one thread) of each round's normal / smart time."),
    ClaimRow("§5.2.4, Table 5-5", QUOTE_5_5, _quality_5_5,
             why=("Re-slicing each sub-box moved no texel's image by a visible amount here.",
                  "Re-slicing places the planes of each sub-box anew (eqs. 4-21/4-22), so the texels meet other "
                  "planes than with normal slicing and the image changes by the difference shown. The thesis "
                  "argues the answer is 'No' because smart slicing is 'intended for eliminating unnecessary "
                  "plane': that is what our lattice option does (equal maps), not what eq. 4-22 does."),
             rule="The thesis's own smart slicing (levelmap.smart_spacing = respace, eqs. 4-21/4-22, n_i read "
                  "as planes per sub-box, the default): held if the eq. 2-9 Luv difference from normal slicing stays "
                  "below 0.01 for every model and plane count (the thesis's Table 5-5 prints 0 throughout)."),
    ClaimRow("§5.1", QUOTE_MEMORY, _memory, verdict=BY_CONSTRUCTION,
             why=("The thesis's arithmetic, reproduced: (planes + 1) / 2 at every plane count.",
                  "The thesis's arithmetic, reproduced: (planes + 1) / 2 at every plane count. (less than 10x or "
                  "not flat: a bug in the counting)"),
             rule="Not judged: 16-bit texels as the thesis counts, the volumetric baseline's slice stack (its "
                  "reported memory_bytes) against the level map's two maps at the most planes measured "
                  "({top}), and whether the level map's count changes with the planes.",
             construction=("both sides are formulas, not measured footprints: the baseline reports "
                           "memory_bytes = (planes + 1) Hc Wc 2 and the tables count the level map as "
                           "2 Hc Wc 2, so the ratio is (planes + 1) / 2 whatever runs")),
    ClaimRow("§6.2", QUOTE_IDENTICAL, _identical, verdict=BY_CONSTRUCTION,
             why=("Shown as a check of our two code paths: identical, as built.",
                  "Shown as a check of our two code paths: not identical: a bug in one of them."),
             rule="Not judged: the largest pixel difference between the level map's final image and the "
                  "volumetric baseline's, in every (model, planes) cell of Table 5-1 (normal slicing, the "
                  "same planes), beside half an 8-bit step (0.5/255).",
             construction=("our baseline shares the level map's plane lattice, acceptance slabs and splat "
                           "kernel (levelmap/slice_image_baseline.py calls splat_plane with the same planes): the images "
                           "are identical by design, so the row tests our code, not the thesis's two "
                           "algorithms")),
    ClaimRow("§5.2.4, Experiment 2 (depth profiling cost)", QUOTE_PROFILE, _profiling, timing=True,
             differs=_PLANES,
             why=("One pass over the position map (parallel over rows) against a full-map pass of the intersection "
                  "triangles per plane.",
                  "Where smart slicing leaves few planes the intersection test is short, and the profiling pass "
                  "over the whole position map is a visible part of it."),
             rule="Against the intersection test, as the sentence compares: held if depth profiling (with the "
                  "thesis's re-slicing, smart_spacing = respace) takes less than 5% of the intersection test "
                  "(the caustics stage less the profiling) in every cell: per cell the median over "
                  "interleaved repeats of each round's ratio, one thread."),
    ClaimRow("§5.1", Q_ONE_PLANE, _one_plane, verdict=BY_CONSTRUCTION,
             why="Shown: by our count the two are equal at one plane, so there is no situation where the level map "
                 "uses more; by the thesis's count the one situation is one plane, as it says.",
             rule="Not judged: the memory counts at one plane, ours (planes + 1 slices) and the thesis's (one per "
                  "plane).",
             construction=("both sides are formulas of the plane count (the baseline's (n + 1) Hc Wc 2 bytes, the "
                           "level map's 2 Hc Wc 2): which is larger at one plane is arithmetic")),
    ClaimRow("§5.2.4, Experiment 2 (Figs. 5-11, 5-12)", Q_VARIES, _sphere_best, timing=True,
             why=("The sphere lit from above shows the light half its depth levels, the most empty levels of the "
                  "models.", "The sphere does not gain the most from smart slicing here."),
             rule=("The sphere half: held if the sphere's median (over the plane counts measured) of the per-cell "
                   "median normal / smart time is the largest of the models (Table 5-3's set-up, one thread)."),
             differs="the thesis's 30 models; we have the teapot, the sphere and the bunny"),
    ClaimRow("§5.2.4, Experiment 2 (Figs. 5-11, 5-12)", Q_VARIES, _dolphin_gain, timing=True,
             rule="Not judged: the stand-in's normal / smart time beside the thesis's 'no difference'.",
             differs="the bunny stands for the dolphin"),
    ClaimRow("§5.2.4, Fig. 5-12", Q_EMPTY, _others_empty,
             why=("The parts of the teapot and the sphere the light cannot see leave several levels empty.",
                  "A model other than the dolphin has fewer than two empty levels here."),
             rule="The 'others' half: held if the teapot and the sphere (lit from above, {levels} depth levels) each "
                  "have at least 2 empty levels in the depth profile of their position map.",
             differs="our teapot and UV sphere, a light from straight above"),
    ClaimRow("§5.2.4, Fig. 5-12", Q_EMPTY, _dolphin_empty,
             rule="Not judged: the stand-in's empty levels beside the thesis's one.",
             differs="the bunny stands for the dolphin"),
    ClaimRow("§5.2.4, Experiment 2 (Tables 5-3, 5-4)", Q_LONGER, _longer, timing=True,
             why="At equal planes smart slicing adds its depth profiling to the same intersection work.",
             rule=("Each cell where smart slicing drops planes: its time over normal slicing's at the k planes it "
                   "draws (normal slicing's time read from its straight line in the plane count, per model); held if "
                   "the median over the cells is above 1 and at most {little:g}.")),
    ClaimRow("§5.2.4, Table 5-4", Q_T54, _table_5_4,
             why=("The re-slicing of eq. 4-22 drops the planes of the empty levels as the thesis's counts show.",
                  "Our counts depart from the thesis's by more than the band in some cells (our models and light)."),
             rule="The teapot and the sphere (eq. 4-22 with n_i counting planes, the default): held if the planes "
                  "smart slicing draws are within max(2, 15%) of the thesis's Table 5-4 at every plane count measured.",
             differs="our teapot and UV sphere (1,984 triangles, Table 5-2's count) under a light from straight above"),
    ClaimRow("§6.1", Q_CULL, _culling,
             why=("Most intersection triangles of most beams fall outside the receiver's box or the plane's texels.",
                  "The bounding-volume test leaves more than half the triangles to fill here."),
             rule=("Normal slicing at {top} planes: held if levelmap.culling = bounds (beams that cannot reach the "
                   "box culled, each plane scissored to its texels) draws at most half the intersection triangles of "
                   "culling = none, on every model (counts; the caustics stage's time shown)."),
             differs="the thesis proposes the test (§6.1) without measuring it"),
    ClaimRow("Abstract", Q_DEPTH, _depth_test,
             why=("Accepting each beam only where its plane meets the receiver's depth puts the light where the "
                  "surface is.",
                  "The depth test does not bring the caustic map closer to the exact reference on every receiver."),
             rule=("The eq. 4-3 study's scenes (the default box, against the exact water reference): held if the "
                   "level map's caustic map with its depth test (the default 50 planes) has a lower rel L1 than with "
                   "one plane (which accepts every texel: the texture-mapping method, as §5.1 says) on every "
                   "receiver.")),
)


def claims(rows, cull, mem1, prow, top):
    """The thesis's claims (:data:`CLAIMS`) judged on the tables' measurements.

    Parameters
    ----------
    rows : list of dict
        :func:`.tipprasert.measure`'s rows.
    cull : dict
        :func:`.tipprasert.culling_study`.
    mem1 : dict
        :func:`.tipprasert.one_plane_memory`.
    prow : list of dict
        :func:`.tipprasert_placement.placement_study`'s rows.
    top : int
        The most planes measured.

    Returns
    -------
    list of Claim
    """
    meshes = list(dict.fromkeys(r["mesh"] for r in rows))
    thesis_of = {r["mesh"]: r["thesis_mesh"] for r in rows}
    measured = {"rows": rows, "cull": cull, "mem1": mem1, "prow": prow, "top": top, "meshes": meshes,
                "thesis_of": thesis_of, "dolphin": next((k for k in meshes if thesis_of[k] == "dolphin"), None),
                "plane_counts": _plane_counts_differ(rows), "levels": depth_levels(), "little": LITTLE}
    return evaluate(PAPER, CLAIMS, measured)
