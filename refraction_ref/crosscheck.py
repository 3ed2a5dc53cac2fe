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

Water scenes (the exact water reference, :mod:`refraction_ref.exact.water`):
the water is the exported dense height-field mesh with the analytic normals
at its vertices; ``paths`` compares the eye rays refracted at the water
(our ``water_dir`` at the analytic surface against Snell at Mitsuba's hit),
``caustics`` Mitsuba's photons through the mesh (:func:`mitsuba_water_photons`)
against our K batches. The volumetric cases are skipped: a graded-index
volume bends rays continuously, and no Mitsuba plugin does.

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

from .compare import angular_error_deg
from .status import EXITED, LIMIT, LOST, MISSED, TIR

__all__ = ["crosscheck_cases", "mitsuba_paths", "paths_case", "images_case", "run_case", "run", "TARGETS",
           "relative_rmse"]

#: the targets of the cross-check (issue "Ground truth checked by an independent renderer")
TARGETS = {"median_deg": 0.01, "p99_deg": 0.5, "status_agree": 0.99, "image_rel_rmse": 0.01}
#: cases whose long TIR chains diverge between two float32-hit tracers (reported, not judged)
TIR_CHAOS = ("is_diamond_2_4", "is_tir_followed")


def crosscheck_cases(only=None):
    """The golden catalogue's cases (or ``only`` those): every one gets a row, cases without a
    cross-check a reason (:func:`run_case`).

    Parameters
    ----------
    only : str or sequence of str, optional
        Case names (comma-separated or a list); None for every case.

    Returns
    -------
    list of dict
        The cases (:func:`refraction_ref.golden.build.catalogue`).
    """
    from .golden.build import catalogue

    return catalogue(only)


def relative_rmse(a, b):
    """``sqrt(mean((a - b)^2)) / mean(|b|)`` over all pixels and channels (b: the reference).

    Parameters
    ----------
    a : array_like
        The image to judge, e.g. (H, W, 3) or (P, 3).
    b : array_like
        The reference, same shape.

    Returns
    -------
    float
        Relative RMSE (the denominator floored at 1e-30).
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return float(np.sqrt(np.mean((a - b) ** 2)) / max(float(np.mean(np.abs(b))), 1e-30))


# --------------------------------------------------------------------------- Mitsuba paths
def _np3(v):
    return np.array(v, dtype=np.float64).reshape(3, -1).T


def _interface(d, sh, ng, eta):
    """One interface crossed with Mitsuba's shading normal ``sh``, as the exact tracer crosses it.

    Where the shading normal sends the refracted (or reflected) ray to the wrong
    side of the geometric normal ``ng``, the geometric normal is used instead;
    a non-finite result keeps the incoming direction and is reported ``lost``.
    Returns ``(out, tir, lost)``.
    """
    sh = np.where((np.sum(sh * ng, axis=1) < 0)[:, None], -sh, sh)
    out, tir = _refract(d, sh, eta)
    sn = np.sign(np.sum(out * ng, axis=1))
    sg = np.sign(np.sum(d * ng, axis=1))
    wrong = np.where(tir, sn == sg, sn != sg)
    if wrong.any():
        o2, t2 = _refract(d[wrong], ng[wrong], eta[wrong])
        out[wrong], tir[wrong] = o2, t2
    lost = ~np.all(np.isfinite(out), axis=1)
    out[lost] = d[lost]
    return out, tir, lost


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
        out, tir, lost = _interface(dd, sh, g, eta)
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
    """The paths cross-check of one case: (numbers, arrays for the figures).

    Parameters
    ----------
    case : dict
        A catalogue case with an exact per-pixel reference.
    folder : str
        Scratch folder for the scene and Mitsuba's files.
    variant : str
        Mitsuba variant for the path tracing (:func:`mitsuba_paths`).

    Returns
    -------
    num : dict
        Angles between the exit directions where both exit (median, p99, max,
        by count of TIR events), exit-position differences relative to the
        scene diagonal, status and interface agreement, timings.
    figs : dict
        ``angle`` (H, W) float64 (NaN where not both exit), ``status_ours``
        and ``status_mitsuba`` (H, W).
    """
    from .camera import Camera

    scene = _paths_only_scene(case, os.path.join(folder, "scene"))
    t0 = time.perf_counter()
    ours = _exact(scene)
    t1 = time.perf_counter()
    mit = mitsuba_paths(scene, os.path.join(folder, "mitsuba"), variant)
    t2 = time.perf_counter()
    cam = Camera.from_dict(scene.data["camera"])
    ray_ang = angular_error_deg(ours["ray_dir"], mit["ray_dir"])
    # Mitsuba's rays start on the near plane (near_clip = 1e-4) along the same line
    off = mit["ray_origin"] - ours["ray_origin"]
    line = np.linalg.norm(np.cross(off, ours["ray_dir"]), axis=-1)
    both = (ours["status"] == EXITED) & (mit["status"] == EXITED)
    ang = angular_error_deg(ours["exit_dir"], mit["exit_dir"])
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
    """Mitsuba's environment emitter along world directions (N, 3): (N, 3) float64 (NaN rows: 0).

    Parameters
    ----------
    mscene : mitsuba.Scene
        A loaded scene with an environment emitter (scalar variant).
    dirs : (..., 3) array_like
        World-space directions the light travels (reshaped to (N, 3)); zero or
        NaN rows give 0.

    Returns
    -------
    (N, 3) float64 ndarray
        Radiance.
    """
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


def loop_radiance(mscene, pixels, max_depth, spawn="line", eps=1e-5):
    # eps: the offset along the ray for spawn='line' (mitsuba_paths uses 1e-5 of the scene's size)
    """Each pixel centre's radiance by a Python loop over Mitsuba's own parts (scalar variant).

    The loop is Mitsuba's ``path`` integrator stripped to what a delta BSDF
    uses: ``scene.ray_intersect``, the shape's BSDF (``bsdf.sample``: the
    Fresnel-free plugin), the shape's ``interior_medium`` (``sigma_t``, Beer-
    Lambert over Mitsuba's segment lengths ``si.t``) and the environment
    emitter's ``eval`` where the ray leaves; paths longer than ``max_depth - 1``
    events are black, as in the integrator. ``spawn`` says how a ray leaves a
    surface: ``'mitsuba'`` by ``si.spawn_ray`` (the integrator's own offset:
    the loop then reproduces ``path`` to float precision, measured by
    :func:`images_case`), ``'line'`` from the hit point ``eps`` along the new
    direction (the exact tracer's offset, as :func:`mitsuba_paths`).

    Parameters
    ----------
    mscene : mitsuba.Scene
        The scene loaded with the Fresnel-free BSDF (scalar variant).
    pixels : (P,) array_like of int
        Flat pixel indices ``row * W + col``.
    max_depth : int
        The integrator's ``max_depth`` (ray segments traced at most).
    spawn : {'line', 'mitsuba'}
        How a ray leaves a surface (see above).
    eps : float
        Offset along the new direction for ``'line'`` (world units).

    Returns
    -------
    radiance, exit_dir : (P, 3) float64
        Per pixel (flat indices ``pixels``); ``exit_dir`` NaN where the path
        ended at the limit.

    References
    ----------
    .. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022,
       https://mitsuba-renderer.org (the ``path`` integrator).
    """
    import mitsuba as mi

    sensor = mscene.sensors()[0]
    W, H = (int(x) for x in sensor.film().size())
    env = mscene.environment()
    ctx = mi.BSDFContext()
    mei = mi.MediumInteraction3f()
    rad = np.zeros((len(pixels), 3))
    out_dir = np.full((len(pixels), 3), np.nan)
    for n, k in enumerate(np.asarray(pixels)):
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((k % W + 0.5) / W, (k // W + 0.5) / H), mi.Point2f(0.5, 0.5))
        tr = np.ones(3)
        sigma = None
        for _ in range(int(max_depth)):
            si = mscene.ray_intersect(ray)
            if sigma is not None:
                tr *= np.exp(-sigma * float(si.t)) if si.is_valid() else 0.0
            if not si.is_valid():
                rad[n] = tr * np.array(env.eval(si), dtype=np.float64).reshape(3)
                out_dir[n] = np.array(ray.d, dtype=np.float64)
                break
            bs, _w = si.bsdf().sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5))
            wo = si.to_world(bs.wo)
            if int(bs.sampled_component) == 1:  # refracted: the medium beyond is decided by the geometric side
                med = si.shape.interior_medium() if float(np.dot(np.array(ray.d), np.array(si.n))) < 0 else None
                sigma = None if med is None else np.array(med.get_scattering_coefficients(mei)[2],
                                                          dtype=np.float64).reshape(3)
            if spawn == "mitsuba":
                ray = si.spawn_ray(wo)
            else:  # as mitsuba_paths: eps along the new direction, eps / 10 off the surface on its side
                p = np.array(si.p, dtype=np.float64)
                d = np.array(wo, dtype=np.float64)
                g = np.array(si.n, dtype=np.float64)
                side = g if float(np.dot(d, g)) >= 0 else -g
                ray = mi.Ray3f(mi.Point3f(*(p + eps * d + 0.1 * eps * side)), mi.Vector3f(*d))
    return rad, out_dir


def _env_dirs(d, dphi, dtheta):
    """Directions ``d`` (N, 3) turned by ``dphi`` in longitude and ``dtheta`` in colatitude (the envmap's axes)."""
    phi = np.arctan2(d[:, 0], -d[:, 2]) + dphi
    th = np.clip(np.arccos(np.clip(d[:, 1], -1.0, 1.0)) + dtheta, 0.0, np.pi)
    return np.stack([np.sin(th) * np.sin(phi), np.cos(th), -np.sin(th) * np.cos(phi)], axis=-1)


def edge_margin_mask(mscene, dirs, env_width):
    """Pixels whose exit direction is more than one envmap texel from a change of the bitmap's value.

    The rule: Mitsuba's envmap at the direction itself and turned by one
    texel either way in longitude (``2 pi / W``) and in colatitude
    (``pi / (H - 1)``) returns one value (to 1e-6 of the largest); a
    bilinear blend across a checker edge reaches at most one texel from it,
    so these pixels' colours do not depend on the blend nor on a path
    difference smaller than a texel. ``dirs`` (N, 3), NaN rows fail.

    Parameters
    ----------
    mscene : mitsuba.Scene
        A loaded scene with the ``envmap`` emitter.
    dirs : (..., 3) array_like
        Exit directions (reshaped to (N, 3)).
    env_width : int
        Width ``W`` of the envmap bitmap (height ``W // 2 + 1``).

    Returns
    -------
    (N,) bool ndarray
    """
    W = int(env_width)
    H = W // 2 + 1
    d = np.nan_to_num(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
    c = envmap_eval(mscene, d)
    scale = max(float(np.abs(c).max()), 1e-30)
    ok = np.all(np.isfinite(np.asarray(dirs).reshape(-1, 3)), axis=1)
    for dp, dt in ((2 * np.pi / W, 0.0), (-2 * np.pi / W, 0.0), (0.0, np.pi / (H - 1)), (0.0, -np.pi / (H - 1))):
        ok &= np.all(np.abs(envmap_eval(mscene, _env_dirs(d, dp, dt)) - c) <= 1e-6 * scale, axis=1)
    return ok


#: a pixel's colour is judged where Mitsuba's exit direction is this close to ours (half an envmap texel
#: at the default width: the paths part measures the directions themselves)
PATH_AGREE_DEG = 0.05


def images_case(case, folder, variant="scalar_rgb", spp_fresnel=64, spp_absorb=64, env_width=None):
    """The images cross-check of one case: (numbers, images for the figures).

    Four Mitsuba images through the pixel centres: ``path`` (``volpath``
    when an object absorbs) with the Fresnel-free plugin; a Python loop over
    Mitsuba's intersector, plugin, media and envmap with the integrator's own
    ``spawn_ray`` (equal to ``path``: its bookkeeping adds nothing) and with
    the exact tracer's offset along the ray (``line``); ``path`` with
    Mitsuba's Fresnel ``dielectric``. The target is judged on the ``line``
    image over the *judged* pixels: status exited or missed in ours, the
    exit direction more than a texel from a change of the envmap bitmap
    (:func:`edge_margin_mask`), and Mitsuba's exit direction within
    :data:`PATH_AGREE_DEG` of ours.

    Parameters
    ----------
    case : dict
        A catalogue case with an exact per-pixel reference.
    folder : str
        Scratch folder for the scenes and Mitsuba's files.
    variant : str
        Mitsuba variant (a scalar one: the loop calls Mitsuba per ray).
    spp_fresnel : int
        Samples per pixel centre of the ``dielectric`` image.
    spp_absorb : int
        Samples per pixel centre of the ``volpath`` image when an object
        absorbs (1 otherwise: a delta BSDF is deterministic).
    env_width : int, optional
        Envmap bitmap width (default :data:`~refraction_ref.interop.mitsuba.ENV_WIDTH`).

    Returns
    -------
    num : dict
        Relative RMSEs (judged, all, away from bitmap edges; the integrator,
        the Fresnel image), pixel counts, noise, timings.
    figs : dict
        ``ours``, ``mitsuba`` (the ``line`` loop), ``path``, ``fresnel``
        (H, W, 3) float64 images and ``judged`` (H, W) bool.
    """
    from .interop import mitsuba as M

    scene = _paths_only_scene(case, os.path.join(folder, "scene"))
    ours = _exact(scene)
    img = np.asarray(ours["image"], dtype=np.float64)
    H, W = img.shape[:2]
    absorbing = any(np.any(np.asarray(o["material"]["absorption"]) > 0) for o in scene.data["objects"])
    M.require(variant)
    M.register_refract_bsdf()
    kw = {"env_width": env_width or M.ENV_WIDTH}
    ms, spec = M.load(scene, os.path.join(folder, "refract"), variant, bsdf="refract", **kw)
    depth = int(spec["integrator"]["max_depth"])
    st = ours["status"]
    flat = img.reshape(-1, 3)
    allpix = np.arange(H * W)
    t0 = time.perf_counter()
    from .meshes import bounds

    v = np.concatenate([m["vertices"] for m in M.object_meshes(scene)])
    lo, hi = bounds(v)
    eps = 1e-5 * max(float(np.linalg.norm(hi - lo)), float(np.abs(v).max()))
    line, line_dir = loop_radiance(ms, allpix, depth, "line", eps)
    t1 = time.perf_counter()
    loop_sp, sp_dir = loop_radiance(ms, allpix, depth, "mitsuba")
    t2 = time.perf_counter()
    obj = np.flatnonzero(st.ravel() != MISSED)  # missed pixels see the environment directly: one sample
    spp = spp_absorb if absorbing else 1  # a delta BSDF through a pixel centre is deterministic
    a, a_sem = render_pixel_centres(ms, spp, seed=1, pixels=obj)
    miss = np.flatnonzero(st.ravel() == MISSED)
    a1, _ = render_pixel_centres(ms, 1, seed=1, pixels=miss)
    a = np.where(np.isnan(a), a1, a).reshape(-1, 3)
    a_sem = np.nan_to_num(a_sem).reshape(-1, 3)
    t3 = time.perf_counter()
    md, _ = M.load(scene, os.path.join(folder, "dielectric"), variant, bsdf="dielectric", **kw)
    f, f_sem = render_pixel_centres(md, spp_fresnel, seed=2, pixels=obj)
    f = np.where(np.isnan(f), a1, f).reshape(-1, 3)
    f_sem = np.nan_to_num(f_sem).reshape(-1, 3)
    t4 = time.perf_counter()
    ok = ((st == EXITED) | (st == MISSED)).ravel()
    odir = np.where(ok[:, None], ours["exit_dir"].reshape(-1, 3), np.nan)
    env_ours = envmap_eval(ms, odir)
    if absorbing:
        # the exact image's transmittance, recovered from its own image and environment look-up
        from .environment import environment_lookup

        e = environment_lookup(scene.data["environment"], np.nan_to_num(odir), scene.base_dir).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            tr = np.where(e > 0, flat / e, 1.0)
        env_ours = env_ours * tr
    margin = ok & edge_margin_mask(ms, odir, kw["env_width"])
    agree_line = angular_error_deg(line_dir, odir) <= PATH_AGREE_DEG
    judged = margin & agree_line
    ang_sp = angular_error_deg(sp_dir, odir)
    both_sp = ok & (st.ravel() != MISSED) & np.all(np.isfinite(sp_dir), axis=1)
    mean_img = max(float(np.mean(np.abs(flat))), 1e-30)

    def rr(x, sel):
        return relative_rmse(x[sel], flat[sel]) if sel.any() else float("nan")

    num = {
        "spp_refract": int(spp), "spp_dielectric": int(spp_fresnel),
        "integrator": spec["integrator"]["type"], "env_width": int(kw["env_width"]),
        "max_depth": depth, "rr_depth": int(spec["integrator"].get("rr_depth", depth)),
        "pixels": int(H * W), "judged_pixels": int(judged.sum()),
        "edge_pixels": int(np.count_nonzero(ok & ~margin)), "path_differs_pixels": int(np.count_nonzero(margin & ~agree_line)),
        "limit_pixels": int(np.count_nonzero(~ok)),
        # the target: Mitsuba's parts with the exact tracer's offset, on the judged pixels
        "rel_rmse_judged": rr(line, judged),
        "rel_rmse_line_all": relative_rmse(line, flat),
        "rel_rmse_line_margin": rr(line, margin),
        "rel_rmse_env_bitmap": relative_rmse(env_ours, flat),
        # Mitsuba's own integrator against ours, and against the loop that spawns as it does
        "rel_rmse_path": relative_rmse(a, flat),
        "rel_rmse_path_judged": rr(a, judged),
        "rel_rmse_path_margin": rr(a, margin),
        "path_vs_loop_max_abs": float(np.nanmax(np.abs(a - loop_sp))) if not absorbing else float("nan"),
        "path_vs_loop_rel_rmse": float(np.sqrt(np.mean((a - loop_sp) ** 2)) / mean_img),
        "spawn_ray_median_deg": float(np.median(ang_sp[both_sp])) if both_sp.any() else float("nan"),
        "spawn_ray_p99_deg": float(np.percentile(ang_sp[both_sp], 99)) if both_sp.any() else float("nan"),
        "spawn_ray_over_texel": int(np.count_nonzero(ang_sp[both_sp] > 180.0 / (kw["env_width"] // 2))),
        "noise_rel": float(np.sqrt(np.mean(a_sem ** 2)) / mean_img),
        "fresnel_rel_rmse": relative_rmse(f, flat),
        "fresnel_rel_rmse_judged": rr(f, judged),
        "fresnel_noise_rel": float(np.sqrt(np.mean(f_sem ** 2)) / mean_img),
        "fresnel_mean_ratio": float(np.mean(f[obj]) / max(float(np.mean(flat[obj])), 1e-30)) if obj.size else 1.0,
        "loop_s": t1 - t0, "loop_spawn_s": t2 - t1, "mitsuba_s": t3 - t2, "mitsuba_fresnel_s": t4 - t3,
    }
    figs = {"ours": img, "mitsuba": line.reshape(H, W, 3), "path": a.reshape(H, W, 3), "fresnel": f.reshape(H, W, 3),
            "judged": judged.reshape(H, W)}
    return num, figs


# --------------------------------------------------------------------------- caustics
def _receiver_soup(v, f):
    """A receiver as a triangle soup with its face normals at every corner (flat shading in Mitsuba).

    Parameters
    ----------
    v : (V, 3) array_like
    f : (F, 3) array_like

    Returns
    -------
    dict
        ``vertices`` (3F, 3), ``faces`` (F, 3), ``normals`` (3F, 3).
    """
    tri = np.asarray(v, dtype=np.float64)[np.asarray(f)]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return {"vertices": tri.reshape(-1, 3), "faces": np.arange(3 * len(tri)).reshape(-1, 3),
            "normals": np.repeat(nrm, 3, axis=0)}


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
    L = np.asarray(light["direction"], np.float64)
    L /= np.linalg.norm(L)
    a = np.cross(L, [0.0, 1.0, 0.0] if abs(L[1]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(L, a)
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
    :func:`mitsuba_paths`), spawned along the ray. A photon that reaches a
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
    """
    from .caustics.splat import splat_bilinear
    from .interop import mitsuba as M
    from .meshes import bounds, object_mesh

    mi = M.require(variant)
    d = scene.data
    lights = d.get("lights") or []
    if any(lt["type"] != "directional" for lt in lights):
        raise ValueError("mitsuba_photons: directional lights only (a point light's photons are not built)")
    objs = M.object_meshes(scene)
    K = len(objs)
    recv = [_receiver_soup(*object_mesh(rc, scene.base_dir)) for rc in d["receivers"]]
    face_norm = any(m["normals"] is None for m in objs)
    parts = objs + [dict(r, normals=None if face_norm else r["normals"]) for r in recv]
    v, f, nrm, owner = _merged_mesh(parts)  # owner < K: object, else receiver owner - K
    os.makedirs(folder, exist_ok=True)
    M.write_ply(os.path.join(folder, "photons.ply"), v, f, nrm)
    s = mi.load_dict({"type": "scene", "all": {"type": "ply", "filename": os.path.join(folder, "photons.ply"),
                                                "face_normals": nrm is None}})
    rface_n = np.concatenate([np.cross(r["vertices"][1::3] - r["vertices"][0::3],
                                       r["vertices"][2::3] - r["vertices"][0::3]) for r in recv])
    rface_n /= np.linalg.norm(rface_n, axis=1, keepdims=True)
    nobj_faces = int(np.count_nonzero(owner < K))
    ior = np.array([m["ior"] for m in objs] + [float(d["outside_ior"])])
    absn = np.array([np.asarray(m["absorption"], np.float64) * m["ior"] for m in objs] + [np.zeros(3)])
    outside = K
    maxb = int(d["exact"]["max_bounces"] if max_bounces is None else max_bounces)
    ov = np.concatenate([m["vertices"] for m in objs])
    lo, hi = bounds(v)
    diag = float(np.linalg.norm(hi - lo))
    eps = 1e-5 * max(diag, float(np.abs(v).max()))
    maps = [np.zeros(tuple(sh) + (1,)) for sh in shapes]
    stats = {"photons": 0, "deposited": 0, "limit": 0}
    rng = np.random.default_rng(int(seed))
    for lt in lights:
        o, dirn, flux = _light_photons(lt, ov, n, rng, diag)
        N = len(flux)
        rad = np.asarray(lt.get("radiance", [1.0, 1.0, 1.0]), np.float64)
        medium = np.full(N, outside)
        inter = np.zeros(N, np.int32)
        trans = np.ones((N, 3))
        active = np.ones(N, bool)
        stats["photons"] += N
        for bounce in range(maxb + 1):
            ov32 = o.astype(np.float32).T
            dv32 = dirn.astype(np.float32).T
            ray = mi.Ray3f(mi.Point3f(ov32[0], ov32[1], ov32[2]), mi.Vector3f(dv32[0], dv32[1], dv32[2]))
            si = s.ray_intersect(ray, mi.Bool(active))
            valid = np.array(si.is_valid(), dtype=bool) & active
            if not valid.any():
                break
            prim = np.array(si.prim_index, dtype=np.int64)
            p = _np3(si.p)
            t = np.array(si.t, dtype=np.float64)
            idx = np.flatnonzero(valid)
            seg = np.where(np.isfinite(t[idx]), t[idx], 0.0)
            trans[idx] *= np.exp(-absn[medium[idx]] * seg[:, None])
            isrec = prim[idx] >= nobj_faces
            # receivers: a photon through an object deposits; a direct one (no refraction) is not a caustic
            hr = idx[isrec]
            dep = hr[inter[hr] > 0]
            for r in range(len(recv)):
                fr = np.asarray(frames[r], np.float64)
                sel = dep[owner[prim[dep]] - K == r]
                if not sel.size:
                    continue
                u, vv, Vn = fr[1], fr[2], fr[3]
                Hc, Wc = shapes[r]
                q = p[sel] - fr[0]
                col = (q @ u) / (u @ u) * Wc
                row = (q @ vv) / (vv @ vv) * Hc
                texel = np.linalg.norm(u) * np.linalg.norm(vv) / (Wc * Hc)
                cosv = np.abs(rface_n[prim[sel] - nobj_faces] @ Vn)
                val = flux[sel] * cosv / texel * np.mean(trans[sel] * rad, axis=1)
                splat_bilinear(col, row, val[:, None], (Hc, Wc), out=maps[r])
                stats["deposited"] += int(sel.size)
            active[hr] = False
            a_ = idx[~isrec]
            if bounce == maxb:
                stats["limit"] += int(a_.size)
                break
            if not a_.size:
                break
            ng = _np3(si.n)[a_]
            sh = _np3(si.sh_frame.n)[a_]
            dd = dirn[a_]
            cos_g = np.sum(dd * ng, axis=1)
            entering = cos_g < 0
            obj = owner[prim[a_]]
            eta = ior[medium[a_]] / np.where(entering, ior[obj], ior[outside])
            out, tir, lost = _interface(dd, sh, ng, eta)
            crossed = ~tir & ~lost
            medium[a_[crossed]] = np.where(entering[crossed], obj[crossed], outside)
            inter[a_[crossed]] += 1
            active[a_[lost]] = False
            side = np.where((np.sum(out * ng, axis=1) >= 0)[:, None], ng, -ng)
            o[a_] = p[a_] + eps * out + (0.1 * eps) * side
            dirn[a_] = out
            # photons that left every surface behind are done
            miss = ~np.array(si.is_valid(), dtype=bool) & active
            active[miss] = False
    return [m[..., 0] for m in maps], stats


# --------------------------------------------------------------------------- water
def _load_ply_scene(mi, path, v, f, nrm):
    """A Mitsuba scene of one PLY (``nrm`` per vertex, or None for face normals)."""
    from .interop import mitsuba as M

    M.write_ply(path, v, f, nrm)
    return mi.load_dict({"type": "scene", "all": {"type": "ply", "filename": path, "face_normals": nrm is None}})


def _ray(mi, o, d):
    o32 = np.asarray(o, np.float32).T
    d32 = np.asarray(d, np.float32).T
    return mi.Ray3f(mi.Point3f(o32[0], o32[1], o32[2]), mi.Vector3f(d32[0], d32[1], d32[2]))


def _map_visibility(mi, rscene, owner, frame, shape, reach):
    """Receiver ``r``'s map visibility by Mitsuba's ray caster: per texel centre, the first receiver
    surface along ``-V`` from ``reach`` above the map plane (its owner, or -1) and its depth ``p . V``."""
    fr = np.asarray(frame, np.float64)
    Hc, Wc = shape
    a, b = np.meshgrid(np.arange(Hc), np.arange(Wc), indexing="ij")
    pts = fr[0] + ((b.ravel() + 0.5) / Wc)[:, None] * fr[1] + ((a.ravel() + 0.5) / Hc)[:, None] * fr[2]
    Vn = fr[3] / np.linalg.norm(fr[3])
    si = rscene.ray_intersect(_ray(mi, pts + reach * Vn, np.tile(-Vn, (len(pts), 1))))
    ok = np.array(si.is_valid(), dtype=bool)
    own = np.where(ok, owner[np.where(ok, np.array(si.prim_index, dtype=np.int64), 0)], -1)
    depth = np.where(ok, _np3(si.p) @ Vn, np.nan)
    return own.reshape(Hc, Wc), depth.reshape(Hc, Wc)


def _splat_on_map(col, row, val, shape):
    """Bilinear splat (texel centres at +0.5) that drops the weights falling off the map, as the exact
    water reference's maps do."""
    Hc, Wc = shape
    c, r = col - 0.5, row - 0.5
    j0, i0 = np.floor(c).astype(np.int64), np.floor(r).astype(np.int64)
    fx, fy = c - j0, r - i0
    acc = np.zeros(Hc * Wc)
    for di, wy in ((0, 1.0 - fy), (1, fy)):
        for dj, wx in ((0, 1.0 - fx), (1, fx)):
            a, b = i0 + di, j0 + dj
            good = (a >= 0) & (a < Hc) & (b >= 0) & (b < Wc)
            acc += np.bincount(a[good] * Wc + b[good], weights=(val * wy * wx)[good], minlength=Hc * Wc)
    return acc.reshape(Hc, Wc)


def _water_light_photons(light, water, top, low, density, rng):
    """Jittered photons of a light through the horizontal rectangle ``y = top`` over the water, ``density``
    per unit area (``n`` x ``n``): start points, unit directions, flux (the light's mean radiance, ``/ r^2``
    for a point light, times the cosine to the plane and the photon's share of the area).

    The rectangle is the water's plus 2 %, widened by the light's horizontal travel from ``top`` down to
    the lowest water ``low`` (a slanted ray that meets a trough at the edge starts that far outside)."""
    sx, sz = (float(s) for s in water["size"])
    cx, cz = np.meshgrid([-sx / 2, sx / 2], [-sz / 2, sz / 2])
    corners = np.stack([cx.ravel(), np.full(4, low), cz.ravel()], axis=1)
    dc = (np.tile(np.asarray(light["direction"], np.float64), (4, 1)) if light["type"] == "directional"
          else corners - np.asarray(light["position"], np.float64))
    shift = float(np.max(np.hypot(dc[:, 0], dc[:, 2]) / np.abs(dc[:, 1]))) * (top - low)
    sx, sz = 1.02 * sx + 2 * shift, 1.02 * sz + 2 * shift
    n = max(int(np.ceil(np.sqrt(density * sx * sz))), 1)
    N = n * n
    gi, gj = np.divmod(np.arange(N), int(n))
    x = ((gj + rng.random(N)) / n - 0.5) * sx
    z = ((gi + rng.random(N)) / n - 0.5) * sz
    o = np.stack([x, np.full(N, top), z], axis=1)
    w = float(np.mean(np.asarray(light["radiance"], np.float64)))
    if light["type"] == "directional":
        d = np.tile(np.asarray(light["direction"], np.float64), (N, 1))
        e = np.full(N, w)
    else:
        d = o - np.asarray(light["position"], np.float64)
        e = w / np.sum(d * d, axis=1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o, d, e * np.abs(d[:, 1]) * (sx * sz / N), sx * sz


def mitsuba_water_photons(scene, folder, frames, shapes, density, seeds, variant="llvm_ad_rgb",
                          water_resolution=None):
    """Caustic maps of a water scene from photons through Mitsuba's intersector, in our map frames.

    An independent photon tracer for the exact water reference
    (:mod:`refraction_ref.exact.water`): per light ``n`` x ``n`` jittered
    photons (stream ``np.random.default_rng(seed)``, ``density`` per unit
    area) through a horizontal rectangle just above the waves (the water's
    size plus 2 %, widened by the light's horizontal travel down to the
    lowest water), each carrying
    the light's flux through its share of that rectangle; the water is the
    exported dense height-field mesh (:func:`~refraction_ref.interop.mitsuba.export_water_mesh`,
    the analytic normals at its vertices, Mitsuba's interpolated shading
    normal at a hit); Snell in float64 at Mitsuba's hit (``outside_ior`` to
    ``water.ior``; the refracted photon must go down, and does not meet the
    water again, as in the reference); then Mitsuba's first receiver hit
    (receivers shadow each other), ``exp(-K t)`` over the distance in water.
    A photon deposits ``flux exp(-K t) |n_r . V| / A_texel`` bilinearly in
    the frame ``(origin, u, v, V)``, weights off the map dropped, where the
    map sees its point: the first receiver surface along ``-V`` through the
    photon's texel centre, cast by Mitsuba, is the photon's receiver within
    ``2 texel / max(|n_r . V|, 0.05)`` of its depth (the rule of the maps).

    Parameters
    ----------
    scene : Scene
        A water scene (directional or point lights).
    folder : str
        Where the water and receiver PLYs are written.
    frames : list of (4, 3) arrays
        Our ``caustic_frame_r`` (the only thing read from our side).
    shapes : list of (Hc, Wc)
    density : float
        Photons per unit area of the rectangle, per light and batch.
    seeds : sequence of int
        One batch per seed.
    variant : str
        Mitsuba variant (a vectorised one).
    water_resolution : int, optional
        Quads per side of the water mesh (default the export's).

    Returns
    -------
    maps : list (per seed) of list (per receiver) of (Hc, Wc) float64
    stats : dict
        ``photons``, ``water`` (met the water), ``deposited`` (seen by a map)
        per batch (means), ``window`` (the rectangles' area, summed over the
        lights), the mesh's ``resolution``.

    References
    ----------
    .. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
       with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
       University, 2006, eq. 2-8, §4.5, eqs. 4-17, 4-18.
    .. [2] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org.
    """
    from .interop import mitsuba as M
    from .meshes import object_mesh

    mi = M.require(variant)
    d = scene.data
    w = d["water"]
    wm, res = M.export_water_mesh(w, water_resolution)
    os.makedirs(folder, exist_ok=True)
    wscene = _load_ply_scene(mi, os.path.join(folder, "water.ply"), wm.vertices, wm.faces, wm.normals)
    recv = [_receiver_soup(*object_mesh(rc, scene.base_dir)) for rc in d["receivers"]]
    rv, rf, _, owner = _merged_mesh([dict(r, normals=None) for r in recv])
    rscene = _load_ply_scene(mi, os.path.join(folder, "receivers.ply"), rv, rf, None)
    rn = np.cross(rv[rf[:, 1]] - rv[rf[:, 0]], rv[rf[:, 2]] - rv[rf[:, 0]])
    rn /= np.linalg.norm(rn, axis=1, keepdims=True)
    allv = np.concatenate([wm.vertices, rv])
    reach = 4.0 * float(np.linalg.norm(allv.max(0) - allv.min(0)))
    vis = [_map_visibility(mi, rscene, owner, frames[r], shapes[r], reach) for r in range(len(recv))]
    top = float(wm.vertices[:, 1].max()) + 1e-3 * max(float(s) for s in w["size"])
    low = float(wm.vertices[:, 1].min())
    eta = float(d["outside_ior"]) / float(w["ior"])
    K = float(w["absorption"])
    out, stats = [], {"photons": 0, "water": 0, "deposited": 0, "window": 0.0}
    for seed in seeds:
        rng = np.random.default_rng(int(seed))
        maps = [np.zeros(tuple(sh)) for sh in shapes]
        for lt in d["lights"]:
            o, dirn, flux, window = _water_light_photons(lt, w, top, low, density, rng)
            si = wscene.ray_intersect(_ray(mi, o, dirn))
            hit = np.flatnonzero(np.array(si.is_valid(), dtype=bool))
            stats["photons"] += len(flux)
            stats["window"] += window
            stats["water"] += int(hit.size)
            t, tir, lost = _interface(dirn[hit], _np3(si.sh_frame.n)[hit], _np3(si.n)[hit], np.full(hit.size, eta))
            go = ~tir & ~lost & (t[:, 1] < 0)
            pw, t, f = _np3(si.p)[hit][go], t[go], flux[hit][go]
            sr = rscene.ray_intersect(_ray(mi, pw, t))
            ok = np.array(sr.is_valid(), dtype=bool)
            prim = np.array(sr.prim_index, dtype=np.int64)[ok]
            p = _np3(sr.p)[ok]
            val = f[ok] * np.exp(-K * np.linalg.norm(p - pw[ok], axis=1))
            for r in range(len(recv)):
                m = owner[prim] == r
                fr = np.asarray(frames[r], np.float64)
                Hc, Wc = shapes[r]
                Vn = fr[3] / np.linalg.norm(fr[3])
                q = p[m] - fr[0]
                col = (q @ fr[1]) / (fr[1] @ fr[1]) * Wc
                row = (q @ fr[2]) / (fr[2] @ fr[2]) * Hc
                jn = np.clip(np.floor(col).astype(np.int64), 0, Wc - 1)
                in_ = np.clip(np.floor(row).astype(np.int64), 0, Hc - 1)
                cosv = np.abs(rn[prim[m]] @ Vn)
                texel = max(np.linalg.norm(fr[1]) / Wc, np.linalg.norm(fr[2]) / Hc)
                seen = (vis[r][0][in_, jn] == r) & (np.abs(p[m] @ Vn - vis[r][1][in_, jn])
                                                   <= 2.0 * texel / np.maximum(cosv, 0.05))
                area = np.linalg.norm(fr[1]) * np.linalg.norm(fr[2]) / (Wc * Hc)
                maps[r] += _splat_on_map(col[seen], row[seen], (val[m] * cosv / area)[seen], (Hc, Wc))
                stats["deposited"] += int(seen.sum())
        out.append(maps)
    k = max(len(out), 1)
    return out, {"photons": stats["photons"] // k, "water": stats["water"] // k,
                 "deposited": stats["deposited"] // k, "window": stats["window"] / k, "resolution": res}


def water_paths_case(case, folder, variant="llvm_ad_rgb", water_resolution=None):
    """The eye rays of a water scene's ``image``: our refracted direction at the analytic surface
    (stage buffers ``water_pos``, ``water_dir``) against Snell at Mitsuba's hit on the exported mesh.

    Parameters
    ----------
    case : dict
        A catalogue case with water.
    folder : str
        Scratch folder for the scene and Mitsuba's files.
    variant : str
        Mitsuba variant (a vectorised one).
    water_resolution : int, optional
        Quads per side of the water mesh (default the export's).

    Returns
    -------
    num : dict
        ``kind: 'water'``; pixels meeting the water in either, their
        agreement (``status_agree``: over all pixels, whether the eye ray
        meets the water), median / p99 / max angle between the refracted
        directions where both meet it, hit-point distance p99 (world units),
        the mesh's resolution and the expected normal error of its
        interpolated normals.
    figs : dict
        ``angle`` (H, W), ``status_ours``, ``status_mitsuba`` (H, W: 1 where
        the eye ray meets the water).

    References
    ----------
    .. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
       with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
       University, 2006, eq. 2-8 (Snell at the water), §4.6 (the view).
    """
    import refraction_ref as rr

    from .camera import Camera
    from .golden.build import case_scene
    from .interop import mitsuba as M
    from .status import VIEW_LOST, VIEW_THROUGH, VIEW_TIR

    scene = case_scene(case, os.path.join(folder, "scene"))
    t0 = time.perf_counter()
    a = rr.render(scene, method="exact", keep="image").arrays
    t1 = time.perf_counter()
    vs = a["stage.image.view_status"]
    ours = np.isin(vs, (VIEW_THROUGH, VIEW_LOST, VIEW_TIR))
    mi = M.require(variant)
    d = scene.data
    w = d["water"]
    cam = Camera.from_dict(d["camera"])
    H, W = cam.height, cam.width
    wm, res = M.export_water_mesh(w, water_resolution)
    os.makedirs(folder, exist_ok=True)
    wscene = _load_ply_scene(mi, os.path.join(folder, "water.ply"), wm.vertices, wm.faces, wm.normals)
    sensor = mi.load_dict({"type": "perspective", "fov": float(cam.fov_y), "fov_axis": "y", "near_clip": 1e-4,
                           "far_clip": 1e4,
                           "to_world": mi.ScalarTransform4f().look_at(origin=list(cam.eye), target=list(cam.target),
                                                                      up=list(cam.up)),
                           "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}}})
    idx = np.arange(H * W)
    pos = np.stack([(idx % W + 0.5) / W, (idx // W + 0.5) / H]).astype(np.float32)
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(pos[0], pos[1]), mi.Point2f(0.5, 0.5))
    si = wscene.ray_intersect(mi.Ray3f(ray))
    t2 = time.perf_counter()
    mit = np.array(si.is_valid(), dtype=bool)
    dd = _np3(ray.d)
    dd /= np.linalg.norm(dd, axis=1, keepdims=True)
    eta = np.full(len(dd), float(d["outside_ior"]) / float(w["ior"]))
    t, tir, _ = _interface(dd, _np3(si.sh_frame.n), _np3(si.n), eta)
    both = ours.ravel() & mit & ~tir & np.all(np.isfinite(a["stage.image.water_dir"].reshape(-1, 3)), axis=1)
    ang = np.full(H * W, np.nan)
    ang[both] = angular_error_deg(a["stage.image.water_dir"].reshape(-1, 3)[both], t[both])
    dp = np.linalg.norm(a["stage.image.water_pos"].reshape(-1, 3)[both] - _np3(si.p)[both], axis=1)
    x = ang[both]
    num = {"kind": "water", "pixels": int(H * W), "water_ours": int(ours.sum()), "water_mitsuba": int(mit.sum()),
           "both": int(both.sum()), "status_agree": float(np.mean(ours.ravel() == mit)),
           "median_deg": float(np.median(x)) if x.size else float("nan"),
           "p99_deg": float(np.percentile(x, 99)) if x.size else float("nan"),
           "max_deg": float(x.max()) if x.size else float("nan"),
           "water_pos_p99": float(np.percentile(dp, 99)) if dp.size else float("nan"),
           "resolution": res, "normal_error_deg": water_mesh_normal_error_deg(w, res),
           "ours_s": t1 - t0, "mitsuba_s": t2 - t1}
    figs = {"angle": ang.reshape(H, W), "status_ours": ours.astype(np.int8),
            "status_mitsuba": mit.reshape(H, W).astype(np.int8)}
    return num, figs


def water_mesh_normal_error_deg(water, resolution):
    """The expected largest angle between the mesh's interpolated normal and the analytic one (degrees).

    Linear interpolation of the normal over a triangle errs by ``e^2 / 8``
    (``e = sqrt(2) h``, its longest edge, ``h`` the quad side) times the
    normal's second derivative, at most ``sum_k A_k k^3``
    for waves ``A sin(k x + phase)`` (``k = 2 pi / wavelength``); the
    refracted direction errs by ``1 - 1 / n`` of that at normal incidence.

    Parameters
    ----------
    water : dict
        The resolved ``water`` block.
    resolution : int
        Quads per side of the mesh.

    Returns
    -------
    float
        The bound on the normal's angle, degrees.
    """
    h = max(float(s) for s in water["size"]) / int(resolution)
    third = sum(float(wv["amplitude"]) * (2 * np.pi / float(wv["wavelength"])) ** 3 for wv in water.get("waves", []))
    return float(np.degrees(2.0 * h * h / 8.0 * third))


#: batches of each side in the caustics cross-check (the golden suite's exact_caustics_sphere uses 8)
CAUSTIC_BATCHES = 8


def _mesh_batches(scene, folder, frames, shapes, K, q, oversample):
    """Mitsuba's K batches of mesh caustics (:func:`mitsuba_photons`), ``oversample`` times our
    photon density over its own window; (maps per batch, numbers for the report)."""
    from .caustics.receivers import receiver_set
    from .interop.mitsuba import object_meshes

    texel_min = min(b.texel_area for b in receiver_set(scene, scene.data["lights"][0],
                                                       int(scene.data["caustics"]["map_size"])).boxes)
    flux_ours = q * texel_min / max([float(np.max(lt.get("radiance", [1.0]))) for lt in scene.data["lights"]]
                                   + [1.0])
    # photons per side for Mitsuba's window at `oversample` times our density
    ov = np.concatenate([m["vertices"] for m in object_meshes(scene)])
    L = np.asarray(scene.data["lights"][0]["direction"], np.float64)
    L /= np.linalg.norm(L)
    a = np.cross(L, [0.0, 1.0, 0.0] if abs(L[1]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(L, a)
    area = 1.02 ** 2 * np.ptp(ov @ a) * np.ptp(ov @ b)
    n = int(np.ceil(np.sqrt(oversample * area / flux_ours)))
    mit, st = [], []
    for k in range(K):
        m, s_ = mitsuba_photons(scene, folder, frames, shapes, n, 1000 + k)
        mit.append(m)
        st.append(s_)
    return mit, {"photons_ours": int(scene.data["exact"]["photons"]) ** 2, "photons_mitsuba": n * n,
                 "photon_flux_ours": flux_ours, "photon_flux_mitsuba": area / (n * n),
                 "deposited_mitsuba": int(np.mean([x["deposited"] for x in st])),
                 "limit_mitsuba": int(np.mean([x["limit"] for x in st]))}


def _water_batches(scene, folder, frames, shapes, K, q, oversample):
    """Mitsuba's K batches of water caustics (:func:`mitsuba_water_photons`), ``oversample`` times
    our sample density over the water; (maps per batch, numbers for the report)."""
    w = scene.data["water"]
    M_ = int(scene.data["exact"]["water_samples"])
    sx, sz = (float(v) for v in w["size"])
    flux_ours = sx * sz / (M_ * M_)  # one water sample's area (per unit light, as photon_flux_mitsuba)
    mit, st = mitsuba_water_photons(scene, folder, frames, shapes, oversample / flux_ours,
                                    [1000 + k for k in range(K)])
    return mit, {"photons_ours": M_ * M_, "photons_mitsuba": st["photons"], "photon_flux_ours": flux_ours,
                 "photon_flux_mitsuba": st["window"] / st["photons"], "deposited_mitsuba": st["deposited"],
                 "water_mitsuba": st["water"], "limit_mitsuba": 0, "water_resolution": st["resolution"],
                 "normal_error_deg": water_mesh_normal_error_deg(w, st["resolution"])}


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
    """
    import refraction_ref as rr

    from .golden.build import _seed_key, case_scene, photon_quantum
    from .golden.tolerances import ZTEST, judge
    from .metrics import relative_l1

    K = int(batches or case.get("batches") or CAUSTIC_BATCHES)
    water = case["scene"].get("water") is not None
    if water:  # the maps do not read the camera: a small one keeps our K renders' image stage short
        case = copy.deepcopy(case)
        case["scene"]["camera"] = dict(case["scene"]["camera"], width=8, height=8)
    scene = case_scene(case, os.path.join(folder, "scene"))
    sk = _seed_key(scene)
    t0 = time.perf_counter()
    ours = [rr.render(scene, method="exact", overrides={sk: b}).arrays for b in range(K)]
    t1 = time.perf_counter()
    R = len(scene.data["receivers"])
    frames = [ours[0][f"caustic_frame_{r}"] for r in range(R)]
    shapes = [ours[0][f"caustic_map_{r}"].shape for r in range(R)]
    q = photon_quantum(scene)
    batches_of = _water_batches if water else _mesh_batches
    mit, info = batches_of(scene, os.path.join(folder, "mitsuba"), frames, shapes, K, q, oversample)
    t2 = time.perf_counter()
    num = dict(info, batches=K, quantum=q, ours_s=t1 - t0, mitsuba_s=t2 - t1, receivers=[])
    figs = []
    spec = dict(ZTEST, quantum=q)
    # texel area of each map over the smallest (the golden quantum is for the smallest)
    texel = [float(np.linalg.norm(np.cross(f[1], f[2]))) / (sh[0] * sh[1]) for f, sh in zip(frames, shapes)]
    texel = [min(texel) / t for t in texel]
    for r in range(R):
        ob = np.stack([o[f"caustic_map_{r}"].astype(np.float64) for o in ours])
        mb = np.stack([m[r] for m in mit])
        om, mm = ob.mean(0), mb.mean(0)
        h = K // 2
        verd = [judge(mb[k], om, spec, batches=ob) for k in range(K)]
        back = [judge(ob[k], mm, spec, batches=mb) for k in range(K)]
        # the golden quantum is one photon on the smallest texel of all the maps: on a receiver of larger
        # texels its floor p q^2 swamps the batch variance; the same test with this map's own quantum is stricter
        own = [judge(mb[k], om, dict(ZTEST, quantum=q * texel[r] / max(texel)), batches=ob) for k in range(K)]
        num["receivers"].append({
            "rel_l1": float(relative_l1(mm, om)),
            "rel_l1_ours_halves": float(relative_l1(ob[:h].mean(0), ob[h:].mean(0))),
            "rel_l1_mitsuba_halves": float(relative_l1(mb[:h].mean(0), mb[h:].mean(0))),
            "power_ratio": float(mm.sum() / max(float(om.sum()), 1e-30)),
            "batches": K, "ztest_pass": int(sum(v["ok"] for v in verd)),
            "ztest_max_abs_z": float(max(v["error"]["max_abs_z"] for v in verd)),
            "ztest_threshold": float(verd[0]["error"]["threshold"]),
            "ztest_reverse_pass": int(sum(v["ok"] for v in back)),
            "ztest_own_quantum_pass": int(sum(v["ok"] for v in own)),
            "ztest_own_quantum_max_abs_z": float(max(v["error"]["max_abs_z"] for v in own)),
        })
        figs.append({"ours": om, "mitsuba": mm})
    return num, figs


def _panels(n):
    """A row of ``n`` square panels (the report's figures: A, B, A-B, ...)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(1, n, figsize=(4 * n, 4))


def _save_panels(fig, ax, path, title):
    """Write a figure of :func:`_panels` to ``path`` and close it; its file name, as the report links it."""
    import matplotlib.pyplot as plt

    for a in ax:
        a.axis("off")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return os.path.basename(path)


def _caustics_figure(figs, path, name):
    f = figs[0]
    vmax = float(np.percentile(f["ours"], 99.5)) or 1.0
    fig, ax = _panels(3)
    ax[0].imshow(f["ours"], vmin=0, vmax=vmax, cmap="inferno", interpolation="nearest")
    ax[0].set_title("A: ours (exact), K-batch mean")
    ax[1].imshow(f["mitsuba"], vmin=0, vmax=vmax, cmap="inferno", interpolation="nearest")
    ax[1].set_title("B: photons on Mitsuba's intersector")
    im = ax[2].imshow(f["ours"] - f["mitsuba"], vmin=-vmax / 4, vmax=vmax / 4, cmap="RdBu", interpolation="nearest")
    ax[2].set_title("A-B")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    return _save_panels(fig, ax, path, name + ": caustic_map_0")


# --------------------------------------------------------------------------- cases, report, cluster
def _has_caustics(case):
    s = case["scene"]
    return bool(s.get("lights")) and bool(s.get("receivers")) and (
        case["method"] == "exact" or case.get("reference") == "exact")


def _skip_reason(case):
    if case["method"] == "volumetric":
        return ("volumetric: a graded-index volume (continuous refraction) has no Mitsuba plugin (media "
                "scatter and absorb, they do not bend rays); no exact mesh reference to cross-check")
    if case["method"] == "exact" and not _has_caustics(case):
        return "exact method without receivers: nothing beyond the image-space cases' references"
    return None


def run_case(case, folder, parts=("paths", "images", "caustics"), figures=True):
    """Cross-check one case into ``folder``; its entry (numbers per part, figure files, or a skip reason).

    Paths and images run on the cases with an exact per-pixel reference
    (``reference: exact``), caustics on every case with lights and receivers
    whose method or reference is exact. A water scene's paths are its eye
    rays refracted at the water (:func:`water_paths_case`), its caustics
    Mitsuba's photons through the water mesh (:func:`mitsuba_water_photons`);
    its image is not cross-checked.

    Parameters
    ----------
    case : dict
        A catalogue case.
    folder : str
        The case's output folder (figures).
    parts : sequence of {'paths', 'images', 'caustics'}
        The cross-checks to run.
    figures : bool
        Write the PNG figures.

    Returns
    -------
    dict
        ``name``, ``purpose``, ``method``, and ``skipped`` (a reason) or the
        parts' numbers and ``seconds``.
    """
    t0 = time.perf_counter()
    entry = {"name": case["name"], "purpose": case["purpose"], "method": case["method"]}
    why = _skip_reason(case)
    if why:
        entry["skipped"] = why
        return entry
    os.makedirs(folder, exist_ok=True)
    water = case["scene"].get("water") is not None
    pixels = case.get("reference") == "exact" and not water
    with tempfile.TemporaryDirectory(prefix="crosscheck-") as tmp:
        if "paths" in parts and water:  # the eye rays refracted at the water (the images are not cross-checked)
            num, pf = water_paths_case(case, os.path.join(tmp, "paths"))
            entry["paths"] = num
            if figures:
                entry["paths"]["figure"] = _paths_figure(pf, os.path.join(folder, "paths.png"), case["name"],
                                                         "meets the water")
        if "paths" in parts and pixels:
            num, pf = paths_case(case, os.path.join(tmp, "paths"))
            entry["paths"] = num
            if figures:
                entry["paths"]["figure"] = _paths_figure(pf, os.path.join(folder, "paths.png"), case["name"])
        if "images" in parts and pixels:
            num, imf = images_case(case, os.path.join(tmp, "images"))
            entry["images"] = num
            if figures:
                entry["images"]["figure"] = _images_figure(imf, os.path.join(folder, "images.png"), case["name"])
        if "caustics" in parts and _has_caustics(case):
            num, cf = caustics_case(case, os.path.join(tmp, "caustics"))
            entry["caustics"] = num
            if figures:
                entry["caustics"]["figure"] = _caustics_figure(cf, os.path.join(folder, "caustics.png"),
                                                               case["name"])
    entry["seconds"] = time.perf_counter() - t0
    return entry


def _paths_figure(f, path, name, what="status"):
    fig, ax = _panels(3)
    ax[0].imshow(f["status_ours"], vmin=0, vmax=4, cmap="tab10", interpolation="nearest")
    ax[0].set_title(f"A: {what}, ours (exact)")
    ax[1].imshow(f["status_mitsuba"], vmin=0, vmax=4, cmap="tab10", interpolation="nearest")
    ax[1].set_title(f"B: {what}, Mitsuba paths")
    im = ax[2].imshow(np.log10(np.maximum(f["angle"], 1e-7)), vmin=-6, vmax=1, cmap="magma", interpolation="nearest")
    ax[2].set_title("A-B: " + ("refracted" if what != "status" else "exit") + " angle, log10 deg")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    return _save_panels(fig, ax, path, name)


def _images_figure(f, path, name):
    fig, ax = _panels(5)
    ax[0].imshow(np.clip(f["ours"], 0, 1), interpolation="nearest")
    ax[0].set_title("A: ours (exact)")
    ax[1].imshow(np.clip(f["mitsuba"], 0, 1), interpolation="nearest")
    ax[1].set_title("B: Mitsuba parts, Fresnel-free")
    d = (f["ours"] - f["mitsuba"]).mean(-1)
    im = ax[2].imshow(d, vmin=-0.5, vmax=0.5, cmap="RdBu", interpolation="nearest")
    ax[2].set_title("A-B (grey: not judged)")
    ax[2].contourf(~f["judged"], levels=[0.5, 1.5], colors=["0.6"], alpha=0.35)
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    ax[3].imshow(np.clip(f["path"], 0, 1), interpolation="nearest")
    ax[3].set_title("Mitsuba path integrator")
    ax[4].imshow(np.clip(f["fresnel"], 0, 1), interpolation="nearest")
    ax[4].set_title("Mitsuba dielectric (Fresnel)")
    return _save_panels(fig, ax, path, name)


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


def run(out, only=None, parts=("paths", "images", "caustics"), workers=None, scheduler=None, log=print,
        client=None, report=None, merge=None):
    """Cross-check the catalogue (or ``only`` those cases) into ``out``: ``crosscheck.json``,
    ``crosscheck.md`` (or the Markdown file ``report``, its figure links relative to it) and ``<case>/*.png``. Cases run as Dask tasks with ``workers``
    (a LocalCluster) or ``scheduler`` (as ``golden build``), else here one by one.

    Parameters
    ----------
    out : str
        Output folder (created when missing).
    only : str or sequence of str, optional
        Case names; None for the whole catalogue.
    parts : sequence of {'paths', 'images', 'caustics'}
        The cross-checks to run.
    workers : int, optional
        Processes of a local Dask cluster.
    scheduler : str, optional
        Address of a running Dask scheduler.
    log : callable
        ``log(str)`` for one line per finished case.
    client : distributed.Client, optional
        An open Dask client to use.
    report : str, optional
        Path of the Markdown report (default ``out/crosscheck.md``).
    merge : str, optional
        An earlier ``crosscheck.json``: its cases that this run does not redo
        are kept (their figures are not copied: give the same ``out``).

    Returns
    -------
    dict
        ``targets``, ``tir_chaos``, ``versions`` and ``cases`` (per case its
        :func:`run_case` entry), as written to ``crosscheck.json``.
    """
    from .files import atomic_open

    cases = crosscheck_cases(only)
    entries = {}
    if merge:
        with open(merge) as fh:
            entries.update(json.load(fh)["cases"])
    os.makedirs(out, exist_ok=True)

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
        from distributed import as_completed

        from .cluster import dask_client

        with dask_client(scheduler, workers, 1, client) as client:  # closed quietly, as golden build's
            futures = [client.submit(_case_task, c, tuple(parts), pure=False) for c in cases]
            for fu in as_completed(futures):
                done(*fu.result())
    from .contract import software_versions

    result = {"targets": TARGETS, "tir_chaos": list(TIR_CHAOS), "versions": _versions(software_versions()),
              "cases": dict(sorted(entries.items()))}
    with atomic_open(os.path.join(out, "crosscheck.json"), "w") as f:
        json.dump(result, f, indent=1, sort_keys=True, default=float)
    md = report or os.path.join(out, "crosscheck.md")
    link = os.path.relpath(os.path.abspath(out), os.path.dirname(os.path.abspath(md)))
    with atomic_open(md, "w") as f:
        f.write(report_markdown(result, "" if link == "." else link + "/"))
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


def _counts(d):
    """Status counts as ``{0: n, ...}`` (integer keys, also after a JSON round trip: ``--merge``)."""
    return str({int(k): int(v) for k, v in sorted(d.items(), key=lambda kv: int(kv[0]))})


def _mark(ok):
    return "pass" if ok else "**FAIL**"


def verdicts(name, e):
    """Each target's verdict for one case entry: {target: bool or None (reported, not judged)}.

    Parameters
    ----------
    name : str
        The case name (the :data:`TIR_CHAOS` cases' angles are not judged).
    e : dict
        The case's entry (:func:`run_case`).

    Returns
    -------
    dict of str to bool or None
    """
    v = {}
    p = e.get("paths")
    if p:
        chaos = name in TIR_CHAOS
        v["median_deg"] = None if chaos else p["median_deg"] <= TARGETS["median_deg"]
        v["p99_deg"] = None if chaos else p["p99_deg"] <= TARGETS["p99_deg"]
        v["status_agree"] = p["status_agree"] >= TARGETS["status_agree"]
    i = e.get("images")
    if i:
        v["image_rel_rmse"] = i["rel_rmse_judged"] <= TARGETS["image_rel_rmse"]
    c = e.get("caustics")
    if c:
        v["caustics_ztest"] = all(r["ztest_pass"] == r["batches"] for r in c["receivers"])
    return v


def failed_targets(name, e):
    """The targets a case's entry misses (judged ones only; a skipped case misses none).

    Parameters
    ----------
    name : str
        The case name.
    e : dict
        The case's entry (:func:`run_case`).

    Returns
    -------
    list of str
        Target names of :func:`verdicts` whose verdict is False, in its order.
    """
    if "skipped" in e:
        return []
    return [k for k, x in verdicts(name, e).items() if x is False]


def _summary(result):
    """The report's findings, from the numbers."""
    T = result["targets"]
    c = result["cases"]
    ran = {k: e for k, e in c.items() if "skipped" not in e}
    P = {k: e["paths"] for k, e in ran.items() if "paths" in e and e["paths"].get("kind") != "water"}
    Wp = {k: e["paths"] for k, e in ran.items() if "paths" in e and e["paths"].get("kind") == "water"}
    I = {k: e["images"] for k, e in ran.items() if "images" in e}
    C = {k: e["caustics"] for k, e in ran.items() if "caustics" in e}
    out = ["**Findings.**", ""]
    if P:
        p99bad = [k for k, p in P.items() if k not in result["tir_chaos"] and p["p99_deg"] > T["p99_deg"]]
        out.append(f"* Paths ({len(P)} cases): median exit-angle difference at most "
                   f"{_fmt(max(p['median_deg'] for p in P.values()))} deg, status agreement at least "
                   f"{_fmt(100 * min(p['status_agree'] for p in P.values()), 5)} %; p99 over {T['p99_deg']} deg on "
                   + (", ".join(f"{k} ({_fmt(P[k]['p99_deg'])} deg; without TIR on the path "
                                f"{_fmt(P[k]['p99_deg_no_tir'])} deg)" for k in p99bad) or "no case")
                   + ": long total-internal-reflection chains, where two float32 intersectors part (as the "
                   "TIR-chaos cases).")
    if I:
        out.append(f"* Images ({len(I)} cases): judged on the pixels whose exit direction is more than one envmap "
                   f"texel from a change of the bitmap and whose Mitsuba path agrees with ours within "
                   f"{PATH_AGREE_DEG} deg, the image of Mitsuba's intersector, Fresnel-free plugin, media and envmap "
                   f"(spawned as the exact tracer does) differs from ours by at most "
                   f"{_fmt(100 * max(i['rel_rmse_judged'] for i in I.values()))} % relative RMSE. Mitsuba's "
                   "`path` integrator gives the same pixels as a Python loop over those parts with its own "
                   "`si.spawn_ray` (largest difference "
                   f"{_fmt(max((i['path_vs_loop_max_abs'] for i in I.values() if np.isfinite(i['path_vs_loop_max_abs'])), default=float('nan')))}"
                   "): its MIS, eta and Russian-roulette bookkeeping add nothing, and all of its difference from "
                   "ours comes from the spawn offset (`(1 + max|p|) 8.9e-5` along the normal), which moves "
                   "exit directions by degrees after TIR chains (column *path integrator*; docs/oracle.md). "
                   "The envmap bitmap's bilinear blend across checker edges is the rest of the all-pixel "
                   "error (column *envmap bitmap*). `volpath` (absorption) is a stochastic estimator: its "
                   "difference is compared with its own noise.")
    if Wp:
        out.append(f"* Water paths ({len(Wp)} cases): the eye rays refracted at the water, ours at the analytic "
                   f"surface against Snell at Mitsuba's hit on the exported height-field mesh "
                   f"({', '.join(sorted({str(p['resolution']) for p in Wp.values()}))} quads a side, the analytic "
                   f"normals at its vertices, interpolated by Mitsuba): median at most "
                   f"{_fmt(max(p['median_deg'] for p in Wp.values()))} deg, p99 at most "
                   f"{_fmt(max(p['p99_deg'] for p in Wp.values()))} deg (bound of the interpolated normal's error "
                   f"at most {_fmt(max(p['normal_error_deg'] for p in Wp.values()))} deg), hit points within "
                   f"{_fmt(max(p['water_pos_p99'] for p in Wp.values()))} (p99, world units); the pixels meeting "
                   f"the water agree on at least {_fmt(100 * min(p['status_agree'] for p in Wp.values()), 5)} % "
                   "of the pixels. The water images are not cross-checked (their shading reads our maps).")
    if C:
        out.append("* Caustics: " + "; ".join(
            f"{k}{f' receiver {i}' if len(e['receivers']) > 1 else ''}: rel L1 {_fmt(100 * r['rel_l1'])} % "
            f"(each side's own half-vs-half noise "
            f"{_fmt(100 * r['rel_l1_ours_halves'])} / {_fmt(100 * r['rel_l1_mitsuba_halves'])} %), power ratio "
            f"{_fmt(r['power_ratio'], 5)}, Z-test {r['ztest_pass']} of {r['batches']} Mitsuba batches pass "
            f"(reverse {r['ztest_reverse_pass']} of {r['batches']})"
            for k, e in C.items() for i, r in enumerate(e["receivers"])) + ".")
    skipped = {}
    for k, e in c.items():
        if "skipped" in e:
            skipped.setdefault(e["skipped"], []).append(k)
    for why, names in sorted(skipped.items()):
        out.append(f"* Skipped, {', '.join(sorted(names))}: {why}.")
    return out


def _water_paths_rows(name, e, T, link):
    """The report's table of a water case's eye rays (:func:`water_paths_case`)."""
    p = e["paths"]
    v = verdicts(name, e)
    return ["| paths (eye rays refracted at the water) | value | target |", "|---|---|---|",
            f"| pixels / meeting the water: ours, Mitsuba, both | {p['pixels']} / {p['water_ours']}, "
            f"{p['water_mitsuba']}, {p['both']} | |",
            f"| which pixels meet the water: agreement | {_fmt(100 * p['status_agree'], 6)} % | >= "
            f"{T['status_agree']:.0%} {_mark(v['status_agree'])} |",
            f"| refracted direction median | {_fmt(p['median_deg'])} deg | <= {T['median_deg']} "
            f"{_mark(v['median_deg'])} |",
            f"| refracted direction p99; max | {_fmt(p['p99_deg'])}; {_fmt(p['max_deg'])} deg | <= {T['p99_deg']} "
            f"{_mark(v['p99_deg'])} |",
            f"| water hit point p99 (world units) | {_fmt(p['water_pos_p99'])} | |",
            f"| water mesh: quads a side; bound of its interpolated normal's error | {p['resolution']}; "
            f"{_fmt(p['normal_error_deg'])} deg | |",
            "", f"![paths {name}]({link}{name}/{p.get('figure', 'paths.png')})"]


def report_markdown(result, link=""):
    """The cross-check report: findings, a summary table, then a table and figures per case.

    ``link`` prefixes the figure paths (the case folders relative to the Markdown file).

    Parameters
    ----------
    result : dict
        What :func:`run` returns.
    link : str
        Prefix of the figure paths (``""`` or ending in ``/``).

    Returns
    -------
    str
        The Markdown report.
    """
    T = result["targets"]
    lines = ["# Cross-check of the exact references against Mitsuba 3", "",
             "Written by `refraction-ref crosscheck` (refraction_ref/crosscheck.py); conventions in "
             "docs/oracle.md, section *Cross-check against Mitsuba 3*. Versions: "
             + ", ".join(f"{k} {v}" for k, v in sorted(result["versions"].items()) if isinstance(v, str)) + ".", "",
             f"Targets: exit directions where both exit, median <= {T['median_deg']} deg and p99 <= "
             f"{T['p99_deg']} deg (TIR-chaos cases {', '.join(result['tir_chaos'])} reported, not judged); "
             f"status agreement >= {T['status_agree']:.0%} of pixels; image relative RMSE <= "
             f"{T['image_rel_rmse']:.0%} on the judged pixels (rule in the findings); caustic maps pass the "
             "golden suite's Z-test (every Mitsuba batch against our K batches).", ""]
    lines += _summary(result) + [""]
    lines += ["| case | median deg | p99 deg | status agree | image rel RMSE (judged) | path integrator "
              "(judged / all) | envmap bitmap (all) | Fresnel moves image | caustics rel L1; Z-test | verdict |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for name, e in result["cases"].items():
        if "skipped" in e:
            lines.append(f"| {name} | - | - | - | - | - | - | - | - | skipped: {e['skipped']} |")
            continue
        p, i, c = e.get("paths", {}), e.get("images", {}), e.get("caustics", {})
        failed = failed_targets(name, e)
        verdict = "**FAIL**: " + ", ".join(failed) if failed else "pass"
        if name in result["tir_chaos"]:
            verdict += " (TIR chaos: angles reported)"
        cs = "; ".join(f"{_fmt(100 * r['rel_l1'])} %; {r['ztest_pass']}/{r['batches']}" for r in c["receivers"]) \
            if c else "-"
        lines.append(f"| {name} | {_fmt(p.get('median_deg'))} | {_fmt(p.get('p99_deg'))} | "
                     f"{_fmt(100 * p['status_agree'], 5) + ' %' if p else '-'} | "
                     f"{_fmt(100 * i['rel_rmse_judged']) + ' %' if i else '-'} | "
                     f"{(_fmt(100 * i['rel_rmse_path_judged']) + ' % / ' + _fmt(100 * i['rel_rmse_path']) + ' %') if i else '-'} | "
                     f"{_fmt(100 * i['rel_rmse_env_bitmap']) + ' %' if i else '-'} | "
                     f"{_fmt(100 * i['fresnel_rel_rmse']) + ' %' if i else '-'} | {cs} | {verdict} |")
    for name, e in result["cases"].items():
        if "skipped" in e:
            continue
        lines += ["", f"## {name}", "", e["purpose"], ""]
        p = e.get("paths")
        if p and p.get("kind") == "water":
            lines += _water_paths_rows(name, e, T, link)
        elif p:
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
                      f"| status counts ours / Mitsuba | {_counts(p['status_ours'])} / {_counts(p['status_mitsuba'])} | |",
                      f"| interface count agreement (both exit) | {_fmt(100 * p['interfaces_agree_both_exit'], 6)} % | |",
                      f"| p99 (pixels over 0.5 deg) by TIR events on the path: none / 1-2 / 3+ | "
                      f"{_fmt(p['p99_deg_no_tir'])} ({p['over_0_5_no_tir']} of {p['paths_no_tir']}) / "
                      f"{_fmt(p['p99_deg_tir_1_2'])} ({p['over_0_5_tir_1_2']} of {p['paths_tir_1_2']}) / "
                      f"{_fmt(p['p99_deg_tir_3_plus'])} ({p['over_0_5_tir_3_plus']} of {p['paths_tir_3_plus']}) | |",
                      "", f"![paths {name}]({link}{name}/{p.get('figure', 'paths.png')})"]
        i = e.get("images")
        if i:
            lines += ["", "| images | value |", "|---|---|",
                      f"| Mitsuba integrator; spp (Fresnel-free / dielectric); max_depth = rr_depth | "
                      f"{i['integrator']}; {i['spp_refract']} / {i['spp_dielectric']}; {i['max_depth']} |",
                      f"| judged pixels of {i['pixels']} (left out: {i['edge_pixels']} within a texel of a bitmap "
                      f"edge, {i['path_differs_pixels']} whose paths part by more than {PATH_AGREE_DEG} deg, "
                      f"{i['limit_pixels']} at the bounce limit) | {i['judged_pixels']} |",
                      f"| **rel RMSE, judged pixels** (Mitsuba's intersector, plugin, media, envmap; spawned "
                      f"along the ray) | **{_fmt(100 * i['rel_rmse_judged'])} %** |",
                      f"| the same image: all pixels / pixels away from bitmap edges | "
                      f"{_fmt(100 * i['rel_rmse_line_all'])} % / {_fmt(100 * i['rel_rmse_line_margin'])} % |",
                      f"| envmap bitmap error on this image ({i['env_width']} texels wide), all pixels | "
                      f"{_fmt(100 * i['rel_rmse_env_bitmap'])} % |",
                      f"| `{i['integrator']}` integrator: rel RMSE judged / away from edges / all | "
                      f"{_fmt(100 * i['rel_rmse_path_judged'])} % / {_fmt(100 * i['rel_rmse_path_margin'])} % / "
                      f"{_fmt(100 * i['rel_rmse_path'])} % (noise {_fmt(100 * i['noise_rel'])} %) |",
                      f"| `{i['integrator']}` against the loop with its own `spawn_ray`: largest difference; rel "
                      f"RMSE | {_fmt(i['path_vs_loop_max_abs'])}; {_fmt(100 * i['path_vs_loop_rel_rmse'])} % |",
                      f"| `spawn_ray` exit directions against ours: median / p99 deg; pixels over a texel | "
                      f"{_fmt(i['spawn_ray_median_deg'])} / {_fmt(i['spawn_ray_p99_deg'])}; "
                      f"{i['spawn_ray_over_texel']} |",
                      f"| Fresnel (`dielectric`) vs ours: rel RMSE all / judged; mean over object pixels | "
                      f"{_fmt(100 * i['fresnel_rel_rmse'])} % / {_fmt(100 * i['fresnel_rel_rmse_judged'])} % "
                      f"(noise {_fmt(100 * i['fresnel_noise_rel'])} %); x{_fmt(i['fresnel_mean_ratio'], 4)} |",
                      "", f"![images {name}]({link}{name}/{i.get('figure', 'images.png')})"]
        c = e.get("caustics")
        if c:
            lines += ["", "| caustics | value |", "|---|---|",
                      f"| batches each side; photons per batch ours / Mitsuba (flux per photon) | {c['batches']}; "
                      f"{c['photons_ours']} / {c['photons_mitsuba']} ({_fmt(c['photon_flux_ours'])} / "
                      f"{_fmt(c['photon_flux_mitsuba'])}) |"]
            lines += [f"| Mitsuba photons on the receivers through the object; at the bounce limit | "
                      f"{c['deposited_mitsuba']}; {c['limit_mitsuba']} |"] if "water_resolution" not in c else [
                      f"| Mitsuba photons meeting the water; seen by a map | {c['water_mitsuba']}; "
                      f"{c['deposited_mitsuba']} |",
                      f"| water mesh: quads a side; bound of its interpolated normal's error | "
                      f"{c['water_resolution']}; {_fmt(c['normal_error_deg'])} deg |"]
            for r, x in enumerate(c["receivers"]):
                lines += [f"| receiver {r}: rel L1 of the K-batch means (blur 1 texel) | {_fmt(100 * x['rel_l1'])} % |",
                          f"| receiver {r}: own noise, half vs half of the batches: ours / Mitsuba | "
                          f"{_fmt(100 * x['rel_l1_ours_halves'])} % / {_fmt(100 * x['rel_l1_mitsuba_halves'])} % |",
                          f"| receiver {r}: power Mitsuba / ours | {_fmt(x['power_ratio'], 5)} |",
                          f"| receiver {r}: Z-test (alpha 1e-3, Bonferroni), Mitsuba batches passing against ours; "
                          f"max abs z (threshold) | {x['ztest_pass']} of {x['batches']}; "
                          f"{_fmt(x['ztest_max_abs_z'])} ({_fmt(x['ztest_threshold'])}) |",
                          f"| receiver {r}: reverse, our batches against Mitsuba's | {x['ztest_reverse_pass']} of "
                          f"{x['batches']} |"]
                if "ztest_own_quantum_pass" in x:
                    lines.append(f"| receiver {r}: Z-test with this map's own quantum (one photon on its texel); max "
                                 f"abs z | {x['ztest_own_quantum_pass']} of {x['batches']}; "
                                 f"{_fmt(x['ztest_own_quantum_max_abs_z'])} |")
            lines += ["", f"![caustics {name}]({link}{name}/{c.get('figure', 'caustics.png')})"]
    return "\n".join(lines) + "\n"
