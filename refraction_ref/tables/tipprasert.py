"""Tipprasert (2006) Tables 5-1, 5-3, 5-4 and 5-5 and the thesis's claims, for ``refraction-ref tables``.

For the teapot (6,320 triangles), a UV sphere of 1,984 triangles (Table 5-2)
and, in full mode, the bunny in place of the thesis's dolphin, each alone in
the default pool under the default waves with the light from above: the
rendering time against the number of planes for the level map and the
volumetric baseline (Table 5-1), with normal and smart slicing (5-3), the
planes smart slicing actually draws (5-4) and the eq. 2-9 Luv difference of
the images with smart slicing on and off (5-5), for both ways of placing the
smart planes (``levelmap.smart_spacing``: ``lattice`` drops the empty
planes of the normal slicing, ``respace`` re-spaces eq. 4-22's ``n_i``
planes in each sub-box).

The defaults are the thesis's: plane placement of eqs. 4-2/4-3 and 4-7 to
4-9 (``levelmap.planes`` counts planes, the tables' "Num Plane"), and every
intersection triangle drawn over the whole map on every plane
(``levelmap.culling = "none"``), so that the per-plane work is what the
GPU of the thesis did. Times are medians of interleaved repeats (every
plane count and variant in turn in each round) on this
CPU; the thesis's are seconds on a GeForce 6800, so shapes and ratios are
compared, never absolute times.

References
----------
N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene with
Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn University,
2006, §5.2.4 (Tables 5-1 to 5-5, Figs. 5-10 to 5-12), §2.7 (eq. 2-9),
§4.7.2 (eqs. 4-21, 4-22).
"""

from __future__ import annotations

import os
import statistics
import time

import numpy as np

from .common import TABLE_THREADS, Report, Table, table_threads
from .tipprasert_claims import claims
from .tipprasert_placement import placement_study, placement_table, readings
from .tipprasert_scenes import PAPER, SUN_TOP, model_scene, rounded, thesis_rows, uv_sphere

__all__ = ["run", "uv_sphere", "model_scene", "thesis_rows", "SUN_TOP", "measure", "culling_study",
           "one_plane_memory", "tables", "culling_table", "plot", "VARIANTS", "slice_setup", "slice_images_ms"]


def _timed(scene):
    from ..levelmap.pipeline import render_levelmap

    t0 = time.perf_counter()
    arrays, info = render_levelmap(scene, warm=False)
    return time.perf_counter() - t0, arrays, info


VARIANTS = (("normal", {"levelmap.smart_slicing": False}),
            ("smart", {"levelmap.smart_slicing": True, "levelmap.smart_spacing": "lattice"}),
            ("respace", {"levelmap.smart_slicing": True, "levelmap.smart_spacing": "respace"}),
            ("volumetric", {"levelmap.variant": "volumetric"}))


def slice_setup(scene):
    """What the volumetric baseline's slice images read, for one model scene (its one receiver and light).

    Parameters
    ----------
    scene : Scene
        :func:`model_scene`'s scene.

    Returns
    -------
    (RasterSetup, Box, str)
        The receiver's triangles set up in the box's map, the box, ``caustics.placement``.
    """
    from ..levelmap.pipeline import prepare

    ctx = prepare(scene)
    pair = ctx["pairs"][0][0]
    return pair.setup, pair.box, ctx["placement"]


def slice_images_ms(prep, n):
    """T(I) of eq. 5-3: the baseline's slice images for ``n`` sample planes, timed alone (ms).

    One orthographic rasterization of the receiver per slab (the slab between the water and the box, then
    one per plane: ``n + 1``), as :func:`~refraction_ref.levelmap.slice_image_baseline.slice_image_caustics` draws them
    before each plane's splat.

    Parameters
    ----------
    prep : tuple
        :func:`slice_setup`'s result.
    n : int
        Sample planes.

    Returns
    -------
    float
    """
    from ..levelmap.planes import plane_lattice
    from ..raster import rasterize_ortho

    setup, box, placement = prep
    lat = plane_lattice(box, n, placement)
    t0 = time.perf_counter()
    rasterize_ortho(setup, box.size, slab=(lat.zlo, lat.s, -np.inf, -1.0))
    for i in range(n):
        rasterize_ortho(setup, box.size, slab=(lat.zlo, lat.s, float(i), float(i)))
    return (time.perf_counter() - t0) * 1e3


def measure(meshes, planes, repeats, size=None, log=print):
    """Rows of every table: per (model, planes) the medians of interleaved repeats of each variant.

    Parameters
    ----------
    meshes : list of (ours, thesis) names
    planes : list of int
    repeats : int
    size : dict, optional
        Overrides for small runs (``levelmap.map_size``, ``water.resolution``, camera size).
    """
    from ..metrics import luv_difference
    from ..scene import load_scene

    th = thesis_rows()
    rows = []
    for mesh, tname in meshes:
        scenes = {}
        for n in planes:
            base = model_scene(mesh, n, overrides=size)
            for k, o in VARIANTS:
                scenes[(n, k)] = load_scene(base, o)
        for sc in scenes.values():  # untimed: loads the model, touches the buffers
            _timed(sc)
        sprep = slice_setup(scenes[(planes[0], "normal")])
        for n in planes:  # untimed: the rasterizer's first call of each slab count
            slice_images_ms(sprep, n)
        t_i = {n: [] for n in planes}  # T(I): the baseline's slice images alone
        t_dp = {n: [] for n in planes}  # T(DP): the level map's position and diffuse maps (its level_map stage)
        times = {key: [] for key in scenes}
        caus = {key: [] for key in scenes}  # the caustics stage alone: where the planes' work is
        prof = {key: [] for key in scenes}  # smart slicing's depth profiling, every repeat (its median is reported)
        last = {}
        # interleaved: each repeat runs every plane count and variant in turn, so that a slow spell of the
        # machine hits a different plane count in each repeat and the medians leave it out
        for _ in range(repeats):
            for key, sc in scenes.items():
                t, arrays, info = _timed(sc)
                times[key].append(t)
                caus[key].append(info["timings_ms"]["caustics"])
                prof[key].append(info["timings_ms"].get("caustics.smart_slicing", 0.0))
                if key[1] == "normal":
                    t_dp[key[0]].append(info["timings_ms"]["level_map"])
                    t_i[key[0]].append(slice_images_ms(sprep, key[0]))
                last[key] = (arrays, info)
        for n in planes:
            med = {k: statistics.median(times[(n, k)]) for k, _ in VARIANTS}
            cm = {k: statistics.median(caus[(n, k)]) for k, _ in VARIANTS}
            an, inn = last[(n, "normal")]
            sm, ism = last[(n, "smart")]
            rs, irs = last[(n, "respace")]
            vo, ivo = last[(n, "volumetric")]
            hc, wc = an["caustic_map_0"].shape[:2]
            t = th[n]
            row = {"mesh": mesh, "thesis_mesh": tname, "planes": n,
                   "levelmap_s": med["normal"], "smart_s": med["smart"], "respace_s": med["respace"],
                   "volumetric_s": med["volumetric"],
                   # every repeat's seconds per variant, in round order (the claims' per-round ratios and spreads)
                   "rounds": {k: list(times[(n, k)]) for k, _ in VARIANTS},
                   "caustics_rounds": {k: list(caus[(n, k)]) for k, _ in VARIANTS},
                   "profiling_ms": statistics.median(prof[(n, "smart")]),
                   # per round: the thesis's smart slicing (respace): depth profiling, and the caustics stage
                   # less it (the intersection test: the planes' intersection triangles, depth-tested)
                   "profiling_rounds": list(prof[(n, "respace")]),
                   "intersection_rounds": [c - q for c, q in zip(caus[(n, "respace")], prof[(n, "respace")])],
                   "t_i_rounds": list(t_i[n]), "t_dp_rounds": list(t_dp[n]),
                   "t_i_ms": statistics.median(t_i[n]), "t_dp_ms": statistics.median(t_dp[n]),
                   "caustics_normal_ms": cm["normal"], "caustics_smart_ms": cm["smart"],
                   "caustics_volumetric_ms": cm["volumetric"],
                   "planes_used": ism["planes_used"], "planes_respaced": irs["planes_used"],
                   "empty_levels": (irs["stats"][0].get("smart") or {}).get("empty_levels"),
                   "luv_smart_on_off": luv_difference(an["image"], sm["image"], an["object_mask"]),
                   "luv_respace_on_off": luv_difference(an["image"], rs["image"], an["object_mask"]),
                   "maps_identical": bool(np.array_equal(an["caustic_map_0"], sm["caustic_map_0"])),
                   # §6.2: the level map's image against the volumetric baseline's
                   "luv_levelmap_volumetric": luv_difference(an["image"], vo["image"], an["object_mask"]),
                   "image_max_diff_volumetric": float(np.nanmax(np.abs(np.asarray(an["image"], float)
                                                                      - np.asarray(vo["image"], float)))),
                   "maps_identical_volumetric": bool(np.array_equal(an["caustic_map_0"], vo["caustic_map_0"])),
                   # §5.1: the GPU memory of each, 16-bit texels as the thesis counts them: the baseline's slice
                   # stack (reported by the baseline) against the level map's two maps (position and diffuse)
                   "memory_volumetric_b": int(sum(x.get("memory_bytes", 0) for x in ivo["stats"])),
                   "memory_levelmap_b": int(2 * hc * wc * 2 * len(ivo["stats"])),
                   "thesis_levelmap_s": t[f"t51_{tname}_levelmap"], "thesis_volumetric_s": t[f"t51_{tname}_volumetric"],
                   "thesis_normal_s": t[f"t53_{tname}_normal"], "thesis_smart_s": t[f"t53_{tname}_smart"],
                   "thesis_planes_used": t[f"t54_{tname}"], "thesis_luv": t[f"t55_{tname}"]}
            rows.append(row)
            if log:
                log(f"  {mesh:7s} {n:3d} planes: level map {row['levelmap_s']:.3f} s, smart {row['smart_s']:.3f} s "
                    f"({row['planes_used']} planes; thesis {row['thesis_planes_used']:.0f}), respaced "
                    f"{row['respace_s']:.3f} s ({row['planes_respaced']}), volumetric {row['volumetric_s']:.3f} s, "
                    f"Luv {row['luv_smart_on_off']:.3g} / {row['luv_respace_on_off']:.3g}")
    return rows


def culling_study(meshes, planes, repeats, size=None):
    """§6.1's bounding-volume culling against the thesis's per-plane work, normal slicing, per model.

    Parameters
    ----------
    meshes : list of (ours, thesis) names
    planes : int
        Plane count.
    repeats : int
        Interleaved timed rounds after an untimed render of each.
    size : dict, optional
        Overrides of small runs.

    Returns
    -------
    dict
        Model -> per culling (``none``, ``bounds``): ``triangles`` drawn and the caustics stage's ms per round;
        ``identical`` (the maps).
    """
    out = {}
    for mesh, _ in meshes:
        sc = {c: model_scene(mesh, planes, overrides=size, smart_slicing=False, culling=c) for c in ("none", "bounds")}
        res = {c: {"ms": []} for c in sc}
        maps = {}
        for c, x in sc.items():
            _, arrays, info = _timed(x)
            res[c]["triangles"] = int(sum(st.get("triangles_drawn", 0) for st in info["stats"]))
            maps[c] = arrays["caustic_map_0"]
        for _ in range(repeats):
            for c, x in sc.items():
                res[c]["ms"].append(_timed(x)[2]["timings_ms"]["caustics"])
        res["identical"] = bool(np.array_equal(maps["none"], maps["bounds"]))
        out[mesh] = res
    return out


def one_plane_memory(size=None):
    """§5.1's one situation: the baseline's slice stack and the level map's maps at one plane (bytes).

    Parameters
    ----------
    size : dict, optional
        Overrides (map size and so on).

    Returns
    -------
    dict
        ``volumetric`` (memory_bytes at 1 plane), ``levelmap`` (two 16-bit maps), ``map`` (Hc, Wc).
    """
    from ..scene import load_scene

    sc = load_scene(model_scene("sphere", 1, overrides=size), {"levelmap.variant": "volumetric"})
    _, arrays, info = _timed(sc)
    hc, wc = arrays["caustic_map_0"].shape[:2]
    return {"volumetric": int(sum(x.get("memory_bytes", 0) for x in info["stats"])), "levelmap": 2 * hc * wc * 2,
            "map": (hc, wc)}


def tables(rows, note, plots):
    """The four :class:`~.common.Table` of the report from :func:`measure`'s rows.

    Parameters
    ----------
    rows : list of dict
        :func:`measure`'s rows.
    note : str
        Note printed under every table.
    plots : dict
        Table number (``'1'``, ``'3'``, ``'4'``, ``'5'``) -> figure file name.

    Returns
    -------
    list of Table
        Tables 5-1, 5-3, 5-4 and 5-5.
    """
    t1 = Table("tipprasert_5_1", "Table 5-1: rendering time (s), level map against the volumetric baseline",
               ["model (paper)", "planes", "ours level map", "ours volumetric", "ours volumetric / level map",
                "paper level map", "paper volumetric", "paper volumetric / level map"],
               [[f"{r['mesh']} ({r['thesis_mesh']})", r["planes"], rounded(r["levelmap_s"]), rounded(r["volumetric_s"]),
                 rounded(r["volumetric_s"] / r["levelmap_s"], 2), rounded(r["thesis_levelmap_s"]), rounded(r["thesis_volumetric_s"]),
                 rounded(r["thesis_volumetric_s"] / r["thesis_levelmap_s"], 2)] for r in rows], note, plots.get("1"))
    t3 = Table("tipprasert_5_3", "Table 5-3: rendering time (s), normal against smart slicing",
               ["model (paper)", "planes", "ours normal", "ours smart", "ours normal / smart", "ours smart respaced",
                "paper normal", "paper smart", "paper normal / smart"],
               [[f"{r['mesh']} ({r['thesis_mesh']})", r["planes"], rounded(r["levelmap_s"]), rounded(r["smart_s"]),
                 rounded(r["levelmap_s"] / r["smart_s"], 2), rounded(r["respace_s"]), rounded(r["thesis_normal_s"]),
                 rounded(r["thesis_smart_s"]), rounded(r["thesis_normal_s"] / r["thesis_smart_s"], 2)] for r in rows],
               note, plots.get("3"))
    t4 = Table("tipprasert_5_4", "Table 5-4: planes actually drawn with smart slicing",
               ["model (paper)", "planes", "ours smart (lattice)", "ours smart (respaced, eq. 4-22)", "paper"],
               [[f"{r['mesh']} ({r['thesis_mesh']})", r["planes"], r["planes_used"], r["planes_respaced"],
                 rounded(r["thesis_planes_used"], 0)] for r in rows], note, plots.get("4"))
    t5 = Table("tipprasert_5_5", "Table 5-5: intensity difference (eq. 2-9, CIE Luv) with smart slicing on and off",
               ["model (paper)", "planes", "ours smart (lattice)", "ours smart (respaced, eq. 4-22)", "paper"],
               [[f"{r['mesh']} ({r['thesis_mesh']})", r["planes"], rounded(r["luv_smart_on_off"], 4),
                 rounded(r["luv_respace_on_off"], 4), rounded(r["thesis_luv"], 4)] for r in rows], note, plots.get("5"))
    return [t1, t3, t4, t5]


def culling_table(cull, planes):
    """:func:`culling_study` as a :class:`~.common.Table`."""
    rows = []
    for mesh, v in cull.items():
        for c in ("none", "bounds"):
            rows.append([mesh, planes, c, v[c]["triangles"], rounded(statistics.median(v[c]["ms"]), 1),
                         "yes" if v["identical"] else "no"])
    return Table("tipprasert_6_1", "§6.1: bounding-volume culling of the intersection triangles (normal slicing)",
                 ["model", "planes", "levelmap.culling", "ours triangles drawn", "ours caustics stage ms",
                  "maps identical"], rows,
                 note=("none: every intersection triangle drawn over the whole map on every plane (the thesis's work, "
                       "Figs. 4-15, 5-7); bounds: the beams that cannot reach the box culled and each plane scissored "
                       "to its texels (§6.1's proposal). Medians of interleaved rounds on one thread."))


def plot(rows, out):
    """Figures for Tables 5-1, 5-3, 5-4, 5-5 (ours and the thesis's), one panel per model: file names.

    Parameters
    ----------
    rows : list of dict
        :func:`measure`'s rows.
    out : str
        Folder the PNG files are written to.

    Returns
    -------
    dict
        Table number (``'1'``, ``'3'``, ``'4'``, ``'5'``) -> file name.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..files import savefig_atomic

    specs = {
        "1": ((("levelmap_s", "level map"), ("volumetric_s", "volumetric")),
              (("thesis_levelmap_s", "thesis level map"), ("thesis_volumetric_s", "thesis volumetric")), "seconds"),
        "3": ((("levelmap_s", "normal"), ("smart_s", "smart"), ("respace_s", "smart, respaced")),
              (("thesis_normal_s", "thesis normal"), ("thesis_smart_s", "thesis smart")), "seconds"),
        "4": ((("planes", "requested"), ("planes_used", "used (lattice)"), ("planes_respaced", "used (respaced)")),
              (("thesis_planes_used", "thesis used"),), "planes"),
        "5": ((("luv_smart_on_off", "Luv (lattice)"), ("luv_respace_on_off", "Luv (respaced)")),
              (("thesis_luv", "thesis"),), "eq. 2-9"),
    }
    meshes = list(dict.fromkeys((r["mesh"], r["thesis_mesh"]) for r in rows))
    names = {}
    for k, (ours, theirs, ylabel) in specs.items():
        fig, axs = plt.subplots(1, len(meshes), figsize=(4.4 * len(meshes), 3.6), squeeze=False)
        for ax, (mesh, tname) in zip(axs[0], meshes):
            rs = [r for r in rows if r["mesh"] == mesh]
            x = [r["planes"] for r in rs]
            for (key, label), style in zip(ours, ("-o", "-s", "-^")):
                ax.plot(x, [r[key] for r in rs], style, ms=3, label=label)
            twin = ax.twinx() if ylabel == "seconds" else ax
            for (key, label), style in zip(theirs, ("--", ":")):
                twin.plot(x, [r[key] for r in rs], style, color="gray" if style == "--" else "k",
                          label=f"{label} ({tname})")
            ax.set_title(f"{mesh} (thesis: {tname})")
            ax.set_xlabel("planes")
            ax.set_ylabel(ylabel + (" (this CPU)" if ylabel == "seconds" else ""))
            if twin is not ax:
                twin.set_ylabel("thesis seconds (GeForce 6800)")
            h1, l1 = ax.get_legend_handles_labels()
            h2, l2 = twin.get_legend_handles_labels() if twin is not ax else ([], [])
            ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left")
        fig.suptitle(f"Tipprasert (2006) Table 5-{k}, reproduced")
        fig.tight_layout()
        name = f"levelmap_table5_{k}.png"
        savefig_atomic(fig, os.path.join(out, name), dpi=90)
        plt.close(fig)
        names[k] = name
    return names


def run(quick=False, out=".", log=print):
    """Measure Tables 5-1, 5-3, 5-4, 5-5 and check the thesis's claims.

    Parameters
    ----------
    quick : bool
        The teapot and the sphere at 3, 17 and 31 planes, 128^2 maps, a
        64x64 water mesh and a 128^2 image, 5 interleaved repeats (about 10 s on
        two cores). Otherwise the thesis's set-up: teapot, sphere and bunny (for
        the dolphin), 3 to 101 planes in steps of 7, 512^2 maps, the default
        128x128 water and 512^2 image, 3 interleaved repeats.
    out : path-like
        Folder for the plots.
    log : callable or None

    Returns
    -------
    Report
    """
    from ..warm import warm

    t0 = time.perf_counter()
    out = os.fspath(out)
    os.makedirs(out, exist_ok=True)
    warm("levelmap")
    if quick:
        meshes = [("teapot", "teapot"), ("sphere", "sphere")]
        planes = [3, 17, 31]
        # 5: the smart-slicing verdict may flip run to run in the smoke run (teapot cells near its 1.2x line; 9 held
        # it steady), which the straddle marker says; the committed report is the full run's
        repeats = 5
        size = {"levelmap.map_size": 128, "water.resolution": 64, "camera.width": 128, "camera.height": 128}
        note = ("Quick run: teapot and the 1,984-triangle sphere at 3, 17 and 31 planes, 128^2 maps, 64x64 water, "
                "128^2 image, medians of 5 interleaved repeats, one Numba thread; times in seconds on this CPU (the "
                "thesis's on a GeForce 6800: compare "
                "ratios and shapes).")
    else:
        meshes = [("teapot", "teapot"), ("sphere", "sphere"), ("bunny", "dolphin")]
        planes = list(range(3, 102, 7))
        if planes[-1] != 101:
            planes.append(101)
        repeats = 3
        size = None
        note = ("Teapot, the 1,984-triangle sphere of Table 5-2 and the bunny (for the thesis's dolphin), each in "
                "the default pool (128x128 water, three waves, light from above), 512^2 maps and image; the thesis's "
                "plane placement (eqs. 4-2/4-3, 4-7 to 4-9) and per-plane work (levelmap.culling = none); medians of "
                "3 interleaved repeats, one Numba thread (TABLE_THREADS), seconds on this CPU (the thesis's: a "
                "GeForce 6800; compare ratios and shapes).")
    log = log or (lambda *a, **k: None)
    log(f"Tipprasert 2006: Tables 5-1, 5-3, 5-4, 5-5 ({'quick' if quick else 'full'}, {TABLE_THREADS} Numba "
        "thread) ...")
    with table_threads():
        rows = measure(meshes, planes, repeats, size, log)
    log("Tipprasert 2006: §6.1 culling, §5.1 at one plane ...")
    with table_threads():
        cull = culling_study(meshes[:2], planes[-1], 2 if quick else 3, size)
    mem1 = one_plane_memory(size)
    log("Tipprasert 2006: eq. 4-3 read two ways, against the exact water reference ...")
    prow, ms, es = placement_study(quick, log)
    plots = plot(rows, out)
    rep = Report(PAPER, tables(rows, note, plots) + [placement_table(prow, ms, es), culling_table(cull, planes[-1]),
                                                     readings(prow, ms)],
                 claims(rows, cull, mem1, prow, planes[-1]))
    rep.seconds = time.perf_counter() - t0
    rep.rows = rows  # the raw measurements (benchmarks/levelmap_tables.py writes them to CSV)
    return rep
