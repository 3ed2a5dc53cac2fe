"""The cross-check's targets, verdicts and Markdown report (``crosscheck.md``).

:data:`TARGETS` are the numbers each case must meet; :func:`verdicts` judges
one case's entry (:func:`~refraction_ref.interop.crosscheck.run_case`) against
them and :func:`failed_targets` lists the misses (the report's FAIL and the
command's exit status); :func:`report_markdown` writes the findings, a summary
table, and per case its tables and figures.
"""

from __future__ import annotations

import numpy as np

from .images import PATH_AGREE_DEG

__all__ = ["TARGETS", "TIR_CHAOS", "verdicts", "failed_targets", "report_markdown"]

#: the targets of the cross-check
TARGETS = {"median_deg": 0.01, "p99_deg": 0.5, "status_agree": 0.99, "image_rel_rmse": 0.01}
#: cases whose long TIR chains diverge between two float32-hit tracers (reported, not judged)
TIR_CHAOS = ("is_diamond_2_4", "is_tir_followed")


def _fmt(x, nd=3):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-"
    return f"{x:.{nd}g}"


def _pct(x, nd=3):
    """``100 x`` as :func:`_fmt` writes it, with `` %``."""
    return _fmt(100 * x, nd) + " %"


def _counts(d):
    """Status counts as ``{0: n, ...}`` (integer keys, also after a JSON round trip: ``--merge``)."""
    return str({int(k): int(v) for k, v in sorted(d.items(), key=lambda kv: int(kv[0]))})


def _mark(ok):
    return "pass" if ok else "**FAIL**"


def verdicts(name, e):
    """Each target's verdict for one case entry: {target: bool or None (reported, not judged)}.

    Parameters
    ----------
    name : str
        The case name (the :data:`TIR_CHAOS` cases' angles are not judged).
    e : dict
        The case's entry (:func:`~refraction_ref.interop.crosscheck.run_case`).

    Returns
    -------
    dict of str to bool or None
    """
    v = {}
    p = e.get("paths")
    if p:
        chaos = name in TIR_CHAOS
        v["median_deg"] = None if chaos else p["median_deg"] <= TARGETS["median_deg"]
        v["p99_deg"] = None if chaos else p["p99_deg"] <= TARGETS["p99_deg"]
        v["status_agree"] = p["status_agree"] >= TARGETS["status_agree"]
    i = e.get("images")
    if i:
        v["image_rel_rmse"] = i["rel_rmse_judged"] <= TARGETS["image_rel_rmse"]
    c = e.get("caustics")
    if c:
        v["caustics_ztest"] = all(r["ztest_pass"] == r["batches"] for r in c["receivers"])
    return v


def failed_targets(name, e):
    """The targets a case's entry misses (judged ones only; a skipped case misses none).

    Parameters
    ----------
    name : str
        The case name.
    e : dict
        The case's entry (:func:`~refraction_ref.interop.crosscheck.run_case`).

    Returns
    -------
    list of str
        Target names of :func:`verdicts` whose verdict is False, in its order.
    """
    if "skipped" in e:
        return []
    return [k for k, x in verdicts(name, e).items() if x is False]


def _paths_finding(P, T, tir_chaos):
    p99bad = [k for k, p in P.items() if k not in tir_chaos and p["p99_deg"] > T["p99_deg"]]
    return (f"* Paths ({len(P)} cases): median exit-angle difference at most "
            f"{_fmt(max(p['median_deg'] for p in P.values()))} deg, status agreement at least "
            f"{_fmt(100 * min(p['status_agree'] for p in P.values()), 5)} %; p99 over {T['p99_deg']} deg on "
            + (", ".join(f"{k} ({_fmt(P[k]['p99_deg'])} deg; without TIR on the path "
                         f"{_fmt(P[k]['p99_deg_no_tir'])} deg)" for k in p99bad) or "no case")
            + ": long total-internal-reflection chains, where two float32 intersectors part (as the "
            "TIR-chaos cases).")


def _images_finding(I):
    loop = max((i["path_vs_loop_max_abs"] for i in I.values() if np.isfinite(i["path_vs_loop_max_abs"])),
               default=float("nan"))
    return (f"* Images ({len(I)} cases): judged on the pixels whose exit direction is more than one envmap "
            f"texel from a change of the bitmap and whose Mitsuba path agrees with ours within "
            f"{PATH_AGREE_DEG} deg, the image of Mitsuba's intersector, Fresnel-free plugin, media and envmap "
            f"(spawned as the exact tracer does) differs from ours by at most "
            f"{_fmt(100 * max(i['rel_rmse_judged'] for i in I.values()))} % relative RMSE. Mitsuba's "
            "`path` integrator gives the same pixels as a Python loop over those parts with its own "
            f"`si.spawn_ray` (largest difference {_fmt(loop)}"
            "): its MIS, eta and Russian-roulette bookkeeping add nothing, and all of its difference from "
            "ours comes from the spawn offset (`(1 + max|p|) 8.9e-5` along the normal), which moves "
            "exit directions by degrees after TIR chains (column *path integrator*; docs/oracle.md). "
            "The envmap bitmap's bilinear blend across checker edges is the rest of the all-pixel "
            "error (column *envmap bitmap*). `volpath` (absorption) is a stochastic estimator: its "
            "difference is compared with its own noise.")


def _water_finding(Wp):
    return (f"* Water paths ({len(Wp)} cases): the eye rays refracted at the water, ours at the analytic "
            f"surface against Snell at Mitsuba's hit on the exported height-field mesh "
            f"({', '.join(sorted({str(p['resolution']) for p in Wp.values()}))} quads a side, the analytic "
            f"normals at its vertices, interpolated by Mitsuba): median at most "
            f"{_fmt(max(p['median_deg'] for p in Wp.values()))} deg, p99 at most "
            f"{_fmt(max(p['p99_deg'] for p in Wp.values()))} deg (bound of the interpolated normal's error "
            f"at most {_fmt(max(p['normal_error_deg'] for p in Wp.values()))} deg), hit points within "
            f"{_fmt(max(p['water_pos_p99'] for p in Wp.values()))} (p99, world units); the pixels meeting "
            f"the water agree on at least {_fmt(100 * min(p['status_agree'] for p in Wp.values()), 5)} % "
            "of the pixels. The water images are not cross-checked (their shading reads our maps).")


def _caustics_finding(C):
    return "* Caustics: " + "; ".join(
        f"{k}{f' receiver {i}' if len(e['receivers']) > 1 else ''}: rel L1 {_fmt(100 * r['rel_l1'])} % "
        f"(each side's own half-vs-half noise "
        f"{_fmt(100 * r['rel_l1_ours_halves'])} / {_fmt(100 * r['rel_l1_mitsuba_halves'])} %), power ratio "
        f"{_fmt(r['power_ratio'], 5)}, Z-test {r['ztest_pass']} of {r['batches']} Mitsuba batches pass "
        f"(reverse {r['ztest_reverse_pass']} of {r['batches']})"
        for k, e in C.items() for i, r in enumerate(e["receivers"])) + "."


def _summary(result):
    """The report's findings, from the numbers."""
    c = result["cases"]
    ran = {k: e for k, e in c.items() if "skipped" not in e}
    P = {k: e["paths"] for k, e in ran.items() if "paths" in e and e["paths"].get("kind") != "water"}
    Wp = {k: e["paths"] for k, e in ran.items() if "paths" in e and e["paths"].get("kind") == "water"}
    I = {k: e["images"] for k, e in ran.items() if "images" in e}
    C = {k: e["caustics"] for k, e in ran.items() if "caustics" in e}
    out = ["**Findings.**", ""]
    if P:
        out.append(_paths_finding(P, result["targets"], result["tir_chaos"]))
    if I:
        out.append(_images_finding(I))
    if Wp:
        out.append(_water_finding(Wp))
    if C:
        out.append(_caustics_finding(C))
    skipped = {}
    for k, e in c.items():
        if "skipped" in e:
            skipped.setdefault(e["skipped"], []).append(k)
    for why, names in sorted(skipped.items()):
        out.append(f"* Skipped, {', '.join(sorted(names))}: {why}.")
    return out


def _water_paths_rows(name, e, T, link):
    """The report's table of a water case's eye rays (:func:`~refraction_ref.interop.water.water_paths_case`)."""
    p = e["paths"]
    v = verdicts(name, e)
    return ["| paths (eye rays refracted at the water) | value | target |", "|---|---|---|",
            f"| pixels / meeting the water: ours, Mitsuba, both | {p['pixels']} / {p['water_ours']}, "
            f"{p['water_mitsuba']}, {p['both']} | |",
            f"| which pixels meet the water: agreement | {_fmt(100 * p['status_agree'], 6)} % | >= "
            f"{T['status_agree']:.0%} {_mark(v['status_agree'])} |",
            f"| refracted direction median | {_fmt(p['median_deg'])} deg | <= {T['median_deg']} "
            f"{_mark(v['median_deg'])} |",
            f"| refracted direction p99; max | {_fmt(p['p99_deg'])}; {_fmt(p['max_deg'])} deg | <= {T['p99_deg']} "
            f"{_mark(v['p99_deg'])} |",
            f"| water hit point p99 (world units) | {_fmt(p['water_pos_p99'])} | |",
            f"| water mesh: quads a side; bound of its interpolated normal's error | {p['resolution']}; "
            f"{_fmt(p['normal_error_deg'])} deg | |",
            "", f"![paths {name}]({link}{name}/{p.get('figure', 'paths.png')})"]


def _paths_rows(name, e, T, link):
    """The report's table of a case's paths (:func:`~refraction_ref.interop.paths.paths_case`)."""
    p = e["paths"]
    v = verdicts(name, e)
    return ["| paths | value | target |", "|---|---|---|",
            f"| primary rays, largest angle to ours | {_fmt(p['primary_ray_max_deg'])} deg | float32 |",
            f"| pixels / object pixels / both exit | {p['pixels']} / {p['object_pixels']} / "
            f"{p['both_exit']} | |",
            f"| exit direction median | {_fmt(p['median_deg'])} deg | <= {T['median_deg']} "
            f"{'' if v['median_deg'] is None else _mark(v['median_deg'])} |",
            f"| exit direction p99 | {_fmt(p['p99_deg'])} deg | <= {T['p99_deg']} "
            f"{'' if v['p99_deg'] is None else _mark(v['p99_deg'])} |",
            f"| exit direction max; share over 0.5 deg | {_fmt(p['max_deg'])} deg; "
            f"{_fmt(100 * p['frac_over_0_5_deg'])} % | |",
            f"| exit position median / p99 (/ scene diagonal) | {_fmt(p['exit_pos_median_rel'])} / "
            f"{_fmt(p['exit_pos_p99_rel'])} | |",
            f"| status agreement (all / object pixels) | {_fmt(100 * p['status_agree'], 6)} % / "
            f"{_fmt(100 * p['status_agree_object_pixels'], 6)} % | >= {T['status_agree']:.0%} "
            f"{_mark(v['status_agree'])} |",
            f"| status counts ours / Mitsuba | {_counts(p['status_ours'])} / {_counts(p['status_mitsuba'])} | |",
            f"| interface count agreement (both exit) | {_fmt(100 * p['interfaces_agree_both_exit'], 6)} % | |",
            f"| p99 (pixels over 0.5 deg) by TIR events on the path: none / 1-2 / 3+ | "
            f"{_fmt(p['p99_deg_no_tir'])} ({p['over_0_5_no_tir']} of {p['paths_no_tir']}) / "
            f"{_fmt(p['p99_deg_tir_1_2'])} ({p['over_0_5_tir_1_2']} of {p['paths_tir_1_2']}) / "
            f"{_fmt(p['p99_deg_tir_3_plus'])} ({p['over_0_5_tir_3_plus']} of {p['paths_tir_3_plus']}) | |",
            "", f"![paths {name}]({link}{name}/{p.get('figure', 'paths.png')})"]


def _images_rows(name, i, link):
    """The report's table of a case's images (:func:`~refraction_ref.interop.images.images_case`)."""
    return ["", "| images | value |", "|---|---|",
            f"| Mitsuba integrator; spp (Fresnel-free / dielectric); max_depth = rr_depth | "
            f"{i['integrator']}; {i['spp_refract']} / {i['spp_dielectric']}; {i['max_depth']} |",
            f"| judged pixels of {i['pixels']} (left out: {i['edge_pixels']} within a texel of a bitmap "
            f"edge, {i['path_differs_pixels']} whose paths part by more than {PATH_AGREE_DEG} deg, "
            f"{i['limit_pixels']} at the bounce limit) | {i['judged_pixels']} |",
            f"| **rel RMSE, judged pixels** (Mitsuba's intersector, plugin, media, envmap; spawned "
            f"along the ray) | **{_pct(i['rel_rmse_judged'])}** |",
            f"| the same image: all pixels / pixels away from bitmap edges | "
            f"{_pct(i['rel_rmse_line_all'])} / {_pct(i['rel_rmse_line_margin'])} |",
            f"| envmap bitmap error on this image ({i['env_width']} texels wide), all pixels | "
            f"{_pct(i['rel_rmse_env_bitmap'])} |",
            f"| `{i['integrator']}` integrator: rel RMSE judged / away from edges / all | "
            f"{_pct(i['rel_rmse_path_judged'])} / {_pct(i['rel_rmse_path_margin'])} / "
            f"{_pct(i['rel_rmse_path'])} (noise {_pct(i['noise_rel'])}) |",
            f"| `{i['integrator']}` against the loop with its own `spawn_ray`: largest difference; rel "
            f"RMSE | {_fmt(i['path_vs_loop_max_abs'])}; {_pct(i['path_vs_loop_rel_rmse'])} |",
            f"| `spawn_ray` exit directions against ours: median / p99 deg; pixels over a texel | "
            f"{_fmt(i['spawn_ray_median_deg'])} / {_fmt(i['spawn_ray_p99_deg'])}; "
            f"{i['spawn_ray_over_texel']} |",
            f"| Fresnel (`dielectric`) vs ours: rel RMSE all / judged; mean over object pixels | "
            f"{_pct(i['fresnel_rel_rmse'])} / {_pct(i['fresnel_rel_rmse_judged'])} "
            f"(noise {_pct(i['fresnel_noise_rel'])}); x{_fmt(i['fresnel_mean_ratio'], 4)} |",
            "", f"![images {name}]({link}{name}/{i.get('figure', 'images.png')})"]


def _caustics_rows(name, c, link):
    """The report's table of a case's caustics (:func:`~refraction_ref.interop.caustics.caustics_case`)."""
    lines = ["", "| caustics | value |", "|---|---|",
             f"| batches each side; photons per batch ours / Mitsuba (flux per photon) | {c['batches']}; "
             f"{c['photons_ours']} / {c['photons_mitsuba']} ({_fmt(c['photon_flux_ours'])} / "
             f"{_fmt(c['photon_flux_mitsuba'])}) |"]
    if "water_resolution" not in c:
        lines += [f"| Mitsuba photons on the receivers through the object; at the bounce limit | "
                  f"{c['deposited_mitsuba']}; {c['limit_mitsuba']} |"]
    else:
        lines += [f"| Mitsuba photons meeting the water; seen by a map | {c['water_mitsuba']}; "
                  f"{c['deposited_mitsuba']} |",
                  f"| water mesh: quads a side; bound of its interpolated normal's error | "
                  f"{c['water_resolution']}; {_fmt(c['normal_error_deg'])} deg |"]
    for r, x in enumerate(c["receivers"]):
        lines += [f"| receiver {r}: rel L1 of the K-batch means (blur 1 texel) | {_pct(x['rel_l1'])} |",
                  f"| receiver {r}: own noise, half vs half of the batches: ours / Mitsuba | "
                  f"{_pct(x['rel_l1_ours_halves'])} / {_pct(x['rel_l1_mitsuba_halves'])} |",
                  f"| receiver {r}: power Mitsuba / ours | {_fmt(x['power_ratio'], 5)} |",
                  f"| receiver {r}: Z-test (alpha 1e-3, Bonferroni), Mitsuba batches passing against ours; "
                  f"max abs z (threshold) | {x['ztest_pass']} of {x['batches']}; "
                  f"{_fmt(x['ztest_max_abs_z'])} ({_fmt(x['ztest_threshold'])}) |",
                  f"| receiver {r}: reverse, our batches against Mitsuba's | {x['ztest_reverse_pass']} of "
                  f"{x['batches']} |"]
        if "ztest_own_quantum_pass" in x:
            lines.append(f"| receiver {r}: Z-test with this map's own quantum (one photon on its texel); max "
                         f"abs z | {x['ztest_own_quantum_pass']} of {x['batches']}; "
                         f"{_fmt(x['ztest_own_quantum_max_abs_z'])} |")
    return lines + ["", f"![caustics {name}]({link}{name}/{c.get('figure', 'caustics.png')})"]


def _summary_row(name, e, tir_chaos):
    """A case's row of the report's summary table."""
    if "skipped" in e:
        return f"| {name} | - | - | - | - | - | - | - | - | skipped: {e['skipped']} |"
    p, i, c = e.get("paths", {}), e.get("images", {}), e.get("caustics", {})
    failed = failed_targets(name, e)
    verdict = "**FAIL**: " + ", ".join(failed) if failed else "pass"
    if name in tir_chaos:
        verdict += " (TIR chaos: angles reported)"
    cs = "; ".join(f"{_fmt(100 * r['rel_l1'])} %; {r['ztest_pass']}/{r['batches']}" for r in c["receivers"]) \
        if c else "-"
    return (f"| {name} | {_fmt(p.get('median_deg'))} | {_fmt(p.get('p99_deg'))} | "
            f"{_fmt(100 * p['status_agree'], 5) + ' %' if p else '-'} | "
            f"{_pct(i['rel_rmse_judged']) if i else '-'} | "
            f"{(_pct(i['rel_rmse_path_judged']) + ' / ' + _pct(i['rel_rmse_path'])) if i else '-'} | "
            f"{_pct(i['rel_rmse_env_bitmap']) if i else '-'} | "
            f"{_pct(i['fresnel_rel_rmse']) if i else '-'} | {cs} | {verdict} |")


def report_markdown(result, link=""):
    """The cross-check report: findings, a summary table, then a table and figures per case.

    ``link`` prefixes the figure paths (the case folders relative to the Markdown file).

    Parameters
    ----------
    result : dict
        What :func:`~refraction_ref.interop.crosscheck.run` returns.
    link : str
        Prefix of the figure paths (``""`` or ending in ``/``).

    Returns
    -------
    str
        The Markdown report.
    """
    T = result["targets"]
    lines = ["# Cross-check of the exact references against Mitsuba 3", "",
             "Written by `refraction-ref crosscheck` (refraction_ref/interop/crosscheck.py); conventions in "
             "docs/oracle.md, section *Cross-check against Mitsuba 3*. Versions: "
             + ", ".join(f"{k} {v}" for k, v in sorted(result["versions"].items()) if isinstance(v, str)) + ".", "",
             f"Targets: exit directions where both exit, median <= {T['median_deg']} deg and p99 <= "
             f"{T['p99_deg']} deg (TIR-chaos cases {', '.join(result['tir_chaos'])} reported, not judged); "
             f"status agreement >= {T['status_agree']:.0%} of pixels; image relative RMSE <= "
             f"{T['image_rel_rmse']:.0%} on the judged pixels (rule in the findings); caustic maps pass the "
             "golden suite's Z-test (every Mitsuba batch against our K batches).", ""]
    lines += _summary(result) + [""]
    lines += ["| case | median deg | p99 deg | status agree | image rel RMSE (judged) | path integrator "
              "(judged / all) | envmap bitmap (all) | Fresnel moves image | caustics rel L1; Z-test | verdict |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    lines += [_summary_row(name, e, result["tir_chaos"]) for name, e in result["cases"].items()]
    for name, e in result["cases"].items():
        if "skipped" in e:
            continue
        lines += ["", f"## {name}", "", e["purpose"], ""]
        p = e.get("paths")
        if p and p.get("kind") == "water":
            lines += _water_paths_rows(name, e, T, link)
        elif p:
            lines += _paths_rows(name, e, T, link)
        if e.get("images"):
            lines += _images_rows(name, e["images"], link)
        if e.get("caustics"):
            lines += _caustics_rows(name, e["caustics"], link)
    return "\n".join(lines) + "\n"
