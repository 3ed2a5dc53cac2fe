"""Tipprasert (2006) eq. 4-3 read two ways, against the exact water reference, and the readings the rows rest on.

Eq. 4-3 sets the reference box's extents from the receiver's vertices
farthest along its axes; read as the whole vector's length (``caustics.placement
= thesis``) or as the coordinate along each axis (``component``, the default).
:func:`placement_study` renders the level map's caustic map with each reading
and compares it with the exact water reference in the same box;
:func:`readings` lists every reading of the thesis the Tipprasert rows rest on.

References
----------
N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene with
Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn University,
2006, §4.2.1 (eqs. 4-1 to 4-3), §4.7.2 (eq. 4-22), §2.7 (eq. 2-9).
"""

from __future__ import annotations

import json

import numpy as np

from .common import Table, readings_table
from .tipprasert_scenes import PAPER, rounded

__all__ = ["READINGS", "ONE_PLANE", "component_box", "placement_scenes", "placement_study", "placement_table",
           "readings"]

#: eq. 4-3's readings measured against the exact water reference: (name, overrides)
READINGS = (("full norm (caustics.placement = thesis)", {"caustics.placement": "thesis"}),
            ("component along each axis (caustics.placement = component, default)",
             {"caustics.placement": "component"}),
            ("tight box (caustics.placement = tight)", {"caustics.placement": "tight"}))


def component_box(vertices, T0, size, placement="tight", origin=None):
    """Eq. 4-3 read component-wise for ``placement = "thesis"`` (the study's name for the reading).

    The component-wise reading is the placement ``caustics.placement =
    "component"`` (the default), which
    :func:`~refraction_ref.caustics.boxes.reference_box` computes; this maps
    the study's ``"thesis"`` to it and passes the other placements through.

    Parameters
    ----------
    vertices : (N, 3) array_like
        The receiver's world-space vertices.
    T0 : (3,) array_like
        Refracted light direction.
    size : int or (Hc, Wc)
        Texels of the maps.
    placement : {"tight", "thesis", "component"}
        ``"thesis"`` is read component-wise; others pass through.
    origin : (3,) array_like, optional
        ``P_0`` (default the vertices' bounding-box centre).

    Returns
    -------
    Box

    References
    ----------
    Tipprasert (2006), §4.2.1, eqs. 4-2, 4-3.
    """
    from ..caustics.boxes import reference_box

    return reference_box(vertices, T0, size, "component" if placement == "thesis" else placement, origin)


def placement_scenes(quick):
    """The wavy pools of the eq. 4-3 study: (name, scene data); the bundled scene, and in full two more.

    Parameters
    ----------
    quick : bool
        Only the bundled pool floor.

    Returns
    -------
    list of (str, dict)
    """
    from ..levelmap import default_scene

    base = json.loads(json.dumps(default_scene().data, default=lambda o: None))
    out = []
    if quick:
        d = json.loads(json.dumps(base))
        d["receivers"] = d["receivers"][:1]
        return [("bundled pool floor (levelmap_default.json, sun (0.3, -1, 0.2))", d)]
    out.append(("bundled scene (levelmap_default.json: floor and teapot, sun (0.3, -1, 0.2))", base))
    for amp, sun in ((3.0, [0.6, -1.0, 0.3]), (2.0, [-0.5, -1.0, 0.5])):
        d = json.loads(json.dumps(base))
        d["receivers"] = d["receivers"][:1]
        for w in d["water"]["waves"]:
            w["amplitude"] *= amp
        d["lights"][0]["direction"] = sun
        out.append((f"pool floor, waves x{amp:g}, sun ({sun[0]:g}, {sun[1]:g}, {sun[2]:g})", d))
    return out


#: the placement study's extra row: the default box with one plane (no depth test)
ONE_PLANE = "component, one plane (no depth test)"


def placement_study(quick=False, log=print):
    """Eq. 4-3's readings against the exact water reference: one row per (scene, receiver, reading).

    Each reading's level-map caustic map is compared with the exact reference
    rendered in the same box (:mod:`refraction_ref.exact.water`):
    the relative L1 of :func:`~refraction_ref.metrics.relative_l1`
    (both blurred by one texel, over the receiver's own texels) and the ratio
    of the blurred maps' peaks. Quick: the bundled floor alone, 256^2 maps,
    1024^2 exact samples; full: three scenes, 512^2 maps, 2048^2 samples.

    Parameters
    ----------
    quick : bool
        Quick (CI smoke) sizes.
    log : callable or None
        Receives one line per row.

    Returns
    -------
    rows : list of dict
        ``scene``, ``receiver``, ``reading``, ``box``, ``own``, ``planes_used``,
        ``rel_l1``, ``peak``.
    ms : int
        Map side in texels.
    es : int
        Exact samples per side.
    """
    from ..exact.pipeline import render_water_exact
    from ..filters import gaussian_filter_zero
    from ..metrics import relative_l1
    from ..levelmap.pipeline import planes_pass, prepare, render_levelmap
    from ..scene import load_scene

    ms, es = (256, 1024) if quick else (512, 2048)
    size = {"caustics.map_size": ms, "exact.water_samples": es, "camera.width": 32, "camera.height": 32}
    rows = []
    for name, data in placement_scenes(quick):
        base = load_scene(data, size)
        for reading, o in READINGS:
            sc = load_scene(base, o)
            arrays, info = render_levelmap(sc)
            exact, _ = render_water_exact(sc)
            ctx = prepare(sc)
            boxes = planes_pass(sc)["boxes"]
            used = info["planes_used_per_receiver"]
            for r, pair in enumerate(ctx["pairs"]):
                own = pair[0].lm.own
                a, b = arrays[f"caustic_map_{r}"], exact[f"caustic_map_{r}"]
                ab = gaussian_filter_zero(np.where(own, np.nan_to_num(a), 0.0), 1.0)
                bb = gaussian_filter_zero(np.where(own, np.nan_to_num(b), 0.0), 1.0)
                bx = boxes[r][0]
                row = {"scene": name, "receiver": sc.data["receivers"][r].get("name", f"receiver {r}"),
                       "reading": reading, "box": f"{bx.w:.2f} x {bx.h:.2f} x {bx.d:.2f}",
                       "own": float(own.mean()), "planes_used": used[r][0],
                       "rel_l1": relative_l1(a, b, own), "peak": float(ab[own].max() / max(bb[own].max(), 1e-300))}
                rows.append(row)
                if log:
                    log(f"  eq. 4-3 {reading[:22]:22s} {row['receiver']:10s}: box {row['box']}, rel L1 "
                        f"{row['rel_l1']:.4f}, peak {row['peak']:.3f}")
            if o.get("caustics.placement") == "component":
                # the abstract's depth texture: the same box with one plane, which accepts every texel (no depth
                # test: the texture-mapping method of §3.3, as §5.1 says), against the same exact maps
                one, _ = render_levelmap(load_scene(sc, {"levelmap.planes": 1}))
                for r, pair in enumerate(ctx["pairs"]):
                    own = pair[0].lm.own
                    rows.append({"scene": name, "receiver": sc.data["receivers"][r].get("name", f"receiver {r}"),
                                 "reading": ONE_PLANE, "box": rows[-len(ctx["pairs"]) + r]["box"],
                                 "own": float(own.mean()), "planes_used": 1,
                                 "rel_l1": relative_l1(one[f"caustic_map_{r}"], exact[f"caustic_map_{r}"], own),
                                 "peak": float("nan")})
    return rows, ms, es


def placement_table(rows, ms, es):
    """The eq. 4-3 study as a :class:`~.common.Table`, with a sentence on the reading its numbers support.

    Parameters
    ----------
    rows : list of dict
        :func:`placement_study`'s rows.
    ms : int
        Map side in texels.
    es : int
        Exact samples per side.

    Returns
    -------
    Table
    """
    by = {}
    for r in rows:
        by.setdefault((r["scene"], r["receiver"]), {})[r["reading"]] = r
    full, comp, tight = (x[0] for x in READINGS)
    better = [k for k, v in by.items() if comp in v and full in v and v[comp]["rel_l1"] < v[full]["rel_l1"]]
    sentence = (f"The component-wise reading is closer to the exact reference than the full norm on {len(better)} of "
                f"{len(by)} receivers (rel L1 "
                + "; ".join(f"{k[1]} in {k[0].split(' (')[0]}: {v[full]['rel_l1']:.3f} full norm, "
                            f"{v[comp]['rel_l1']:.3f} component, {v[tight]['rel_l1']:.3f} tight" for k, v in by.items())
                + "). ")
    note = ("Eq. 4-3 sets the box extents w, h, d = 2|P_x|, 2|P_y|, 2|P_z| for the vertices farthest along U, V, W "
            "from the receiver's origin P_0. Read as the whole vector's length (caustics.placement = thesis, the "
            "default of contract_version 4) the box of a flat floor is as tall as it is wide and most texels and planes fall outside the "
            "receiver; read as the coordinate along each axis (the box's stated purpose: enclose the receiver along "
            "U, V, W) it is the receiver's own extent about P_0 (caustics.placement = component, the default "
            "from contract_version 5). " + sentence +
            f"Level-map caustic maps against the exact water reference rendered in the same box: rel L1 of both "
            f"blurred by one texel over the receiver's own texels, peak = the level map's blurred maximum over the "
            f"exact one's; {ms}^2 maps, {es}^2 exact samples, 50 planes, the default 128x128 water.")
    return Table("tipprasert_eq4_3", "Eq. 4-3 read two ways: the level map's caustic map against the exact reference",
                 ["scene", "receiver", "eq. 4-3 reading", "box w x h x d", "map texels on the receiver",
                  "planes in use", "rel L1 vs exact", "peak / exact peak"],
                 [[r["scene"], r["receiver"], r["reading"], r["box"], rounded(r["own"], 3), r["planes_used"],
                   rounded(r["rel_l1"], 4), rounded(r["peak"], 3)] for r in rows], note)


def readings(prow, ms):
    """The readings the Tipprasert rows rest on (:func:`.common.readings_table`), eq. 4-3's with this run's numbers.

    Parameters
    ----------
    prow : list of dict
        :func:`placement_study`'s rows.
    ms : int
        Their map side.

    Returns
    -------
    Table
    """
    from ..scene import load_scene

    lm = load_scene({}).data["levelmap"]
    by = {}
    for r in prow:
        by.setdefault((r["scene"].split(" (")[0], r["receiver"]), {})[r["reading"].split(" (")[0]] = r["rel_l1"]
    eq43 = "; ".join(f"{rec} in {sc}: {v['full norm']:.3f} full norm, {v['component along each axis']:.3f} component"
                     for (sc, rec), v in by.items())
    better = sum(v["component along each axis"] < v["full norm"] for v in by.values())
    return readings_table("tipprasert_readings", PAPER, [
        ("caustics.placement (component)", "eq. 4-3: w, h, d = 2|P_x|, 2|P_y|, 2|P_z|", "|P_a| as the farthest "
         "vertex's component along axis a (the box about P_0 enclosing the receiver)",
         f"every level-map row (the boxes); against the exact water reference at {ms}^2, rel L1 ({better} of "
         f"{len(by)} receivers closer with the component reading): {eq43}"),
        ("levelmap.smart_spacing (respace) and eq. 4-22's n_i (planes)", "§4.7.2: each sub-box re-sliced, n_i from "
         "eq. 4-22, planes or slices not said", "the thesis's re-slicing, n_i planes per sub-box",
         "Tables 5-3, 5-4, 5-5, smart slicing and profiling rows"),
        (f"levelmap.depth_levels ({lm['depth_levels']})", "§4.7.2: 'The number of divided depth level is "
         "specified by user' (no number)", f"{lm['depth_levels']} levels", "Tables 5-3 to 5-5, smart slicing, "
         "profiling, Fig. 5-12"),
        ("eq. 2-9's image difference", "§2.7: a Luv difference of two images", "averaged over the receiver's "
         "pixels (object_mask), not the whole image", "Table 5-5"),
        ("the light of the tables", "not stated for Experiments 1 and 2", "a directional light from straight above "
         "(0, -1, 0)", "every Table 5-1 to 5-5 row"),
        ("levelmap.culling (none)", "Figs. 4-15, 5-7: every intersection triangle drawn on every plane",
         "none in the tables (the thesis's per-plane work); bounds is §6.1's proposal", "every timing row; §6.1"),
        ("eq. 4-1's N", "chosen at random", "the world z axis (x when z is nearly parallel to V)", "every level-map "
         "row (reproducible boxes)"),
    ])
