"""The oracle's own passes replayed on a candidate's upstream buffers: what a passing upstream difference explains.

A downstream buffer whose upstream input differs within tolerance is judged
also against the oracle's pass run on the candidate's own upstream buffers
(float32 depths move positions beyond float64's tolerance through the
normals' central differences: docs/oracle.md, "Float32 rasterizers"): for the
image-space method the layer counts and the LDI against the candidate's own
bitmask, the search bounds against its own LDI (:func:`peel_explanations`),
the trace's positions against the oracle's trace on its own LDI
(:func:`trace_explanations`), the photons' exits against the light's passes on
its own light LDI (:func:`photon_explanations`) and their hits against the
march of its own photons (:func:`hit_explanations`). Every replay is used only
where the same replay on the golden's own buffers reproduces the golden.

The method's passes are imported where a replay runs: ``refraction_ref.check`` is imported with the
package, and a check of another method never pays for the image-space passes.

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.4.2 (peeling), §3.6-3.7 (the trace,
   search bounds), §4.1 (photons and their hits on the receivers).
"""

from __future__ import annotations

import os
import re

import numpy as np

from ..camera import Camera
from ..scene import load_scene

__all__ = ["peel_explanations", "trace_explanations", "photon_explanations", "hit_explanations",
           "replay_group", "replay"]


def peel_explanations(golden, name, gold, cand, passed):
    """For the image-space method: {key: array the oracle's own pass gives on the candidate's upstream buffers}.

    Only where the candidate supplied the upstream buffer and it passed (within tolerance): the layer
    counts (popcount of the bitmask), the LDI (peeled from the bitmask, §3.4.2) and the search bounds
    (reduced from the LDI, §3.7). Each is first run on the golden's own upstream buffers and used only
    if it reproduces the golden there.

    Parameters
    ----------
    golden : str
        The golden suite's folder (the case's ``scene.json``).
    name : str
        The case.
    gold, cand : dict of str to ndarray
        The golden's and the candidate's arrays of the case.
    passed : dict of str to bool
        The keys judged so far and whether they passed.

    Returns
    -------
    dict of str to ndarray

    References
    ----------
    Chaudhari (2008), §3.4.2 (peeling), §3.7 (search bounds).
    """
    out = {}
    bits_ok = "stage.voxelize.bits" in cand and passed.get("stage.voxelize.bits")
    ldi_ok = "stage.peel.ldi" in cand and passed.get("stage.peel.ldi")
    if not (bits_ok or ldi_ok):
        return out
    from ..imagespace.depth_bounds import global_bounds
    from ..imagespace.pipeline import Layers, MinMax, Voxels, pass_peel, pass_reduce

    p = load_scene(os.path.join(golden, name, "scene.json")).data["imagespace"]
    if p.get("peeling", "separate") != "separate":
        return out

    def pick(k):
        return cand[k] if (k in cand and passed.get(k)) else gold[k]

    # the replay on the golden's buffers reads the golden's other inputs too (zlo, zhi, zmin, zmax): a
    # candidate's depths within tolerance (an unsnapped rasterizer's) must not spoil the replay's check
    def peel(bits, src=pick):
        voxels = Voxels(bits=bits, zlo=src("stage.voxelize.zlo"), zhi=src("stage.voxelize.zhi"), ldi=None,
                        total=None)
        return pass_peel(voxels, bits.shape[:2], p)

    def reduce(ldi, src=pick):
        gmin, gmax = global_bounds(src("stage.minmax.zmin"), src("stage.minmax.zmax"))
        minmax = MinMax(tri_view=None, zmin=None, zmax=None, frags=None, gmin=gmin, gmax=gmax)
        return pass_reduce(minmax, Layers(ldi=ldi, total=None, lut=None, ran=False, why=""), p)

    try:
        ldi = None
        if bits_ok:
            gp = peel(gold["stage.voxelize.bits"], gold.__getitem__)
            if np.array_equal(gp.ldi, gold["stage.peel.ldi"]):
                cp = peel(cand["stage.voxelize.bits"])
                ldi = cp.ldi
                if ldi.shape == gold["stage.peel.ldi"].shape:
                    out["stage.peel.ldi"] = ldi
                dc = cp.total.astype(np.int16)
                out["stage.peel.depth_complexity"] = out["depth_complexity"] = dc
        if ldi_ok:
            ldi = cand["stage.peel.ldi"]
        if ldi is not None and ldi.shape == gold["stage.peel.ldi"].shape:
            gr = reduce(gold["stage.peel.ldi"], gold.__getitem__)
            if all(np.array_equal(getattr(gr, b), gold[f"stage.reduce.{b}"]) for b in ("bounds_hi", "bounds_lo")):
                cr = reduce(ldi)
                out.update({f"stage.reduce.{b}": getattr(cr, b) for b in ("bounds_hi", "bounds_lo")})
    except (KeyError, ValueError, TypeError):  # a golden without these buffers: judge against the golden alone
        return out
    return out


def trace_explanations(golden, name, gold, cand, passed):
    """The eye's trace run by the oracle on the candidate's own LDI: {position key: array}.

    The trace reads the LDI's depths at its probes and differentiates them for the normals (a central
    difference over ``2 delta`` pixels): one float32 ulp of a depth tilts a normal by
    ``sqrt(2) ulp(d) / (2 delta p(d))`` (``p(d)`` the pixel's footprint at depth d: 7.7e-6 rad at d = 2.6
    on the catalogue's 128 x 128 views), which moves the next interface point, a segment of the object's
    size away, by 4-8e-6: more than ``close`` allows a position (``1e-6 + 1e-5 |g|``) per ulp. A
    rasterizer whose depths are float32 (1-3 ulps from the oracle's, within ``ldi``'s tolerance) moves
    every position after interface 0 so. Its positions are therefore also judged against the oracle's
    trace run on its own passing LDI (with its own passing layer counts, ``zmax``, ``zlo``/``zhi`` and
    search bounds, the golden's where it supplies none or they fail). Only the positions and path lengths
    (``exit_pos``, ``path_pos``, ``path_length``): directions, codes and images are judged against the
    golden alone. Used only if the same replay on the golden's own buffers reproduces the golden.

    Parameters
    ----------
    golden, name, gold, cand, passed
        As :func:`peel_explanations`.

    Returns
    -------
    dict of str to ndarray

    References
    ----------
    Chaudhari (2008), §3.6-3.7 (the trace).
    """
    ldi = cand.get("stage.peel.ldi")
    if ldi is None or not passed.get("stage.peel.ldi") or ldi.shape != gold["stage.peel.ldi"].shape:
        return {}
    from ..imagespace.pipeline import (Bounds, Layers, MinMax, Voxels, check_materials, grid_camera, pass_trace,
                                       trace_knobs)
    from ..meshes import scene_geometry

    sc = load_scene(os.path.join(golden, name, "scene.json"))
    p = sc.data["imagespace"]
    if p.get("peeling", "separate") != "separate" or p.get("depth", "bitmask") != "bitmask":
        return {}

    def pick(k, alt=None):
        for kk in (k, alt):
            if kk and kk in cand and passed.get(kk) and np.shape(cand[kk]) == np.shape(gold[k]):
                return cand[kk]
        return gold[k]

    cam = Camera.from_dict(sc.data["camera"])
    ior, _ = check_materials(scene_geometry(sc))
    outside = float(sc.data["outside_ior"])

    def run(src, layers):
        minmax = MinMax(None, None, src("stage.minmax.zmax"), None, 0.0, 0.0)
        voxels = Voxels(None, src("stage.voxelize.zlo"), src("stage.voxelize.zhi"), None, None)
        total = np.asarray(src("stage.peel.depth_complexity", "depth_complexity")).astype(np.int32)
        bounds = Bounds(src("stage.reduce.bounds_hi"), src("stage.reduce.bounds_lo"), "")
        return pass_trace(minmax, voxels, Layers(layers, total, None, True, ""), bounds, grid_camera(cam, p["grid"]),
                          trace_knobs(p, int(p["record"])), (ior, outside), image=cam)

    keys = {"exit_pos": "exit_pos", "path_length": "path_length", "stage.trace.exit_pos": "exit_pos",
            "stage.trace.path_pos": "path_pos", "stage.trace.path_length": "path_length"}
    try:
        gr = run(lambda k, alt=None: gold[k], gold["stage.peel.ldi"])
        same = [k for k, t in keys.items() if k in gold and gr.get(t) is not None
                and np.array_equal(np.asarray(gr[t], gold[k].dtype), gold[k], equal_nan=True)]
        if not same:
            return {}
        cr = run(pick, ldi)
        return {k: np.asarray(cr[keys[k]]) for k in same}
    except (KeyError, ValueError, TypeError):  # a golden without these buffers: judge against the golden alone
        return {}


def _light_trace(sc, gold, light):
    """The oracle's passes in light ``light``'s view and a trace of them on any LDI (``run(ldi)``), or None.

    The light's depths, bitmask and bounds are not contract keys: the oracle's own (computed from the
    scene) serve, and the layer counts follow the LDI given (its present layers, the oracle's count where
    every layer is present).
    """
    from ..imagespace.pipeline import (Layers, check_materials, pass_minmax, pass_peel, pass_reduce, pass_trace,
                                       pass_voxelize, trace_knobs)
    from ..lights import light_camera
    from ..meshes import scene_geometry
    from ..status import EXITED

    d = sc.data
    p = d["imagespace"]
    if p.get("peeling", "separate") != "separate" or p.get("depth", "bitmask") != "bitmask":
        return None
    geom = scene_geometry(sc)
    ior, _ = check_materials(geom)
    lcam = light_camera(d["lights"][light], geom.vertices, int(p["photons"]))
    minmax = pass_minmax(geom, lcam, p)
    voxels = pass_voxelize(minmax, lcam, p)
    peeled = pass_peel(voxels, lcam.shape, p)
    if not np.array_equal(peeled.ldi, gold[f"stage.photon_trace.ldi_{light}"]):
        return None

    def run(ldi):
        nfin = np.isfinite(ldi).sum(axis=0)
        total = np.where(nfin >= ldi.shape[0], np.maximum(peeled.total, nfin), nfin).astype(peeled.total.dtype)
        layers = Layers(ldi, total, None, True, "")
        trace = pass_trace(minmax, voxels, layers, pass_reduce(minmax, layers, p), lcam, trace_knobs(p),
                           (ior, float(d["outside_ior"])))
        ex = np.flatnonzero(trace["status"].ravel() == EXITED)
        return trace["exit_pos"].reshape(-1, 3)[ex], trace["exit_dir"].reshape(-1, 3)[ex]

    return run


def photon_explanations(golden, name, gold, cand, passed, light):
    """The light's photon trace run by the oracle on the candidate's own light LDI: {exit_pos_l: array}.

    The photons are the eye's trace in the light's view (§4.1): their exit points move with the light
    LDI's last bits as the eye's positions do with the eye's (:func:`trace_explanations`). Used only
    where the candidate's ``stage.photon_trace.ldi_l`` passed, the oracle's light passes reproduce the
    golden's LDI and photons, and the replay exits as many photons as the candidate's key holds.

    Parameters
    ----------
    golden, name, gold, cand, passed
        As :func:`peel_explanations`.
    light : int
        The light.

    Returns
    -------
    dict of str to ndarray

    References
    ----------
    Chaudhari (2008), §4.1 (photons: the trace in the light's view).
    """
    k_ldi, k_pos = f"stage.photon_trace.ldi_{light}", f"stage.photon_trace.exit_pos_{light}"
    ldi = cand.get(k_ldi)
    if ldi is None or not passed.get(k_ldi) or ldi.shape != gold[k_ldi].shape or k_pos not in cand:
        return {}
    try:
        run = _light_trace(load_scene(os.path.join(golden, name, "scene.json")), gold, light)
        if run is None:
            return {}
        og, dg = run(gold[k_ldi])
        if not (np.array_equal(og, gold[k_pos]) and np.array_equal(dg, gold[f"stage.photon_trace.exit_dir_{light}"])):
            return {}
        oc, _ = run(ldi)
        return {k_pos: oc} if oc.shape == np.shape(cand[k_pos]) else {}
    except (KeyError, ValueError, TypeError, IndexError):
        return {}


def hit_explanations(golden, name, gold, cand, passed, light):
    """The receiver hits run by the oracle on the candidate's own photons and depth image: {hit_pos_l: array}.

    The eye-space march samples the photon's line once per camera pixel against the receivers' depth
    image: an exit point moved within its tolerance (or by the light LDI's last bits,
    :func:`photon_explanations`) can cross the depth image one sample earlier or later, a jump of up to a
    pixel's footprint along the receiver. The hits are therefore also judged against the oracle's march
    of the candidate's own passing ``exit_pos_l``, ``exit_dir_l`` and ``receiver_depth`` buffers (the
    golden's where it supplies none or they fail); used only if the same march of the golden's buffers
    reproduces the golden.

    Parameters
    ----------
    golden, name, gold, cand, passed, light
        As :func:`photon_explanations`.

    Returns
    -------
    dict of str to ndarray

    References
    ----------
    Chaudhari (2008), §4.1 (the photons' hits on the receivers).
    """
    from ..caustics.receivers import receiver_hits, receiver_set

    k_hit = f"stage.receiver_hit.hit_pos_{light}"
    ins = (f"stage.photon_trace.exit_pos_{light}", f"stage.photon_trace.exit_dir_{light}",
           "stage.receiver_depth.depth", "stage.receiver_depth.triangle")
    if not any(k in cand and passed.get(k) and np.shape(cand[k]) == np.shape(gold[k]) for k in ins):
        return {}

    def pick(k):
        return cand[k] if (k in cand and passed.get(k) and np.shape(cand[k]) == np.shape(gold[k])) else gold[k]

    try:
        sc = load_scene(os.path.join(golden, name, "scene.json"))
        d = sc.data
        rs = receiver_set(sc, d["lights"][0], int(d["caustics"]["map_size"]))
        cam = Camera.from_dict(d["camera"])
        mode = d["imagespace"]["receiver_hit"]

        def run(src):
            P, _ = receiver_hits(rs, src(ins[0]), src(ins[1]), mode, cam, (src(ins[2]), src(ins[3])))
            return P

        if not np.array_equal(run(gold.__getitem__), gold[k_hit], equal_nan=True):
            return {}
        P = run(pick)
        return {k_hit: P} if P.shape == gold[k_hit].shape else {}
    except (KeyError, ValueError, TypeError, IndexError, ImportError):
        return {}


#: which upstream keys each explanation reads (the explanation is computed once they are judged), and the
#: group of keys one replay explains
_EXPLAINED_BY = {"stage.peel.ldi": ("stage.voxelize.bits",),
                 "stage.peel.depth_complexity": ("stage.voxelize.bits",),
                 "depth_complexity": ("stage.voxelize.bits",),
                 "stage.reduce.bounds_hi": ("stage.voxelize.bits", "stage.peel.ldi"),
                 "stage.reduce.bounds_lo": ("stage.voxelize.bits", "stage.peel.ldi")}
_TRACE_UPSTREAM = ("stage.peel.ldi", "stage.peel.depth_complexity", "stage.minmax.zmax", "stage.voxelize.zlo",
                   "stage.voxelize.zhi", "stage.reduce.bounds_hi", "stage.reduce.bounds_lo")
_EXPLAINED_BY.update({k: _TRACE_UPSTREAM for k in ("exit_pos", "path_length", "stage.trace.exit_pos",
                                                    "stage.trace.path_pos", "stage.trace.path_length")})
_PER_LIGHT = (
    (re.compile(r"stage\.photon_trace\.exit_pos_(\d+)"), "photons", ("stage.photon_trace.ldi_{0}",)),
    (re.compile(r"stage\.receiver_hit\.hit_pos_(\d+)"), "hits",
     ("stage.photon_trace.exit_pos_{0}", "stage.photon_trace.exit_dir_{0}", "stage.receiver_depth.depth",
      "stage.receiver_depth.triangle")),
)


def replay_group(key):
    """(group, light, upstream keys) of a key an image-space replay may explain, or None.

    Parameters
    ----------
    key : str
        A contract key.

    Returns
    -------
    tuple or None
        ``group`` (``'peel'``, ``'trace'``, ``'photons'``, ``'hits'``), ``light`` (int or None) and the
        upstream keys the replay reads.
    """
    if key in _EXPLAINED_BY:
        return ("trace" if _EXPLAINED_BY[key] is _TRACE_UPSTREAM else "peel", None, _EXPLAINED_BY[key])
    for rx, group, ups in _PER_LIGHT:
        m = rx.fullmatch(key)
        if m:
            l = int(m.group(1))
            return group, l, tuple(u.format(l) for u in ups)
    return None


def replay(group, light, golden, name, gold, cand, passed):
    """The replay of one group (:func:`replay_group`): {key: array}.

    Parameters
    ----------
    group : str
        The replay (:func:`replay_group`).
    light : int or None
        The light of a per-light replay.
    golden, name, gold, cand, passed
        As :func:`peel_explanations`.

    Returns
    -------
    dict of str to ndarray
    """
    if group == "peel":
        return peel_explanations(golden, name, gold, cand, passed)
    if group == "trace":
        return trace_explanations(golden, name, gold, cand, passed)
    if group == "photons":
        return photon_explanations(golden, name, gold, cand, passed, light)
    return hit_explanations(golden, name, gold, cand, passed, light)
