"""Chaudhari (2008): the thesis's claims of chs. 3 and 4 as rows judged on the tables' measurements.

Each :class:`~.claims.ClaimRow` quotes a sentence, states its rule (fixed
before measuring) and names the judge that reads :func:`claims`'
measurements: Table 4.1's and 4.2's cells (:mod:`.chaudhari`), the
comparisons timed round by round (:mod:`.chaudhari_models`), the §3.5 and
§3.7 studies (:mod:`.chaudhari_quality`) and the further studies
(:mod:`.chaudhari_more`).

References
----------
Chaudhari, K. (2008). *Real-Time Multiple Refractions Through Deformable
Objects*. MSc thesis, UMBC. §§3.2-3.7, §§4.1-4.3, Table 4.1, Table 4.2,
Figs. 3.4, 4.5, 4.8.
"""

from __future__ import annotations

import statistics

from . import chaudhari as T
from . import chaudhari_quality as Q
from .chaudhari_models import PAPER, fps_ratio, ratio
from .chaudhari_more import COMPACT, CORRECT_L1, MORE_CLAIMS, RARE, SEVERE
from .claims import ClaimRow, Finding, evaluate, ratio_straddles, ratio_text
from .common import BY_CONSTRUCTION, NOT_COMPARABLE, NOT_MEASURED, TABLE_THREADS, straddles

__all__ = ["CLAIMS", "NO_GAIN_ROW", "claims", "claim_no_gain", "CONSIDERABLE", "NO_GAIN", "MIN_MULTI"]

Q_FPS = ("Our renderer achieves interactive frame rates ranging from 25 FPS to above 100 FPS depending upon the "
         "geometry and voxelization resolution.")
Q_DC = ("We observed that the performance is mainly dependent on the depth complexity of a model and not the number "
        "of polygons in it.")
Q_TRACE_DC = ("Although not on the number of triangles, the time taken by Photon Tracing is dependent on the depth "
              "complexity of the scene.")
Q_PEEL = ("time taken by Depth Layer Peeling and Parallel Reduction remains fairly constant for a particular scene and "
          "it does not depend on the number of triangles in the scene.")
Q_ONE_TWO = ("It can be observed that the time taken to trace photons for a single bunny scene is less than that for "
             "the scene with two bunny models.")
Q_BOTTLENECK = "for a high polygonal model, this photon generation pass may become a bottleneck in the entire pipeline"
Q_FORWARD = "This is a crude approximation that leads to severe artifacts."
Q_DELTA = ("It can be observed that with $\\delta = 2$, errors are smoother than with $\\delta = 1$ and there is no "
           "considerable difference in the accuracy when compared to 3x3 neighborhood technique.")
Q_TIGHT = ("To converge to a correct intersection point in minimum number of iterations, each search must be "
           "restricted by a tighter Z_{max} value.")
Q_LOOSE = ("We compared the performance of tightly restricted binary search using 5 iterations with a loosely "
           "restricted binary search using increased number of iterations for similar output. We could not see a "
           "performance gain by avoiding parallel reduction and increasing the number of iterations.")
Q_SINGLE = ("Hence, for most photons, the search terminated after just a single iteration. Only the photons that "
            "travel through the region with a high depth-complexity are traced further.")
Q_LAYERS = ("Voxelization resolutions are also varied along with the number of depth layers utilized to trace "
            "photons through the model.")

#: "no considerable difference": delta = 2's median front-normal error at most this times mesh3x3's
CONSIDERABLE = 1.25
#: "no performance gain": the loose search's frame at least this share of the tight one's
NO_GAIN = 0.95
#: §3.7's tight bound is judged on a scene only with at least this many pixels crossing more than two interfaces
MIN_MULTI = 100


# --------------------------------------------------------------------------- §4.1, §4.2: the frame rates
def _frame_rates(m):
    fps = [c["frame_fps"] for r in m["rows41"] for (_, _, mode), c in r["cells"].items() if mode == "thesis"]
    return Finding(None, f"{min(fps):.0f} to {max(fps):.0f} FPS over Table 4.1's cells on {TABLE_THREADS} thread of "
                         "this CPU (frame incl. photon generation; the thesis's 512^2 viewport at both grids)")


def _grid_trend(m):
    rows41, cols = m["rows41"], m["cols"]
    grids = sorted({r for _, r in cols})
    if len(grids) < 2:
        return Finding(None, "—", "The quick run measures the 256 grid only.", verdict=NOT_MEASURED,
                       rule="The trend only: held if every row renders fewer frames per second at the 512 grid "
                            "than at 256.")
    lo_g, hi_g = grids[0], grids[-1]
    layers = sorted({L for L, _ in cols})
    sp = [fps_ratio(r["cells"][(L, lo_g, "thesis")], r["cells"][(L, hi_g, "thesis")]) for r in rows41 for L in layers]
    shown = [T.THESIS_4_1_ALL[r["model"]][1][(L, lo_g)] / T.THESIS_4_1_ALL[r["model"]][1][(L, hi_g)]
             for r in rows41 for L in layers]
    every = [f[(L, lo_g)] / f[(L, hi_g)] for _, f in T.THESIS_4_1_ALL.values() for L in (16, 32)]
    return Finding(
        all(x.median > 1.0 for x in sp),
        f"FPS {lo_g} / FPS {hi_g}: medians {min(x.median for x in sp):.2f}-{max(x.median for x in sp):.2f} over "
        f"{len(sp)} (model, layers) pairs, single rounds {min(x.low for x in sp):.2f}-"
        f"{max(x.high for x in sp):.2f} ({sp[0].n} rounds each; thesis: {min(shown):.2f}-{max(shown):.2f} for "
        f"the rows shown, {min(every):.2f}-{max(every):.2f} over all {len(T.THESIS_4_1_ALL)} rows)",
        straddles=any(straddles(x.low, x.high, 1.0) for x in sp),
        rule=(f"The trend only: held if every row and layer count of Table 4.1 renders fewer frames per second at "
              f"the {hi_g} grid than at {lo_g}: frame incl. photon generation, the median over interleaved "
              f"repeats (after warm-up, on {TABLE_THREADS} thread) of each round's frame ratio {hi_g} / {lo_g} "
              "above 1."))


def _polygons_and_layers(m, key="frame"):
    cmp = m["cmp"]
    hi_p, lo_p = cmp["polys"]
    one, two = cmp["shells"]["one shell"], cmp["shells"]["two shells"]
    return (hi_p["triangles"] / lo_p["triangles"], two["dc_mean"] / one["dc_mean"], ratio(hi_p, lo_p, key),
            ratio(two, one, key), one, two)


def _depth_not_polygons(m):
    tri, dcr, r_tri, r_dc, one, two = _polygons_and_layers(m)
    held = r_dc[0] >= 1.15 and r_tri[0] < 1.5
    return Finding(
        held,
        f"polygons: {tri:.1f}x the triangles cost {ratio_text(r_tri)} the frame (Bunny I against Bunny-lowpoly, view "
        f"{m['cmp']['polys_view']}); depth complexity: {dcr:.2f}x the mean fragments per pixel (max {one['dc_max']} "
        f"-> {two['dc_max']}) at equal triangles and silhouette cost {ratio_text(r_dc)} the frame (one against two "
        "nested spheres)",
        "" if held else ("Not both halves: " + "; ".join(x for x in (
            "the depth complexity moved the frame by less than 1.15x (thesis mode peels all 32 layers whatever "
            "the depth complexity; only the trace sees it)" if r_dc[0] < 1.15 else "",
            "the triangles moved it by 1.5x or more (the min/max, voxelization and photon-generation "
            "rasterizations are per triangle)" if r_tri[0] >= 1.5 else "") if x) + "."),
        straddles=ratio_straddles(r_dc, 1.15) or ratio_straddles(r_tri, 1.5))


def _trace_follows_depth(m):
    tri, dcr, t_tri, t_dc, one, two = _polygons_and_layers(m, "trace")
    return Finding(t_dc[0] >= 1.15 and 0.67 <= t_tri[0] <= 1.5,
                   f"trace {ratio_text(t_dc)} for {dcr:.2f}x the depth complexity (equal triangles; interfaces "
                   f"{one['interfaces']:,} -> {two['interfaces']:,}); {ratio_text(t_tri)} for {tri:.1f}x the triangles",
                   straddles=ratio_straddles(t_dc, 1.15) or ratio_straddles(t_tri, 0.67, 1.5))


def _peel_constant(m):
    ii_a, i_a, ii_b, i_b = m["cmp"]["quad"]
    r = [("I-A/I-B", ratio(i_a, i_b, "peel"), ratio(i_a, i_b, "reduce")),
         ("II-A/II-B", ratio(ii_a, ii_b, "peel"), ratio(ii_a, ii_b, "reduce"))]
    band = all(0.67 <= x[0] <= 1.5 and 0.67 <= y[0] <= 1.5 for _, x, y in r)
    return Finding(band, "; ".join(f"{k}: peel {ratio_text(x)}, reduce {ratio_text(y)}" for k, x, y in r)
                   + ("; every ratio within 0.67-1.5" if band else "; a ratio outside 0.67-1.5 (timing noise or the "
                      "bitmask's fill)"))


def _one_bunny_less(m):
    cmp = m["cmp"]
    one_t, two_t = cmp["one_two"]
    r12 = ratio(one_t, two_t, "trace")
    return Finding(r12[0] <= 0.9,
                   f"trace II-A / I-A = {ratio_text(r12)}, view {cmp['one_two_view']}; traced pixels "
                   f"{one_t['traced_pixels']:,} against {two_t['traced_pixels']:,}, interfaces {one_t['interfaces']:,} "
                   f"against {two_t['interfaces']:,}; whole frame {ratio_text(ratio(one_t, two_t))}",
                   straddles=ratio_straddles(r12, 0.9))


def _bottleneck(m):
    # §4.2 refers to Table 4.2: I-A (the high-polygon pair) against I-B, photon generation's share of I-A's frame
    # (the thesis's six stages; our shading, which the thesis's table leaves out, left out) against the thesis's own
    # share at the same grid
    _, i_a, _, i_b = m["cmp"]["quad"]
    t42, res42 = m["t42"], m["res42"]
    th_share = {g: T.THESIS_4_2["Photon Generation"][g][0] / sum(v[g][0] for v in T.THESIS_4_2.values())
                for g in (256, 512)}
    th_ratio = {g: T.THESIS_4_2["Photon Generation"][g][0] / T.THESIS_4_2["Photon Generation"][g][1]
                for g in (256, 512)}
    shares = [g / (f - sh) for g, f, sh in zip(i_a["pgen"], i_a["frame"], i_a["shade"])]
    per = {res42[0]: (statistics.median(shares), min(shares), max(shares), ratio(i_a, i_b, "pgen"))}
    for g in res42[1:]:
        a_, b_ = t42.get(("I-A", g)), t42.get(("I-B", g))
        if a_ and b_:
            tot = a_["pipeline_ms"] - a_["stages_ms"].get("shade", 0.0) + a_["photon_generation_ms"]
            sh1 = a_["photon_generation_ms"] / tot
            r1 = a_["photon_generation_ms"] / b_["photon_generation_ms"]
            per[g] = (sh1, sh1, sh1, (r1, r1, r1))
    tri = i_a["triangles"] / i_b["triangles"] if i_a.get("triangles") and i_b.get("triangles") else float("nan")
    return Finding(
        all(v[0] >= th_share[g] and v[3][0] > 2.0 for g, v in per.items()),
        "; ".join(f"{g}: photon generation {100 * v[0]:.1f}% of I-A's frame"
                  + (f" (rounds {100 * v[1]:.0f}-{100 * v[2]:.0f}%)" if v[1] != v[2] else " (medians)")
                  + f" against the thesis's {100 * th_share[g]:.1f}%; I-A / I-B "
                  + (ratio_text(v[3]) if v[3][1] != v[3][2] else f"{v[3][0]:.2f}x (medians)")
                  + f" (thesis {th_ratio[g]:.2f}x)" for g, v in per.items())
        + f"; {tri:.1f}x the triangles (thesis 9.6x)",
        straddles=any(straddles(v[1], v[2], th_share[g]) or ratio_straddles(v[3], 2.0) for g, v in per.items()),
        rule=("Table 4.2's scenes, as the sentence refers to it: held if, at every grid measured, photon "
              "generation takes at least the thesis's own share of I-A's frame at that grid ("
              + ", ".join(f"{100 * x:.1f}% at {g}" for g, x in th_share.items())
              + "; the six stages of Table 4.2, our shading left out) AND more than 2x I-B's photon generation "
                "(the median of per-round shares and ratios at the smallest grid, medians at the larger)."),
        differs=(f"I-A is two of our 69,451-triangle bunnies ({tri:.1f}x I-B's triangles); the thesis's I-A is two "
                 "144k Bunny II (9.6x). The pass is timed apart (one more rasterization of the objects)."))


# --------------------------------------------------------------------------- §3.5, §3.7, the layer count
def _normals(m):
    by = {(r["scene"], r["option"]): r for r in m["ns"]}
    scenes = list(dict.fromkeys(r["scene"] for r in m["ns"]))
    fw, d1, d2, m3 = (o for o, _ in Q.NORMAL_OPTIONS if not o.startswith("central delta=3"))
    return by, scenes, fw, d1, d2, m3


def _forward_crude(m):
    by, scenes, fw, _, d2, _ = _normals(m)
    ratios = {s: by[(s, fw)]["normal_median"] / by[(s, d2)]["normal_median"] for s in scenes}
    return Finding(all(x >= 2.0 for x in ratios.values()),
                   "; ".join(f"{s}: front-normal median {by[(s, fw)]['normal_median']:.2f} deg with eq. 3.1 against "
                             f"{by[(s, d2)]['normal_median']:.2f} with eq. 3.2 (delta 2), {ratios[s]:.1f}x; exit p90 "
                             f"{by[(s, fw)]['exit_p90']:.2f} against {by[(s, d2)]['exit_p90']:.2f} deg"
                             for s in scenes))


def _delta_two(m):
    by, scenes, _, d1, d2, m3 = _normals(m)
    smooth = {s: (by[(s, d2)]["roughness"], by[(s, d1)]["roughness"]) for s in scenes}
    near = {s: by[(s, d2)]["normal_median"] / by[(s, m3)]["normal_median"] for s in scenes}
    h1 = all(a < b for a, b in smooth.values())
    h2 = all(x <= CONSIDERABLE for x in near.values())
    return Finding(
        h1 and h2,
        "; ".join(f"{s}: roughness delta 2 {smooth[s][0]:.2f} against delta 1 {smooth[s][1]:.2f} deg; front-normal "
                  f"median delta 2 {by[(s, d2)]['normal_median']:.2f} (delta 1 {by[(s, d1)]['normal_median']:.2f}) "
                  f"against mesh3x3 {by[(s, m3)]['normal_median']:.2f} deg, {near[s]:.2f}x" for s in scenes),
        "Both halves." if h1 and h2 else "Not both halves: " + "; ".join(x for x in (
            "" if h1 else "delta 2's error map is not smoother than delta 1's (a wider step spans more curvature "
                          "and more silhouette)",
            "" if h2 else f"delta 2's error is more than {CONSIDERABLE}x the 3x3 mesh's") if x) + ".")


def _tight_bound(m):
    bs = m["bs"]
    rows = {(r["scene"], r["bound"], r["iterations"]): r for r in bs["rows"]}
    bsc = list(dict.fromkeys(r["scene"] for r in bs["rows"]))
    mu = bs["multi"]
    judged = [sc for sc in bsc if mu[sc]["pixels"] >= MIN_MULTI]

    def pair(sc, k):
        x = mu[sc].get(k)
        return f"{x['median']:.2f}/{x['p90']:.2f}" if x else "—"

    tight_ok = bool(judged) and all(mu[sc][("tight", 5)]["median"] < mu[sc][("loose", 5)]["median"]
                                    and mu[sc][("tight", 5)]["p90"] < mu[sc][("loose", 5)]["p90"] for sc in judged)
    measured = "; ".join(
        f"{sc}: {mu[sc]['pixels']:,} pixels cross more than {Q.MULTI} interfaces (exact)"
        + (f"; on them, exit median/p90 at 5 iterations tight {pair(sc, ('tight', 5))}, loose "
           f"{pair(sc, ('loose', 5))}, exact per-layer maxima {pair(sc, ('global', 5))} deg; at 16: tight "
           f"{pair(sc, ('tight', 16))}, loose {pair(sc, ('loose', 16))}" if mu[sc]["pixels"] else "") for sc in bsc)
    measured += "; all hit pixels, 5 iterations: " + ", ".join(
        f"{sc} tight {rows[(sc, 'tight', 5)]['median']:.2f}/{rows[(sc, 'tight', 5)]['p90']:.2f}, loose "
        f"{rows[(sc, 'loose', 5)]['median']:.2f}/{rows[(sc, 'loose', 5)]['p90']:.2f}" for sc in bsc)
    if not judged:
        return Finding(None, measured, f"Too few pixels cross more than {Q.MULTI} interfaces at this size to judge the "
                                       "bound where it can differ.", verdict=NOT_MEASURED)
    return Finding(tight_ok, measured)


def _no_gain(m):
    # The thesis's alternative can only gain where a loose search with FEWER iterations than the tight one's 5
    # reaches similar output: with 5 or more it does at least the tight search's work and skips only the
    # reduction, so its frame is at least (1 - the reduction's share) of the tight one's by construction.
    tim = m["bs"]["timing"]
    timed = {s: v for s, v in tim.items() if v["n_loose"]}
    fewer = {s: v for s, v in timed.items() if v["n_loose"] < 5}
    never = [s for s, v in tim.items() if not v["n_loose"]]
    share = {s: v.get("reduce_share", float("nan")) for s, v in timed.items()}
    parts = [f"{s}: loose needs {v['n_loose']} iterations for similar output, frame loose/tight "
             f"{ratio_text(v['ratio'])}, the reduction {100 * share[s]:.1f}% of the tight frame" for s, v in timed.items()]
    parts += [f"{s}: no loose count from {min(Q.LOOSE_ITERATIONS)} to {max(Q.LOOSE_ITERATIONS)} reaches similar "
              "output (the alternative cannot be run there)" for s in never]
    if fewer:
        return Finding(all(v["ratio"][0] >= NO_GAIN for v in fewer.values()), "; ".join(parts),
                       straddles=any(ratio_straddles(v["ratio"], NO_GAIN) for v in fewer.values()))
    return Finding(
        None, "; ".join(parts), "No loose search with fewer than 5 iterations reaches the tight search's output, so "
                                "the comparison the thesis describes cannot show a gain here.", verdict=BY_CONSTRUCTION,
        construction=("the loose runs that reach similar output do at least the tight run's 5 iterations and skip "
                      "only the reduction (" + ", ".join(f"{s} {100 * x:.1f}%" for s, x in share.items())
                      + f" of the tight frame), so loose / tight >= 1 minus that share, above {NO_GAIN} whatever the "
                      "machine" if timed else "no loose run reaches similar output, so no gain can be shown"))


def _single_search(m):
    bs = m["bs"]
    rows = {(r["scene"], r["bound"], r["iterations"]): r for r in bs["rows"]}
    bsc = list(dict.fromkeys(r["scene"] for r in bs["rows"]))
    srch = bs["searches"]
    b = srch.get("bunny")
    it1 = {s: (rows[(s, "tight", 1)]["p90"], rows[(s, "tight", 5)]["p90"]) for s in bsc}
    return Finding(b is not None and b["one"] > 0.5,
                   "; ".join(f"{s}: {100 * v['one']:.1f}% of the hit pixels exit after one back-face search, "
                             f"{100 * v['more']:.1f}% after more, {100 * v['stopped']:.1f}% stopped (exact: "
                             f"{100 * v['exact_one']:.1f}% cross two interfaces)" for s, v in srch.items())
                   + "; the other reading, one binary-search iteration: exit p90 "
                   + ", ".join(f"{s} {a:.2f} against {c:.2f} deg at 5" for s, (a, c) in it1.items()),
                   verdict="" if b else NOT_MEASURED)


def _layer_count(m):
    grids = sorted({r for _, r in m["cols"]})
    # per pair the median over the rounds of each round's FPS 16 / FPS 32 (both cells timed in the same rounds)
    pairs = [(row["model"], g, fps_ratio(row["cells"][(16, g, "thesis")], row["cells"][(32, g, "thesis")]),
              row["thesis_fps"][(16, g)] / row["thesis_fps"][(32, g)]) for row in m["rows41"] for g in grids
             if (16, g, "thesis") in row["cells"] and (32, g, "thesis") in row["cells"]]
    return Finding(bool(pairs) and all(x.median > 1.0 for _, _, x, _ in pairs),
                   f"FPS 16 / FPS 32 layers (thesis mode): medians {min(p[2].median for p in pairs):.2f}-"
                   f"{max(p[2].median for p in pairs):.2f} over {len(pairs)} (model, grid) cells, single rounds "
                   f"{min(p[2].low for p in pairs):.2f}-{max(p[2].high for p in pairs):.2f} "
                   f"({pairs[0][2].n if pairs else 0} rounds each; thesis: {min(p[3] for p in pairs):.2f}-"
                   f"{max(p[3] for p in pairs):.2f})",
                   straddles=any(straddles(p[2].low, p[2].high, 1.0) for p in pairs))


NO_GAIN_ROW = ClaimRow(
    "§4.2", Q_LOOSE, _no_gain, timing=True,
    why=("A loose search with fewer iterations reaches similar output but its frame is not cheaper by more than 5%.",
         "A loose search with fewer iterations than 5 reaches the tight search's output and its frame is cheaper: "
         "avoiding the reduction gains here."),
    rule=("The alternative exercised: loose (no reduction, the object's Zmax) with {loose_iterations} iterations; "
          "similar output: the fewest n whose exit median and p90 are within 5% of tight(5)'s ({setup}); held if the "
          "frame loose(n) / tight(5) (min/max to trace, reduction only in tight; median of per-round ratios, "
          "{threads} thread) is at least {no_gain} on every scene where n < 5 reaches similar output. Where the "
          "fewest similar n is 5 or more the ratio is at least 1 minus the reduction's share by construction, and a "
          "scene where no n reaches similar output cannot run the alternative: neither counts as evidence."))

CLAIMS = (
    ClaimRow("§4.1", Q_FPS, _frame_rates, verdict=NOT_COMPARABLE, timing=True,
             why="An 8800 GTX's absolute frame rate is not a CPU's; the trend the claim implies (the rate falls with "
                 "the voxelization resolution) is judged in the next row.",
             rule="Absolute frame rates of a GPU are not compared with a CPU's."),
    ClaimRow("§4.1", Q_FPS, _grid_trend, timing=True,
             why=("The frame rate falls with the grid in every row, as in the thesis's Table 4.1; both grids render "
                  "the thesis's 512^2 viewport, so the larger grid adds voxels, layer texels and finer depth images, "
                  "not pixels.", "Some row is not slower at the larger grid.")),
    ClaimRow("§4.2", Q_DC, _depth_not_polygons, timing=True,
             why="Both halves: the per-pixel passes do not see triangles, while each extra layer is an extra "
                 "interface for every photon crossing it.",
             rule=("Both halves, frames incl. photon generation, 32 layers, thesis mode, {res}^2, median of per-round "
                   "ratios of interleaved renders: held if 4.7x the triangles at about equal depth complexity cost "
                   "less than 1.5x the frame AND twice the depth complexity at equal triangles and silhouette costs "
                   "at least 1.15x the frame.")),
    ClaimRow("§4.2, Table 4.2", Q_TRACE_DC, _trace_follows_depth, timing=True,
             why=("The trace walks the LDI's layers per photon: more layers crossed, more interfaces to find; the "
                  "mesh is not read.", "The trace stage did not follow the depth complexity as stated here."),
             rule=("Held if the trace stage takes at least 1.15x for twice the depth complexity at equal triangles "
                   "and silhouette, and 0.67-1.5x for 4.7x the triangles (median of per-round ratios).")),
    ClaimRow("§4.2, Table 4.2", Q_PEEL, _peel_constant, verdict=BY_CONSTRUCTION, timing=True,
             why="Shown for the sizes only: a departure from 1 here is timing noise or a different bitmask fill, "
                 "never the triangles.",
             rule=("Not judged: the ratios of peel and reduce between the full-bunny and the low-poly scenes (median "
                   "of per-round ratios), I-A/I-B and II-A/II-B, one camera ({cmp[one_two_view]}, distance 4.8), "
                   "shown beside the band 0.67-1.5 the row was judged on before."),
             construction=("both passes read only the bitmask and the depth images, whose size is the grid's: no "
                           "code path of either reads a triangle, so they cannot depend on the triangle count")),
    ClaimRow("§4.2, Table 4.2", Q_ONE_TWO, _one_bunny_less, timing=True,
             why=("In one framing the second bunny adds interfaces (and pixels, unless it hides behind the first), "
                  "and each is traced work.",
                  "In one framing one bunny's trace is not clearly cheaper than two bunnies' here."),
             rule=("One camera for both (distance 4.8, I-A's view of highest depth complexity, II-A = I-A less one "
                   "bunny): held if the trace of one full bunny takes at most 0.9x that of two (median of per-round "
                   "ratios of interleaved renders).")),
    ClaimRow("§4.2, Table 4.2", Q_BOTTLENECK, _bottleneck, timing=True,
             why=("The extra rasterization costs in proportion to the triangles, and on the high-polygon pair it "
                  "takes at least the share of the frame the thesis's own Table 4.2 shows.",
                  "On Table 4.2's high-polygon pair the extra rasterization takes less of the frame than in the "
                  "thesis's own table, or does not grow with the triangles.")),
    ClaimRow("§3.5, eq. 3.1", Q_FORWARD, _forward_crude,
             why=("Taking a pixel as one unit of depth tilts every normal (no perspective correction).",
                  "Eq. 3.1's normals are not clearly worse than eq. 3.2's here."),
             rule="Held if eq. 3.1's median front-normal error against the exact reference is at least 2x eq. 3.2's "
                  "(delta 2) on every scene ({setup})."),
    ClaimRow("§3.5, Fig. 3.4", Q_DELTA, _delta_two,
             rule=("Both halves on every scene ({setup}): held if delta 2's front-normal error map is smoother than "
                   "delta 1's (lower mean absolute difference between neighbouring pixels) AND its median front-normal "
                   "error is at most {considerable}x the 3x3 mesh's.")),
    ClaimRow("§3.7", Q_TIGHT, _tight_bound,
             why=("Where the bound can differ (a back face before the backmost) the tight bound gives the more "
                  "accurate exit at equal iterations.",
                  "Even where the layer searched is not the backmost, the tight (MIP) bound is not more accurate "
                  "than the object's Zmax at 5 iterations here: the MIP block's maximum plus the margin reaches about "
                  "as far, and the error is the depth images' and normals', not the search's."),
             rule=("Judged where the bounds can differ: the pixels whose exact path crosses more than {multi} "
                   "interfaces (for the first back face of a two-interface path the layer's maximum is the object's, "
                   "so tight = loose + margin there). Held if, at 5 iterations, the tight (MIP) bound's exit-direction "
                   "median and p90 against the exact reference on those pixels are both below the loose bound's (the "
                   "object's largest depth for every layer), on every scene with at least {min_multi} such pixels "
                   "({setup})."),
             differs=("our scenes (the bunny, a convex sphere with no such pixels); the thesis judged by eye on its "
                      "models")),
    NO_GAIN_ROW,
    ClaimRow("§3.7", Q_SINGLE, _single_search,
             why=("Most rays meet the backmost face at their first back-face search and stop there (the early "
                  "termination of §3.7).", "Fewer than half the bunny's rays stop after one back-face search."),
             rule=("'Iteration' read as one step of the recursive search over the layers (the sentence follows the "
                   "early termination at the backmost face; a search of 5 binary-search iterations is fixed): held if "
                   "more than half the pixels the bunny covers exit after one back-face search (interfaces <= 2), "
                   "{qres}^2, default camera, tight bound, 5 iterations.")),
    ClaimRow("Table 4.1", Q_LAYERS, _layer_count, timing=True,
             why=("Peeling and reducing 16 channels instead of 32 is cheaper in every row, as the thesis's table "
                  "shows.", "Some row is not faster with 16 layers."),
             rule=("Table 4.1 states no sentence on the layer count; its numbers say fewer layers render faster. Held "
                   "if every row and grid of Table 4.1 renders more frames per second with 16 layers than with 32 "
                   "(thesis mode: all layers peeled; frames incl. photon generation; the median over interleaved "
                   "repeats after warm-up of each round's FPS ratio above 1, {threads} thread)."),
             differs=("not the thesis's mechanism: it traced photons by rendering a full-screen quad once per layer "
                      "(§4.2: '32 times'), so its trace cost grows with the layer count; ours stops each ray at its "
                      "last interface, so only our peel and reduce (16 or 32 channels, thesis mode) see it, and a "
                      "smaller ratio than the thesis's is expected")),
) + MORE_CLAIMS


def _setup(qres):
    return {"setup": f"{qres}^2, the bunny (IOR 1.2, default camera) and a sphere (IOR 1.5), every other knob the "
                     "thesis's",
            "threads": TABLE_THREADS, "considerable": CONSIDERABLE, "no_gain": NO_GAIN, "min_multi": MIN_MULTI,
            "multi": Q.MULTI, "loose_iterations": ", ".join(map(str, Q.LOOSE_ITERATIONS)), "rare_percent": 100 * RARE,
            "compact": COMPACT, "severe": SEVERE, "correct_l1": CORRECT_L1}


def claims(measured):
    """The thesis's claims (:data:`CLAIMS`) judged on a run's measurements.

    Parameters
    ----------
    measured : dict
        ``rows41`` (:func:`.chaudhari.table_4_1`'s rows, cells with ``frame_ms``), ``t42``
        (:func:`.chaudhari.table_4_2`), ``res42`` (its grids), ``cols`` (Table 4.1's columns), ``cmp`` (the
        comparisons timed round by round), ``res`` (the smallest grid), ``ns``, ``bs``, ``qres`` (the §3.5 and §3.7
        studies and their image side), ``vox``, ``tim``, ``caus`` and ``vox_res`` (:mod:`.chaudhari_more`'s
        studies and the voxel study's grid).

    Returns
    -------
    list of Claim
    """
    return evaluate(PAPER, CLAIMS, {**_setup(measured["qres"]), **measured})


def claim_no_gain(tim, setup):
    """§4.2's "no performance gain by avoiding parallel reduction" (:data:`NO_GAIN_ROW`) on a bounds study's timing.

    Evidence only where a loose search with fewer than 5 iterations reaches the tight search's output; otherwise
    the outcome follows from the code (:data:`.common.BY_CONSTRUCTION`).

    Parameters
    ----------
    tim : dict
        Scene -> ``n_loose`` (the fewest similar loose count or None), ``ratio`` (median, low, high of the per-round
        frame loose / tight) and ``reduce_share``.
    setup : str
        The set-up, for the rule.

    Returns
    -------
    Claim
    """
    return evaluate(PAPER, [NO_GAIN_ROW], {**_setup(0), "setup": setup, "bs": {"timing": tim}})[0]
