"""The caustics cross-check: our exact caustic maps against photons traced on Mitsuba 3's intersector.

An independent photon tracer (:func:`mitsuba_photons`; for water
:func:`~refraction_ref.interop.water.mitsuba_water_photons`) deposits into
our map frames; ``K`` batches each way are compared by relative L1 beside
each side's own noise and by the golden suite's Z-test
(:func:`caustics_case`).

References
----------
.. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org.
.. [2] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
   ed., §8.2 (Snell's law, total internal reflection).
"""

from __future__ import annotations

import copy
import os
import time

import numpy as np

from ..caustics.receivers import receiver_set
from ..caustics.splat import splat_bilinear
from ..golden.build import SEED_KEY, case_scene, photon_quantum
from ..golden.tolerances import ZTEST, judge
from ..meshes import object_mesh
from ..metrics import relative_l1
from ..render import render
from . import mitsuba as M
from .rays import cross_interface, map_coords, merged_mesh, mitsuba_ray, points, receiver_soup, spawn_offset
from .water import mitsuba_water_photons, water_mesh_normal_error_deg

__all__ = ["mitsuba_photons", "caustics_case", "CAUSTIC_BATCHES"]

#: batches of each side in the caustics cross-check (the golden suite's exact_caustics_sphere uses 8)
CAUSTIC_BATCHES = 8


def _light_axes(light):
    """A directional light's unit direction ``L`` and two unit axes ``a``, ``b`` across it."""
    L = np.asarray(light["direction"], np.float64)
    L /= np.linalg.norm(L)
    a = np.cross(L, [0.0, 1.0, 0.0] if abs(L[1]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    return L, a, np.cross(L, a)


def _light_photons(light, ov, n, rng, diag):
    """``n`` x ``n`` jittered photons of a directional light over the objects' outline plus 2 %.

    Parameters
    ----------
    light : dict
        A directional light of the scene.
    ov : (V, 3) float64
        The objects' vertices.
    n : int
        Photons per side.
    rng : numpy.random.Generator
        Two draws of ``n^2`` each (columns, then rows).
    diag : float
        The scene's diagonal: the photons start ``2 diag`` before the objects' centre.

    Returns
    -------
    o, dirn : (n^2, 3) float64
        Start points and directions.
    flux : (n^2,) float64
        Each photon's share of the rectangle's area (unit irradiance perpendicular to the light).
    """
    L, a, b = _light_axes(light)
    pa, pb = ov @ a, ov @ b
    ca, cb = (pa.max() + pa.min()) / 2, (pb.max() + pb.min()) / 2
    wa, wb = 1.02 * (pa.max() - pa.min()), 1.02 * (pb.max() - pb.min())
    N = int(n) * int(n)
    gi, gj = np.divmod(np.arange(N), int(n))
    ua = (gj + rng.random(N)) / n - 0.5
    ub = (gi + rng.random(N)) / n - 0.5
    centre = ov.mean(axis=0)
    base = centre - (centre @ a) * a - (centre @ b) * b - 2.0 * diag * L
    o = base + (ca + ua * wa)[:, None] * a + (cb + ub * wb)[:, None] * b
    return o, np.tile(L, (N, 1)), np.full(N, wa * wb / N)


class _PhotonScene:
    """The objects and receivers of :func:`mitsuba_photons` as one Mitsuba scene, with what a bounce reads."""

    def __init__(self, mi, scene, folder, max_bounces):
        d = scene.data
        objs = M.object_meshes(scene)
        self.n_objects = len(objs)
        self.recv = [receiver_soup(*object_mesh(rc, scene.base_dir)) for rc in d["receivers"]]
        face_norm = any(m["normals"] is None for m in objs)
        parts = objs + [dict(r, normals=None if face_norm else r["normals"]) for r in self.recv]
        v, f, nrm, self.owner = merged_mesh(parts)  # owner < n_objects: object, else receiver owner - n_objects
        os.makedirs(folder, exist_ok=True)
        M.write_ply(os.path.join(folder, "photons.ply"), v, f, nrm)
        self.mscene = mi.load_dict({"type": "scene", "all": {"type": "ply",
                                                             "filename": os.path.join(folder, "photons.ply"),
                                                             "face_normals": nrm is None}})
        rv = [r["vertices"] for r in self.recv]
        self.rface_n = np.concatenate([np.cross(x[1::3] - x[0::3], x[2::3] - x[0::3]) for x in rv])
        self.rface_n /= np.linalg.norm(self.rface_n, axis=1, keepdims=True)
        self.nobj_faces = int(np.count_nonzero(self.owner < self.n_objects))
        self.ior = np.array([m["ior"] for m in objs] + [float(d["outside_ior"])])
        self.absn = np.array([np.asarray(m["absorption"], np.float64) * m["ior"] for m in objs] + [np.zeros(3)])
        self.max_bounces = int(d["exact"]["max_bounces"] if max_bounces is None else max_bounces)
        self.ov = np.concatenate([m["vertices"] for m in objs])
        self.eps, self.diag = spawn_offset(v)


def _deposit(ps, hits, frames, shapes, maps):
    """Splat the photons ``hits = (index, hit points, prim, flux, transmittance x radiance)`` that reached a
    receiver through an object into its map; the number deposited."""
    dep, p, prim, flux, colour = hits
    n = 0
    for r in range(len(ps.recv)):
        fr = np.asarray(frames[r], np.float64)
        sel = dep[ps.owner[prim[dep]] - ps.n_objects == r]
        if not sel.size:
            continue
        Hc, Wc = shapes[r]
        col, row = map_coords(p[sel], fr, (Hc, Wc))
        texel = np.linalg.norm(fr[1]) * np.linalg.norm(fr[2]) / (Wc * Hc)
        cosv = np.abs(ps.rface_n[prim[sel] - ps.nobj_faces] @ fr[3])
        val = flux[sel] * cosv / texel * np.mean(colour[sel], axis=1)
        splat_bilinear(col, row, val[:, None], (Hc, Wc), out=maps[r])
        n += int(sel.size)
    return n


def _trace_light(mi, ps, light, rng, n, deposit):
    """Trace one light's ``n`` x ``n`` photons through ``ps`` (:class:`_PhotonScene`); (photons, at the limit).

    ``deposit(hits)`` splats the photons that reach a receiver after at least one refraction
    (:func:`_deposit`) and returns how many it splatted.
    """
    o, dirn, flux = _light_photons(light, ps.ov, n, rng, ps.diag)
    N = len(flux)
    rad = np.asarray(light.get("radiance", [1.0, 1.0, 1.0]), np.float64)
    outside = ps.n_objects
    medium = np.full(N, outside)
    inter = np.zeros(N, np.int32)
    trans = np.ones((N, 3))
    active = np.ones(N, bool)
    deposited = limit = 0
    for bounce in range(ps.max_bounces + 1):
        si = ps.mscene.ray_intersect(mitsuba_ray(mi, o, dirn), mi.Bool(active))
        valid = np.array(si.is_valid(), dtype=bool) & active
        if not valid.any():
            break
        prim = np.array(si.prim_index, dtype=np.int64)
        p = points(si.p)
        t = np.array(si.t, dtype=np.float64)
        idx = np.flatnonzero(valid)
        seg = np.where(np.isfinite(t[idx]), t[idx], 0.0)
        trans[idx] *= np.exp(-ps.absn[medium[idx]] * seg[:, None])
        isrec = prim[idx] >= ps.nobj_faces
        # receivers: a photon through an object deposits; a direct one (no refraction) is not a caustic
        hr = idx[isrec]
        deposited += deposit((hr[inter[hr] > 0], p, prim, flux, trans * rad))
        active[hr] = False
        a_ = idx[~isrec]
        if bounce == ps.max_bounces:
            limit += int(a_.size)
            break
        if not a_.size:
            break
        ng = points(si.n)[a_]
        entering = np.sum(dirn[a_] * ng, axis=1) < 0
        obj = ps.owner[prim[a_]]
        eta = ps.ior[medium[a_]] / np.where(entering, ps.ior[obj], ps.ior[outside])
        out, tir, lost = cross_interface(dirn[a_], points(si.sh_frame.n)[a_], ng, eta)
        crossed = ~tir & ~lost
        medium[a_[crossed]] = np.where(entering[crossed], obj[crossed], outside)
        inter[a_[crossed]] += 1
        active[a_[lost]] = False
        side = np.where((np.sum(out * ng, axis=1) >= 0)[:, None], ng, -ng)
        o[a_] = p[a_] + ps.eps * out + (0.1 * ps.eps) * side
        dirn[a_] = out
        # photons that left every surface behind are done
        active[~np.array(si.is_valid(), dtype=bool) & active] = False
    return N, deposited, limit


def mitsuba_photons(scene, folder, frames, shapes, n, seed, variant="llvm_ad_rgb", max_bounces=None):
    """Caustic maps from photons traced through Mitsuba's intersector, in our map frames.

    An independent photon tracer: ``n`` x ``n`` jittered photons (stream
    ``np.random.default_rng(seed)``) over a rectangle of its own, the
    objects' outline seen along the directional light plus 2 % (not our
    light camera's window), each carrying that rectangle's area over
    ``n^2`` (unit irradiance perpendicular to the light); hits by Mitsuba's
    ``scene.ray_intersect`` (float32) on one PLY of the objects (the exact
    reference's shading normals) and receivers; Snell / TIR in float64 at
    Mitsuba's shading normals (the Fresnel-free rules of
    :func:`~refraction_ref.interop.rays.cross_interface`), spawned along the
    ray. A photon that reaches a
    receiver after at least one refraction deposits ``flux |n_r . V| /
    A_texel`` (its irradiance on the receiver; ``V`` the frame's normal) at
    its position in that receiver's frame ``(origin, u, v, V)`` with
    bilinear weights (:func:`~refraction_ref.caustics.splat.splat_bilinear`,
    the binning our maps use; the Z-test compares like estimators). Beer-
    Lambert ``exp(-a ior l)`` per channel, averaged over the channels.

    Parameters
    ----------
    scene : Scene
        Directional lights only.
    folder : str
        Where the merged PLY of the objects and receivers is written.
    frames : list of (4, 3) arrays
        Our ``caustic_frame_r`` (the only thing read from our side).
    shapes : list of (Hc, Wc)
    n : int
        Photons per side, per light.
    seed : int
        Seed of the jitter.
    variant : str
        Mitsuba variant.
    max_bounces : int, optional
        Interfaces a photon may cross (default ``exact.max_bounces``).

    Returns
    -------
    maps : list of (Hc, Wc) float64
    stats : dict
        Photons traced, reaching a receiver through an object, stopped at the bounce limit.

    References
    ----------
    .. [1] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd ed., §8.2.
    """
    mi = M.require(variant)
    lights = scene.data.get("lights") or []
    if any(lt["type"] != "directional" for lt in lights):
        raise ValueError("mitsuba_photons: directional lights only (a point light's photons are not built)")
    ps = _PhotonScene(mi, scene, folder, max_bounces)
    maps = [np.zeros(tuple(sh) + (1,)) for sh in shapes]
    stats = {"photons": 0, "deposited": 0, "limit": 0}
    rng = np.random.default_rng(int(seed))
    for lt in lights:
        traced, deposited, limit = _trace_light(mi, ps, lt, rng, n,
                                                lambda hits: _deposit(ps, hits, frames, shapes, maps))
        stats["photons"] += traced
        stats["deposited"] += deposited
        stats["limit"] += limit
    return [m[..., 0] for m in maps], stats


def _mesh_photons_per_side(scene, quantum, oversample):
    """Photons per side for Mitsuba's window at ``oversample`` times our photon density; (n, our flux, area)."""
    texel_min = min(b.texel_area for b in receiver_set(scene, scene.data["lights"][0],
                                                       int(scene.data["caustics"]["map_size"])).boxes)
    flux_ours = quantum * texel_min / max([float(np.max(lt.get("radiance", [1.0]))) for lt in scene.data["lights"]]
                                          + [1.0])
    ov = np.concatenate([m["vertices"] for m in M.object_meshes(scene)])
    _, a, b = _light_axes(scene.data["lights"][0])
    area = 1.02 ** 2 * np.ptp(ov @ a) * np.ptp(ov @ b)
    return int(np.ceil(np.sqrt(oversample * area / flux_ours))), flux_ours, area


def _batches(scene, folder, frames, shapes, quantum, sizes):
    """Mitsuba's batches (``sizes = (K, oversample)``), of the mesh caustics (:func:`mitsuba_photons`) or
    the water's (:func:`~refraction_ref.interop.water.mitsuba_water_photons`), ``oversample`` times our
    photon density over its own window; (maps per batch, numbers for the report)."""
    K, oversample = sizes
    if scene.data.get("water") is not None:
        w = scene.data["water"]
        samples = int(scene.data["exact"]["water_samples"])
        sx, sz = (float(v) for v in w["size"])
        flux_ours = sx * sz / (samples * samples)  # one water sample's area (per unit light, as photon_flux_mitsuba)
        mit, st = mitsuba_water_photons(scene, folder, frames, shapes, oversample / flux_ours,
                                        [1000 + k for k in range(K)])
        return mit, {"photons_ours": samples * samples, "photons_mitsuba": st["photons"],
                     "photon_flux_ours": flux_ours, "photon_flux_mitsuba": st["window"] / st["photons"],
                     "deposited_mitsuba": st["deposited"], "water_mitsuba": st["water"], "limit_mitsuba": 0,
                     "water_resolution": st["resolution"],
                     "normal_error_deg": water_mesh_normal_error_deg(w, st["resolution"])}
    n, flux_ours, area = _mesh_photons_per_side(scene, quantum, oversample)
    mit, st = [], []
    for k in range(K):
        m, s_ = mitsuba_photons(scene, folder, frames, shapes, n, 1000 + k)
        mit.append(m)
        st.append(s_)
    return mit, {"photons_ours": int(scene.data["exact"]["photons"]) ** 2, "photons_mitsuba": n * n,
                 "photon_flux_ours": flux_ours, "photon_flux_mitsuba": area / (n * n),
                 "deposited_mitsuba": int(np.mean([x["deposited"] for x in st])),
                 "limit_mitsuba": int(np.mean([x["limit"] for x in st]))}


def _receiver_row(ob, mb, quantum, own_quantum):
    """One receiver's numbers: our batches ``ob`` and Mitsuba's ``mb`` (K, Hc, Wc) compared."""
    K = len(ob)
    our_mean, mit_mean = ob.mean(0), mb.mean(0)
    h = K // 2
    spec = dict(ZTEST, quantum=quantum)
    verd = [judge(mb[k], our_mean, spec, batches=ob) for k in range(K)]
    back = [judge(ob[k], mit_mean, spec, batches=mb) for k in range(K)]
    # the golden quantum is one photon on the smallest texel of all the maps: on a receiver of larger
    # texels its floor p q^2 swamps the batch variance; the same test with this map's own quantum is stricter
    own = [judge(mb[k], our_mean, dict(ZTEST, quantum=own_quantum), batches=ob) for k in range(K)]
    return {
        "rel_l1": float(relative_l1(mit_mean, our_mean)),
        "rel_l1_ours_halves": float(relative_l1(ob[:h].mean(0), ob[h:].mean(0))),
        "rel_l1_mitsuba_halves": float(relative_l1(mb[:h].mean(0), mb[h:].mean(0))),
        "power_ratio": float(mit_mean.sum() / max(float(our_mean.sum()), 1e-30)),
        "batches": K, "ztest_pass": int(sum(v["ok"] for v in verd)),
        "ztest_max_abs_z": float(max(v["error"]["max_abs_z"] for v in verd)),
        "ztest_threshold": float(verd[0]["error"]["threshold"]),
        "ztest_reverse_pass": int(sum(v["ok"] for v in back)),
        "ztest_own_quantum_pass": int(sum(v["ok"] for v in own)),
        "ztest_own_quantum_max_abs_z": float(max(v["error"]["max_abs_z"] for v in own)),
    }, {"ours": our_mean, "mitsuba": mit_mean}


def caustics_case(case, folder, batches=None, oversample=2.0):
    """Our exact caustic maps against the independent photon tracer on Mitsuba's intersector.

    ``K`` batches each way: ours with ``exact.photon_seed = 0 .. K-1`` (as
    ``golden build``), Mitsuba's with seeds ``1000 + k`` and
    ``oversample`` times our photon density (its per-photon flux at most
    ours / oversample). Per receiver: relative L1 of the K-batch means
    (blurred one texel, :func:`~refraction_ref.metrics.relative_l1`)
    beside each side's own noise (the same measure between its two halves of
    batches), and the golden suite's Z-test
    (:data:`~refraction_ref.golden.tolerances.ZTEST`, ``quantum`` as
    ``golden build``): every Mitsuba batch against our K batches.

    Parameters
    ----------
    case : dict
        A catalogue case with lights and receivers.
    folder : str
        Scratch folder for the scene and Mitsuba's files.
    batches : int, optional
        ``K``; default the case's ``batches`` or :data:`CAUSTIC_BATCHES`.
    oversample : float
        Mitsuba's photon density over ours.

    Returns
    -------
    num : dict
        Photon counts and fluxes, and per receiver (``receivers``) the
        relative L1, the halves' noise, the power ratio and the Z-test counts.
    figs : list of dict
        Per receiver the K-batch means ``ours`` and ``mitsuba`` (map shape).

    References
    ----------
    .. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org.
    """
    K = int(batches or case.get("batches") or CAUSTIC_BATCHES)
    if case["scene"].get("water") is not None:  # the maps do not read the camera: a small one keeps our K
        case = copy.deepcopy(case)  # renders' image stage short
        case["scene"]["camera"] = dict(case["scene"]["camera"], width=8, height=8)
    scene = case_scene(case, os.path.join(folder, "scene"))
    t0 = time.perf_counter()
    ours = [render(scene, method="exact", overrides={SEED_KEY: b}).arrays for b in range(K)]
    t1 = time.perf_counter()
    R = len(scene.data["receivers"])
    frames = [ours[0][f"caustic_frame_{r}"] for r in range(R)]
    shapes = [ours[0][f"caustic_map_{r}"].shape for r in range(R)]
    q = photon_quantum(scene)
    mit, info = _batches(scene, os.path.join(folder, "mitsuba"), frames, shapes, q, (K, oversample))
    t2 = time.perf_counter()
    num = dict(info, batches=K, quantum=q, ours_s=t1 - t0, mitsuba_s=t2 - t1, receivers=[])
    figs = []
    # texel area of each map over the smallest (the golden quantum is for the smallest)
    texel = [float(np.linalg.norm(np.cross(f[1], f[2]))) / (sh[0] * sh[1]) for f, sh in zip(frames, shapes)]
    texel = [min(texel) / t for t in texel]
    for r in range(R):
        ob = np.stack([o[f"caustic_map_{r}"].astype(np.float64) for o in ours])
        mb = np.stack([m[r] for m in mit])
        row, fig = _receiver_row(ob, mb, q, q * texel[r] / max(texel))
        num["receivers"].append(row)
        figs.append(fig)
    return num, figs
