"""Sun et al. (2008): the studies behind the claims, beside Tables 1 and 2 (:mod:`.sun`).

The scenes the tables and studies render (icospheres, the Luneburg lens, the
bundled Fig. 9 scene, a glass sphere over a floor, a graded-index blob), the
timed studies of §5.1, §6 and Table 1's caption (:func:`linear_study`,
:func:`adaptive_study`, :func:`pipeline_study`) and the quality studies of
§4.1, §5.3, §7 and Fig. 6 against the exact reference (:func:`quality_study`).
:mod:`.sun_claims` judges the paper's sentences on what they return.

References
----------
.. [1] X. Sun, K. Zhou, E. Stollnitz, J. Shi, B. Guo, "Interactive
   Relighting of Dynamic Refractive Objects", ACM TOG 27(3), Article 35,
   2008, §4.1, §4.4, §5.1, §5.3, §6, §7, Figs. 6, 9, Table 1.
"""

from __future__ import annotations

import os

import numpy as np

from .common import Table, time_rounds

__all__ = ["PAPER", "luneburg", "icosphere", "render_stats", "fig9_scene", "CAPTION_STAGES", "linear_study",
           "adaptive_study", "pipeline_study", "FIG6_IOR", "PAPER_FIG6", "PAPER_FIG9", "paper_says", "quality_scene",
           "quality_study", "LUNEBURG_TOLERANCES", "LUNEBURG_R", "luneburg_tolerance", "grin_blob", "grin_tolerance",
           "fig9_study"]

PAPER = "Sun et al. 2008"

_SUBDIV = {1280: 3, 5120: 4, 20480: 5, 81920: 6}


def luneburg(N, R=0.8):
    """A Luneburg lens of radius R in the cube [-1, 1]^3: n = sqrt(2 - (r/R)^2) inside, 1 outside.

    Parameters
    ----------
    N : int
        Voxels per axis.
    R : float
        Lens radius, in units of the cube's half side.

    Returns
    -------
    (N, N, N) float64
        Index of refraction at the voxel centres.
    """
    c = (np.arange(N) + 0.5) / N * 2.0 - 1.0
    X, Y, Z = np.meshgrid(c, c, c, indexing="ij")
    r2 = (X ** 2 + Y ** 2 + Z ** 2) / R ** 2
    return np.where(r2 < 1, np.sqrt(np.maximum(2 - r2, 1.0)), 1.0)


def icosphere(tris):
    """An icosphere of radius 0.5 with ``tris`` triangles (1,280, 5,120, 20,480 or 81,920): (vertices, faces)."""
    from ..analytic import icosphere_mesh

    return icosphere_mesh(_SUBDIV[tris], 0.5)


def render_stats(scene, overrides):
    """One volumetric render of ``scene`` with ``overrides``: (its ``stats``, its ``timings_ms``)."""
    import refraction_ref as rr

    r = rr.render(scene, method="volumetric", overrides=overrides)
    return r.meta["stats"], r.meta["timings_ms"]


def fig9_scene():
    """The bundled Fig. 9 scene (``data/volumetric_fig9.json``) as a scene dict, checked by the loader."""
    import refraction_ref as rr

    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return rr.load_scene(os.path.join(here, "data", "volumetric_fig9.json")).data


#: the stages of Table 1's caption: our stage -> the paper's name
CAPTION_STAGES = {"gradient": "gradient generation", "octree": "octree construction",
                  "smooth": "irradiance merging", "view": "viewing pass"}


def linear_study(t1, M, quick, small):
    """§5.1: the march of Table 1's three photon rows timed round by round (the march stage alone).

    Parameters
    ----------
    t1 : list of dict
        Table 1's rows (:func:`.sun.run`'s; ``tris``, ``fit``, ``ph``, stats ``a``, ``scene``).
    M : int
        Initial photons per side of the first row.
    quick : bool
        7 rounds instead of 9.
    small : dict
        Overrides of the timed renders (a tiny camera).

    Returns
    -------
    dict
        ``rounds``, ``march_ms`` (per row, the rounds' march ms) and ``steps`` (per row, photon steps).
    """
    by = {(r["tris"], r["fit"], r["ph"]): r for r in t1}
    ph_rows = [by[(20480, 0.8, m)] for m in (M // 4, M // 2, M)]
    rounds = 7 if quick else 9  # quick: a smoke run of the rule (its single rounds are marked where they straddle)
    fns = [lambda sc=r["scene"]: render_stats(sc, small)[1] for r in ph_rows]
    ms = time_rounds(fns, rounds, warmup=1, sample=lambda t: t["march"])
    return {"rounds": rounds, "march_ms": ms, "steps": [float(r["a"]["photon_steps"]) for r in ph_rows]}


def adaptive_study(N, M):
    """§6: the adaptive march's steps on Table 1's first row against a uniform march counted on the chords.

    No knob marches one voxel everywhere (a constant octree node is crossed in one step whatever eps and eps'
    are), so the baseline is counted: a one-voxel march takes at least ``|end - start| / voxel`` steps per photon
    (the chord; the bent path is longer), for every photon whose end is known (it exited or reached a receiver;
    the others count 0). A lower bound on the baseline: a ratio of the adaptive steps to it is an upper bound on
    the true one.

    Parameters
    ----------
    N, M : int
        Volume resolution and initial photons per side.

    Returns
    -------
    dict
        ``steps`` (adaptive), ``chord_steps`` (one-voxel steps on the chords), ``tiny_eps_steps`` (eps = eps' =
        1e-12), ``ds_min2_steps`` (``volumetric.ds_min = 2``), ``known`` (photons with a known end), ``photons``.
    """
    import refraction_ref as rr

    v, f = icosphere(20480)
    sc = {"camera": {"width": 8, "height": 8}, "objects": [{"mesh": (v * 1.6, f), "fit": None}],
          "lights": [{"type": "directional", "direction": [0.0, -1.0, 0.0]}],
          "volumetric": {"resolution": N, "photons": M, "padding": 0, "bounds": [[-1, -1, -1], [1, 1, 1]]}}
    ra = rr.render(sc, method="volumetric", keep="stages")
    s_ad = ra.meta["stats"]["photon_steps"]
    st = np.asarray(ra["stage.march.photon_status"])
    start = np.asarray(ra["stage.photons.start_pos"])
    end = np.where((st == 5)[:, None], np.asarray(ra["stage.march.hit_pos"]), np.asarray(ra["stage.march.exit_pos"]))
    known = (st == 1) | (st == 5)
    voxel = 2.0 / N
    s_one = float(np.ceil(np.linalg.norm(end[known] - start[known], axis=1) / voxel).sum())
    s_eps = render_stats(sc, {"volumetric.eps": 1e-12, "volumetric.eps2": 1e-12})[0]["photon_steps"]
    s_two = render_stats(sc, {"volumetric.ds_min": 2.0})[0]["photon_steps"]
    return {"steps": s_ad, "chord_steps": s_one, "tiny_eps_steps": s_eps, "ds_min2_steps": s_two,
            "known": int(known.sum()), "photons": len(st)}


def pipeline_study(N, M, cam, quick):
    """Table 1's caption: the four stages at half the resolution and the full one, the view at a quarter of the pixels.

    Parameters
    ----------
    N, M : int
        Volume resolution and initial photons per side.
    cam : dict
        The camera block of the timed renders (``width``, ``height``).
    quick : bool
        2 rounds instead of 3.

    Returns
    -------
    dict
        ``half`` (the lower resolution), ``rounds``, ``stages`` (resolution -> stage -> ms per round) and
        ``view_ms`` (``quarter``, ``full`` -> the viewing pass's ms per round).
    """
    import refraction_ref as rr

    v, f = icosphere(20480)
    half = N // 2

    def scene(n, w, h):
        return {"camera": {"width": w, "height": h}, "objects": [{"mesh": (v * 1.6, f), "fit": None}],
                "lights": [{"type": "directional", "direction": [0.0, -1.0, 0.0]}],
                "volumetric": {"resolution": n, "photons": max(M // 4, 16), "padding": 0,
                               "bounds": [[-1, -1, -1], [1, 1, 1]]}}

    rounds = 2 if quick else 3
    W, H = cam["width"], cam["height"]
    st = {n: {k: [] for k in CAPTION_STAGES} for n in (half, N)}
    for n in (half, N):  # warm-up
        rr.render(scene(n, W, H), method="volumetric")
    for _ in range(rounds):
        for n in (half, N):
            t = rr.render(scene(n, W, H), method="volumetric").meta["timings_ms"]
            for k in CAPTION_STAGES:
                st[n][k].append(t[k])
    ses = rr.Session(scene(N, W, H))
    ses.render("volumetric")
    vt = {k: [] for k in ("quarter", "full")}
    sizes = {"quarter": (W // 2, H // 2), "full": (W, H)}
    for k, (w, h) in sizes.items():  # warm-up of each size
        ses.update({"camera.width": w, "camera.height": h})
        ses.render("volumetric")
    for _ in range(rounds + 2):
        for k, (w, h) in sizes.items():
            ses.update({"camera.width": w, "camera.height": h})
            vt[k].append(ses.render("volumetric").meta["timings_ms"]["view"])
    return {"half": half, "rounds": rounds, "stages": st, "view_ms": vt}


#: Fig. 6's index of refraction ("Two objects with refractive index of 1.1")
FIG6_IOR = 1.1
PAPER_FIG6 = ("Fig. 6 (no numbers): 'Two objects with refractive index of 1.1, as rendered by (a, b) eikonal "
              "rendering; (c, d) our technique; and (e, f) ground-truth ray tracer', compared by eye (size and shape "
              "of the caustics); Table 2 for 6(c): 42,000 photons propagated, 2.8 M steps, 7.90 frames per second; "
              "6(d): 36,000, 2.7 M, 7.88 (640 × 480, 1024 × 1024 photons, 128^3 volume, GeForce 8800 Ultra)")
PAPER_FIG9 = ("Fig. 9 (no numbers): the deformed glass sphere's caustic on the floor at 128^3; §7: 'surface caustics "
              "and shadows become blurred' at the 128^3 limit")


def paper_says(setting):
    """The paper's statement beside one row of the quality table (the paper gives no numbers for these)."""
    if setting.startswith("paper defaults"):
        return "the paper's defaults: blur 9 (§4.1), eps = 0.005 and eps' = 0.02 with an 8-voxel limit (§5.3)"
    if setting in ("blur 7", "blur 11"):
        return "as blur 5's row"
    if setting.startswith("blur"):
        return ("§4.1 (by eye, 128^3, a sphere's refracted background pattern): 'a small improvement' from blur 5 "
                "to 7 to 9, 'no substantial change' at 11; the paper's default is 9")
    if setting.startswith("one tolerance") and "0.005" not in setting:
        return "as the first tolerance row's"
    if setting.startswith("one tolerance"):
        return ("§5.3 (by eye): a slight increase of eps 'may cause many octree nodes to be merged ... dramatically "
                "reduced rendering quality'; the paper uses eps = 0.005 with eps' = 0.02 and an 8-voxel limit")
    if setting.startswith("supersample"):
        return ("§4.1 (by eye): 'the quality of the refracted pattern improves as supersampling is increased, "
                "regardless of which blur kernel is used'; the paper uses 4x4x4")
    if setting.startswith("resolution"):
        return "§7: limited to 128^3, so 'surface caustics and shadows become blurred' (no numbers)"
    if setting.startswith("Fig. 9"):
        return PAPER_FIG9
    return None


def quality_scene(N, M, cmap, ior=1.5):
    """A glass sphere (IOR 1.5, radius 0.8) over a floor in the cube [-1, 1]^3, no medium (the exact reference has
    none), a slanted directional light; ``N``^3 voxels, ``M``^2 photons, ``cmap``^2 caustic map.

    Parameters
    ----------
    N : int
        ``volumetric.resolution``.
    M : int
        ``volumetric.photons`` (texture side per light).
    cmap : int
        Caustic map side in texels.
    ior : float
        The sphere's index (1.5; Fig. 6's objects have 1.1).

    Returns
    -------
    dict
        The scene dict.
    """
    return {"camera": {"width": 8, "height": 8},
            "objects": [{"mesh": "sphere", "fit": 0.8, "material": {"ior": ior}}],
            "lights": [{"type": "directional", "direction": [0.2, -1.0, -0.1]}],
            "receivers": [{"mesh": "plane", "size": [1.9, 1.9], "transform": {"translate": [0.0, -0.9, 0.0]}}],
            "imagespace": {"caustic_map": cmap}, "exact": {"photons": 1024},
            "volumetric": {"resolution": N, "photons": M, "scattering": 0.0, "bounds": [[-1, -1, -1], [1, 1, 1]]}}

def quality_study(quick, log=print):
    """§4.1's blur kernels, §5.3's tolerance and §7's resolution, judged on the caustic map against the exact reference.

    Quality claims are judged by error against the exact caustics reference
    (:mod:`refraction_ref.exact.pipeline`, 1024^2 jittered photons), never by
    time: the relative L1 of the receiver's caustic map, both blurred by one
    texel. Quick: 32^3 and 64^3, 128^2 photons, a 64^2 map; full: 128^3 and
    256^3, 512^2 photons, a 128^2 map. Not timed: rendered on every Numba thread.

    Parameters
    ----------
    quick : bool
        Quick (CI smoke) sizes.
    log : callable or None
        Receives progress lines.

    Returns
    -------
    table : Table
        Relative L1 of each run's caustic map against the exact reference.
    measured : dict
        ``rel_l1`` (setting -> rel L1), ``runs`` (setting -> (rel L1, photon steps)), ``defaults`` (the paper
        defaults' setting), ``fig6`` ((rel L1, steps) at Fig. 6's index), ``fig9`` (:func:`fig9_study`), ``lun``
        (:func:`luneburg_tolerance`), ``blob`` (:func:`grin_tolerance`), ``N`` and ``blob_n`` (the blob's side).

    References
    ----------
    Sun et al. (2008), §4.1, §5.3, §7.
    """
    import numba

    import refraction_ref as rr

    from ..metrics import relative_l1

    N, M, cmap = (32, 128, 64) if quick else (128, 512, 128)
    sc = quality_scene(N, M, cmap)
    if quick:  # the smoke run's exact references: a quarter of the photons
        sc["exact"]["photons"] = 512
    before = numba.get_num_threads()
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    try:
        ex = rr.render(sc, method="exact").arrays["caustic_map_0"]
        sc11 = dict(quality_scene(N, M, cmap, ior=FIG6_IOR), exact=dict(sc["exact"]))
        ex11 = rr.render(sc11, method="exact").arrays["caustic_map_0"]
        r11 = rr.render(sc11, method="volumetric")
        fig6 = (relative_l1(r11.arrays["caustic_map_0"], ex11, blur=1.0), int(r11.meta["stats"]["photon_steps"]))
        log(f"  IOR {FIG6_IOR} (Fig. 6): rel L1 {fig6[0]:.4f}, {fig6[1]:,} steps")
        runs = [("paper defaults (blur 9, eps 0.005, eps' 0.02)", {}),
                ("blur 5", {"volumetric.blur": 5}), ("blur 7", {"volumetric.blur": 7}),
                ("blur 11", {"volumetric.blur": 11}),
                ("one tolerance eps = eps' = 0.005", {"volumetric.eps": 0.005, "volumetric.eps2": 0.005}),
                ("one tolerance eps = eps' = 0.02 (4x)", {"volumetric.eps": 0.02, "volumetric.eps2": 0.02}),
                ("one tolerance eps = eps' = 0.08 (16x)", {"volumetric.eps": 0.08, "volumetric.eps2": 0.08}),
                (f"resolution {2 * N}^3", {"volumetric.resolution": 2 * N}),
                ("supersample 1, blur 9", {"volumetric.supersample": 1}),
                ("supersample 2, blur 9", {"volumetric.supersample": 2}),
                ("supersample 1, blur 5", {"volumetric.supersample": 1, "volumetric.blur": 5}),
                ("supersample 2, blur 5", {"volumetric.supersample": 2, "volumetric.blur": 5})]
        res = {}
        for name, o in runs:
            r = rr.render(sc, method="volumetric", overrides=o)
            res[name] = (relative_l1(r.arrays["caustic_map_0"], ex, blur=1.0), int(r.meta["stats"]["photon_steps"]))
            log(f"  {name}: rel L1 {res[name][0]:.4f}, {res[name][1]:,} steps")
        fig9 = fig9_study(N, M, cmap, log)
        lun = luneburg_tolerance(N, 64 if quick else 256, log)
        blob = grin_tolerance(*((16, 32, 32) if quick else (64, 128, 64)), log)
    finally:
        numba.set_num_threads(before)
    e = {k: v[0] for k, v in res.items()}
    d = runs[0][0]
    table = Table(
        key="sun_quality", title="Caustic accuracy against the exact reference: blur kernel, tolerance, resolution",
        columns=["setting", "volume", "ours rel L1 vs exact", "ours photon steps", "paper (what it shows)"],
        rows=[[k, f"{2 * N}^3" if k.startswith("resolution") else f"{N}^3", round(v[0], 4), v[1], paper_says(k)]
              for k, v in res.items()]
        + [[f"IOR {FIG6_IOR} (Fig. 6's index), paper defaults", f"{N}^3", round(fig6[0], 4), fig6[1], PAPER_FIG6]]
        + [["Fig. 9 scene, no medium, paper defaults", f"{n}^3", round(v[0], 4), v[1], PAPER_FIG9]
           for n, v in fig9.items()]
        + [[f"Luneburg lens, {k}: focus miss median (p90) in voxels, not rel L1", f"{N}^3",
            f"{v['median']:.3f} ({v['p90']:.3f})", v["steps"],
            "§5.3 (by eye, no numbers): the tolerance's effect on 'some volumetric data'"] for k, v in lun.items()]
        + [[f"GRIN blob, {k}: caustic rel L1 against the converged graded-index reference", "16^3" if quick else
            "64^3", round(v["rel_l1"], 4), v["steps"], "§5.3 (by eye, no numbers)"] for k, v in blob.items()],
        note=(f"A glass sphere (IOR 1.5, radius 0.8) over a floor, no participating medium (the exact reference "
              f"has none), light (0.2, -1, -0.1); {N}^3 volume, {M}^2 photons, 4^3 supersampling, a {cmap}^2 caustic "
              "map against the exact reference's (1024^2 jittered photons); rel L1 of both maps blurred by one "
              "texel. The paper chose its blur on a sphere's refracted background pattern at 128^3 and its "
              "tolerance and resolution by eye; the caustic map against an exact reference is our stand-in. The IOR "
              f"{FIG6_IOR} row: the same sphere at Fig. 6's index against the exact reference at that index (the "
              "paper's ground-truth ray tracer); we have no eikonal renderer. The Fig. 9 rows: the bundled Fig. 9 "
              "scene (data/volumetric_fig9.json, the deformed sphere over its floor) with its scattering medium "
              "removed (volumetric.scattering = 0: the exact reference has no medium, and with it the map's flux "
              "is 0.77 of the exact one's), the same photons and map, against the exact reference of that scene."))
    return table, {"rel_l1": e, "runs": res, "defaults": d, "fig6": fig6, "fig9": fig9, "lun": lun, "blob": blob,
                   "N": N, "blob_n": 16 if quick else 64}


#: §5.3 on a graded volume: the settings of the Luneburg lens study (label, overrides)
LUNEBURG_TOLERANCES = (("paper defaults (eps 0.005, eps' 0.02, 8-voxel limit)", {}),
                       ("one tolerance eps = eps' = 0.005", {"volumetric.eps": 0.005, "volumetric.eps2": 0.005}),
                       ("one tolerance eps = eps' = 0.02 (4x)", {"volumetric.eps": 0.02, "volumetric.eps2": 0.02}),
                       ("one tolerance eps = eps' = 0.08 (16x)", {"volumetric.eps": 0.08, "volumetric.eps2": 0.08}))
#: the lens's radius in the Luneburg study (the cube's half side is 1)
LUNEBURG_R = 0.8


def luneburg_tolerance(N, M, log=print):
    """§5.3 on a graded-index volume: photons through a Luneburg lens against its closed-form focus, by tolerance.

    A directional light along -z over the lens ``n = sqrt(2 - r^2 / R^2)`` (R 0.8 in the cube [-1, 1]^3,
    :func:`luneburg`): every ray that meets the lens leaves it through the focus ``F = (0, 0, -R)``
    (:func:`~refraction_ref.analytic.luneburg_lens`). Per setting the photons that start within 0.7 R of the
    axis and exit are measured by the distance, in voxels, from ``F`` to their exit line.

    Parameters
    ----------
    N : int
        Voxels per axis.
    M : int
        Photons per side of the light's texture.
    log : callable or None

    Returns
    -------
    dict
        Label of :data:`LUNEBURG_TOLERANCES` -> ``median`` and ``p90`` miss (voxels), ``photons`` measured,
        ``steps``.
    """
    import refraction_ref as rr

    sc = {"camera": {"width": 8, "height": 8}, "objects": [],
          "lights": [{"type": "directional", "direction": [0.0, 0.0, -1.0]}],
          "volume": {"ior": luneburg(N, LUNEBURG_R), "bounds": [[-1, -1, -1], [1, 1, 1]]},
          "volumetric": {"resolution": N, "photons": M}}
    F = np.array([0.0, 0.0, -LUNEBURG_R])
    out = {}
    for label, o in LUNEBURG_TOLERANCES:
        r = rr.render(sc, method="volumetric", overrides=o, keep="stages")
        st = np.asarray(r["photon_status"])
        start = np.asarray(r["stage.photons.start_pos"])
        sel = (st == 1) & (np.hypot(start[:, 0], start[:, 1]) < 0.7 * LUNEBURG_R)
        p, d = np.asarray(r["photon_exit_pos"])[sel], np.asarray(r["photon_exit_dir"])[sel]
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        w = F - p
        miss = np.linalg.norm(w - np.sum(w * d, axis=1)[:, None] * d, axis=1) / (2.0 / N)
        out[label] = {"median": float(np.median(miss)), "p90": float(np.percentile(miss, 90)),
                      "photons": int(sel.sum()), "steps": int(r.meta["stats"]["photon_steps"])}
        if log:
            log(f"  Luneburg {N}^3, {label}: miss median {out[label]['median']:.2f}, p90 {out[label]['p90']:.2f} "
                f"voxels, {out[label]['steps']:,} steps")
    return out


def grin_blob(N):
    """A smooth asymmetric graded-index blob in [-1, 1]^3 at ``N``^3 voxel centres.

    Two Gaussian bumps of index (+0.4, sigma 0.25; +0.25, sigma 0.18), off centre: the ``blob`` of
    ``benchmarks/grin_error_vs_time.py``.

    Parameters
    ----------
    N : int

    Returns
    -------
    (N, N, N) float64
    """
    c = (np.arange(N) + 0.5) / N * 2.0 - 1.0
    X, Y, Z = np.meshgrid(c, c, c, indexing="ij")

    def bump(cx, cy, cz, sd):
        return np.exp(-((X - cx) ** 2 + (Y - cy) ** 2 + (Z - cz) ** 2) / (2 * sd * sd))

    return 1.0 + 0.4 * bump(-0.15, 0.1, 0.0, 0.25) + 0.25 * bump(0.3, -0.25, 0.15, 0.18)


def grin_tolerance(N, M, cmap, log=print):
    """§5.3 on a graded volume against the converged reference: the blob's floor caustic by tolerance.

    The blob (:func:`grin_blob`) under a sun from above, a floor below the box; the converged graded-index
    reference (``--method exact`` on a volume scene, :mod:`refraction_ref.exact.grin`: DOP853 on the method's own
    field and photons) against the volumetric method with :data:`LUNEBURG_TOLERANCES`' settings.

    Parameters
    ----------
    N, M, cmap : int
        Volume side, photons per side, caustic map side.
    log : callable or None

    Returns
    -------
    dict
        Label -> ``rel_l1`` (the floor's caustic map against the reference, both blurred one texel), ``pos``
        (median photon exit error, voxels, photons exiting in both), ``steps``.
    """
    import refraction_ref as rr

    from ..metrics import relative_l1

    sc = {"camera": {"width": 8, "height": 8}, "objects": [],
          "volume": {"ior": grin_blob(N), "bounds": [[-1, -1, -1], [1, 1, 1]]},
          "lights": [{"type": "directional", "direction": [0.0, -1.0, 0.0]}],
          "receivers": [{"mesh": "plane", "size": [2.4, 2.4], "transform": {"translate": [0.0, -1.2, 0.0]}}],
          "caustics": {"map_size": cmap}, "volumetric": {"photons": M}}
    ref = rr.render(sc, method="exact").arrays
    out = {}
    for label, o in LUNEBURG_TOLERANCES:
        a = rr.render(sc, method="volumetric", overrides=o)
        both = (np.asarray(a["photon_status"]) == 1) & (np.asarray(ref["photon_status"]) == 1)
        dp = np.linalg.norm(np.asarray(a["photon_exit_pos"])[both] - np.asarray(ref["photon_exit_pos"])[both],
                            axis=1) / (2.0 / N)
        out[label] = {"rel_l1": float(relative_l1(a.arrays["caustic_map_0"], ref["caustic_map_0"], blur=1.0)),
                      "pos": float(np.median(dp)) if dp.size else float("nan"),
                      "steps": int(a.meta["stats"]["photon_steps"])}
        if log:
            log(f"  GRIN blob {N}^3, {label}: caustic rel L1 {out[label]['rel_l1']:.4f} against the converged "
                f"reference, exits {out[label]['pos']:.2f} voxels, {out[label]['steps']:,} steps")
    return out


def fig9_study(N, M, cmap, log=print):
    """§7 on the paper's Fig. 9 scene: its caustic at ``N``^3 and ``2N``^3 against the exact reference, no medium.

    The bundled scene carries a scattering medium (0.2) that the exact
    reference does not model, so both sides drop it here; the camera is
    shrunk (only the floor's caustic map is compared).

    Parameters
    ----------
    N : int
        The lower volume resolution (the paper's 128 in the full run).
    M : int
        ``volumetric.photons`` (texture side).
    cmap : int
        Caustic map side in texels.
    log : callable or None
        Receives progress lines.

    Returns
    -------
    dict
        ``{resolution: (rel L1 against the exact reference, photon steps)}`` for ``N`` and ``2 * N``.

    References
    ----------
    Sun et al. (2008), §7, Fig. 9.
    """
    import refraction_ref as rr

    from ..metrics import relative_l1

    scene = fig9_scene()
    common = {"camera.width": 8, "camera.height": 8, "caustics.map_size": cmap}
    ex = rr.render(scene, method="exact", overrides=common).arrays["caustic_map_0"]
    out = {}
    for n in (N, 2 * N):
        r = rr.render(scene, method="volumetric", overrides=dict(
            common, **{"volumetric.scattering": 0.0, "volumetric.resolution": n, "volumetric.photons": M}))
        out[n] = (relative_l1(r.arrays["caustic_map_0"], ex, blur=1.0), int(r.meta["stats"]["photon_steps"]))
        if log:
            log(f"  Fig. 9 scene, no medium, {n}^3: rel L1 {out[n][0]:.4f}, {out[n][1]:,} steps")
    return out
