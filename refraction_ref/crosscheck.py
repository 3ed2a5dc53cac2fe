"""``refraction-ref crosscheck``: the exact references checked against an independent renderer, Mitsuba 3.

For every case of the golden catalogue (:mod:`refraction_ref.golden.build`)
with an exact reference, the scene is exported to Mitsuba
(:mod:`refraction_ref.interop.mitsuba`) and measured three ways:

``paths``
    Every pixel's ray through Mitsuba's own sensor, intersection
    (``scene.ray_intersect``, float32) and shading normals (``si.sh_frame.n``),
    refracted here by Snell's law in float64 (the exact references'
    conventions: shading normal flipped to the geometric side, the geometric
    normal where the shading normal sends the ray to the wrong side, total
    internal reflection followed, the medium by the geometric normal),
    against our exact method's ``exit_dir``, ``exit_pos`` and ``status``:
    median, p99 and largest angle between the exit directions where both
    exit, status agreement over all pixels. The primary rays themselves are
    compared first (the camera convention).
``images``
    Our exact image against Mitsuba's ``path`` integrator (``volpath`` when
    an object absorbs) with the Fresnel-free BSDF
    (:func:`~refraction_ref.interop.mitsuba.register_refract_bsdf`) through
    the pixel centres: relative RMSE; and with Mitsuba's own ``dielectric``
    (Fresnel), to say how far Fresnel moves each image.
``caustics``
    Our exact caustic maps against Mitsuba's particle tracer on the same
    receivers in our map frames.

Every case is one Dask task when ``workers`` (a ``LocalCluster``) or a
``scheduler`` is given, as ``golden build`` runs its cases.

References
----------
.. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org.
.. [2] M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 3rd
   ed., §8.2 (Snell's law, total internal reflection).
"""

from __future__ import annotations

import copy
import json
import os
import tempfile
import time

import numpy as np

from .status import EXITED, LIMIT, LOST, MISSED, TIR

__all__ = ["crosscheck_cases", "mitsuba_paths", "paths_case", "images_case", "run_case", "run", "TARGETS",
           "angle_deg", "relative_rmse"]

#: the targets of the cross-check (issue "Ground truth checked by an independent renderer")
TARGETS = {"median_deg": 0.01, "p99_deg": 0.5, "status_agree": 0.99, "image_rel_rmse": 0.01}
#: cases whose long TIR chains diverge between two float32-hit tracers (reported, not judged)
TIR_CHAOS = ("is_diamond_2_4", "is_tir_followed")


def crosscheck_cases(only=None):
    """The golden catalogue's cases (or ``only`` those): every one gets a row, cases without a
    cross-check a reason (:func:`run_case`)."""
    from .golden.build import catalogue

    return catalogue(only)


def angle_deg(a, b):
    """Angle in degrees between unit vectors (..., 3), accurate near zero (atan2 of cross and dot)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.degrees(np.arctan2(c, np.sum(a * b, axis=-1)))


def relative_rmse(a, b):
    """``sqrt(mean((a - b)^2)) / mean(|b|)`` over all pixels and channels (b: the reference)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return float(np.sqrt(np.mean((a - b) ** 2)) / max(float(np.mean(np.abs(b))), 1e-30))


# --------------------------------------------------------------------------- Mitsuba paths
def _np3(v):
    return np.array(v, dtype=np.float64).reshape(3, -1).T


def _refract(d, n, eta):
    """Snell / TIR of unit directions ``d`` at normals ``n`` (any side), relative index ``eta``, float64."""
    s = np.where(np.sum(d * n, axis=1) < 0, 1.0, -1.0)[:, None]
    nf = n * s  # facing the incoming ray
    ci = -np.sum(d * nf, axis=1)
    k = 1.0 - eta * eta * (1.0 - ci * ci)
    tir = k < 0
    t = eta[:, None] * d + (eta * ci - np.sqrt(np.maximum(k, 0.0)))[:, None] * nf
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    r = d + (2 * ci)[:, None] * nf
    return np.where(tir[:, None], r, t), tir


def _merged_mesh(meshes):
    vs, fs, ns, fo = [], [], [], []
    off = 0
    face_normals = any(m["normals"] is None for m in meshes)
    for k, m in enumerate(meshes):
        vs.append(m["vertices"])
        fs.append(m["faces"] + off)
        ns.append(m["normals"] if m["normals"] is not None else np.zeros_like(m["vertices"]))
        fo.append(np.full(len(m["faces"]), k, np.int64))
        off += len(m["vertices"])
    return (np.concatenate(vs), np.concatenate(fs), None if face_normals else np.concatenate(ns),
            np.concatenate(fo))


def mitsuba_paths(scene, folder, variant="llvm_ad_rgb", max_bounces=None, spawn="line", record=0):
    """Every pixel's path through Mitsuba's sensor, intersections and shading normals.

    Parameters
    ----------
    scene : Scene
        A scene with refractive objects (no water).
    folder : str
        Where the exported mesh goes.
    variant : str
        A vectorised variant: ``llvm_ad_rgb`` (all pixels per call) or ``cuda_ad_rgb``.
    spawn : {'line', 'mitsuba'}
        How a ray leaves a surface: ``'line'`` from Mitsuba's hit point moved
        ``1e-5 scale`` along the new direction and ``1e-6 scale`` off the
        surface (the exact tracer's offset is ``1e-5 scale`` along both, and it
        then recomputes the hit from the un-offset point); ``'mitsuba'``
        Mitsuba's ``si.spawn_ray`` (``(1 + max |p|) 8.9e-5`` along the
        geometric normal: the next hit moves by about that much, which moves
        the exit directions by about 0.01 degrees, see docs/oracle.md).
    record : int
        Keep the first ``record`` hit points per path (``path_pos``, as the
        exact reference's ``exact.record``), to find where two paths part.

    Returns
    -------
    dict
        ``ray_origin``, ``ray_dir`` (H, W, 3) of Mitsuba's sensor; ``status``
        (H, W) int8 (:mod:`refraction_ref.status`), ``exit_pos``,
        ``exit_dir`` (H, W, 3), ``interfaces`` and ``events`` (H, W: refractions; refractions and
        total internal reflections).
    """
    from .camera import Camera
    from .interop import mitsuba as M

    mi = M.require(variant)
    d = scene.data
    cam = Camera.from_dict(d["camera"])
    H, W = cam.height, cam.width
    meshes = M.object_meshes(scene)
    os.makedirs(folder, exist_ok=True)
    v, f, nrm, fo = _merged_mesh(meshes)
    M.write_ply(os.path.join(folder, "objects.ply"), v, f, nrm)
    sdict = {"type": "scene",
             "sensor": {"type": "perspective", "fov": float(cam.fov_y), "fov_axis": "y", "near_clip": 1e-4,
                        "far_clip": 1e4,
                        "to_world": mi.ScalarTransform4f().look_at(origin=list(cam.eye), target=list(cam.target),
                                                                   up=list(cam.up)),
                        "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}}},
             "objects": {"type": "ply", "filename": os.path.join(folder, "objects.ply"),
                         "face_normals": nrm is None}}
    s = mi.load_dict(sdict)
    sensor = s.sensors()[0]
    n = H * W
    idx = np.arange(n)
    ii, jj = idx // W, idx % W
    pos = np.stack([(jj + 0.5) / W, (ii + 0.5) / H]).astype(np.float32)
    ior = np.array([m["ior"] for m in meshes] + [float(d["outside_ior"])])
    outside = len(meshes)
    maxb = int(d["exact"]["max_bounces"] if max_bounces is None else max_bounces)
    status = np.full(n, -1, np.int8)
    exit_pos = np.full((n, 3), np.nan)
    exit_dir = np.full((n, 3), np.nan)
    interfaces = np.zeros(n, np.int16)
    medium = np.full(n, outside, np.int64)
    last_tir = np.zeros(n, bool)
    pos_now = np.full((n, 3), np.nan)
    path_pos = np.full((n, max(int(record), 1), 3), np.nan)
    events = np.zeros(n, np.int32)

    if variant.startswith("scalar"):
        raise ValueError("mitsuba_paths: use a vectorised variant (llvm_ad_rgb); scalar_rgb is for single rays")
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(pos[0], pos[1]), mi.Point2f(0.5, 0.5))
    ray = mi.Ray3f(ray)
    o0 = _np3(ray.o)
    dirn = _np3(ray.d)
    dirn /= np.linalg.norm(dirn, axis=1, keepdims=True)
    d0 = dirn.copy()
    from .meshes import bounds

    lo, hi = bounds(v)
    eps = 1e-5 * max(float(np.linalg.norm(hi - lo)), float(np.abs(v).max()))
    active = np.ones(n, bool)
    for b in range(maxb + 1):
        si = s.ray_intersect(ray, mi.Bool(active))
        valid = np.array(si.is_valid(), dtype=bool) & active
        miss = active & ~valid
        if b == 0:
            status[miss] = MISSED
            exit_dir[miss] = d0[miss]
        else:
            status[miss] = EXITED
            exit_pos[miss] = pos_now[miss]
            exit_dir[miss] = dirn[miss]
        act = valid
        if b == maxb:
            status[act] = np.where(last_tir[act], TIR, LIMIT)
            break
        if not act.any():
            break
        p = _np3(si.p)
        ng = _np3(si.n)
        ns = _np3(si.sh_frame.n)
        prim = np.array(si.prim_index, dtype=np.int64)
        a = np.flatnonzero(act)
        dd, g, sh = dirn[a], ng[a], ns[a]
        cos_g = np.sum(dd * g, axis=1)
        entering = cos_g < 0
        obj = fo[prim[a]]
        n1 = ior[medium[a]]
        n2 = np.where(entering, ior[obj], ior[outside])
        eta = n1 / n2
        sh = np.where((np.sum(sh * g, axis=1) < 0)[:, None], -sh, sh)
        out, tir = _refract(dd, sh, eta)
        sn = np.sign(np.sum(out * g, axis=1))
        sg = np.sign(cos_g)
        wrong = np.where(tir, sn == sg, sn != sg)
        if wrong.any():
            o2, t2 = _refract(dd[wrong], g[wrong], eta[wrong])
            out[wrong], tir[wrong] = o2, t2
        lost = ~np.all(np.isfinite(out), axis=1)
        out[lost] = dd[lost]
        crossed = ~tir & ~lost
        medium[a[crossed]] = np.where(entering[crossed], obj[crossed], outside)
        interfaces[a[crossed]] += 1
        last_tir[a] = tir
        pos_now[a] = p[a]
        events[a] += 1
        if b < record:
            path_pos[a, b] = p[a]
        dirn[a] = out
        status[a[lost]] = LOST
        active = act.copy()
        active[a[lost]] = False
        dv = dirn.astype(np.float32).T
        if spawn == "mitsuba":
            ray = si.spawn_ray(mi.Vector3f(dv[0], dv[1], dv[2]))
        else:
            side = np.where((np.sum(out * g, axis=1) >= 0)[:, None], g, -g)
            org = pos_now.copy()
            org[a] = p[a] + eps * out + (0.1 * eps) * side
            ov = np.nan_to_num(org).astype(np.float32).T
            ray = mi.Ray3f(mi.Point3f(ov[0], ov[1], ov[2]), mi.Vector3f(dv[0], dv[1], dv[2]))
    assert not np.any(status < 0)
    return {"ray_origin": o0.reshape(H, W, 3), "ray_dir": d0.reshape(H, W, 3), "status": status.reshape(H, W),
            "exit_pos": exit_pos.reshape(H, W, 3), "exit_dir": exit_dir.reshape(H, W, 3),
            "interfaces": interfaces.reshape(H, W), "events": events.reshape(H, W),
            **({"path_pos": path_pos.reshape(H, W, -1, 3)} if record else {})}


def _exact(scene):
    import refraction_ref as rr

    return rr.render(scene, method="exact").arrays


def _paths_only_scene(case, folder):
    """The case's scene without lights and receivers (the per-pixel trace does not read them)."""
    from .golden.build import case_scene

    c = copy.deepcopy(case)
    c["scene"]["lights"] = []
    c["scene"]["receivers"] = []
    return case_scene(c, folder)


def paths_case(case, folder, variant="llvm_ad_rgb"):
    """The paths cross-check of one case: (numbers, arrays for the figures)."""
    from .camera import Camera

    scene = _paths_only_scene(case, os.path.join(folder, "scene"))
    t0 = time.perf_counter()
    ours = _exact(scene)
    t1 = time.perf_counter()
    mit = mitsuba_paths(scene, os.path.join(folder, "mitsuba"), variant)
    t2 = time.perf_counter()
    cam = Camera.from_dict(scene.data["camera"])
    ray_ang = angle_deg(ours["ray_dir"], mit["ray_dir"])
    # Mitsuba's rays start on the near plane (near_clip = 1e-4) along the same line
    off = mit["ray_origin"] - ours["ray_origin"]
    line = np.linalg.norm(np.cross(off, ours["ray_dir"]), axis=-1)
    both = (ours["status"] == EXITED) & (mit["status"] == EXITED)
    ang = angle_deg(ours["exit_dir"], mit["exit_dir"])
    a = ang[both]
    from .meshes import bounds, scene_geometry

    lo, hi = bounds(scene_geometry(scene).vertices)
    scale = float(np.linalg.norm(hi - lo))
    dp = np.linalg.norm(ours["exit_pos"] - mit["exit_pos"], axis=-1)[both] / scale
    agree = ours["status"] == mit["status"]
    hit = (ours["status"] != MISSED) | (mit["status"] != MISSED)
    num = {
        "pixels": int(agree.size), "object_pixels": int(hit.sum()), "both_exit": int(both.sum()),
        "primary_ray_max_deg": float(ray_ang.max()), "primary_origin_off_line": float(line.max()),
        "median_deg": float(np.median(a)) if a.size else float("nan"),
        "p99_deg": float(np.percentile(a, 99)) if a.size else float("nan"),
        "max_deg": float(a.max()) if a.size else float("nan"),
        "frac_over_0_5_deg": float(np.mean(a > 0.5)) if a.size else float("nan"),
        "exit_pos_median_rel": float(np.median(dp)) if dp.size else float("nan"),
        "exit_pos_p99_rel": float(np.percentile(dp, 99)) if dp.size else float("nan"),
        "status_agree": float(agree.mean()),
        "status_agree_object_pixels": float(agree[hit].mean()) if hit.any() else 1.0,
        "status_ours": {int(k): int(v) for k, v in zip(*np.unique(ours["status"], return_counts=True))},
        "status_mitsuba": {int(k): int(v) for k, v in zip(*np.unique(mit["status"], return_counts=True))},
        "interfaces_agree_both_exit": float(np.mean((ours["interfaces"] == mit["interfaces"])[both]))
        if both.any() else float("nan"),
        "ours_s": t1 - t0, "mitsuba_s": t2 - t1, "camera": [cam.width, cam.height],
    }
    # where the two part: float32 hits differ by ~1e-7, and a chain of total internal reflections
    # (thin walls, IOR 2.4) multiplies that at every event until the exits differ by degrees
    tir = mit["events"] - mit["interfaces"]
    for lab, sel in (("no_tir", both & (tir == 0)), ("tir_1_2", both & (tir >= 1) & (tir <= 2)),
                     ("tir_3_plus", both & (tir >= 3))):
        x = ang[sel]
        num[f"paths_{lab}"] = int(sel.sum())
        num[f"p99_deg_{lab}"] = float(np.percentile(x, 99)) if x.size else float("nan")
        num[f"over_0_5_{lab}"] = int(np.count_nonzero(x > 0.5))
    figs = {"angle": np.where(both, ang, np.nan), "status_ours": ours["status"], "status_mitsuba": mit["status"]}
    return num, figs


# --------------------------------------------------------------------------- images
def render_pixel_centres(mscene, spp, seed=0, pixels=None):
    """Mitsuba's integrator through pixel centres, ``spp`` samples each (scalar variant, one ray a call).

    Our exact images sample each pixel at its centre (docs/oracle.md); a film
    render would average over the pixel's area, so the rays come from
    ``sensor.sample_ray`` at the centres and go to ``integrator.sample``.
    (The vectorised ``llvm_ad_rgb`` integrators need LLVM >= 16 for
    ``fminimum``; this machine's LLVM 14/15 stop with "Cannot select
    fminimum", so images run on ``scalar_rgb``.)

    Parameters
    ----------
    pixels : (P,) int array, optional
        Flat pixel indices to render (default all); the others stay NaN.

    Returns
    -------
    mean, sem : (H, W, 3) float64
        The per-pixel mean of the samples and its standard error.
    """
    import mitsuba as mi

    sensor = mscene.sensors()[0]
    W, H = (int(x) for x in sensor.film().size())
    integ = mscene.integrator()
    sampler = mi.load_dict({"type": "independent"})
    mean = np.full((H * W, 3), np.nan)
    sem = np.full((H * W, 3), np.nan)
    idx = np.arange(H * W) if pixels is None else np.asarray(pixels)
    for k in idx:
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((k % W + 0.5) / W, (k // W + 0.5) / H), mi.Point2f(0.5, 0.5))
        rd = mi.RayDifferential3f(ray)
        sampler.seed(int(seed) * 1000003 + int(k))
        x = np.empty((spp, 3))
        for j in range(spp):
            L, _, _ = integ.sample(mscene, sampler, rd, None, True)
            x[j] = np.array(L, dtype=np.float64).reshape(3)
        mean[k] = x.mean(0)
        sem[k] = x.std(0, ddof=1) / np.sqrt(spp) if spp > 1 else 0.0
    return mean.reshape(H, W, 3), sem.reshape(H, W, 3)


def envmap_eval(mscene, dirs):
    """Mitsuba's environment emitter along world directions (N, 3): (N, 3) float64 (NaN rows: 0)."""
    import mitsuba as mi

    env = mscene.environment()
    d = np.nan_to_num(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
    bad = ~np.any(d != 0, axis=1)
    d[bad] = [0.0, 0.0, -1.0]
    out = np.zeros((len(d), 3))
    si = mi.SurfaceInteraction3f()
    for k in range(len(d)):
        si.wi = mi.Vector3f(-d[k])
        out[k] = np.array(env.eval(si), dtype=np.float64).reshape(3)
    out[bad] = 0.0
    return out


def images_case(case, folder, variant="scalar_rgb", spp_fresnel=64, spp_absorb=64, env_width=None):
    """The images cross-check of one case: (numbers, images for the figures)."""
    from .interop import mitsuba as M

    scene = _paths_only_scene(case, os.path.join(folder, "scene"))
    ours = _exact(scene)
    img = np.asarray(ours["image"], dtype=np.float64)
    H, W = img.shape[:2]
    absorbing = any(np.any(np.asarray(o["material"]["absorption"]) > 0) for o in scene.data["objects"])
    mi = M.require(variant)
    M.register_refract_bsdf()
    kw = {"env_width": env_width or M.ENV_WIDTH}
    ms, spec = M.load(scene, os.path.join(folder, "refract"), variant, bsdf="refract", **kw)
    t0 = time.perf_counter()
    st = ours["status"]
    spp = spp_absorb if absorbing else 2
    obj = np.flatnonzero(st.ravel() != MISSED)  # missed pixels see the environment directly: one sample
    a, a_sem = render_pixel_centres(ms, spp, seed=1, pixels=obj)
    miss = np.flatnonzero(st.ravel() == MISSED)
    a1, _ = render_pixel_centres(ms, 1, seed=1, pixels=miss)
    a = np.where(np.isnan(a), a1, a)
    a_sem = np.nan_to_num(a_sem)
    t1 = time.perf_counter()
    md, _ = M.load(scene, os.path.join(folder, "dielectric"), variant, bsdf="dielectric", **kw)
    f, f_sem = render_pixel_centres(md, spp_fresnel, seed=2, pixels=obj)
    f = np.where(np.isnan(f), a1, f)
    f_sem = np.nan_to_num(f_sem)
    t2 = time.perf_counter()
    dirs = np.where((st == EXITED)[..., None] | (st == MISSED)[..., None], ours["exit_dir"], np.nan)
    env_ours_dirs = envmap_eval(ms, dirs).reshape(H, W, 3)
    if absorbing:
        # the exact image's transmittance, recovered from its own image and environment look-up
        from .environment import environment_lookup

        e = environment_lookup(scene.data["environment"], np.nan_to_num(dirs), scene.base_dir).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            tr = np.where(e > 0, img / e, 1.0)
        env_ours_dirs = env_ours_dirs * tr
    ok = (st == EXITED) | (st == MISSED)
    clean = ok & np.all(np.abs(env_ours_dirs - img) <= 1e-4 * max(float(np.abs(img).max()), 1e-30), axis=-1)
    num = {
        "spp_refract": int(spp), "spp_dielectric": int(spp_fresnel),
        "integrator": spec["integrator"]["type"], "env_width": int(kw["env_width"]),
        "rel_rmse": relative_rmse(a, img),
        "rel_rmse_exited_or_missed": relative_rmse(a[ok], img[ok]),
        "rel_rmse_env_bitmap": relative_rmse(env_ours_dirs, img),
        "rel_rmse_paths_only": relative_rmse(a, env_ours_dirs),
        # pixels whose own exit direction the bitmap reproduces (away from the checker's edges, where
        # Mitsuba's bilinear envmap blends two squares over one texel): the paths alone
        "rel_rmse_unblended": relative_rmse(a[clean], img[clean]) if clean.any() else float("nan"),
        "blended_pixels": int(np.count_nonzero(~clean)),
        "noise_rel": float(np.sqrt(np.mean(a_sem ** 2)) / max(float(np.mean(np.abs(img))), 1e-30)),
        "fresnel_rel_rmse": relative_rmse(f, img),
        "fresnel_noise_rel": float(np.sqrt(np.mean(f_sem ** 2)) / max(float(np.mean(np.abs(img))), 1e-30)),
        "fresnel_mean_ratio": float(np.mean(f[st != MISSED]) / max(float(np.mean(img[st != MISSED])), 1e-30))
        if np.any(st != MISSED) else 1.0,
        "limit_pixels": int(np.count_nonzero(~ok)),
        "mitsuba_s": t1 - t0, "mitsuba_fresnel_s": t2 - t1,
    }
    return num, {"ours": img, "mitsuba": a, "fresnel": f}


# --------------------------------------------------------------------------- cases, report, cluster
def _skip_reason(case):
    s = case["scene"]
    if case["method"] == "volumetric":
        return ("volumetric: a graded-index volume (continuous refraction) has no Mitsuba plugin (media "
                "scatter and absorb, they do not bend rays); no exact mesh reference to cross-check")
    if s.get("water") is not None:
        return ("water: the exact water reference traces the analytic surface from the light only (caustic "
                "maps); the caustics cross-check (Mitsuba ptracer) is not built yet")
    if case["method"] == "exact" or case.get("reference") != "exact":
        return "caustics: the ptracer cross-check of the exact photon maps is not built yet"
    return None


def run_case(case, folder, parts=("paths", "images"), figures=True):
    """Cross-check one case into ``folder``; its entry (numbers per part, figure files, or a skip reason)."""
    t0 = time.perf_counter()
    entry = {"name": case["name"], "purpose": case["purpose"], "method": case["method"]}
    why = _skip_reason(case)
    if why:
        entry["skipped"] = why
        return entry
    os.makedirs(folder, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="crosscheck-") as tmp:
        if "paths" in parts:
            num, pf = paths_case(case, os.path.join(tmp, "paths"))
            entry["paths"] = num
            if figures:
                entry["paths"]["figure"] = _paths_figure(pf, os.path.join(folder, "paths.png"), case["name"])
        if "images" in parts:
            num, imf = images_case(case, os.path.join(tmp, "images"))
            entry["images"] = num
            if figures:
                entry["images"]["figure"] = _images_figure(imf, os.path.join(folder, "images.png"), case["name"])
    entry["seconds"] = time.perf_counter() - t0
    return entry


def _paths_figure(f, path, name):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(12, 4))
    ax[0].imshow(f["status_ours"], vmin=0, vmax=4, cmap="tab10", interpolation="nearest")
    ax[0].set_title("A: status, ours (exact)")
    ax[1].imshow(f["status_mitsuba"], vmin=0, vmax=4, cmap="tab10", interpolation="nearest")
    ax[1].set_title("B: status, Mitsuba paths")
    im = ax[2].imshow(np.log10(np.maximum(f["angle"], 1e-7)), vmin=-6, vmax=1, cmap="magma", interpolation="nearest")
    ax[2].set_title("A-B: exit angle, log10 deg")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    for a in ax:
        a.axis("off")
    fig.suptitle(name)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return os.path.basename(path)


def _images_figure(f, path, name):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 4, figsize=(16, 4))
    ax[0].imshow(np.clip(f["ours"], 0, 1), interpolation="nearest")
    ax[0].set_title("A: ours (exact)")
    ax[1].imshow(np.clip(f["mitsuba"], 0, 1), interpolation="nearest")
    ax[1].set_title("B: Mitsuba path, Fresnel-free")
    d = (f["ours"] - f["mitsuba"]).mean(-1)
    im = ax[2].imshow(d, vmin=-0.5, vmax=0.5, cmap="RdBu", interpolation="nearest")
    ax[2].set_title("A-B")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    ax[3].imshow(np.clip(f["fresnel"], 0, 1), interpolation="nearest")
    ax[3].set_title("Mitsuba dielectric (Fresnel)")
    for a in ax:
        a.axis("off")
    fig.suptitle(name)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return os.path.basename(path)


def _case_task(case, parts, threads=1):
    """One case on a Dask worker: (name, entry, {figure file: bytes})."""
    import numba

    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    with tempfile.TemporaryDirectory(prefix="crosscheck-case-") as d:
        entry = run_case(case, d, parts)
        files = {}
        for fn in os.listdir(d):
            with open(os.path.join(d, fn), "rb") as fh:
                files[fn] = fh.read()
    return case["name"], entry, files


def run(out, only=None, parts=("paths", "images"), workers=None, scheduler=None, log=print, client=None):
    """Cross-check the catalogue (or ``only`` those cases) into ``out``: ``crosscheck.json``,
    ``crosscheck.md`` and ``<case>/*.png``. Cases run as Dask tasks with ``workers``
    (a LocalCluster) or ``scheduler`` (as ``golden build``), else here one by one."""
    from .files import atomic_open

    cases = crosscheck_cases(only)
    os.makedirs(out, exist_ok=True)
    entries = {}

    def done(name, entry, files=None):
        entries[name] = entry
        if files:
            os.makedirs(os.path.join(out, name), exist_ok=True)
            for fn, data in files.items():
                with open(os.path.join(out, name, fn), "wb") as fh:
                    fh.write(data)
        log(f"  {name}: " + (f"skipped ({entry['skipped'][:60]}...)" if "skipped" in entry else
                             f"{entry.get('seconds', 0):.0f} s"))

    if scheduler is None and workers is None and client is None:
        for c in cases:
            done(c["name"], run_case(c, os.path.join(out, c["name"]), parts))
    else:
        from distributed import Client, LocalCluster, as_completed

        own = client is None
        cluster = None
        if own:
            if scheduler:
                client = Client(scheduler)
            else:
                cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                       dashboard_address=None)
                client = Client(cluster)
        try:
            futures = [client.submit(_case_task, c, tuple(parts), pure=False) for c in cases]
            for fu in as_completed(futures):
                done(*fu.result())
        finally:
            if own:
                client.close()
                if cluster is not None:
                    cluster.close()
    from .contract import software_versions

    result = {"targets": TARGETS, "tir_chaos": list(TIR_CHAOS), "versions": _versions(software_versions()),
              "cases": dict(sorted(entries.items()))}
    with atomic_open(os.path.join(out, "crosscheck.json"), "w") as f:
        json.dump(result, f, indent=1, sort_keys=True, default=float)
    with atomic_open(os.path.join(out, "crosscheck.md"), "w") as f:
        f.write(report_markdown(result))
    return result


def _versions(v):
    try:
        import drjit
        import mitsuba

        v = dict(v, mitsuba=mitsuba.__version__, drjit=drjit.__version__)
    except ImportError:
        pass
    return v


def _fmt(x, nd=3):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-"
    return f"{x:.{nd}g}"


def _mark(ok):
    return "pass" if ok else "**FAIL**"


def verdicts(name, e):
    """Each target's verdict for one case entry: {target: bool or None (reported, not judged)}."""
    v = {}
    p = e.get("paths")
    if p:
        chaos = name in TIR_CHAOS
        v["median_deg"] = None if chaos else p["median_deg"] <= TARGETS["median_deg"]
        v["p99_deg"] = None if chaos else p["p99_deg"] <= TARGETS["p99_deg"]
        v["status_agree"] = p["status_agree"] >= TARGETS["status_agree"]
    i = e.get("images")
    if i:
        v["image_rel_rmse"] = i["rel_rmse_unblended"] <= TARGETS["image_rel_rmse"]
    return v


def report_markdown(result):
    """The cross-check report: a summary table, then a table and figures per case."""
    T = result["targets"]
    lines = ["# Cross-check of the exact references against Mitsuba 3", "",
             "Written by `refraction-ref crosscheck` (refraction_ref/crosscheck.py); conventions in "
             "docs/oracle.md, section *Cross-check against Mitsuba 3*. Versions: "
             + ", ".join(f"{k} {v}" for k, v in sorted(result["versions"].items()) if isinstance(v, str)) + ".", "",
             f"Targets: exit directions where both exit, median <= {T['median_deg']} deg and p99 <= "
             f"{T['p99_deg']} deg (TIR-chaos cases {', '.join(result['tir_chaos'])} reported, not judged); "
             f"status agreement >= {T['status_agree']:.0%} of pixels; image relative RMSE <= "
             f"{T['image_rel_rmse']:.0%} (on the pixels whose exit direction the envmap bitmap reproduces; "
             "the bitmap's own error beside it).", "",
             "| case | median deg | p99 deg | max deg | status agree | image rel RMSE (unblended) | "
             "image rel RMSE (all) | envmap bitmap error | Fresnel moves image | verdict |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, e in result["cases"].items():
        if "skipped" in e:
            lines.append(f"| {name} | - | - | - | - | - | - | - | - | skipped: {e['skipped']} |")
            continue
        p, i = e.get("paths", {}), e.get("images", {})
        v = verdicts(name, e)
        judged = [x for x in v.values() if x is not None]
        verdict = ("pass" if all(judged) else "**FAIL**: " + ", ".join(k for k, x in v.items() if x is False))
        if name in result["tir_chaos"]:
            verdict += " (TIR chaos: angles reported)"
        lines.append(f"| {name} | {_fmt(p.get('median_deg'))} | {_fmt(p.get('p99_deg'))} | {_fmt(p.get('max_deg'))} | "
                     f"{_fmt(100 * p['status_agree'], 5) + ' %' if p else '-'} | "
                     f"{_fmt(100 * i['rel_rmse_unblended']) + ' %' if i else '-'} | "
                     f"{_fmt(100 * i['rel_rmse']) + ' %' if i else '-'} | "
                     f"{_fmt(100 * i['rel_rmse_env_bitmap']) + ' %' if i else '-'} | "
                     f"{_fmt(100 * i['fresnel_rel_rmse']) + ' %' if i else '-'} | {verdict} |")
    for name, e in result["cases"].items():
        if "skipped" in e:
            continue
        lines += ["", f"## {name}", "", e["purpose"], ""]
        p = e.get("paths")
        if p:
            v = verdicts(name, e)
            lines += ["| paths | value | target |", "|---|---|---|",
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
                      f"| status counts ours / Mitsuba | {p['status_ours']} / {p['status_mitsuba']} | |",
                      f"| interface count agreement (both exit) | {_fmt(100 * p['interfaces_agree_both_exit'], 6)} % | |",
                      f"| p99 (pixels over 0.5 deg) by TIR events on the path: none / 1-2 / 3+ | "
                      f"{_fmt(p['p99_deg_no_tir'])} ({p['over_0_5_no_tir']} of {p['paths_no_tir']}) / "
                      f"{_fmt(p['p99_deg_tir_1_2'])} ({p['over_0_5_tir_1_2']} of {p['paths_tir_1_2']}) / "
                      f"{_fmt(p['p99_deg_tir_3_plus'])} ({p['over_0_5_tir_3_plus']} of {p['paths_tir_3_plus']}) | |",
                      "", f"![paths {name}]({name}/{p.get('figure', 'paths.png')})"]
        i = e.get("images")
        if i:
            lines += ["", "| images | value |", "|---|---|",
                      f"| Mitsuba integrator, spp (Fresnel-free / dielectric) | {i['integrator']}, {i['spp_refract']} / "
                      f"{i['spp_dielectric']} |",
                      f"| noise of the Fresnel-free render (rel. RMS standard error) | {_fmt(i['noise_rel'])} |",
                      f"| rel RMSE, all pixels | {_fmt(100 * i['rel_rmse'])} % |",
                      f"| rel RMSE, pixels the bitmap reproduces ({i['blended_pixels']} blended pixels left out) | "
                      f"{_fmt(100 * i['rel_rmse_unblended'])} % |",
                      f"| envmap bitmap error on this image ({i['env_width']} texels wide) | "
                      f"{_fmt(100 * i['rel_rmse_env_bitmap'])} % |",
                      f"| Mitsuba vs our exit directions in Mitsuba's envmap | {_fmt(100 * i['rel_rmse_paths_only'])} % |",
                      f"| Fresnel (dielectric) vs ours: rel RMSE; mean over object pixels | "
                      f"{_fmt(100 * i['fresnel_rel_rmse'])} % (noise {_fmt(100 * i['fresnel_noise_rel'])} %); "
                      f"x{_fmt(i['fresnel_mean_ratio'], 4)} |",
                      f"| pixels stopped at the bounce limit (black in Mitsuba) | {i['limit_pixels']} |",
                      "", f"![images {name}]({name}/{i.get('figure', 'images.png')})"]
    return "\n".join(lines) + "\n"
