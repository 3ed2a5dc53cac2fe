"""Chaudhari (2008): the thesis's statements beyond Tables 4.1 and 4.2, measured for ``refraction-ref tables``.

Each study measures one or two sentences of chs. 3 and 4 beyond the tables:
the occupancy bitmask's memory (§3.2), the additive blending's carries and
the local slicing (§3.3), on-the-fly peeling
(§3.4.1), the 4-texel normals against the 3x3 mesh (§3.5), the full-resolution
reduction at the 512 grid (§4.2), the peeling pass above the 512 grid (§4.3)
and the caustics of a sphere against the exact reference (Fig. 4.5). The
claims judged on them (:data:`MORE_CLAIMS`) state their rule before the
numbers and say where the set-up differs from the thesis's.

References
----------
Chaudhari, K. (2008). *Real-Time Multiple Refractions Through Deformable
Objects*. MSc thesis, UMBC. §§3.2-3.7, 4.2, 4.3, Fig. 4.5, Fig. 4.8.
"""

from __future__ import annotations

import json
import os
import statistics

import numpy as np

from . import chaudhari as T
from . import chaudhari_quality as Q
from .chaudhari_models import ratio, time_frames
from .claims import ClaimRow, Finding, ratio_text
from .common import BY_CONSTRUCTION, NOT_MEASURED, TABLE_THREADS, Table, straddles

__all__ = ["voxel_study", "timing_study", "caustics_study", "table", "MORE_CLAIMS", "RARE", "COMPACT", "SEVERE",
           "CORRECT_L1"]

#: §3.3 "rare": the share of covered pixels whose bitmask a carry of the additive blending changes, at most
RARE = 0.01
#: §3.3 "more compact": a pixel's local slices are compact when its depth range is below this share of the global
COMPACT = 0.9
#: §3.4.1 "severely reduces the performance": on-the-fly peeling's frame at least this times the separate pass's
SEVERE = 1.5
#: Fig. 4.5: the image-space caustic map's rel L1 against the exact reference at most this, its flux within 10 %
CORRECT_L1 = 0.25


def voxel_study(mods, rows41, res, names=None, log=None):
    """§3.2, §3.3: the bitmask's bytes, the additive blending's carries and the local slicing, per model.

    Each model of Table 4.1 in its view of highest depth complexity on a ``res``^2 grid (image = grid): the
    min/max pass, then the voxelization with ``blend = add`` (the thesis's) and with ``or``.

    Parameters
    ----------
    mods : dict
        Row name -> :class:`.chaudhari.Model`.
    rows41 : list of dict
        :func:`.chaudhari.table_4_1`'s rows (their ``view``).
    res : int
        Grid (and image) side.
    names : sequence of str, optional
        The rows to measure (default: every row of ``rows41``).
    log : callable, optional

    Returns
    -------
    dict
        Row -> ``covered`` (pixels), ``carry`` (pixels whose words differ between add and or),
        ``compact`` (pixels whose local depth range is below :data:`COMPACT` of the global one),
        ``bytes`` (the bitmask's), ``grid`` ((H, W, slices)).
    """
    from ..imagespace import pipeline as P

    out = {}
    for row in rows41:
        name = row["model"]
        if names is not None and name not in names:
            continue
        model = mods[name]
        d = T.with_view(T.scene_of(model), row["view"], model.distance, res)
        prep = Q.PreparedScene(d)
        minmax = P.pass_minmax(prep.geom, prep.cam, prep.p)
        add = P.pass_voxelize(minmax, prep.cam, dict(prep.p, blend="add"))
        logical_or = P.pass_voxelize(minmax, prep.cam, dict(prep.p, blend="or"))
        covered = np.isfinite(minmax.zmin) & np.isfinite(minmax.zmax)
        carry = np.any(np.asarray(add.bits) != np.asarray(logical_or.bits), axis=-1) & covered
        local = (minmax.zmax - minmax.zmin)[covered]
        out[name] = {"covered": int(covered.sum()), "carry": int(carry.sum()),
                     "compact": int(np.count_nonzero(local < COMPACT * (minmax.gmax - minmax.gmin))),
                     "local_median": float(np.median(local) / max(minmax.gmax - minmax.gmin, 1e-300)),
                     "bytes": int(np.asarray(add.bits).nbytes),
                     "grid": (int(covered.shape[0]), int(covered.shape[1]), int(prep.p["slices"]))}
        if log:
            o = out[name]
            log(f"  {name} {res}^2: carries on {o['carry']} of {o['covered']} covered pixels, local slices compact on "
                f"{o['compact']}, bitmask {o['bytes'] / 2 ** 20:.2f} MiB")
    return out


def timing_study(mods, v41, v42, res, grids, rounds, log=None):
    """§3.4.1, §3.5, §4.2, §4.3: frames timed round by round (:func:`.chaudhari_models.time_frames`).

    Parameters
    ----------
    mods : dict
        Row name -> :class:`.chaudhari.Model`.
    v41, v42 : View
        Bunny I's and I-A's views of highest depth complexity.
    res : int
        The run's smallest grid (the variants of §3.4.1 and §3.5 are timed on it).
    grids : sequence of int
        The run's grids; with 512 among them the full-resolution reduction (§4.2) and the 1024 grid (§4.3) are
        timed too.
    rounds : int
        Rounds.
    log : callable, optional

    Returns
    -------
    dict
        ``variants``: [separate peel and eq. 3.2 normals, on-the-fly peeling, 3x3 mesh normals];
        ``reduce``: [I-A with the MIP bound, with the full-resolution one] at the 512 grid or None;
        ``peel``: [Bunny I at the 512 grid, at 1024] or None.
    """
    from ..scene import load_scene
    base = T.cell_scene(mods["Bunny I"], v41, res, 32, "thesis")
    if log:
        log("  §3.4.1, §3.5: on-the-fly peeling and the 3x3 mesh normals against the thesis's passes ...")
    out = {"variants": time_frames([base, load_scene(base, {"imagespace.peeling": "lut"}),
                                    load_scene(base, {"imagespace.normals": "mesh3x3"})], rounds),
           "reduce": None, "peel": None}
    if 512 in grids:
        if log:
            log("  §4.2: the full-resolution reduction at the 512 grid; §4.3: peeling at the 1024 grid ...")
        ia = T.cell_scene(mods["I-A"], v42, 512, 32, "thesis")
        out["reduce"] = time_frames([ia, load_scene(ia, {"imagespace.bounds": "global"})], rounds)
        out["peel"] = time_frames([T.cell_scene(mods["Bunny I"], v41, g, 32, "thesis") for g in (512, 1024)],
                                  max(3, rounds // 2))
    return out


def caustics_study(quick, log=None):
    """Fig. 4.5: a glass sphere's caustic on a floor, the image-space method against the exact reference.

    The golden case ``is_caustics_sphere``'s scene (a sphere of IOR 1.5 over a plane, a directional light),
    rendered larger: the caustic map of the receiver by both methods.

    Parameters
    ----------
    quick : bool
        64^2 maps and image, 128^2 photons, 256^2 exact photons; else 256^2, 512^2, 1024^2.
    log : callable, optional

    Returns
    -------
    dict
        ``rel_l1`` (both blurred by one texel), ``flux`` (ours over the exact), ``map``, ``photons``, ``exact``.
    """
    import refraction_ref as rr

    from ..metrics import relative_l1

    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with open(os.path.join(here, "data", "golden", "is_caustics_sphere.json")) as f:
        sc = json.load(f)["scene"]
    ph, cm, ex, w = (128, 64, 256, 64) if quick else (512, 256, 1024, 256)
    sc["imagespace"] = {"photons": ph, "caustic_map": cm}
    sc["exact"] = {"photons": ex}
    sc["camera"].update(width=w, height=w)
    a = rr.render(sc, method="imagespace").arrays["caustic_map_0"]
    b = rr.render(sc, method="exact").arrays["caustic_map_0"]
    out = {"rel_l1": float(relative_l1(a, b, blur=1.0)), "flux": float(np.sum(a) / max(np.sum(b), 1e-300)),
           "map": cm, "photons": ph, "exact": ex}
    if log:
        log(f"  Fig. 4.5 sphere caustic: rel L1 {out['rel_l1']:.3f} against the exact reference, flux "
            f"{out['flux']:.3f}")
    return out


Q_MEMORY = ("Using just one bit per grid cell (one byte = eight bits), the same resolution can be obtained in just "
            "$2MB$ of memory.")
Q_OVERFLOW = ("Additive blending has a problem of overflowing when the two fragments intersect with the same cell; "
              "however, the occurrence of such scenarios with our algorithm is rare since we use a high resolution "
              "grid.")
Q_COMPACT = "Although this technique generates a distorted grid, for most pixels it provides more compact slicing than uniform voxelization."
Q_FLY = ("This severely reduces the performance, as it contains several branching instructions and therefore becomes "
         "a hindrance in exploiting GPU's parallelism.")
Q_4TEX = ("Our method requires only 4 texture accesses, making it more efficient than 3x3 neighborhood which requires 9 "
          "texture accesses.")
Q_SIL = "For $\\delta = 2$ errors are more prominent at the silhouettes of the object."
Q_FIVE = ("However, Oliveira et al. (2007) observed that in most of the cases, 5 such iterations provide a reasonably "
          "accurate estimation of the intersection point.")
Q_MIP = ("Using a low-resolution MIP level doesn't guarantee a correct maximum depth value of a texture; however, it "
         "provides a sufficient approximation.")
Q_RED512 = "For a 512x512 resolution texture, parallel reduction on 32 textures becomes a bottleneck."
Q_FIG48 = ("Non-linear relationship between the number of triangles and frame rate clearly indicates that the "
           "algorithm is not limited by the number of triangles in the scene.")
Q_PEEL1024 = ("Second, depth peeling pass, although accelerated by a binary search on the bits, is still a hindrance "
              "while utilizing a voxelization resolution higher than $512 \\times 512 \\times 256$.")
Q_FIG45 = ("Caustics produced by a sphere rendered to indicate the correctness of our photon tracing technique (left) "
           "and the same view is rendered using a refractive dragon (right).")

# --------------------------------------------------------------------------- the claims of these studies
def _memory(m):
    # §3.2 memory: the bitmask's layout
    v0 = next(iter(m["vox"].values()))
    H, W, S = v0["grid"]
    per = v0["bytes"] / (H * W * S / 8)
    return Finding(None, f"our bitmask at {H}x{W}x{S}: {v0['bytes'] / 2 ** 20:.2f} MiB ({per:.2f} bit per cell); at "
                         f"256x256x256 {256 ** 3 / 8 / 2 ** 20:.0f} MiB, at 1024x1024x256 "
                         f"{1024 * 1024 * 256 / 8 / 2 ** 20:.0f} MiB, at 1920x1080x256 "
                         f"{1920 * 1080 * 256 / 8 / 2 ** 20:.1f} MiB (the thesis: 2, 32, about 64 MB)")


def _overflow_rare(m):
    vox, res = m["vox"], m["vox_res"]
    share = {k: v["carry"] / max(v["covered"], 1) for k, v in vox.items()}
    return Finding(all(x <= RARE for x in share.values()),
                   "; ".join(f"{k}: {v['carry']:,} of {v['covered']:,} covered pixels ({100 * share[k]:.2f}%)"
                             for k, v in vox.items()) + f" at the {res} grid",
                   differs=("" if res == 512 else f"the {res} grid (the thesis's figures use 512)")
                   + ("; " if res != 512 and len(vox) < 4 else "") + (f"{len(vox)} of our 4 Table 4.1 rows"
                                                                       if len(vox) < 4 else ""))


def _compact_slicing(m):
    vox = m["vox"]
    frac = {k: v["compact"] / max(v["covered"], 1) for k, v in vox.items()}
    return Finding(all(x > 0.5 for x in frac.values()),
                   "; ".join(f"{k}: {100 * frac[k]:.0f}% of the covered pixels (median local range "
                             f"{100 * v['local_median']:.0f}% of the global)" for k, v in vox.items()))


def _on_the_fly(m):
    # §3.4.1 on-the-fly peeling
    base, lut, _ = m["tim"]["variants"]
    r = ratio(lut, base)
    return Finding(r[0] >= SEVERE,
                   f"frame with on-the-fly peeling / with the separate pass {ratio_text(r)}; peel + trace "
                   f"{statistics.median(lut['peel']) + statistics.median(lut['trace']):.1f} against "
                   f"{statistics.median(base['peel']) + statistics.median(base['trace']):.1f} ms",
                   straddles=straddles(r[1], r[2], SEVERE))


def _four_texels(m):
    # §3.5: 4 texels against 9
    base, _, m3 = m["tim"]["variants"]
    r = ratio(m3, base, "trace")
    return Finding(r[0] > 1.0, f"trace with the 3x3 mesh normals / with eq. 3.2 (delta 2) {ratio_text(r)}",
                   straddles=straddles(r[1], r[2], 1.0))


def _silhouettes(m):
    # Fig. 3.4: delta 2 at the silhouettes
    by = {(x["scene"], x["option"]): x for x in m["ns"]}
    scenes = list(dict.fromkeys(x["scene"] for x in m["ns"]))
    d1, d2 = "central delta=1", "central delta=2 (thesis)"
    return Finding(all(by[(s, d2)]["sil_median"] > by[(s, d1)]["sil_median"] for s in scenes),
                   "; ".join(f"{s}: front-normal median within 2 pixels of the silhouette delta 2 "
                             f"{by[(s, d2)]['sil_median']:.2f} against delta 1 {by[(s, d1)]['sil_median']:.2f} deg "
                             f"(inside {by[(s, d2)]['int_median']:.2f} against {by[(s, d1)]['int_median']:.2f})"
                             for s in scenes))


def _bounds_rows(m, a, b):
    rows = {(x["scene"], x["bound"], x["iterations"]): x for x in m["bs"]["rows"]}
    return {s: (rows[(s,) + a], rows[(s,) + b]) for s in dict.fromkeys(x["scene"] for x in m["bs"]["rows"])}


def _five_iterations(m):
    # §3.6: 5 iterations
    near = _bounds_rows(m, ("tight", 5), ("tight", 16))
    return Finding(all(a["median"] <= 1.1 * b["median"] + 1e-9 and a["p90"] <= 1.1 * b["p90"] + 1e-9
                       for a, b in near.values()),
                   "; ".join(f"{s}: exit median/p90 {a['median']:.2f}/{a['p90']:.2f} deg at 5 iterations, "
                             f"{b['median']:.2f}/{b['p90']:.2f} at 16" for s, (a, b) in near.items()))


def _mip_level(m):
    # §3.7: the MIP level
    mip = _bounds_rows(m, ("tight", 5), ("global", 5))
    return Finding(all(a["median"] <= 1.05 * b["median"] + 1e-9 and a["p90"] <= 1.05 * b["p90"] + 1e-9
                       for a, b in mip.values()),
                   "; ".join(f"{s}: exit median/p90 {a['median']:.2f}/{a['p90']:.2f} deg with the 256 MIP bound, "
                             f"{b['median']:.2f}/{b['p90']:.2f} with the exact per-layer maxima"
                             for s, (a, b) in mip.items()))


def _reduction_512(m):
    # §4.2: the full-resolution reduction at 512
    if m["tim"]["reduce"] is None:
        return Finding(None, "—", "The quick run has no 512 grid.", verdict=NOT_MEASURED,
                       rule="Held if the full-resolution reduction at the 512 grid takes at least 2x the MIP one's.")
    mipf, glob = m["tim"]["reduce"]
    r = ratio(glob, mipf, "reduce")
    share = statistics.median([g / (f - s) for g, f, s in zip(glob["reduce"], glob["frame"], glob["shade"])])
    th = T.THESIS_4_2["Parallel Reduction"]
    return Finding(
        r[0] >= 2.0,
        f"I-A at the 512 grid: reduction of the 32 full-resolution layers / of their 256 MIP level {ratio_text(r)}; "
        f"the full one {100 * share:.1f}% of the frame (the thesis's Table 4.2, reduced at 512 on purpose: "
        f"{th[512][0] / th[256][0]:.2f}x its 256 time)", straddles=straddles(r[1], r[2], 2.0),
        rule=("I-A in its view, 512 grid, 32 layers, thesis mode, frames incl. photon generation: held if the "
              "reduction stage with bounds = global (every layer's exact maximum over 512^2) takes at least 2x "
              "the one with the MIP level of 256^2 (median of per-round ratios; the thesis's own Table 4.2: "
              f"{th[512][0] / th[256][0]:.1f}x)."))


def _triangles_nonlinear(m):
    # Fig. 4.8: frame rate against triangles
    rows41, cols = m["rows41"], m["cols"]
    if not rows41 or len(rows41) < 2:
        return None
    tris = {r_["model"]: r_["cells"][(cols[0][0], cols[0][1], "thesis")]["triangles"] for r_ in rows41}
    lo_m, hi_m = min(tris, key=tris.get), max(tris, key=tris.get)
    tr = tris[hi_m] / tris[lo_m]
    fr = {(L, g): next(r_ for r_ in rows41 if r_["model"] == hi_m)["cells"][(L, g, "thesis")]["frame_ms"]
          / next(r_ for r_ in rows41 if r_["model"] == lo_m)["cells"][(L, g, "thesis")]["frame_ms"]
          for L, g in cols}
    th = [(n, t) for n, (t, _) in T.THESIS_4_1_ALL.items()]
    thl, thh = min(th, key=lambda x: x[1]), max(th, key=lambda x: x[1])
    thr = {c: T.THESIS_4_1_ALL[thl[0]][1][c] / T.THESIS_4_1_ALL[thh[0]][1][c] for c in T.COLS_4_1}
    return Finding(all(x < tr / 4 for x in fr.values()),
                   f"{hi_m} / {lo_m} ({tr:.1f}x the triangles): frame {min(fr.values()):.2f}-{max(fr.values()):.2f}x "
                   f"over {len(fr)} (layers, grid) columns (the thesis's {thh[0]} / {thl[0]}, {thh[1] / thl[1]:.0f}x "
                   f"the triangles: {min(thr.values()):.2f}-{max(thr.values()):.2f}x)",
                   differs=f"{len(rows41)} of Table 4.1's 16 rows (the meshes we have)")


def _peel_1024(m):
    # §4.3: peeling above the 512 grid
    if m["tim"]["peel"] is None:
        return Finding(None, "—", "The quick run has no 512 grid.", verdict=NOT_MEASURED,
                       rule="Held if the peel's share of the frame grows from the 512 grid to 1024 and reaches the "
                            "thesis's own share at 512.")
    p512, p1024 = m["tim"]["peel"]
    sh = [statistics.median([p / (f - s) for p, f, s in zip(x["peel"], x["frame"], x["shade"])])
          for x in (p512, p1024)]
    th = T.THESIS_4_2["Depth Layer Peeling"][512][0] / sum(v[512][0] for v in T.THESIS_4_2.values())
    return Finding(sh[1] > sh[0] and sh[1] >= th,
                   f"Bunny I, peel {100 * sh[0]:.1f}% of the frame at the 512 grid, {100 * sh[1]:.1f}% at 1024 (the "
                   f"thesis's Table 4.2 at 512: {100 * th:.1f}%); peel {statistics.median(p512['peel']):.0f} -> "
                   f"{statistics.median(p1024['peel']):.0f} ms",
                   differs="the 1024 grid stands for 'higher than 512x512x256'; slices stay 256")


def _sphere_caustic(m):
    # Fig. 4.5
    caus = m["caus"]
    return Finding(caus["rel_l1"] <= CORRECT_L1 and abs(caus["flux"] - 1.0) <= 0.1,
                   f"rel L1 {caus['rel_l1']:.3f} against the exact reference, flux {caus['flux']:.3f} of the exact "
                   f"one's ({caus['map']}^2 map, {caus['photons']}^2 photons, exact {caus['exact']}^2)")


#: the claims of these studies, judged on ``vox``, ``tim``, ``caus`` (this module's studies), ``ns``, ``bs``
#: (:mod:`.chaudhari_quality`), ``rows41``, ``cols`` (Table 4.1), ``vox_res`` and ``qres``
MORE_CLAIMS = (
    ClaimRow("§3.2", Q_MEMORY, _memory, verdict=BY_CONSTRUCTION, why="Shown: the layout holds the thesis's arithmetic.",
             rule="Not judged: the bytes of our occupancy words against one bit per grid cell.",
             construction="the bitmask is stored as uint32 words of 32 slices each, one bit per cell: its size is "
                          "H W slices / 8 bytes by its layout"),
    ClaimRow("§3.3", Q_OVERFLOW, _overflow_rare,
             why=("Two fragments of one pixel seldom land in the same of its 256 slices.",
                  "Two fragments of one pixel fall into one slice often enough here (thin features, grazing "
                  "surfaces) that the carry moves a layer in more than 1% of the pixels."),
             rule=("Held if the additive blending's carries change the bitmask (words differing from the logical "
                   "OR's) in at most {rare_percent:g}% of the covered pixels, for every Table 4.1 model measured, each "
                   "in its view of highest depth complexity at the {vox_res}x{vox_res}x256 grid.")),
    ClaimRow("§3.3", Q_COMPACT, _compact_slicing,
             why=("The per-pixel bounds follow the object's own thickness along each pixel's ray, which for most "
                  "pixels is well below the object's whole depth range.",
                  "For most pixels the object spans nearly its whole depth range along the ray here."),
             rule=("Held if the per-pixel depth range (Zmax - Zmin, the local slicing) is below {compact:g}x the "
                   "object's global range (the uniform voxelization's) on more than half the covered pixels, for "
                   "every Table 4.1 model measured (its view of highest depth complexity, {vox_res} grid). The local "
                   "range never exceeds the global one (by construction); how far below it lies is the "
                   "measurement.")),
    ClaimRow("§3.4.1", Q_FLY, _on_the_fly, timing=True,
             why=("Finding each layer's bit again at every probe of every search costs more than peeling every "
                  "layer once.",
                  "The look-up tables find a layer's bit cheaply enough on a CPU that peeling on the fly is not "
                  "{severe:g}x slower here."),
             rule=("Bunny I in its view of highest depth complexity, 512^2 viewport, {vox_res} grid, 32 layers, "
                   "thesis mode, frames incl. photon generation, {threads} thread: held if imagespace.peeling = lut "
                   "(8-bit look-up tables during the trace, §3.4.1) takes at least {severe:g}x the frame of the "
                   "separate pass (median of per-round ratios)."),
             differs=("a CPU thread, where the thesis's argument is about a GPU's branching; without an LDI the "
                      "on-the-fly search is bounded by the object's Zmax (no reduction)")),
    ClaimRow("§3.5", Q_4TEX, _four_texels, timing=True,
             why=("Four depth reads per normal cost less than nine.",
                  "The 3x3 mesh normals are not slower than eq. 3.2's here."),
             rule=("The same frames as the row above: held if the trace with imagespace.normals = mesh3x3 takes "
                   "longer than with the thesis's central differences (median of per-round trace ratios above 1)."),
             differs="our 3x3 mesh reads depth texels too, not a mesh's vertex normals"),
    ClaimRow("§3.5, Fig. 3.4", Q_SIL, _silhouettes,
             why=("A step of two pixels reaches across the silhouette more often than a step of one.",
                  "Delta 2's error at the silhouettes is not above delta 1's here."),
             rule=("§3.5's normals study ({qres}^2, the bunny and the sphere against the exact reference): held if "
                   "delta 2's median front-normal error on the pixels within 2 pixels of the silhouette is above "
                   "delta 1's there, on every scene.")),
    ClaimRow("§3.6", Q_FIVE, _five_iterations,
             why=("Past 5 halvings the search's interval is below the depth images' own error.",
                  "Five iterations leave an error more than 10% above sixteen's here."),
             rule=("§3.7's bounds study ({qres}^2, tight bound, against the exact reference): held if 5 "
                   "binary-search iterations give an exit-direction median and p90 within 10% of 16 iterations', on "
                   "every scene."),
             differs="the sentence reports Oliveira et al.'s observation; we test it on the thesis's multi-layer "
                     "search"),
    ClaimRow("§3.7", Q_MIP, _mip_level,
             why=("The MIP level's maximum plus the margin bounds the search about as well as the exact maxima.",
                  "The MIP bound's exits are more than 5% worse than the exact maxima's here."),
             rule=("The bounds study ({qres}^2, 5 iterations): held if the MIP bound's (bounds = mip, 256 level, 1% "
                   "margin) exit median and p90 are within 5% of the exact per-layer maxima's (bounds = global), on "
                   "every scene.")),
    ClaimRow("§4.2", Q_RED512, _reduction_512, timing=True,
             why=("Reducing four times the texels of 32 layers costs several times the MIP level's reduction.",
                  "The full-resolution reduction is not 2x the MIP level's here: the reduction reads each layer once "
                  "and its cost is small beside the trace's.")),
    ClaimRow("Fig. 4.8", Q_FIG48, _triangles_nonlinear, timing=True,
             why=("The per-pixel passes do not see triangles; only the rasterizations do.",
                  "Our frame grows with the triangles by more than a quarter of their ratio: the CPU's rasterizations "
                  "(min/max, voxelization, photon generation) weigh more than the thesis's GPU's."),
             rule=("Table 4.1's rows (frames incl. photon generation): held if, in every (layers, grid) column, the "
                   "frame of the row with the most triangles is less than a quarter of the triangle ratio times the "
                   "frame of the row with the fewest (a frame proportional to the triangles would give the whole "
                   "ratio).")),
    ClaimRow("§4.3", Q_PEEL1024, _peel_1024, timing=True,
             why=("Four times the texels, each decoded bit by bit, make the peel a larger part of the frame above "
                  "512.", "Above the 512 grid the peel does not take a larger share of the frame than the thesis's "
                  "peel at 512."),
             rule=("Bunny I in its view, 512^2 viewport, 32 layers, thesis mode: held if the peeling pass's share of "
                   "the frame (incl. photon generation, less shading) grows from the 512 grid to the 1024 grid and at "
                   "1024 is at least the thesis's own peel share at 512 (Table 4.2, I-A).")),
    ClaimRow("Fig. 4.5", Q_FIG45, _sphere_caustic,
             why=("The photons traced through the sphere's layers land where the exact reference's do.",
                  "The image-space caustic departs from the exact reference by more than the rule allows here."),
             rule=("The golden case is_caustics_sphere's scene (a sphere of IOR 1.5 over a floor): held if the "
                   "image-space caustic map's rel L1 against the exact reference (both blurred by one texel) is at "
                   "most {correct_l1:g} and its flux within 10% of the exact one's."),
             differs="the thesis shows the image by eye (a bumpy floor); ours is a flat floor against a numerical "
                     "reference"),
)


def table(vox, tim, caus):
    """The raw numbers of these studies as one :class:`Table`.

    Parameters
    ----------
    vox, tim, caus : dict
        :func:`voxel_study`, :func:`timing_study`, :func:`caustics_study`.

    Returns
    -------
    Table
    """
    rows = [[f"§3.2-3.3 {k}", f"{v['grid'][0]}x{v['grid'][1]}x{v['grid'][2]}", "covered pixels / carries / compact "
             "local slices / bitmask MiB", f"{v['covered']} / {v['carry']} / {v['compact']} / "
             f"{v['bytes'] / 2 ** 20:.2f}"] for k, v in vox.items()]
    names = ("separate peel, eq. 3.2", "on-the-fly peel (lut)", "3x3 mesh normals")
    for n, x in zip(names, tim["variants"]):
        rows.append([f"§3.4.1/§3.5 Bunny I, {n}", "", "frame / peel / trace ms (medians)",
                     f"{statistics.median(x['frame']):.1f} / {statistics.median(x['peel']):.1f} / "
                     f"{statistics.median(x['trace']):.1f}"])
    if tim["reduce"] is not None:
        for n, x in zip(("MIP 256 bound", "full-resolution bound"), tim["reduce"]):
            rows.append([f"§4.2 I-A, {n}", "512 grid", "frame / reduce ms (medians)",
                         f"{statistics.median(x['frame']):.1f} / {statistics.median(x['reduce']):.2f}"])
    if tim["peel"] is not None:
        for g, x in zip((512, 1024), tim["peel"]):
            rows.append([f"§4.3 Bunny I, {g} grid", f"{g} grid", "frame / peel ms (medians)",
                         f"{statistics.median(x['frame']):.1f} / {statistics.median(x['peel']):.1f}"])
    rows.append(["Fig. 4.5 sphere caustic", f"{caus['map']}^2 map", "rel L1 vs exact / flux ratio",
                 f"{caus['rel_l1']:.3f} / {caus['flux']:.3f}"])
    return Table("chaudhari_more", "§§3.2-4.3, Figs. 4.5, 4.8: the studies of the further claims",
                 ["study", "grid", "quantity", "ours"], rows,
                 note=(f"Timed frames: the thesis's frame incl. photon generation, medians of interleaved rounds on "
                       f"{TABLE_THREADS} thread, 512^2 viewport, 32 layers, thesis mode (all layers peeled)."))
