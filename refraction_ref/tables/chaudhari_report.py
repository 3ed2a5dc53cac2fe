"""Chaudhari (2008) Tables 4.1 and 4.2 and the thesis's claims, for ``refraction-ref tables``.

The tables' measurements are :mod:`.chaudhari`'s; :mod:`.chaudhari_models`
chooses the models (the built-in bunny, a decimated "Bunny-lowpoly", two
bunnies, Igea) and times them round by round; this module runs the tables
and studies and judges the claims of chs. 3 and 4 (:mod:`.chaudhari_claims`)
beside what we measure. A CPU is compared with the thesis's NVIDIA 8800 GTX
through ratios (16 against 32 layers, low against high polygon count, one
bunny against two), never through absolute frame rates.

References
----------
Chaudhari, K. (2008). *Real-Time Multiple Refractions Through Deformable
Objects*. MSc thesis, UMBC. §4.2 (performance), Tables 4.1 and 4.2.
"""

from __future__ import annotations

import os
import statistics
import time

import numpy as np

from . import chaudhari as T
from . import chaudhari_more as X
from . import chaudhari_quality as Q
from .chaudhari_claims import claims
from .chaudhari_models import (IOR, PAPER, TWO_BUNNY_DISTANCE, decimate, interleaved_timer, lowpoly_bunny, models,
                               shell_models, time_frames)
from .claims import ratio_text
from .common import TABLE_THREADS, Report, Table, readings_table, table_threads

__all__ = ["run", "decimate", "lowpoly_bunny", "models", "shell_models"]


def _f(x, nd=1):
    return None if x is None else round(float(x), nd)


def run(quick=False, out=".", log=print):
    """Measure Tables 4.1 and 4.2, the depth-complexity study, and check the thesis's claims.

    Parameters
    ----------
    quick : bool
        256x256 only, 5 repeats after one warm-up: the CI smoke run. Otherwise
        256 and 512, 9 repeats after two. Timed on :data:`.common.TABLE_THREADS`
        Numba thread(s), the cells of a model interleaved round by round. Both run every row (four models of Table 4.1, I-A, II-A,
        II-B and the two shell scenes).
    out : path-like
        Folder for the plot (the only file this writes besides the report's).
    log : callable

    Returns
    -------
    Report
    """
    with table_threads():
        return _run(quick, out, log)


def _run(quick, out, log):
    t0 = time.perf_counter()
    out = os.fspath(out)
    os.makedirs(out, exist_ok=True)
    mods, method = models(quick)
    m = _measure_tables(mods, quick, log)
    m.update(_comparisons(mods, m["res"], m["cmp_reps"], log))
    ratio_rows, tab41 = _table_4_1(m, quick, method)
    tabs = [tab41, _table_4_2(m, mods, out, ratio_rows), _depth_table(m)]
    # §3.5 and §3.7 against the exact reference (quality, not time), and the §3.7 frame ratio
    qres = 128 if quick else 512
    log(f"Chaudhari 2008: §3.5 normals and §3.7 search bounds against the exact reference ({qres}^2) ...")
    ns = Q.normals_study(qres)
    bs = Q.bounds_study(qres, rounds=m["cmp_reps"])
    tabs += _quality_tables(ns, bs, qres)
    log("Chaudhari 2008: §§3.2-4.3 and Figs. 4.5, 4.8 (bitmask, peeling, normals, reduction, caustics) ...")
    res42 = m["res42"]
    vox = X.voxel_study(mods, m["rows41"], max(res42), names=("Bunny-lowpoly", "Bunny I") if quick else None,
                        log=None)
    tim = X.timing_study(mods, m["v41"], m["v42"], m["res"], res42, 3 if quick else m["cmp_reps"], log=None)
    caus = X.caustics_study(quick, log=None)
    found = claims({"rows41": m["rows41"], "t42": m["t42"], "res42": res42, "cmp": m["cmp"], "cols": m["cols"],
                    "res": m["res"], "ns": ns, "bs": bs, "qres": qres, "vox": vox, "tim": tim, "caus": caus,
                    "vox_res": max(res42)})
    tabs += [X.table(vox, tim, caus), _readings(mods, bs)]
    return Report(PAPER, tabs, found, time.perf_counter() - t0)


def _measure_tables(mods, quick, log):
    """Tables 4.1 and 4.2 timed: their rows, the sizes and repeats of the run."""
    reps = 5 if quick else 9  # quick: 3 flipped Table 4.1's 16-vs-32-layer verdict run to run
    cols = ((32, 256), (16, 256)) if quick else T.COLS_4_1
    res42 = (256,) if quick else (256, 512)
    many = interleaved_timer(reps, warmup=1 if quick else 2)
    cache = {}
    log("Chaudhari 2008: Table 4.1 ...")
    rows41 = T.table_4_1({k: v for k, v in mods.items() if k in T.THESIS_4_1}, cols=cols, cache=cache,
                         log=None, time_many=many)
    # the thesis's frame includes its photon-generation pass (§4.2): one more rasterization per model and grid
    pgen = {}
    for row in rows41:
        for res in sorted({r for _, r in cols}):
            cell = row["cells"][(cols[0][0], res, "thesis")]
            pgen[(row["model"], res)] = T.photon_generation_ms(cell["scene"], reps)
        for (L, res, mode), cell in row["cells"].items():
            cell["frame_ms"] = cell["pipeline_ms"] + pgen[(row["model"], res)]
            cell["frame_fps"] = 1000.0 / cell["frame_ms"]
    log("Chaudhari 2008: Table 4.2 ...")
    t42 = T.table_4_2(mods, many, resolutions=res42, cache=cache,
                      photon_fn=lambda sc: T.photon_generation_ms(sc, reps), log=None)
    # the claims' comparisons: each pair of scenes timed round by round in one loop (frames incl. photon
    # generation), 32 layers, thesis mode, at the smallest grid
    cmp_reps = 5 if quick else 9  # quick: 5 rounds (the peel/reduce row they once flipped is by construction now)
    return {"rows41": rows41, "t42": t42, "cols": cols, "res42": res42, "res": res42[0], "reps": reps,
            "cmp_reps": cmp_reps}


def _comparisons(mods, res, cmp_reps, log):
    """One bunny against two, polygons at fixed depth complexity, depth complexity at fixed triangles."""
    log("Chaudhari 2008: one bunny against two, in one framing ...")
    v42 = T.highest_complexity_view(T.scene_of(mods["I-A"]), T.VIEWS, mods["I-A"].distance)[0]
    quad = time_frames([T.cell_scene(mods[k], v42, res, 32, "thesis")
                        for k in ("II-A", "I-A", "II-B", "Bunny and Bunny")], cmp_reps)
    log("Chaudhari 2008: polygons at fixed depth complexity ...")
    v41 = T.highest_complexity_view(T.scene_of(mods["Bunny I"]), T.VIEWS, 2.6)[0]
    polys = time_frames([T.cell_scene(mods[k], v41, res, 32, "thesis") for k in ("Bunny I", "Bunny-lowpoly")],
                        cmp_reps)
    log("Chaudhari 2008: depth complexity at fixed triangles ...")
    shells = shell_models()
    front = T.VIEWS[0]
    shell_t = time_frames([T.cell_scene(sm, front, res, 32, "thesis") for sm in shells.values()], cmp_reps)
    sh = {}
    for (name, model), t in zip(shells.items(), shell_t):
        dc = T.view_complexities(T.scene_of(model), (front,), model.distance, res)[0]
        sh[name] = dict(t, dc_max=dc["dc_max"], dc_mean=dc["dc_mean"], covered=dc["covered"], note=model.note)
    return {"v41": v41, "v42": v42,
            "cmp": {"quad": quad, "one_two": quad[:2], "one_two_view": v42.name, "polys": polys, "polys_view": v41.name,
                    "shells": sh}}


def _table_4_1(m, quick, method):
    rows41, cols, reps = m["rows41"], m["cols"], m["reps"]
    hdr = ["model", "paper triangles", "our triangles", "view (max fragments/pixel)"]
    for L, r in cols:
        hdr += [f"paper FPS {L} L {r}", f"ours FPS {L} L {r}"]
    hdr += ["paper 16/32 at 256", "ours 16/32 at 256 (thesis mode)", "ours 16/32 at 256 (peel only needed)"]
    t41rows, ratio_rows = [], []
    for row in rows41:
        cells = row["cells"]
        best = next(v for v in row["views"] if v["view"] == row["view"].name)
        line = [row["model"], row["thesis_triangles"], cells[(cols[0][0], cols[0][1], "thesis")]["triangles"],
                f"{row['view'].name} ({best['dc_max']})"]
        for L, r in cols:
            line += [row["thesis_fps"][(L, r)], _f(cells[(L, r, "thesis")]["frame_fps"])]
        th = row["thesis_fps"][(16, 256)] / row["thesis_fps"][(32, 256)]
        ours = cells[(16, 256, "thesis")]["frame_fps"] / cells[(32, 256, "thesis")]["frame_fps"]
        mine = cells[(16, 256, "ours")]["frame_fps"] / cells[(32, 256, "ours")]["frame_fps"]
        line += [round(th, 2), round(ours, 2), round(mine, 2)]
        ratio_rows.append((row["model"], th, ours, mine))
        t41rows.append(line)
    tab41 = Table("chaudhari_4_1", "Table 4.1: frames per second in each model's view of highest depth complexity",
                  hdr, t41rows,
                  note=("FPS = 1000 / frame ms, the frame being the min/max pass to the shaded image plus the "
                        "thesis's photon-generation pass (one more rasterization, timed apart), medians of "
                        f"{reps} interleaved repeats on {TABLE_THREADS} thread of this CPU, thesis mode "
                        "(`imagespace.peel_all`: every one of the 16 or 32 layers peeled, as the thesis's single "
                        "pass writes all 32 channels); paper: NVIDIA 8800 GTX. Compare the ratios, not the frame "
                        "rates. Every cell renders the thesis's 512^2 viewport (§4.1) with the column's voxel grid "
                        "(imagespace.grid 256 or 512), so both columns trace the same pixels. The layer columns "
                        "differ in mechanism: the thesis traced photons by 16 or 32 full-screen passes (§4.2), "
                        "ours stops each ray at its last interface, so only our peel and reduce see the layer "
                        "count. Views: the largest per-pixel fragment count "
                        f"over {len(T.VIEWS)} listed views. Low-poly bunny: {method} decimation."
                        + (" Quick run: 256 texels, 5 repeats." if quick else "")))
    return ratio_rows, tab41


def _table_4_2(m, mods, out, ratio_rows):
    t42, res42, reps = m["t42"], m["res42"], m["reps"]
    hdr42 = ["stage"] + [f"{p} {sc} {r}" for r in res42 for sc in T.SCENES_4_2 for p in ("paper", "ours")]
    rows42 = []
    for stage in list(T.THESIS_4_2) + ["Shade (ours only)", "Traced pixels (ours only)",
                                       "Interfaces (ours only)"]:
        line = [stage]
        for r in res42:
            for k, sc in enumerate(T.SCENES_4_2):
                t = t42.get((sc, r))
                paper = T.THESIS_4_2[stage][r][k] if stage in T.THESIS_4_2 else None
                if t is None:
                    ours = None
                elif stage == "Photon Generation":
                    ours = _f(t["photon_generation_ms"], 2)
                elif stage.startswith("Shade"):
                    ours = _f(t["stages_ms"].get("shade"), 2)
                elif stage.startswith("Traced"):
                    ours = t["traced_pixels"]
                elif stage.startswith("Interfaces"):
                    ours = t["interfaces"]
                else:
                    ours = _f(t["stages_ms"].get(T.STAGE_OF[stage]), 2)
                line += [paper, ours]
        rows42.append(line)
    used = {sc: t42[(sc, res42[0])]["model"] for sc in T.SCENES_4_2 if t42.get((sc, res42[0]))}
    view42 = next((t42[(sc, res42[0])]["view"] for sc in T.SCENES_4_2 if t42.get((sc, res42[0]))), "—")
    return Table("chaudhari_4_2", "Table 4.2: time per stage (ms), 32 layers", hdr42, rows42,
                 note=("Scenes, ours: " + "; ".join(f"{sc} = {mods[name].note}" for sc, name in used.items())
                       + f". All four filmed with one camera: distance {TWO_BUNNY_DISTANCE}, view {view42} (I-A's "
                       "view of highest depth complexity), so one bunny and two are compared in one framing. "
                       "Photon Generation: the thesis rasterizes the geometry once more; we time that pass "
                       "apart (our trace starts from LDI layer 0). The thesis's I-A/II-A used the 144k Bunny II; "
                       f"we have the 69,451 bunny. Medians of {reps} interleaved repeats."),
                 plot=_plot(out, ratio_rows, t42, res42[0]))


def _depth_table(m):
    sh, res, cmp_reps = m["cmp"]["shells"], m["res"], m["cmp_reps"]
    return Table("chaudhari_depth", "§4.2: time against depth complexity at fixed triangles (32 layers, thesis mode)",
                 ["scene", "triangles", "max fragments/pixel", "mean fragments/pixel", "covered pixels",
                  "interfaces", "ours trace ms", "ours photon generation ms", "ours frame ms"],
                 [[f"{k} ({v['note']})", v["triangles"], v["dc_max"], _f(v["dc_mean"], 2), v["covered"],
                   v["interfaces"], _f(statistics.median(v["trace"]), 2), _f(statistics.median(v["pgen"]), 2),
                   _f(statistics.median(v["frame"]), 2)] for k, v in sh.items()],
                 note=(f"Front view, distance 2.6, {res}^2, IOR {IOR}; medians of {cmp_reps} rounds, the two "
                       f"scenes timed in turn in each round on {TABLE_THREADS} thread. "
                       "The triangles and the silhouette are the same; only the layers a ray crosses differ. "
                       "The thesis gives no such scene; we chose nested spheres because they change the depth "
                       "complexity alone."))


def _readings(mods, bs):
    """The readings the Chaudhari rows rest on (:func:`.common.readings_table`)."""
    from ..scene import load_scene

    p = load_scene({}).data["imagespace"]
    margin = p["bound_margin"] * (p["slices"] - 1)
    nl = {s: v["n_loose"] for s, v in bs["timing"].items()}
    return readings_table("chaudhari_readings", PAPER, [
        (f"imagespace.bound_margin ({p['bound_margin']})", "§3.7: 'a small constant value can be added to the "
         "maximum depth obtained'", f"{100 * p['bound_margin']:g}% of the object's depth range, about {margin:.1f} of "
         f"the {p['slices']} slices", "§3.7 tight against loose (the margin reaches past the layer's maximum) and "
         "§4.2 no gain (the fewest similar loose count: " + ", ".join(f"{s} {n}" for s, n in nl.items()) + ")"),
        (f"imagespace.exit_threshold ({p['exit_threshold']})", "§3.7: a photon is dead when its depth approaches "
         "the backmost face 'within a threshold'", "one slice", "§3.7 searches per ray"),
        ("Table 4.2's II-A and II-B", "the caption: II-A 'One bunny, 288,092 triangles', II-B 'One bunny, 30,000' "
         "(the two-bunny counts)", f"one bunny of I-A and of I-B: {mods['II-A'].note}; {mods['II-B'].note}",
         "§4.2 one bunny against two; Table 4.2's II columns"),
        ("Table 4.2's I-A", "two 144k Bunny II (288,092 triangles)", mods["I-A"].note,
         "§4.2 bottleneck (4.6x I-B's triangles against the thesis's 9.6x)"),
        ("photon generation", "§4.2: 'generates photons by rasterizing the geometry one more time'", "one more "
         "min-blend rasterization of the objects, timed apart and added to the frame (our trace starts from LDI "
         "layer 0)", "§4.1 frame rates and trend, Table 4.1, §4.2 performance, depth complexity and bottleneck"),
        ("imagespace.peel_all in the tables (thesis mode)", "§3.4.2: one pass writes all 32 channels",
         "every one of the 16 or 32 layers peeled whatever the depth complexity", "Table 4.1, §4.1, §4.2 rows"),
        ("the view of each row", "§4.2: 'the view comprising of the highest depth complexity possible'",
         f"the largest per-pixel fragment count over {len(T.VIEWS)} listed views (ties to the larger mean)",
         "Table 4.1, Table 4.2 (I-A's view for all four scenes)"),
        ("'similar output' of the loose search", "§4.2: 'increased number of iterations for similar output'",
         "exit median and p90 against the exact reference within 5% of tight(5)'s", "§4.2 no gain"),
    ])


def _plot(out, ratio_rows, t42, res):
    from ..files import savefig_atomic
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 3.4), dpi=80)
    a, b = fig.subplots(1, 2)
    names = [r[0] for r in ratio_rows]
    x = np.arange(len(names))
    a.bar(x - 0.2, [r[1] for r in ratio_rows], 0.4, label="paper (8800 GTX)")
    a.bar(x + 0.2, [r[2] for r in ratio_rows], 0.4, label="ours (thesis mode)")
    a.axhline(1.0, color="k", lw=0.6)
    a.set_xticks(x, names, fontsize=8)
    a.set_ylabel("FPS 16 layers / FPS 32 layers")
    a.set_title("Table 4.1: the layer count's cost", fontsize=9)
    a.legend(fontsize=7)
    stages = [s for s in T.THESIS_4_2]
    scs = [sc for sc in T.SCENES_4_2 if t42.get((sc, res))]
    for k, sc in enumerate(scs):
        t = t42[(sc, res)]
        tot = t["pipeline_ms"] + t["photon_generation_ms"]
        vals = [(t["photon_generation_ms"] if s == "Photon Generation" else t["stages_ms"].get(T.STAGE_OF[s], 0.0))
                / tot for s in stages]
        paper = [T.THESIS_4_2[s][res][T.SCENES_4_2.index(sc)] for s in stages]
        paper = [p / sum(paper) for p in paper]
        bottom_o = bottom_p = 0.0
        for j, s in enumerate(stages):
            c = f"C{j}"
            b.bar(2 * k - 0.35, paper[j], 0.6, bottom=bottom_p, color=c, alpha=0.5)
            b.bar(2 * k + 0.35, vals[j], 0.6, bottom=bottom_o, color=c, label=s if k == 0 else None)
            bottom_p += paper[j]
            bottom_o += vals[j]
    b.set_xticks([2 * k + d for k in range(len(scs)) for d in (-0.35, 0.35)],
                 [f"{sc}\n{w}" for sc in scs for w in ("paper", "ours")], fontsize=7)
    b.set_ylabel("share of the frame")
    b.set_title(f"Table 4.2 at {res}x{res}x256: where the time goes", fontsize=9)
    b.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    name = "chaudhari_tables.png"
    savefig_atomic(fig, os.path.join(out, name))
    return name


def _quality_tables(ns, bs, res):
    scenes = ", ".join(f"{k} (IOR {ior})" for k, (_, ior) in Q.SCENES.items())
    t35 = Table("chaudhari_3_5", "§3.5, Fig. 3.4: normal estimators against the exact reference",
                ["scene", "estimator", "front normal median deg", "front normal p90 deg", "error roughness deg",
                 "exit median deg", "exit p90 deg", "exit %"],
                [[r["scene"], r["option"], _f(r["normal_median"], 2), _f(r["normal_p90"], 2), _f(r["roughness"], 2),
                  _f(r["exit_median"], 2), _f(r["exit_p90"], 2), _f(100 * r["exit"], 1)] for r in ns],
                note=(f"{res}^2, {scenes}; the bunny in the default camera, the sphere from distance 3. Front "
                      "normal: the angle between the normal each method refracted with at the front surface "
                      "(recovered from its first refraction, eta v - w), over the pixels the reference hits; "
                      "roughness: mean absolute difference of that error between neighbouring pixels (how smooth "
                      "the error map of Fig. 3.4 is); exit: the exit-direction error where both exit. Every other "
                      "knob at the thesis's defaults."))
    tim = bs["timing"]
    srch = bs["searches"]
    t37 = Table("chaudhari_3_7", "§3.7: the search bound and the iterations against the exact reference",
                ["scene", "bound", "iterations", "exit median deg", "exit p90 deg", "exit %"],
                [[r["scene"], r["bound"], r["iterations"], _f(r["median"], 2), _f(r["p90"], 2),
                  _f(100 * r["exit"], 1)] for r in bs["rows"]]
                + [[f"{sc}, the {m['pixels']:,} pixels crossing more than {Q.MULTI} interfaces", b, it,
                    _f(v["median"], 2), _f(v["p90"], 2), _f(100 * v["exit"], 1)]
                   for sc, m in bs["multi"].items() for (b, it), v in
                   ((k, x) for k, x in m.items() if k != "pixels")],
                note=(f"{res}^2, the scenes of §3.5's table. tight: the thesis's MIP max-reduction plus margin "
                      "(`bounds=mip`); global: exact per-layer maxima; loose: no reduction, every layer's search "
                      "bounded by the object's largest depth (§3.6's E). Frame loose(n) / tight(5), n the fewest "
                      "iterations whose median and p90 are within 5% of tight(5)'s, timed round by round on "
                      f"{TABLE_THREADS} thread (min/max, voxelization, peel, reduction if any, trace): "
                      + "; ".join(f"{k}: n = {v['n_loose']}, " + (f"{ratio_text(v['ratio'])} ({v['loose_ms']:.2f} against "
                                                                  f"{v['tight_ms']:.2f} ms)" if v["n_loose"] else
                                                                  "none up to 16") for k, v in tim.items())
                      + ". Searches per hit pixel (tight, 5): "
                      + "; ".join(f"{k}: {100 * v['one']:.1f}% exit after one back-face search, {100 * v['more']:.1f}% "
                                  f"after more, {100 * v['stopped']:.1f}% stopped (exact: {100 * v['exact_one']:.1f}% "
                                  "exit after one)" for k, v in srch.items()) + "."))
    return [t35, t37]
