"""Chaudhari (2008) §3.5 and §3.7 measured against the exact reference, for ``refraction-ref tables``.

Two studies, each on the built-in bunny (the default scene's camera, IOR
1.2) and a glass sphere (``mesh: sphere``, IOR 1.5, eye at distance 3),
against the exact mesh reference (``render(scene, method="exact")``):

- :func:`normals_study` (§3.5, Fig. 3.4): the error of the normal the trace
  used at the front surface, and of the exit direction, for eq. 3.1
  (``normals=forward``), eq. 3.2 with ``delta`` 1, 2, 3, and the 3x3 mesh.
  The normal at the front surface is recovered from the first refraction:
  both methods refract the same primary ray at a surface point along it, and
  the refracted direction ``w`` of a unit ray ``v`` (ratio ``eta = n1/n2``)
  satisfies ``eta v - w`` parallel to the normal, so the angle between the
  two methods' ``eta v - w`` lines is the angle between the normals they used.
- :func:`bounds_study` (§3.7): the thesis's tight per-layer bound (the MIP
  max-reduction, ``bounds=mip``) against the loose bound the thesis would
  have without the reduction (§3.6: "The search is restricted up to the
  point E with z = Z_max, where Z_max is the maximum depth of the object",
  the object's largest depth for every layer), over binary-search
  iterations; the frame of each timed round by round; and how many
  interface searches a ray needed.

The loose bound is not a scene knob: :func:`layered` runs the image-space
passes of :mod:`refraction_ref.imagespace.pipeline` by hand, with the
reduction replaced by the object's depth maximum (and no reduction pass).
With the tight bound it reproduces the renderer's trace bit for bit.

References
----------
Chaudhari, K. (2008). *Real-Time Multiple Refractions Through Deformable
Objects*. MSc thesis, UMBC. §3.5 (eqs. 3.1, 3.2, Fig. 3.4), §3.6, §3.7, §4.2.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

__all__ = ["SCENES", "NORMAL_OPTIONS", "study_scene", "PreparedScene", "front_normal_error", "roughness",
           "normals_study", "layered", "bounds_study"]

#: pixels from the silhouette (the reference's hit mask's edge) that count as "at the silhouettes" (Fig. 3.4)
SILHOUETTE = 2

#: scene name -> (scene dict without the camera size, IOR)
SCENES = {
    "bunny": ({"receivers": [], "objects": [{"mesh": "bunny", "fit": 1.0, "material": {"ior": 1.2}}]}, 1.2),
    "sphere": ({"camera": {"eye": [0.0, 0.0, 3.0]}, "receivers": [],
                "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.5}}]}, 1.5),
}

#: §3.5's estimators as imagespace knob overrides (label, overrides)
NORMAL_OPTIONS = (("forward (eq. 3.1)", {"normals": "forward"}),
                  ("central delta=1", {"normals": "central", "delta": 1}),
                  ("central delta=2 (thesis)", {"normals": "central", "delta": 2}),
                  ("central delta=3", {"normals": "central", "delta": 3}),
                  ("mesh3x3 (Fig. 3.4)", {"normals": "mesh3x3"}))


def study_scene(name, res):
    """One scene of the studies (:data:`SCENES`) at ``res``^2 pixels: (scene dict, IOR).

    Parameters
    ----------
    name : str
        A key of :data:`SCENES`.
    res : int
        Image side in pixels.

    Returns
    -------
    (dict, float)
    """
    import copy

    d, ior = SCENES[name]
    d = copy.deepcopy(d)
    d.setdefault("camera", {}).update({"width": int(res), "height": int(res)})
    return d, ior


def front_normal_error(a, b, eta):
    """Per-pixel angle (degrees) between the front-surface normals two runs refracted with.

    Parameters
    ----------
    a, b : mapping
        Runs of one scene and camera with ``record >= 1`` (``path_dir``, (H, W, K, 3), or the stage buffer
        ``stage.trace.path_dir`` of ``render(..., keep="trace")``) and ``ray_dir``.
    eta : float
        ``outside_ior / ior`` at the front surface.

    Returns
    -------
    (H, W) float64
        NaN where either run has no first refraction.
    """
    v = np.asarray(a["ray_dir"], np.float64)
    out = []
    for r in (a, b):
        w = np.asarray(r["path_dir"] if "path_dir" in r else r["stage.trace.path_dir"], np.float64)[..., 0, :]
        n = eta * v - w  # parallel to the normal at the first refraction (Snell's law in vector form)
        out.append(n / np.linalg.norm(n, axis=-1, keepdims=True))
    c = np.abs(np.sum(out[0] * out[1], axis=-1))  # lines, not orientations
    return np.degrees(np.arccos(np.clip(c, 0.0, 1.0)))


def roughness(err):
    """Mean absolute difference of an error map between 4-neighbour pixels where both are finite.

    Parameters
    ----------
    err : (H, W) float
        Per-pixel error map (degrees), NaN where undefined.

    Returns
    -------
    float
        Mean absolute neighbour difference; NaN when no pair is finite.
    """
    d = []
    for x, y in ((err[:, 1:], err[:, :-1]), (err[1:, :], err[:-1, :])):
        ok = np.isfinite(x) & np.isfinite(y)
        d.append(np.abs(x[ok] - y[ok]))
    d = np.concatenate(d)
    return float(d.mean()) if d.size else float("nan")


def _stats(x):
    x = x[np.isfinite(x)]
    if not x.size:
        return float("nan"), float("nan")
    return float(np.median(x)), float(np.percentile(x, 90))


def normals_study(res=128, scenes=("bunny", "sphere"), log=None):
    """§3.5: front-normal and exit-direction error against the exact reference for each estimator.

    Parameters
    ----------
    res : int
        Image side in pixels.
    scenes : sequence of str
        Keys of :data:`SCENES` (``'bunny'``, ``'sphere'``).
    log : callable, optional
        Receives one line per scene and estimator.

    Returns
    -------
    list of dict
        ``scene``, ``option``, ``normal_median``, ``normal_p90`` (degrees,
        front surface), ``roughness`` (:func:`roughness` of the normal-error
        map), ``exit_median``, ``exit_p90`` (degrees, pixels where both
        exit), ``exit`` (fraction of hit pixels exiting), ``pixels``,
        ``sil_median`` and ``int_median`` (the front-normal median within
        :data:`SILHOUETTE` pixels of the silhouette and inside).
    """
    from scipy.ndimage import binary_erosion

    from ..render import render
    from .chaudhari import exit_error

    rows = []
    for name in scenes:
        d, ior = study_scene(name, res)
        ex = render(d, method="exact", overrides={"exact.record": 1}, keep="trace")
        hit = np.asarray(ex["hit"], bool)
        band = hit & ~binary_erosion(hit, iterations=SILHOUETTE, border_value=0)  # Fig. 3.4's silhouettes
        for label, ov in NORMAL_OPTIONS:
            r = render(d, overrides={"imagespace.record": 1, **{f"imagespace.{k}": v for k, v in ov.items()}},
                       keep="trace")
            err = front_normal_error(r.arrays, ex.arrays, 1.0 / ior)
            err[~hit] = np.nan
            e = exit_error(r.arrays, ex.arrays)
            m, p = _stats(err)
            rows.append({"scene": name, "option": label, "normal_median": m, "normal_p90": p,
                         "roughness": roughness(err), "exit_median": e["median"], "exit_p90": e["p90"],
                         "exit": e["exit"], "pixels": int(np.count_nonzero(np.isfinite(err))),
                         "sil_median": _stats(np.where(band, err, np.nan))[0],
                         "int_median": _stats(np.where(hit & ~band, err, np.nan))[0]})
            if log:
                log(f"  {name} {label}: normal median {m:.2f} p90 {p:.2f} deg, roughness {rows[-1]['roughness']:.2f}, "
                    f"exit median {e['median']:.2f} p90 {e['p90']:.2f} deg")
    return rows


class PreparedScene:
    """The passes of one view up to the peel, run once (the bounds and iterations vary after them)."""

    def __init__(self, scene_dict):
        from ..camera import Camera
        from ..meshes import scene_geometry
        from ..scene import load_scene
        from ..imagespace.pipeline import check_materials

        self.scene = load_scene(scene_dict)
        self.p = dict(self.scene.data["imagespace"])
        self.geom = scene_geometry(self.scene)
        self.ior = check_materials(self.geom)[0]
        self.outside = float(self.scene.data["outside_ior"])
        self.cam = Camera.from_dict(self.scene.data["camera"])
        self._passes = None

    def passes(self):
        """minmax, voxelize and peel of this view, run on the first call only (deterministic)."""
        if self._passes is None:
            self._passes = run_passes(self)
        return self._passes


def run_passes(prep):
    """The passes before the search bound: minmax, voxelize, peel (§3.3-3.4).

    Parameters
    ----------
    prep : PreparedScene
        One view's loaded scene, knobs, geometry and camera.

    Returns
    -------
    minmax, voxels, peeled
        The outputs of :func:`~refraction_ref.imagespace.pipeline.pass_minmax`,
        ``pass_voxelize`` and ``pass_peel``.
    """
    from ..imagespace import pipeline as P

    minmax = P.pass_minmax(prep.geom, prep.cam, prep.p)
    voxels = P.pass_voxelize(minmax, prep.cam, prep.p)
    return minmax, voxels, P.pass_peel(voxels, prep.cam.shape, prep.p)


def layered(prep, bound="tight", iterations=5, timings=None):
    """The image-space passes of one view with the tight (MIP) or loose (object Zmax) search bound.

    ``tight`` is the renderer's own reduction (``bounds=mip``, §3.7);
    ``global`` its exact per-layer maxima; ``loose`` skips the reduction and
    bounds every layer's search by the object's largest depth (§3.6's E).

    Parameters
    ----------
    prep : PreparedScene
        One view's loaded scene, knobs, geometry and camera.
    bound : {'tight', 'global', 'loose'}
        The search bound.
    iterations : int
        Binary-search iterations (``imagespace.iterations``).
    timings : dict, optional
        When given, every pass is run again and timed; ``passes``, ``reduce``,
        ``trace`` and ``frame`` (ms) are written into it.

    Returns
    -------
    dict
        :func:`~refraction_ref.imagespace.trace.trace_layers`'s output (world space).
    """
    from ..imagespace import pipeline as P

    p = dict(prep.p, iterations=int(iterations))
    tic = time.perf_counter
    t = {}
    t0 = tic()
    # a timed frame runs every pass; an untimed one reuses the view's passes before the bound
    minmax, voxels, peeled = run_passes(prep) if timings is not None else prep.passes()
    t["passes"] = (tic() - t0) * 1e3
    t0 = tic()
    if bound == "loose":
        L = peeled.ldi.shape[0]
        bounds = P.Bounds(np.full(L, minmax.gmax), np.full(L, minmax.gmin),
                          "the object's largest depth bounds every layer")
    else:
        bounds = P.pass_reduce(minmax, peeled, dict(p, bounds="global" if bound == "global" else "mip"))
    t["reduce"] = (tic() - t0) * 1e3
    t0 = tic()
    traced = P.pass_trace(minmax, voxels, peeled, bounds, prep.cam, P.trace_knobs(p), (prep.ior, prep.outside))
    t["trace"] = (tic() - t0) * 1e3
    if timings is not None:
        timings.update(t, frame=sum(t.values()))
    return traced


#: binary-search iterations tried with the loose bound for "similar output": fewer than the tight search's 5 too, the
#: only counts at which avoiding the reduction could gain (with 5 or more the loose run does at least the tight
#: run's work less the reduction)
LOOSE_ITERATIONS = (1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 16)
#: §3.7's tight bound is judged where it can differ from the loose one: pixels whose exact path crosses more than
#: two interfaces (for the first back face of a two-interface path the layer's maximum is the object's)
MULTI = 2


def _similar(e, ref):
    """The loose search's output is similar to the tight one's: median and p90 exit error within 5 %."""
    return e["median"] <= 1.05 * ref["median"] + 1e-9 and e["p90"] <= 1.05 * ref["p90"] + 1e-9


def bounds_study(res=128, scenes=("bunny", "sphere"), rounds=5, log=None):
    """§3.7: error against the exact reference by bound and iterations, the tight/loose frame ratio, the searches.

    Parameters
    ----------
    res : int
        Image side in pixels.
    scenes : sequence of str
        Keys of :data:`SCENES`.
    rounds : int
        Timed rounds of the tight and loose frames.
    log : callable, optional
        Receives progress lines.

    Returns
    -------
    dict
        ``rows``: per scene, bound and iterations :func:`.chaudhari.exit_error`'s
        median, p90 and exit fraction; ``timing``: per scene the loose
        iterations ``n_loose`` found similar (None if none up to 16) and
        the per-round frame ratio loose(n) / tight(5) (median, low, high);
        ``searches``: per scene the fractions of hit pixels that exit after
        one back-face search (``interfaces == 2``) and after more;
        ``multi``: per scene the pixels whose exact path crosses more than
        :data:`MULTI` interfaces (``pixels``) and, on them, the median and
        p90 exit error per (bound, iterations) of the tight, global and loose
        bounds at 1, 5 and 16 iterations.
    """
    from ..render import render
    from .chaudhari import exit_error

    rows, timing, searches, multi = [], {}, {}, {}
    for name in scenes:
        d, _ = study_scene(name, res)
        ex = render(d, method="exact")
        prep = PreparedScene(d)
        ray = ex.arrays
        many = np.asarray(ray["hit"], bool) & (np.asarray(ray["interfaces"]) > MULTI)
        sub = dict(ray, hit=many)
        multi[name] = {"pixels": int(many.sum())}
        errs = {}
        for bound, its in ([("tight", n) for n in (1, 5, 16)] + [("global", n) for n in (5, 16)]
                           + [("loose", n) for n in LOOSE_ITERATIONS]):
            tr = layered(prep, bound, its)
            got = {"status": tr["status"], "exit_dir": tr["exit_dir"]}
            e = exit_error(got, ray)
            errs[(bound, its)] = e
            if (bound, its) in (("tight", 1), ("tight", 5), ("tight", 16), ("global", 5), ("loose", 5),
                                ("loose", 16)) and many.any():
                m = exit_error(got, sub)
                multi[name][(bound, its)] = {"median": m["median"], "p90": m["p90"], "exit": m["exit"]}
            rows.append({"scene": name, "bound": bound, "iterations": its, "median": e["median"], "p90": e["p90"],
                         "exit": e["exit"]})
            if bound == "tight" and its == 5:
                hit = np.asarray(ray["hit"], bool)
                st, nif = np.asarray(tr["status"])[hit], np.asarray(tr["interfaces"])[hit]
                n = max(1, int(hit.sum()))
                searches[name] = {"one": float(np.count_nonzero((st == 1) & (nif <= 2))) / n,
                                  "more": float(np.count_nonzero((st == 1) & (nif > 2))) / n,
                                  "stopped": float(np.count_nonzero(st != 1)) / n,
                                  "exact_one": float(np.count_nonzero((np.asarray(ray["status"])[hit] == 1)
                                                                      & (np.asarray(ray["interfaces"])[hit] <= 2))) / n}
        ref = errs[("tight", 5)]
        n_loose = next((n for n in LOOSE_ITERATIONS if _similar(errs[("loose", n)], ref)), None)
        if n_loose is not None:
            for _ in range(2):  # warm-up
                layered(prep, "tight", 5)
                layered(prep, "loose", n_loose)
            rs, ft, fl, sh = [], [], [], []
            for _ in range(max(1, int(rounds))):
                a, b = {}, {}
                layered(prep, "tight", 5, a)
                layered(prep, "loose", n_loose, b)
                rs.append(b["frame"] / a["frame"])
                ft.append(a["frame"])
                fl.append(b["frame"])
                sh.append(a["reduce"] / a["frame"])
            timing[name] = {"n_loose": n_loose, "ratio": (statistics.median(rs), min(rs), max(rs)),
                            "tight_ms": statistics.median(ft), "loose_ms": statistics.median(fl), "rounds": len(rs),
                            "reduce_share": statistics.median(sh)}
        else:
            timing[name] = {"n_loose": None}
        if log:
            log(f"  {name}: tight-5 p90 {ref['p90']:.2f}, loose-5 p90 {errs[('loose', 5)]['p90']:.2f} deg; "
                f"loose iterations for similar output: {n_loose}")
    return {"rows": rows, "timing": timing, "searches": searches, "multi": multi}
