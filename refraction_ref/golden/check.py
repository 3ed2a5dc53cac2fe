"""``refraction-ref check CANDIDATE_DIR --golden DIR``: judge a backend's outputs against the golden suite.

A candidate folder has the suite's layout: ``CANDIDATE_DIR/<case>/result.npz``
holding the keys the backend produces (final keys such as ``exit_dir`` and
stage buffers such as ``stage.peel.ldi``), with the golden shapes and
dtypes. Every key the candidate supplies is judged by its tolerance
(:mod:`.tolerances`, recorded per key in the manifest); ``require`` makes a
key mandatory. Per case the report names the **earliest failing stage**:
walking the method's stages in the graph's order (recorded in the
manifest), the first whose buffers fail; that is the pass to fix.

A verdict cannot pass by accident: the run fails when any case fails, when
a requested case is missing, when a case has no key of the contract to
judge, and when a key is not in the contract (``allow_extra`` accepts a
backend's own keys, listed in the report). A suite without its completion
marker (written last by ``golden build``) is refused.

Failures are *located* (:mod:`.tolerances`): differences are allowed only
inside an ambiguity mask computed from the golden (silhouettes, status
boundaries, depth discontinuities of the maps); elsewhere the allowance is a
fraction of the informative elements (non-empty words, covered pixels,
present layers, lit texels). A downstream buffer whose upstream input
differs within tolerance is judged against what that difference explains:
for the image-space method the layer counts and the LDI against the
candidate's own bitmask, the search bounds against the candidate's own LDI,
the trace's positions against the oracle's trace on the candidate's own LDI,
the photons' exits against the light's passes on its own light LDI and their
hits against the march of its own photons, each run through the oracle's pass
(float32 depths move positions beyond float64's tolerance through the
normals' central differences: docs/oracle.md, "Float32 rasterizers").

Writes ``report.md`` (per case and key: pass or fail, the measured error
beside the allowance and the tolerance's rationale, the earliest failing
stage), ``summary.json``, and per failing key the mask of located failing
elements (``<case>__<key>.fail.npy``) and a PNG panel (candidate, golden,
difference with the failures marked, naming the layer or component shown).
"""

from __future__ import annotations

import difflib
import json
import os
import re
import time

import numpy as np

from ..contract import CONTRACT_VERSION
from ..files import NotNpzError, atomic_open, atomic_path, load_npz, savefig_atomic
from .tolerances import _elementwise, _fold, finiteness, fmt_percent, fmt_share, judge, tolerance_for

__all__ = ["check", "CheckError", "CheckReport", "CaseReport", "format_report"]


class CheckError(ValueError):
    """The golden suite itself cannot be used (missing, incomplete, unreadable, another contract version)."""


class CaseReport(dict):
    """One case's verdict: a dict (``ok``, ``method``, ``problems``, ``keys``, ``extra``,
    ``earliest_failing_stage``) with the same names as attributes, and ``rows``: one dict per key judged."""

    ok = property(lambda self: bool(self["ok"]))
    method = property(lambda self: self["method"])
    problems = property(lambda self: self["problems"])
    earliest_failing_stage = property(lambda self: self["earliest_failing_stage"])
    extra = property(lambda self: self["extra"])

    @property
    def rows(self):
        """Per key judged: ``{key, stage, ok, kind, failing, allowed, detail, why}``."""
        return [dict(key=k, **{f: j.get(f) for f in ("stage", "ok", "kind", "failing", "allowed", "detail", "why")})
                for k, j in self["keys"].items()]

    @property
    def failing_keys(self):
        return [k for k, j in self["keys"].items() if not j["ok"]]


class CheckReport(dict):
    """What :func:`check` returns: a dict (``ok``, ``cases``, ``golden``, ``candidate``, ``seconds``,
    ``report``) with attributes ``ok``, ``cases`` (name -> :class:`CaseReport`), ``rows`` (one per case
    and key), ``earliest_failing_stage`` (name -> stage or None) and ``text`` (the Markdown report)."""

    ok = property(lambda self: bool(self["ok"]))
    cases = property(lambda self: self["cases"])

    @property
    def rows(self):
        return [dict(case=name, **r) for name, c in self["cases"].items() for r in c.rows]

    @property
    def earliest_failing_stage(self):
        return {name: c["earliest_failing_stage"] for name, c in self["cases"].items()}

    @property
    def text(self):
        return format_report(self)

    def __repr__(self):
        n_ok = sum(c.ok for c in self.cases.values())
        return f"<CheckReport {'PASS' if self.ok else 'FAIL'}: {n_ok} of {len(self.cases)} cases pass>"


# --------------------------------------------------------------------- the suite
def _load_manifest(golden):
    p = os.path.join(golden, "manifest.json")
    if not os.path.isfile(p):
        raise CheckError(f"check: '{golden}' is not a golden suite (no manifest.json); build one with "
                         f"'refraction-ref golden build {golden}'")
    with open(p, "rb") as f:
        raw = f.read()
    m = json.loads(raw)
    if m.get("contract_version") != CONTRACT_VERSION:
        raise CheckError(f"check: the golden suite '{golden}' follows contract_version {m.get('contract_version')}, "
                         f"this refraction_ref follows {CONTRACT_VERSION} (docs/oracle.md, changelog); rebuild it "
                         "with 'refraction-ref golden build'")
    from .build import COMPLETE

    import hashlib

    mk = os.path.join(golden, COMPLETE)
    done = None
    if os.path.isfile(mk):
        with open(mk) as f:
            done = json.load(f)
    if done is None or done.get("manifest_sha256") != hashlib.sha256(raw).hexdigest():
        raise CheckError(f"check: the golden suite '{golden}' is incomplete: "
                         + ("it has no completion marker (" + COMPLETE + ", written last by 'golden build'), so its "
                            "build stopped or is still running" if done is None else
                            f"its manifest changed after the build completed ({COMPLETE} names another)")
                         + f"; finish it with 'refraction-ref golden build {golden}'")
    return m


def _read_result(path):
    """The candidate's arrays, or a problem sentence (missing, not a zip, unreadable)."""
    try:
        with load_npz(path, "candidate result") as z:
            return {k: z[k] for k in z.files if k != "meta"}, None
    except FileNotFoundError:
        return None, "missing"
    except NotNpzError as e:
        return None, str(e)
    except Exception as e:  # noqa: BLE001 - a broken member of the zip: a problem of the candidate, reported
        return None, f"{path} could not be read ({type(e).__name__}: {e})"


def _dtype_problem(c, spec):
    """Dtypes are judged as documented: the golden's dtype exactly (byte order aside)."""
    g = np.dtype(spec["dtype"])
    if c.dtype.newbyteorder("=") != g.newbyteorder("="):
        return (f"dtype {c.dtype} where the contract has {g.newbyteorder('=')} (docs/oracle.md); write it as "
                f"{g.newbyteorder('=')}")
    return None


# --------------------------------------------------------------------- ambiguity masks
def _changes(a):
    """(H, W) codes -> True where the 3x3 neighbourhood holds another value (edges replicate)."""
    a = np.asarray(a)
    H, W = a.shape
    p = np.pad(a, 1, mode="edge")
    out = np.zeros((H, W), bool)
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            out |= p[di:di + H, dj:dj + W] != a
    return out


def _codes(a):
    """A float array as codes for :func:`_changes` (NaN, inf kept apart); other dtypes as they are."""
    a = np.asarray(a)
    return finiteness(a) if a.dtype.kind == "f" else a


def _jumps(z):
    """Texels beside a depth discontinuity of a position map: finiteness changes, or a step between
    neighbours above ten times the map's median step (a wall, a step, another receiver)."""
    z = np.asarray(z, np.float64)
    fin = np.isfinite(z)
    out = _changes(fin)
    zz = np.where(fin, z, 0.0)
    steps = []
    for ax in (0, 1):
        d = np.abs(np.diff(zz, axis=ax))
        ok = fin & np.roll(fin, -1, axis=ax)
        ok = ok.take(np.arange(z.shape[ax] - 1), axis=ax)
        steps.append((d, ok))
    allst = np.concatenate([d[ok] for d, ok in steps]) if any(ok.any() for _, ok in steps) else np.zeros(0)
    if allst.size:
        thr = 10.0 * max(float(np.median(allst)), 1e-12)
        big = np.zeros(z.shape, bool)
        for ax, (d, ok) in enumerate(steps):
            b = ok & (d > thr)
            sl0 = [slice(None)] * 2
            sl1 = [slice(None)] * 2
            sl0[ax], sl1[ax] = slice(0, -1), slice(1, None)
            big[tuple(sl0)] |= b
            big[tuple(sl1)] |= b
        out |= _changes(big.astype(np.int8)) | big
    return out


#: golden keys whose changes mark the camera picture's silhouettes and decision boundaries
_SILHOUETTE_KEYS = ("depth_complexity", "stage.peel.depth_complexity", "hit", "status", "view_status",
                    "object_mask", "object_mask_direct")


def _context(gold):
    """Per picture shape (H, W): the golden's ambiguity mask over it (camera silhouettes, map discontinuities)."""
    pics = {}
    for k in _SILHOUETTE_KEYS:
        a = gold.get(k)
        if a is not None and a.ndim == 2:
            pics[a.shape] = pics.get(a.shape, np.zeros(a.shape, bool)) | _changes(_codes(a))
    for k, a in gold.items():
        if k.startswith("stage.level_map.position_") and a.ndim == 2:
            pics[a.shape] = pics.get(a.shape, np.zeros(a.shape, bool)) | _jumps(a)
    return pics


def _edge_counts(cc, gc):
    """(H, W) set-bit counts -> True where the candidate's count differs from the golden's and equals the
    golden's count at one of the pixel's 8 neighbours (edges replicate): the coverage an edge moved
    across the pixel's centre hands it.

    A silhouette edge (a fold's, or the object's outline) separates pixels whose counts differ by the
    fragments of the triangles that end there; an edge moved by a sub-pixel amount (another rasterizer's
    snap, float32 set-up) flips the pixels whose centres it crosses to their neighbour's side. A bitmask
    word that lost a set bit inside a surface (a blend that replaced the word) leaves a count no
    neighbour has: 3 beside 2 and 4 where a fold's two sheets share a word.
    """
    H, W = gc.shape
    p = np.pad(gc, 1, mode="edge")
    out = np.zeros((H, W), bool)
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            if di == dj == 1:
                continue
            out |= p[di:di + H, dj:dj + W] == cc
    return out & (cc != gc)


def _ambiguity(key, g, spec, pics, c=None):
    """The ambiguity mask of a key (broadcastable to its failing mask), or None where none applies.

    Bit words (``spec['silhouette'] == 'counts'``): a silhouette explains a fragment that appears or
    vanishes as an edge moves across the pixel's centre, which hands the pixel the coverage of its
    neighbour across that edge: the candidate's set-bit count differs from the golden's and equals the
    golden's count at one of the 8 neighbours (:func:`_edge_counts`). A bit that moved, or a fragment lost
    from inside a surface (a count no neighbour has), is counted against ``fraction`` wherever it is.

    Keys of a light's view (``stage.photon_trace.*``) are over the light's texels, not the camera's
    pixels, even when the two pictures have the same size: only their own layers' edges are ambiguous.
    """
    if not spec.get("locate"):
        return None
    g = np.asarray(g)
    if key.startswith("stage.photon_trace."):
        pics = {shp: np.zeros(shp, bool) for shp in pics}
    for shp, mask in pics.items():
        if g.ndim >= 2 and g.shape[:2] == shp:  # per pixel (H, W, ...)
            m = mask.copy()
            if spec.get("silhouette") == "counts" and c is not None and g.dtype.kind == "u" and g.ndim == 3:
                m &= _edge_counts(_popcount(np.asarray(c, g.dtype)), _popcount(g))
            if spec.get("own_edges") and g.ndim == 2:
                m |= _changes(_codes(g))
            if spec.get("over") == "nonzero" and g.ndim == 2:  # the lit region's edge
                m |= _changes(g != 0)
            return m.reshape(shp + (1,) * (g.ndim - 2))
        if g.ndim >= 3 and g.shape[1:3] == shp:  # per layer or plane (L, H, W, ...)
            m = np.zeros(g.shape[:3], bool) | mask[None]
            for i in range(g.shape[0]):
                gi = g[i] if g.ndim == 3 else np.all(np.isfinite(g[i]), axis=-1) if g.dtype.kind == "f" else g[i, ..., 0]
                m[i] |= _changes(_codes(gi) if g.ndim == 3 else gi)
                if spec.get("over") == "nonzero" and g.ndim == 3:
                    m[i] |= _changes(g[i] != 0)
            return m.reshape(m.shape + (1,) * (g.ndim - 3))
    return None


# --------------------------------------------------------------------- explained by the candidate's upstream
def _imagespace_explanations(golden, name, gold, cand, passed):
    """For the image-space method: {key: array the oracle's own pass gives on the candidate's upstream buffers}.

    Only where the candidate supplied the upstream buffer and it passed (within tolerance): the layer
    counts (popcount of the bitmask), the LDI (peeled from the bitmask, §3.4.2) and the search bounds
    (reduced from the LDI, §3.7). Each is first run on the golden's own upstream buffers and used only
    if it reproduces the golden there.
    """
    out = {}
    bits_ok = "stage.voxelize.bits" in cand and passed.get("stage.voxelize.bits")
    ldi_ok = "stage.peel.ldi" in cand and passed.get("stage.peel.ldi")
    if not (bits_ok or ldi_ok):
        return out
    from ..scene import load_scene
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
        vox = Voxels(bits=bits, zlo=src("stage.voxelize.zlo"), zhi=src("stage.voxelize.zhi"), ldi=None, total=None)
        return pass_peel(vox, bits.shape[:2], p)

    def reduce(ldi, src=pick):
        gmin, gmax = global_bounds(src("stage.minmax.zmin"), src("stage.minmax.zmax"))
        mm = MinMax(tri_view=None, zmin=None, zmax=None, frags=None, gmin=gmin, gmax=gmax)
        return pass_reduce(mm, Layers(ldi=ldi, total=None, lut=None, ran=False, why=""), p)

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


def _trace_explanations(golden, name, gold, cand, passed):
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
    """
    ldi = cand.get("stage.peel.ldi")
    if ldi is None or not passed.get("stage.peel.ldi") or ldi.shape != gold["stage.peel.ldi"].shape:
        return {}
    from ..camera import Camera
    from ..imagespace.pipeline import Bounds, Layers, MinMax, Voxels, check_materials, grid_camera, pass_trace
    from ..meshes import scene_geometry
    from ..scene import load_scene

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
        mm = MinMax(None, None, src("stage.minmax.zmax"), None, 0.0, 0.0)
        vox = Voxels(None, src("stage.voxelize.zlo"), src("stage.voxelize.zhi"), None, None)
        total = np.asarray(src("stage.peel.depth_complexity", "depth_complexity")).astype(np.int32)
        red = Bounds(src("stage.reduce.bounds_hi"), src("stage.reduce.bounds_lo"), "")
        return pass_trace(mm, vox, Layers(layers, total, None, True, ""), red, grid_camera(cam, p["grid"]), p,
                          ior, outside, record=int(p["record"]), image=cam)

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
                                       pass_voxelize)
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
    mm = pass_minmax(geom, lcam, p)
    vox = pass_voxelize(mm, lcam, p)
    pl = pass_peel(vox, lcam.shape, p)
    if not np.array_equal(pl.ldi, gold[f"stage.photon_trace.ldi_{light}"]):
        return None

    def run(ldi):
        nfin = np.isfinite(ldi).sum(axis=0)
        total = np.where(nfin >= ldi.shape[0], np.maximum(pl.total, nfin), nfin).astype(pl.total.dtype)
        lay = Layers(ldi, total, None, True, "")
        tr = pass_trace(mm, vox, lay, pass_reduce(mm, lay, p), lcam, p, ior, float(d["outside_ior"]))
        ex = np.flatnonzero(tr["status"].ravel() == EXITED)
        return tr["exit_pos"].reshape(-1, 3)[ex], tr["exit_dir"].reshape(-1, 3)[ex]

    return run


def _photon_explanations(golden, name, gold, cand, passed, light):
    """The light's photon trace run by the oracle on the candidate's own light LDI: {exit_pos_l: array}.

    The photons are the eye's trace in the light's view (§4.1): their exit points move with the light
    LDI's last bits as the eye's positions do with the eye's (:func:`_trace_explanations`). Used only
    where the candidate's ``stage.photon_trace.ldi_l`` passed, the oracle's light passes reproduce the
    golden's LDI and photons, and the replay exits as many photons as the candidate's key holds.
    """
    k_ldi, k_pos = f"stage.photon_trace.ldi_{light}", f"stage.photon_trace.exit_pos_{light}"
    ldi = cand.get(k_ldi)
    if ldi is None or not passed.get(k_ldi) or ldi.shape != gold[k_ldi].shape or k_pos not in cand:
        return {}
    from ..scene import load_scene

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


def _hit_explanations(golden, name, gold, cand, passed, light):
    """The receiver hits run by the oracle on the candidate's own photons and depth image: {hit_pos_l: array}.

    The eye-space march samples the photon's line once per camera pixel against the receivers' depth
    image: an exit point moved within its tolerance (or by the light LDI's last bits,
    :func:`_photon_explanations`) can cross the depth image one sample earlier or later, a jump of up to a
    pixel's footprint along the receiver. The hits are therefore also judged against the oracle's march
    of the candidate's own passing ``exit_pos_l``, ``exit_dir_l`` and ``receiver_depth`` buffers (the
    golden's where it supplies none or they fail); used only if the same march of the golden's buffers
    reproduces the golden.
    """
    from ..caustics.pipeline import receiver_hits
    from ..caustics.receivers import receiver_set
    from ..camera import Camera
    from ..scene import load_scene

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


def _explanation(key):
    """(group, light, upstream keys) of a key an image-space replay may explain, or None."""
    if key in _EXPLAINED_BY:
        return ("trace" if _EXPLAINED_BY[key] is _TRACE_UPSTREAM else "peel", None, _EXPLAINED_BY[key])
    for rx, group, ups in _PER_LIGHT:
        m = rx.fullmatch(key)
        if m:
            l = int(m.group(1))
            return group, l, tuple(u.format(l) for u in ups)
    return None


def _explain(group, light, golden, name, gold, cand, passed):
    """The replay of one group (:func:`_explanation`): {key: array}."""
    if group == "peel":
        return _imagespace_explanations(golden, name, gold, cand, passed)
    if group == "trace":
        return _trace_explanations(golden, name, gold, cand, passed)
    if group == "photons":
        return _photon_explanations(golden, name, gold, cand, passed, light)
    return _hit_explanations(golden, name, gold, cand, passed, light)


# --------------------------------------------------------------------- shared receiver edges (hit_face ties)
#: a photon whose golden hit lies within this many camera pixels (the pixel's footprint at the hit's depth,
#: measured in the triangles' plane) of an edge two receiver triangles share may name either triangle: the
#: eye-space march names the triangle of the depth image's texel where it detects the crossing, not the one
#: holding the hit (on ``is_caustics_sphere`` 277 of 11608 golden hits lie in the other triangle, all within
#: 2 pixels of the diagonal: a port with an exact ray-triangle hit names those), and an exact hit on the edge
#: itself is a float tie
FACE_TIE_PIXELS = 2.0


def _point_segment_distance(p, a, b):
    """Distance of points p (N, 3) to segments a-b (N, 3 each)."""
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=-1)


def face_ties(golden, name, gold, key, cand_face):
    """Photons whose candidate ``hit_face_l`` differs from the golden's across a shared receiver edge.

    True where the golden and the candidate name two receiver triangles that share an edge (two vertices)
    and the golden's hit point lies within :data:`FACE_TIE_PIXELS` camera pixels of that edge (the pixel's
    footprint at the hit's view depth). None when the scene's receivers or camera cannot be read.

    References
    ----------
    docs/oracle.md, "Conformance" (hit_face ties).
    """
    from ..camera import Camera
    from ..caustics.receivers import receiver_soup
    from ..scene import load_scene

    l = key.rsplit("_", 1)[-1]
    hp = gold.get(f"stage.receiver_hit.hit_pos_{l}")
    gf = np.asarray(gold[key])
    cf = np.asarray(cand_face)
    if hp is None or hp.shape != gf.shape + (3,) or cf.shape != gf.shape:
        return None
    try:
        scene = load_scene(os.path.join(golden, name, "scene.json"))
        tris = receiver_soup(scene).tris
        cam = Camera.from_dict(scene.data["camera"])
    except Exception:  # noqa: BLE001 - no receivers or camera to read: no ties, every difference counts
        return None
    T = len(tris)
    out = np.zeros(gf.shape, bool)
    sel = np.flatnonzero((cf != gf) & (gf >= 0) & (gf < T) & (cf >= 0) & (cf < T) & np.all(np.isfinite(hp), -1))
    if not sel.size:
        return out
    A, B = tris[gf[sel]], tris[cf[sel]]  # (n, 3, 3)
    same = np.all(A[:, :, None, :] == B[:, None, :, :], axis=-1)  # vertex a of A equals vertex b of B
    shared = same.any(axis=2)  # (n, 3): which of A's vertices B has too
    two = shared.sum(axis=1) == 2
    ia = np.argsort(~shared, axis=1, kind="stable")[:, :2]  # the two shared vertices first
    a = np.take_along_axis(A, ia[:, :1, None], axis=1)[:, 0]
    b = np.take_along_axis(A, ia[:, 1:2, None], axis=1)[:, 0]
    p = hp[sel]
    n = np.cross(A[:, 1] - A[:, 0], A[:, 2] - A[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    # measured in the triangles' plane: the eye-space march's hits lie up to a few 1e-3 off it
    dist = _point_segment_distance(p - np.sum((p - A[:, 0]) * n, axis=-1)[:, None] * n, a, b)
    z = np.maximum(-cam.world_to_view(p)[:, 2], 0.0)
    pix = 2.0 * cam.sy * (1.0 if cam.ortho else z) / cam.height
    out[sel] = two & (dist <= FACE_TIE_PIXELS * pix)
    return out


# --------------------------------------------------------------------- shadow-test ties
def margin_ties(gold, key, spec):
    """Pixels where the golden's shadow test is a tie: its margin within ``atol + rtol far`` of 0.

    ``key`` is ``stage.caustic_final.shadow_<l>``; the margin is the golden's ``shadow_margin_<l>``
    (``dl - (zmin + bias)``, 0 at a texel-edge tie), ``far`` the light camera's far plane
    (``stage.photon_trace.camera_<l>``, row 5); None where the golden lacks them.
    """
    head, tail = key.rsplit(".", 1)
    light = tail.rsplit("_", 1)[-1]
    m = gold.get(f"{head}.{spec['margin_key']}{light}")
    if m is None or np.shape(m) != np.shape(gold[key]):
        return None
    cam = gold.get(f"stage.photon_trace.camera_{light}")
    far = float(np.asarray(cam)[5, 1]) if cam is not None and np.shape(cam) == (6, 3) else 1.0
    eps = float(spec.get("margin_atol", 0.0)) + float(spec.get("margin_rtol", 0.0)) * abs(far)
    with np.errstate(invalid="ignore"):
        return np.abs(np.asarray(m, np.float64)) <= eps


# --------------------------------------------------------------------- photons matched one by one
#: photon buffers: (pattern, set, anchors). Keys of one set share their leading axis (one row per photon, in
#: the order the contract gives: light texel order for the mesh methods, photon index for the volumetric);
#: when a candidate's count differs, its photons are matched to the golden's along the first anchor it
#: supplies, in order, and each key is judged on the matched photons, the others named
_PHOTON_SETS = (
    (re.compile(r"stage\.(?:photon_trace|receiver_hit)\.(?:exit_pos|exit_dir|hit_pos|hit_face)_(\d+)"),
     "light {0}", ("stage.photon_trace.exit_pos_{0}", "stage.photon_trace.exit_dir_{0}",
                   "stage.receiver_hit.hit_pos_{0}")),
    (re.compile(r"stage\.photons\.start_(?:pos|dir|radiance)|stage\.march\.(?:exit_pos|exit_dir|photon_status|"
                r"hit_pos|hit_receiver)|photon_(?:exit_pos|exit_dir|status)"),
     "photons", ("stage.photons.start_pos", "stage.photons.start_dir", "photon_exit_pos", "stage.march.exit_pos",
                 "photon_exit_dir", "stage.march.exit_dir")),
)
#: how far ahead (photons) the matching looks for the next match
_ALIGN_WINDOW = 256


def _photon_set(key):
    """(set name, anchor keys) of a photon buffer, or None."""
    for rx, nm, anchors in _PHOTON_SETS:
        m = rx.fullmatch(key)
        if m:
            g = m.groups()
            return nm.format(*g), tuple(a.format(*g) for a in anchors)
    return None


def _rows_match(c_row, g_rows):
    """Which golden rows (n, ...) a candidate row equals within 1e-6 + 1e-5 |g| (NaN meets NaN)."""
    c = np.asarray(c_row, np.float64).reshape(1, -1)
    g = np.asarray(g_rows, np.float64).reshape(len(g_rows), -1)
    with np.errstate(invalid="ignore"):
        ok = (np.abs(c - g) <= 1e-6 + 1e-5 * np.abs(g)) | (np.isnan(c) & np.isnan(g))
    return ok.all(axis=1)


def _row_matches(cand, gold):
    """For each candidate row, the sorted golden rows it equals (:func:`_rows_match`), found through a sort.

    The golden rows are sorted on their first component; a candidate row is compared only with those
    whose first component lies within the tolerance's reach of its own (a binary search), and rows whose
    first component is not finite only with each other: O(n log n) for rows that match few others.
    """
    c = np.asarray(cand, np.float64)
    g = np.asarray(gold, np.float64)
    if len(c) == 0 or len(g) == 0:
        return [np.zeros(0, np.int64) for _ in range(len(c))]
    c, g = c.reshape(len(c), -1), g.reshape(len(g), -1)
    g0 = g[:, 0] if g.shape[1] else np.zeros(len(g))
    fin = np.isfinite(g0)
    order = np.flatnonzero(fin)[np.argsort(g0[fin], kind="stable")]
    keys = g0[order]
    odd = np.flatnonzero(~fin)
    out = []
    for i in range(len(c)):
        c0 = c[i, 0] if c.shape[1] else 0.0
        if np.isfinite(c0):
            # |c0 - g0| <= 1e-6 + 1e-5 |g0| implies |g0| <= (|c0| + 1e-6) / (1 - 1e-5): the reach, widened a hair
            reach = (1e-6 + 1e-5 * (abs(c0) + 1e-6) / (1.0 - 1e-5)) * (1.0 + 1e-9) + 1e-300
            lo, hi = np.searchsorted(keys, c0 - reach, "left"), np.searchsorted(keys, c0 + reach, "right")
            idx = order[lo:hi]
        else:
            idx = odd
        if len(idx):
            idx = np.sort(idx[_rows_match(c[i], g[idx])])
        out.append(idx)
    return out


def align_photons(cand, gold, window=_ALIGN_WINDOW):
    """Match two photon lists kept in one order: pairs (golden index, candidate index), in order.

    Walks both lists: equal rows (within float64 rounding) pair; otherwise the nearer of the next
    candidate row equal to the golden's and the next golden row equal to the candidate's (within
    ``window``) skips the photons between as unmatched; when neither exists the two rows pair anyway (the
    same photon, computed differently: judged, and failing, as such). Which rows equal which is found
    once, through a sort on the first component (:func:`_row_matches`), so the walk is O(n log n).

    Parameters
    ----------
    cand, gold : (P', ...), (P, ...) ndarray
        The anchor key's rows.

    Returns
    -------
    gi, ci : int ndarrays
        Indices of the matched golden and candidate photons.
    """
    nc, ng = len(cand), len(gold)
    c_to_g = _row_matches(cand, gold)
    pairs = [(int(j), i) for i, js in enumerate(c_to_g) for j in js]
    g_to_c = [[] for _ in range(ng)]
    for j, i in pairs:
        g_to_c[j].append(i)
    g_to_c = [np.asarray(x, np.int64) for x in g_to_c]

    def first_after(sorted_idx, at, limit):
        k = np.searchsorted(sorted_idx, at, "right")
        return int(sorted_idx[k]) if k < len(sorted_idx) and sorted_idx[k] < limit else None

    gi, ci = [], []
    i = j = 0
    while i < nc and j < ng:
        m = c_to_g[i]
        k = np.searchsorted(m, j, "left")
        if k < len(m) and m[k] == j:
            gi.append(j), ci.append(i)
            i, j = i + 1, j + 1
            continue
        ng_next = first_after(m, j, j + window)
        nc_next = first_after(g_to_c[j], i, min(nc, i + window))
        kg = None if ng_next is None else ng_next - j
        kc = None if nc_next is None else nc_next - i
        if kg is not None and (kc is None or kg <= kc):
            j += kg
        elif kc is not None:
            i += kc
        else:
            gi.append(j), ci.append(i)
            i, j = i + 1, j + 1
    return np.asarray(gi, np.int64), np.asarray(ci, np.int64)


def _index_list(idx, n=8):
    idx = [int(x) for x in idx]
    return ", ".join(f"#{x}" for x in idx[:n]) + (f", ... ({len(idx)} in all)" if len(idx) > n else "")


def _judge_photons(key, c, g, tol, cand, gold, cache):
    """Judge a photon buffer whose count differs from the golden's, photon by photon; None if it cannot."""
    ps = _photon_set(key)
    if ps is None or c.ndim != g.ndim or c.shape[1:] != g.shape[1:]:
        return None
    nm, anchors = ps
    a = next((a for a in anchors if a in cand and a in gold and np.asarray(cand[a]).shape[0] == c.shape[0]
              and np.asarray(cand[a]).shape[1:] == np.asarray(gold[a]).shape[1:]), None)
    if a is None:
        return None
    if (nm, a, c.shape[0]) not in cache:
        cache[(nm, a, c.shape[0])] = align_photons(np.asarray(cand[a]), np.asarray(gold[a]))
    gi, ci = cache[(nm, a, c.shape[0])]
    r = judge(c[ci], g[gi], tol)
    missing = np.setdiff1d(np.arange(g.shape[0]), gi)
    extra = np.setdiff1d(np.arange(c.shape[0]), ci)
    bad = np.zeros(g.shape[:1], bool)
    bad_m = np.asarray(r["bad"])
    while bad_m.ndim > 1:
        bad_m = bad_m.any(axis=-1)
    bad[gi] = bad_m
    bad[missing] = True
    n_info = max(g.shape[0], c.shape[0])
    n_loc = int(np.count_nonzero(bad_m)) + len(missing) + len(extra)
    frac = n_loc / max(n_info, 1)
    ok = r["ok"] and frac <= r["allowed"]
    ca = np.asarray(cand[a], np.float64)[ci].reshape(len(ci), -1)
    ga = np.asarray(gold[a], np.float64)[gi].reshape(len(gi), -1)
    with np.errstate(invalid="ignore"):
        n_eq = int(np.count_nonzero(((np.abs(ca - ga) <= 1e-6 + 1e-5 * np.abs(ga)) | (np.isnan(ca) & np.isnan(ga)))
                                    .all(axis=1)))
    detail = (f"{c.shape[0]} photons where the golden has {g.shape[0]} ({nm}): {len(gi)} paired in order along "
              f"`{a}` ({n_eq} of them equal there, the rest paired where no equal row lies within "
              f"{_ALIGN_WINDOW} photons); {len(missing)} golden photons with no counterpart "
              f"({_index_list(missing) or 'none'}); {len(extra)} candidate photons with none ({_index_list(extra) or 'none'}); on the paired "
              f"photons: {r['detail']}")
    counts = dict(r["counts"], located=n_loc, informative=n_info,
                  failing=int(r["counts"]["failing"]) + len(missing) + len(extra))
    return dict(r, ok=ok, failing=frac, counts=counts, detail=detail, bad=bad,
                photons={"matched": len(gi), "missing": [int(x) for x in missing],
                         "extra": [int(x) for x in extra], "anchor": a})


#: volumetric image keys judged with no allowance where the viewing ray stopped (status 2 limit, 4 lost)
#: and the candidate's status agrees: the colour gathered before the stop is kept (docs/oracle.md,
#: "smooth and view"), and a port that drops it differs on these pixels only, a share of the image
#: below any fraction (vol_ramp_lost: 1 lost pixel of 1089)
_STOPPED_STRICT = {"image": ("status", "stage.view.status"), "stage.view.image": ("stage.view.status", "status")}
_STOPPED = (2, 4)


def _stopped_strict(key, method, c, g, tol, cand, gold):
    """Pixels judged with no allowance (not even the ambiguity mask): the golden's stopped viewing rays
    (status 2 or 4) where the candidate's status agrees (the golden's when the candidate supplies none).

    Returns ``(failing mask, shaped as the key's elementwise mask, detail)`` or None where the rule does not
    apply.
    """
    names = _STOPPED_STRICT.get(key)
    if method != "volumetric" or names is None or tol.get("kind") != "close" or g.ndim != 3:
        return None
    gs = next((np.asarray(gold[n]) for n in names if n in gold and np.shape(gold[n]) == g.shape[:2]), None)
    if gs is None:
        return None
    cs = next((np.asarray(cand[n]) for n in names if n in cand and np.shape(cand[n]) == g.shape[:2]), gs)
    strict = np.isin(gs, _STOPPED) & (cs == gs)
    n = int(np.count_nonzero(strict))
    if n == 0:
        return None
    el = _elementwise(np.asarray(c), np.asarray(g), tol, None)[0]  # the key's own tolerance, element by element
    bad = strict.reshape(strict.shape + (1,) * (el.ndim - 2)) & el
    nb = int(np.count_nonzero(_fold(bad, strict.shape) if bad.ndim > 2 else bad))
    detail = (f"; stopped viewing rays (status 2 or 4, statuses agreeing): {nb} of {n} pixels differ, "
              f"judged with no allowance{' FAIL' if nb else ''}")
    return bad, detail


def _weight_mask(key, tol, gold):
    """Elements judged under a ``weight_key`` floor: the golden companion's (summed over channels) above
    ``floor`` times its maximum, shaped (..., 1) to broadcast over the key's channels; None without one."""
    wk = tol.get("weight_key")
    if not wk:
        return None
    head, _, last = key.rpartition(".")
    comp = (head + "." if head else "") + last.replace(last.split("_")[0], wk, 1) if last else None
    w = gold.get(comp)
    g = gold.get(key)
    if w is None or g is None:
        return None
    w = np.abs(np.asarray(w, np.float64))
    if w.ndim == g.ndim and w.shape[-1] == 3:
        w = w.sum(axis=-1)
    if w.shape != g.shape[:w.ndim]:
        return None
    mx = float(np.max(w)) if w.size else 0.0
    m = w > float(tol.get("floor", 0.0)) * mx
    return m.reshape(m.shape + (1,) * (g.ndim - m.ndim))


# --------------------------------------------------------------------- panels
def _popcount(words):
    """Set bits per pixel of (H, W, K) unsigned words."""
    w = np.ascontiguousarray(words)
    return np.unpackbits(w.view(np.uint8).reshape(w.shape[:-1] + (-1,)), axis=-1).sum(axis=-1)


def _view(shape, bad, kind, pics):
    """Which 2D picture of an array to show: (index into the array, label), the one with the most failures."""
    bad = np.asarray(bad) if bad is not None else None
    pic_shapes = list(pics)
    if len(shape) >= 3 and tuple(shape[1:3]) in pic_shapes and tuple(shape[:2]) not in pic_shapes:
        counts = bad.reshape(shape[0], -1).sum(axis=1) if bad is not None and bad.shape[:1] == shape[:1] else None
        i = int(np.argmax(counts)) if counts is not None and counts.any() else 0
        return (i,), f"layer {i} of {shape[0]} (the one with the most failures)"
    if len(shape) == 4:  # (H, W, K, 3): interface k
        counts = bad.reshape(shape[0] * shape[1], shape[2], -1).any(-1).sum(0) if bad is not None \
            and bad.ndim >= 3 else None
        i = int(np.argmax(counts)) if counts is not None and counts.any() else 0
        return (slice(None), slice(None), i), f"interface {i} of {shape[2]}"
    return (), ""


def _panel(path, key, c, g, bad, kind=None, pics=None):
    """Candidate, golden and their difference for a failing array, the failing elements marked in red.

    Bit words (H, W, K) show the set bits per pixel and the bits that differ
    (popcount of XOR); unit vectors (``kind == 'angle'``, (..., 3)) show the
    directions as colours and the angle between them in degrees; layered
    arrays (L, H, W, ...) and path records (H, W, K, 3) the layer or
    interface with the most failures (named in the titles); 3-vectors
    otherwise their length.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    c, g = np.asarray(c), np.asarray(g)
    if c.shape != g.shape or c.ndim < 2:
        return None
    idx, label = _view(c.shape, bad, kind, pics or {})
    if idx:
        c, g = c[idx], g[idx]
        bad = np.asarray(bad)[idx] if bad is not None and np.ndim(bad) >= len(idx) else bad
    bad2 = None
    if bad is not None:
        b = np.asarray(bad)
        while b.ndim > 2:
            b = b.any(axis=-1)
        bad2 = b if b.shape == c.shape[:2] else None

    def img(a):
        a = np.asarray(a, np.float64)
        while a.ndim > 3 or (a.ndim == 3 and a.shape[-1] not in (3,)):
            a = a[a.shape[0] // 2] if a.ndim > 3 or a.shape[0] > 3 else a[0]
        if a.ndim == 3:
            a = np.linalg.norm(np.nan_to_num(a), axis=-1)
        return np.atleast_2d(a)

    rgb = None
    comp = ""
    if np.issubdtype(c.dtype, np.unsignedinteger) and c.ndim == 3:
        ci, gi, diff = _popcount(c), _popcount(g), _popcount(c ^ g)
        names = ("set bits per pixel", "bits that differ")
    elif kind == "angle" and c.shape[-1] == 3 and c.ndim in (2, 3):
        cf, gf = np.asarray(c, np.float64), np.asarray(g, np.float64)
        if c.ndim == 2:  # (N, 3): a strip
            cf, gf = cf[None], gf[None]
            bad2 = None
        unit = lambda a: a / np.maximum(np.linalg.norm(np.nan_to_num(a), axis=-1, keepdims=True), 1e-300)  # noqa: E731
        cos = np.clip(np.sum(unit(np.nan_to_num(cf)) * unit(np.nan_to_num(gf)), axis=-1), -1.0, 1.0)
        diff = np.degrees(np.arccos(cos))
        diff[~(np.all(np.isfinite(cf), -1) & np.all(np.isfinite(gf), -1))] = np.nan
        rgb = [np.clip(0.5 + 0.5 * np.nan_to_num(unit(a)), 0.0, 1.0) for a in (cf, gf)]
        ci = gi = None
        names = ("direction as colour (x, y, z -> r, g, b)", "angle between them (deg)")
    else:
        if c.ndim == 3 and c.shape[-1] == 3:
            comp = "length of the 3-vector"
        ci, gi = img(c), img(g)
        if ci.ndim != 2 or ci.shape != gi.shape:
            return None
        with np.errstate(invalid="ignore"):  # inf - inf where both are absent: shown blank
            diff = np.abs(ci - gi)
        names = (comp, "|candidate - golden|")
    sub = "; ".join(x for x in (label, names[0]) if x)
    fig = Figure(figsize=(12, 4.4))
    FigureCanvasAgg(fig)
    ax = fig.subplots(1, 3)
    if rgb is not None:
        for x, a, t in ((ax[0], rgb[0], "candidate"), (ax[1], rgb[1], "golden")):
            x.imshow(a, interpolation="nearest")
            x.set_title(f"{t}: {key}\n{sub}", fontsize=9)
    else:
        fin = np.isfinite(gi)
        lo, hi = (float(np.min(gi[fin])), float(np.max(gi[fin]))) if fin.any() else (0.0, 1.0)
        for x, a, t in ((ax[0], ci, "candidate"), (ax[1], gi, "golden")):
            im = x.imshow(a, vmin=lo, vmax=hi if hi > lo else lo + 1, cmap="viridis", interpolation="nearest")
            x.set_title(f"{t}: {key}" + (f"\n{sub}" if sub else ""), fontsize=9)
            fig.colorbar(im, ax=x, fraction=0.046)
    im = ax[2].imshow(diff, cmap="magma", interpolation="nearest")
    title = names[1]
    if bad2 is not None and bad2.shape == np.shape(diff) and bad2.any():
        ax[2].imshow(np.ma.masked_where(~bad2, np.ones(bad2.shape)), cmap="autumn", vmin=0, vmax=1,
                     interpolation="nearest", alpha=0.8)
        title += f"\nred: {int(bad2.sum())} failing outside the ambiguity mask"
    ax[2].set_title(title, fontsize=9)
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    for x in ax:
        x.set_xticks([])
        x.set_yticks([])
    fig.tight_layout()
    return savefig_atomic(fig, path, dpi=70)


def _same_bytes(a, b):
    """Two arrays with the same dtype, shape and bytes."""
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and np.ascontiguousarray(a).tobytes() == \
        np.ascontiguousarray(b).tobytes()


def _safe(name):
    return "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in name)


# --------------------------------------------------------------------- the check
def check(candidate, golden, require=(), report=None, panels=True, cases=None, allow_extra=False):
    """Judge a candidate folder against a golden suite.

    Parameters
    ----------
    candidate, golden : str
        Folders (see the module docstring).
    require : sequence of str
        Keys every case must supply (a missing one fails the case).
    report : str, optional
        Folder for ``report.md``, ``summary.json``, masks and panels (default: ``candidate/report``).
    panels : bool
        Write a PNG panel per failing key (the ``.fail.npy`` masks are written regardless).
    cases : sequence of str, optional
        Judge only these cases of the suite (each must be in the candidate folder).
    allow_extra : bool
        Accept keys the contract does not have (listed per case in ``extra``); by default they fail
        the case (a typo such as ``exit_dirr`` must not pass unjudged).

    Returns
    -------
    CheckReport
        ``ok`` (every case requested passed, and at least one was judged), ``cases`` (per case a
        :class:`CaseReport`: ``ok``, ``earliest_failing_stage``, ``problems``, ``extra``, ``keys`` with
        each key's judgement), ``seconds``, ``report`` (the path of ``report.md``).

    Raises
    ------
    CheckError
        When the golden suite cannot be used (no manifest, incomplete, another contract version) or the
        candidate folder does not exist.
    """
    t0 = time.perf_counter()
    man = _load_manifest(golden)
    report = report or os.path.join(candidate, "report")
    if not os.path.isdir(candidate):
        raise CheckError(f"check: the candidate folder '{candidate}' does not exist")
    if isinstance(cases, str):
        cases = [c for c in cases.split(",") if c.strip()]
    names = list(man["cases"]) if not cases else [c.strip() for c in cases]
    out = CheckReport(ok=False, golden=os.path.abspath(golden), candidate=os.path.abspath(candidate),
                      contract_version=CONTRACT_VERSION, cases={})
    for name in names:
        res = CaseReport(ok=False, problems=[], keys={}, extra=[], earliest_failing_stage=None, method=None)
        out["cases"][name] = res
        _judge_case(res, name, man["cases"].get(name), candidate, golden, require, report, panels, allow_extra)
    out["ok"] = bool(out["cases"]) and all(c["ok"] for c in out["cases"].values())
    out["seconds"] = time.perf_counter() - t0
    os.makedirs(report, exist_ok=True)
    with atomic_open(os.path.join(report, "summary.json"), "w") as f:
        json.dump(out, f, indent=1, default=float)
    with atomic_open(os.path.join(report, "report.md"), "w") as f:
        f.write(format_report(out))
    out["report"] = os.path.join(report, "report.md")
    return out


def _judge_case(res, name, entry, candidate, golden, require, report, panels, allow_extra):
    """Fill one case's :class:`CaseReport` (``res``) in place."""
    if entry is None:
        res["problems"].append(f"the suite has no case '{name}'")
        return
    res["method"] = entry["method"]
    cpath = os.path.join(candidate, name, "result.npz")
    cand, why = _read_result(cpath)
    if cand is None:
        res["problems"].append(f"missing: {os.path.join(name, 'result.npz')} (the backend did not run this case)"
                               if why == "missing" else why)
        return
    with np.load(os.path.join(golden, name, "golden.npz"), allow_pickle=False) as z:
        gold = {k: z[k] for k in z.files}
    batches = {}
    if "batches" in entry:
        with np.load(os.path.join(golden, name, "batches.npz"), allow_pickle=False) as z:
            batches = {k: z[k] for k in z.files}
    problems = res["problems"]
    failed = False
    for k in require:
        if k not in cand:
            failed = True
            problems.append(f"required key '{k}' is missing")
    unknown = sorted(k for k in cand if k not in entry["keys"])
    if unknown:
        if allow_extra:
            res["extra"] = unknown
            problems.append(f"keys the contract does not have, accepted (allow_extra) and not judged: "
                            f"{', '.join(unknown)}")
        else:
            failed = True
            hints = []
            for u in unknown:
                near = difflib.get_close_matches(u, list(entry["keys"]), n=1)
                hints.append(f"'{u}'" + (f" (did you mean '{near[0]}'?)" if near else ""))
            problems.append(f"keys the contract does not have: {', '.join(hints)}; rename them, or pass "
                            "--allow-extra (allow_extra=True) for a backend's own keys")
    order = list(entry["stages"])
    rank = {s: i for i, s in enumerate(order)}
    # within a stage, the keys a replay may explain after the others (the light's exit points after its LDI)
    later = (lambda k: _explanation(k) is not None) if entry["method"] == "imagespace" else (lambda k: False)
    keys = sorted((k for k in entry["keys"] if k in cand), key=lambda k: (rank.get(entry["keys"][k]["stage"],
                                                                                     len(order)), later(k), k))
    pics = _context(gold)
    passed = {}
    explained = {}  # (replay group, light) -> {key: the oracle's pass run on the candidate's upstream}
    judged_as = {}  # (golden sha256, tolerance) -> the key judged: a byte-identical copy is judged once
    photon_cache = {}
    for k in keys:
        spec = entry["keys"][k]
        # a manifest written without a key's tolerance (by hand, or by another tool): the table's, or its default
        tol = dict(spec.get("tolerance") or tolerance_for(k, dtype=spec.get("dtype")))
        c, g = cand[k], gold[k]
        j = {"stage": spec["stage"], "kind": tol["kind"], "tolerance": tol, "why": tol.get("why", "")}
        res["keys"][k] = j
        bad = None
        sig = (spec.get("sha256"), json.dumps(tol, sort_keys=True, default=str))
        first = judged_as.get(sig) if spec.get("sha256") else None
        if first is not None and _same_bytes(cand[first], c):
            f = res["keys"][first]
            j.update(ok=f["ok"], same_as=first, kind=f["kind"], why=f"as `{first}`",
                     detail=f"same as `{first}` (byte-identical to it here and in the golden): judged once there")
            passed[k] = bool(j["ok"])
            if not j["ok"]:
                failed = True
            continue
        if spec.get("sha256"):
            judged_as.setdefault(sig, k)
        if tuple(c.shape) != tuple(spec["shape"]):
            r = None
            if _dtype_problem(c, spec) is None:
                try:
                    r = _judge_photons(k, np.asarray(c), np.asarray(g), tol, cand, gold, photon_cache)
                except ValueError:
                    r = None
            if r is None:
                ps = _photon_set(k)
                have = [a for a in (ps[1] if ps else ()) if a in cand and np.shape(cand[a])[:1] == np.shape(c)[:1]]
                hint = ("" if not ps else
                        f" (its photons could not be matched along `{have[0]}`, which has the same count)" if have else
                        f" (supply one of {', '.join(f'`{a}`' for a in ps[1])} with this key's photon count, "
                        f"{np.shape(c)[0]}, to have the photons matched one by one)")
                j.update(ok=False, detail=f"shape {tuple(c.shape)} where the golden has {tuple(spec['shape'])}" + hint)
            else:
                r.pop("bad")  # over the golden's photons, not the candidate's: no mask file
                j.update(r)
        elif _dtype_problem(c, spec):
            j.update(ok=False, detail=_dtype_problem(c, spec))
        else:
            amb = _ambiguity(k, g, tol, pics, c)
            if tol.get("face_ties"):
                ties = face_ties(golden, name, gold, k, c)
                if ties is not None:
                    amb = ties if amb is None else (np.asarray(amb, bool) | ties)
            if tol.get("margin_key"):
                ties = margin_ties(gold, k, tol)
                if ties is not None:
                    amb = ties if amb is None else (np.asarray(amb, bool) | ties)
            try:
                r = judge(c, g, tol, batches.get(k), amb, judged=_weight_mask(k, tol, gold))
            except ValueError as e:
                r = {"ok": False, "detail": str(e), "failing": 1.0, "allowed": 0.0, "error": {}, "bad": None}
            how = _explanation(k) if not r["ok"] and entry["method"] == "imagespace" else None
            if how is not None:
                group, light, upstream = how
                if (group, light) not in explained:  # once per replay, after its upstream keys were judged
                    explained[(group, light)] = _explain(group, light, golden, name, gold, cand, passed)
                e = explained[(group, light)].get(k)
                if e is not None and e.shape == g.shape:
                    r2 = judge(c, e.astype(g.dtype), tol, None, amb)
                    if r2["ok"]:
                        own = [u for u in upstream if u in cand and passed.get(u)]
                        ups = " and ".join(own) if len(own) < 3 else ", ".join(own[:-1]) + " and " + own[-1]
                        r2["detail"] = (f"differs from the golden where the candidate's own {ups} (within "
                                        + ("its tolerance) does" if len(own) < 2 else "their tolerances) do")
                                        + "; against the oracle's pass run on " + ("it: " if len(own) < 2 else
                                                                                  "them: ") + r2["detail"])
                        r2["explained_by"] = ups
                        r = r2
            st = _stopped_strict(k, entry["method"], c, g, tol, cand, gold)
            if st is not None:
                sbad, sdetail = st
                r["detail"] = r.get("detail", "") + sdetail
                if np.any(sbad):
                    r["ok"] = False
                    rb = r.get("bad")
                    r["bad"] = sbad if rb is None or np.shape(rb) != sbad.shape else (np.asarray(rb, bool) | sbad)
            bad = r.pop("bad")
            if tol.get("default"):
                r["detail"] = "default tolerance (no rule names this key): " + r["detail"]
            j.update(r)
        passed[k] = bool(j["ok"])
        if not j["ok"]:
            failed = True
            if bad is not None and np.any(bad):
                os.makedirs(report, exist_ok=True)
                mpath = os.path.join(report, f"{_safe(name)}__{_safe(k)}.fail.npy")
                with atomic_path(mpath) as tmp:
                    with open(tmp, "wb") as f:
                        np.save(f, np.asarray(bad))
                j["mask"] = os.path.basename(mpath)
            if panels and (bad is not None or j.get("detail", "").startswith("dtype")):
                os.makedirs(report, exist_ok=True)
                try:
                    pp = _panel(os.path.join(report, f"{_safe(name)}__{_safe(k)}.png"), k, c, g, bad, j["kind"],
                                pics)
                except (ValueError, TypeError):  # a candidate array that cannot be pictured: the row says why
                    pp = None
                if pp:
                    j["panel"] = os.path.basename(pp)
    if not res["keys"]:
        failed = True
        problems.append("no key of the contract was judged: the result holds none of the golden's keys "
                        f"({len(cand)} keys supplied; the contract's are listed in the manifest)")
    failing = [j["stage"] for j in res["keys"].values() if not j["ok"]]
    if failing:
        res["earliest_failing_stage"] = min(failing, key=lambda s: rank.get(s, len(order)))
    res["ok"] = not failed


def format_report(out):
    """The Markdown report of a :func:`check`.

    Parameters
    ----------
    out : CheckReport or dict
        What :func:`check` returns: ``ok``, ``candidate``, ``golden``,
        ``contract_version`` and per case ``ok``, ``method``,
        ``earliest_failing_stage``, ``problems`` and ``keys``.

    Returns
    -------
    str
        The report: a summary table, then per case its problems and a table of
        its judged keys.
    """
    n_ok = sum(1 for c in out["cases"].values() if c["ok"])
    lines = [f"# Conformance report: {'PASS' if out['ok'] else 'FAIL'}", "",
             f"{n_ok} of {len(out['cases'])} cases pass; candidate `{out['candidate']}` against the golden suite "
             f"`{out['golden']}` (contract_version {out['contract_version']}).", "",
             "| case | method | result | earliest failing stage | keys judged |", "|---|---|---|---|---|"]
    for name, c in out["cases"].items():
        lines.append(f"| {name} | {c['method'] or ''} | {'pass' if c['ok'] else '**FAIL**'} | "
                     f"{c['earliest_failing_stage'] or ''} | {len(c['keys'])} |")
    for name, c in out["cases"].items():
        lines += ["", f"## {name}: {'pass' if c['ok'] else 'FAIL'}"]
        if c["earliest_failing_stage"]:
            lines.append(f"\nEarliest failing stage: **{c['earliest_failing_stage']}** (fix this pass first).")
        for p in c["problems"]:
            lines.append(f"\n- {p}")
        if c["keys"]:
            lines += ["", "| key | stage | tolerance | measured | failing / allowed | result | rationale |",
                      "|---|---|---|---|---|---|---|"]
            for k, j in c["keys"].items():
                cn = j.get("counts")
                if cn and "located" in cn:
                    frac = f"{fmt_share(cn['located'], cn['informative'])} / {100 * j['allowed']:.3g} %"
                elif "failing" in j:
                    frac = f"{fmt_percent(100 * j['failing'], whole=j['failing'] >= 1)} % / {100 * j['allowed']:.3g} %"
                else:
                    frac = ""
                links = "".join(f" ([{w}]({j[w]}))" for w in ("panel", "mask") if j.get(w))
                detail = j.get("detail", "").replace("|", "\\|")  # |c| in a detail must not split the row
                why = j.get("why", "").replace("|", "\\|")
                lines.append(f"| `{k}` | {j['stage']} | {j['kind']} | {detail} | {frac} | "
                             f"{'pass' if j['ok'] else '**FAIL**'}{links} | {why} |")
    return "\n".join(lines) + "\n"

