"""Chaudhari (2008): the models of the tables (the low-poly bunny, two bunnies, nested shells) and their timing.

The rows of Tables 4.1 and 4.2 we have meshes for (:func:`models`: the
built-in bunny, a decimated "Bunny-lowpoly", two bunnies, Igea), the
depth-complexity study's nested spheres (:func:`shell_models`), and the
frames timed round by round (:func:`time_frames`) whose per-round ratios
(:func:`ratio`, :func:`fps_ratio`) the claims read.

References
----------
Chaudhari, K. (2008). *Real-Time Multiple Refractions Through Deformable
Objects*. MSc thesis, UMBC. §4.1, §4.2 (performance), Tables 4.1 and 4.2.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from . import chaudhari as T
from .common import ratio_spread
from .tipprasert_scenes import uv_sphere

__all__ = ["PAPER", "IOR", "LOWPOLY_FACES", "TWO_BUNNY_DISTANCE", "SHELL_TRIANGLES", "decimate", "lowpoly_bunny",
           "models", "shell_models", "interleaved_timer", "time_frames", "ratio", "fps_ratio"]

PAPER = "Chaudhari 2008"
IOR = 1.2  # the thesis's glass in its figures (Fig. 4.3)
LOWPOLY_FACES = 15000  # Table 4.1 "Bunny-lowpoly"
TWO_BUNNY_DISTANCE = 4.8  # eye to target that frames both bunnies at fov_y 30


# --------------------------------------------------------------------------- the low-poly bunny
def _cluster(v, f, cell):
    lo = v.min(axis=0)
    key = np.floor((v - lo) / cell).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    n = int(inv.max()) + 1
    cnt = np.bincount(inv, minlength=n).astype(np.float64)
    nv = np.stack([np.bincount(inv, weights=v[:, k], minlength=n) / cnt for k in range(3)], axis=1)
    nf = inv[f]
    ok = (nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])
    nf = nf[ok]
    _, keep = np.unique(np.sort(nf, axis=1), axis=0, return_index=True)  # drop duplicate triangles
    nf = nf[np.sort(keep)]
    used = np.unique(nf)
    remap = np.full(n, -1, np.int64)
    remap[used] = np.arange(len(used))
    return nv[used], remap[nf]


def decimate(v, f, target):
    """A mesh reduced to about ``target`` triangles.

    trimesh's quadric decimation where the optional ``fast-simplification``
    package is installed (``pip install .[bench]``), else vertex clustering on
    a uniform grid whose cell size is bisected to land within 2 % of ``target``.

    Parameters
    ----------
    v : (V, 3) array_like
        Vertices.
    f : (F, 3) array_like of int
        Triangles.
    target : int
        Triangles wanted.

    Returns
    -------
    (vertices, faces, method) : (ndarray, ndarray, str)
        ``method`` is ``"quadric"`` or ``"cluster"``.
    """
    # writable C-ordered copies: the package's meshes are read-only views, which fast-simplification refuses
    v = np.array(v, np.float64, order="C")
    f = np.array(f, np.int64, order="C")
    try:
        import fast_simplification  # noqa: F401  (trimesh's quadric decimation needs it)
        import trimesh

        d = trimesh.Trimesh(v, f, process=False).simplify_quadric_decimation(face_count=int(target))
        return np.asarray(d.vertices, np.float64), np.asarray(d.faces, np.int64), "quadric"
    except ImportError:
        pass
    ext = float(np.max(v.max(axis=0) - v.min(axis=0)))
    lo, hi = ext * 1e-4, ext * 0.2  # small cell -> many faces, large cell -> few
    best = (v, f)
    for _ in range(30):
        cell = np.sqrt(lo * hi)
        nv, nf = _cluster(v, f, cell)
        best = (nv, nf) if abs(len(nf) - target) < abs(len(best[1]) - target) else best
        if abs(len(nf) - target) <= 0.02 * target:
            break
        if len(nf) > target:
            lo = cell
        else:
            hi = cell
    return best[0], best[1], "cluster"


_LOWPOLY = {}


def lowpoly_bunny(target=LOWPOLY_FACES):
    """The built-in bunny decimated to about ``target`` triangles, in memory (nothing is written to disk).

    Parameters
    ----------
    target : int
        Triangles wanted (default :data:`LOWPOLY_FACES`); the result is kept
        per target.

    Returns
    -------
    ((vertices, faces), method)
        A mesh a scene's ``objects[].mesh`` accepts, and :func:`decimate`'s method.
    """
    if target not in _LOWPOLY:
        from ..meshes import load_mesh

        v, f = load_mesh("bunny")
        nv, nf, method = decimate(v, f, target)
        nv.setflags(write=False)
        nf.setflags(write=False)
        _LOWPOLY[target] = ((nv, nf), method)
    return _LOWPOLY[target]


def _obj(mesh, translate=(0.0, 0.0, 0.0), fit=1.0, scale=1.0):
    return {"mesh": mesh, "fit": fit,
            "transform": {"scale": float(scale), "rotate": [0.0, 0.0, 0.0], "translate": list(map(float, translate))},
            "material": {"ior": IOR, "absorption": [0.0, 0.0, 0.0]}}


def models(quick=False):
    """Row name -> :class:`.chaudhari.Model` for every row we have meshes for, and the decimation used.

    Table 4.1's rows (``Bunny-lowpoly``, ``Bunny I``, ``Bunny and Bunny``,
    ``Igea``, each at its own framing) and Table 4.2's scenes ``I-A``,
    ``II-A``, ``II-B`` (with ``I-B`` = ``Bunny and Bunny``), all four at the
    two bunnies' framing (:data:`TWO_BUNNY_DISTANCE`): one bunny against two
    is compared with one camera, as the thesis's Table 4.2 films one scene.
    ``quick`` is accepted for symmetry: quick runs keep every row and shrink
    only sizes and repeats.

    Parameters
    ----------
    quick : bool
        Accepted and ignored (see above).

    Returns
    -------
    dict
        Row name -> :class:`.chaudhari.Model`.
    str
        The decimation method of the low-poly bunny (:func:`decimate`).
    """
    low, method = lowpoly_bunny()
    out = {"Bunny-lowpoly": T.Model([_obj(low)], 2.6, f"bunny decimated to {LOWPOLY_FACES:,} ({method})"),
           "Bunny I": T.Model([_obj("bunny")], 2.6, "the bunny, 69,451")}
    out["Bunny and Bunny"] = T.Model([_obj(low, (-0.55, 0, 0)), _obj(low, (0.55, 0, 0))], TWO_BUNNY_DISTANCE,
                                     f"two decimated bunnies, 2 x {LOWPOLY_FACES:,}")
    out["Igea"] = T.Model([_obj("igea")], 2.6, "Igea, 268,686")
    out["I-A"] = T.Model([_obj("bunny", (-0.55, 0, 0)), _obj("bunny", (0.55, 0, 0))], TWO_BUNNY_DISTANCE,
                         "two full bunnies, 2 x 69,451")
    out["II-A"] = T.Model([_obj("bunny", (-0.55, 0, 0))], TWO_BUNNY_DISTANCE,
                          f"the left bunny of I-A alone, 69,451, same camera (distance {TWO_BUNNY_DISTANCE})")
    out["II-B"] = T.Model([_obj(low, (-0.55, 0, 0))], TWO_BUNNY_DISTANCE,
                          f"the left bunny of I-B alone, {LOWPOLY_FACES:,}, same camera")
    return out, method


#: the depth-complexity study (§4.2): equal triangles and equal silhouettes, depth complexity 2 against 4
SHELL_TRIANGLES = 4096


def shell_models():
    """One glass sphere against two nested ones: the same triangles (4,096) and silhouette, twice the layers.

    ``one shell``: a UV sphere of radius 0.5 with 4,096 triangles (64 x 33);
    ``two shells``: UV spheres of radius 0.5 and 0.4 with 2,048 triangles
    each (32 x 33). Seen from the front at the default distance 2.6, both
    cover the same pixels; inside the inner sphere's silhouette (64 % of the
    pixels) a ray meets 4 interfaces instead of 2.
    """
    one = uv_sphere(64, 33)
    half = uv_sphere(32, 33)
    return {"one shell": T.Model([_obj(one, fit=None)], 2.6, "UV sphere r 0.5, 4,096 triangles"),
            "two shells": T.Model([_obj(half, fit=None), _obj(half, fit=None, scale=0.8)], 2.6,
                                  "UV spheres r 0.5 and 0.4, 2 x 2,048 triangles")}


# --------------------------------------------------------------------------- timing
def interleaved_timer(repeats, warmup=2):
    """A ``time_many(scenes)`` for :func:`.chaudhari.table_4_1`: the cells of one model timed round by round.

    Parameters
    ----------
    repeats : int
        Timed rounds; each round renders every scene in turn (ratios robust to other load).
    warmup : int
        Untimed renders of each scene first.

    Returns
    -------
    callable
        ``time_many(scenes) -> list of dict`` (``pipeline_ms``, ``total_ms``, ``stages_ms`` medians, the last
        ``result``, the per-round ``samples``).
    """
    from ..render import render

    def fn(scenes):
        for sc in scenes:
            for _ in range(warmup):
                render(sc)
        acc = [{"sums": [], "totals": [], "per": {}, "result": None} for _ in scenes]
        for _ in range(repeats):
            for a, sc in zip(acc, scenes):
                res = render(sc)
                a["result"] = res
                a["sums"].append(T.pipeline_ms(res))
                a["totals"].append(float(res.meta["total_ms"]))
                for k, v in res.meta["timings_ms"].items():
                    a["per"].setdefault(k, []).append(float(v))
        return [{"pipeline_ms": statistics.median(a["sums"]), "total_ms": statistics.median(a["totals"]),
                 "stages_ms": {k: statistics.median(v) for k, v in a["per"].items()}, "result": a["result"],
                 "samples": a["sums"], "other_load": 0.0} for a in acc]
    return fn


def time_frames(scenes, repeats, warmup=1):
    """Frames of several scenes timed round by round: per round, each scene's render and photon generation.

    The frame is the thesis's: the per-frame stages plus the photon-generation
    pass (:func:`.chaudhari.photon_generation_pass`). A ratio between two
    scenes is taken within each round (both timed within a second of each
    other), and its median and spread over the rounds reported, so that a
    slow spell of a shared machine weighs on both sides of it alike.

    Parameters
    ----------
    scenes : sequence of Scene or dict
        The scenes to time.
    repeats : int
        Rounds (at least 1).
    warmup : int
        Untimed renders and photon generations of each scene first.

    Returns
    -------
    list of dict
        Per scene: ``frame``, ``trace``, ``peel``, ``reduce``, ``shade``,
        ``pgen`` (ms per round), ``traced_pixels``, ``interfaces``, ``triangles``.
    """
    from ..render import render

    passes = [T.photon_generation_pass(sc) for sc in scenes]
    for sc, pg in zip(scenes, passes):
        for _ in range(max(1, int(warmup))):
            render(sc)
            pg()
    acc = [{"frame": [], "trace": [], "pgen": [], "peel": [], "reduce": [], "shade": []} for _ in scenes]
    last = [None] * len(scenes)
    for _ in range(max(1, int(repeats))):
        for k, (sc, pg) in enumerate(zip(scenes, passes)):
            res = render(sc)
            t0 = time.perf_counter()
            pg()
            g = (time.perf_counter() - t0) * 1e3
            acc[k]["pgen"].append(g)
            acc[k]["frame"].append(T.pipeline_ms(res) + g)
            for st in ("trace", "peel", "reduce", "shade"):
                acc[k][st].append(float(res.meta["timings_ms"][st]))
            last[k] = res
    for a, res in zip(acc, last):
        a["traced_pixels"] = int(np.count_nonzero(np.asarray(res["status"]) != 0))
        a["interfaces"] = int(np.asarray(res["interfaces"], np.int64).sum())
        a["triangles"] = res.meta.get("triangles")
    return acc


def ratio(a, b, key="frame"):
    """(median, lowest, highest) over the rounds of ``a[key] / b[key]`` (:func:`time_frames`).

    Parameters
    ----------
    a, b : dict
        Entries of :func:`time_frames`'s list.
    key : str
        The per-round series compared (``'frame'``, ``'trace'``, ...).

    Returns
    -------
    median, lowest, highest : float
    """
    r = [x / y for x, y in zip(a[key], b[key])]
    return statistics.median(r), min(r), max(r)


def fps_ratio(lo, hi):
    """Spread of the per-round FPS(lo) / FPS(hi) of two Table 4.1 cells timed in the same rounds.

    Each round's frame is its pipeline time plus the cell's photon-generation median (timed apart).

    Parameters
    ----------
    lo, hi : dict
        The cells (``pipeline_ms``, ``frame_ms``, per-round ``samples``) of the lower and the higher setting.

    Returns
    -------
    Spread
    """
    pg_lo, pg_hi = lo["frame_ms"] - lo["pipeline_ms"], hi["frame_ms"] - hi["pipeline_ms"]
    a, b = lo.get("samples") or [lo["pipeline_ms"]], hi.get("samples") or [hi["pipeline_ms"]]
    if len(a) != len(b):  # not timed in the same rounds: the ratio of the medians, as one sample
        a, b = [lo["pipeline_ms"]], [hi["pipeline_ms"]]
    return ratio_spread([x + pg_hi for x in b], [x + pg_lo for x in a])
