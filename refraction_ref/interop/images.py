"""The images cross-check: our exact image against Mitsuba 3's through the pixel centres.

Our exact image against Mitsuba's ``path`` integrator (``volpath`` when an
object absorbs) with the Fresnel-free BSDF
(:func:`~refraction_ref.interop.mitsuba.register_refract_bsdf`) through the
pixel centres: relative RMSE; against a Python loop over Mitsuba's own parts
(intersector, plugin, media, envmap) spawned as the exact tracer spawns; and
with Mitsuba's own ``dielectric`` (Fresnel), to say how far Fresnel moves
each image.

References
----------
.. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org
   (the ``path`` and ``volpath`` integrators, the ``envmap`` emitter).
"""

from __future__ import annotations

import os
import time

import numpy as np

from ..compare import angular_error_deg
from ..environment import environment_lookup
from ..status import EXITED, MISSED
from . import mitsuba as M
from .paths import exact_arrays, paths_only_scene
from .rays import spawn_offset

# the functions below take a loaded Mitsuba scene and import Mitsuba (the optional ``crosscheck`` extra) where
# they run, with the variant the scene was loaded with; the module itself imports without it
__all__ = ["render_pixel_centres", "envmap_eval", "loop_radiance", "edge_margin_mask", "images_case",
           "relative_rmse", "PATH_AGREE_DEG"]

#: a pixel's colour is judged where Mitsuba's exit direction is this close to ours (half an envmap texel
#: at the default width: the paths part measures the directions themselves)
PATH_AGREE_DEG = 0.05


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


def _centre_ray(mi, sensor, k, width, height):
    """The sensor's ray through the centre of flat pixel ``k`` (scalar variant)."""
    return sensor.sample_ray(0.0, 0.5, mi.Point2f((k % width + 0.5) / width, (k // width + 0.5) / height),
                             mi.Point2f(0.5, 0.5))[0]


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
    mscene : mitsuba.Scene
        A loaded scene (scalar variant).
    spp : int
        Samples per pixel centre.
    seed : int
        Seed of the sampler (per pixel ``seed * 1000003 + k``).
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
        rd = mi.RayDifferential3f(_centre_ray(mi, sensor, k, W, H))
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
    direction (the exact tracer's offset, as
    :func:`~refraction_ref.interop.paths.mitsuba_paths`).

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
        Offset along the new direction for ``'line'`` (world units;
        :func:`~refraction_ref.interop.rays.spawn_offset` gives the paths' one).

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
        ray = _centre_ray(mi, sensor, k, W, H)
        transmittance = np.ones(3)
        sigma = None
        for _ in range(int(max_depth)):
            si = mscene.ray_intersect(ray)
            if sigma is not None:
                transmittance *= np.exp(-sigma * float(si.t)) if si.is_valid() else 0.0
            if not si.is_valid():
                rad[n] = transmittance * np.array(env.eval(si), dtype=np.float64).reshape(3)
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


def _mitsuba_images(scene, folder, variant, status, spp, env_width):
    """Mitsuba's four images of :func:`images_case` (flat (P, 3) each), their exit directions and timings."""
    H, W = status.shape
    kw = {"env_width": env_width}
    ms, spec = M.load(scene, os.path.join(folder, "refract"), variant, bsdf="refract", **kw)
    depth = int(spec["integrator"]["max_depth"])
    allpix = np.arange(H * W)
    t0 = time.perf_counter()
    eps, _ = spawn_offset(np.concatenate([m["vertices"] for m in M.object_meshes(scene)]))
    line, line_dir = loop_radiance(ms, allpix, depth, "line", eps)
    t1 = time.perf_counter()
    loop_sp, sp_dir = loop_radiance(ms, allpix, depth, "mitsuba")
    t2 = time.perf_counter()
    obj = np.flatnonzero(status.ravel() != MISSED)  # missed pixels see the environment directly: one sample
    a, a_sem = render_pixel_centres(ms, spp["refract"], seed=1, pixels=obj)
    a1, _ = render_pixel_centres(ms, 1, seed=1, pixels=np.flatnonzero(status.ravel() == MISSED))
    a = np.where(np.isnan(a), a1, a).reshape(-1, 3)
    t3 = time.perf_counter()
    md, _ = M.load(scene, os.path.join(folder, "dielectric"), variant, bsdf="dielectric", **kw)
    f, f_sem = render_pixel_centres(md, spp["dielectric"], seed=2, pixels=obj)
    f = np.where(np.isnan(f), a1, f).reshape(-1, 3)
    t4 = time.perf_counter()
    return {"refract_scene": ms, "spec": spec, "depth": depth, "obj": obj, "line": line, "line_dir": line_dir,
            "loop_sp": loop_sp, "sp_dir": sp_dir, "path": a, "path_sem": np.nan_to_num(a_sem).reshape(-1, 3),
            "fresnel": f, "fresnel_sem": np.nan_to_num(f_sem).reshape(-1, 3),
            "times": {"loop_s": t1 - t0, "loop_spawn_s": t2 - t1, "mitsuba_s": t3 - t2,
                      "mitsuba_fresnel_s": t4 - t3}}


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
    case
        As :func:`~refraction_ref.interop.paths.paths_case`.
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

    References
    ----------
    .. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org.
    """
    scene = paths_only_scene(case, os.path.join(folder, "scene"))
    ours = exact_arrays(scene)
    img = np.asarray(ours["image"], dtype=np.float64)
    H, W = img.shape[:2]
    absorbing = any(np.any(np.asarray(o["material"]["absorption"]) > 0) for o in scene.data["objects"])
    M.require(variant)
    M.register_refract_bsdf()
    env_width = int(env_width or M.ENV_WIDTH)
    st = ours["status"]
    flat = img.reshape(-1, 3)
    spp = spp_absorb if absorbing else 1  # a delta BSDF through a pixel centre is deterministic
    mit = _mitsuba_images(scene, folder, variant, st, {"refract": spp, "dielectric": spp_fresnel}, env_width)
    ok = ((st == EXITED) | (st == MISSED)).ravel()
    odir = np.where(ok[:, None], ours["exit_dir"].reshape(-1, 3), np.nan)
    env_ours = envmap_eval(mit["refract_scene"], odir)
    if absorbing:
        # the exact image's transmittance, recovered from its own image and environment look-up
        e = environment_lookup(scene.data["environment"], np.nan_to_num(odir), scene.base_dir).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            transmittance = np.where(e > 0, flat / e, 1.0)
        env_ours = env_ours * transmittance
    margin = ok & edge_margin_mask(mit["refract_scene"], odir, env_width)
    agree_line = angular_error_deg(mit["line_dir"], odir) <= PATH_AGREE_DEG
    judged = margin & agree_line
    num = {"spp_refract": int(spp), "spp_dielectric": int(spp_fresnel),
           "integrator": mit["spec"]["integrator"]["type"], "env_width": env_width, "max_depth": mit["depth"],
           "rr_depth": int(mit["spec"]["integrator"].get("rr_depth", mit["depth"])),
           "pixels": int(H * W), "judged_pixels": int(judged.sum()),
           "edge_pixels": int(np.count_nonzero(ok & ~margin)),
           "path_differs_pixels": int(np.count_nonzero(margin & ~agree_line)),
           "limit_pixels": int(np.count_nonzero(~ok))}
    num.update(_image_errors(flat, mit, judged, margin, absorbing))
    num["rel_rmse_env_bitmap"] = relative_rmse(env_ours, flat)
    num.update(_spawn_ray_angles(mit["sp_dir"], odir, ok & (st.ravel() != MISSED), env_width))
    num.update(mit["times"])
    figs = {"ours": img, "mitsuba": mit["line"].reshape(H, W, 3), "path": mit["path"].reshape(H, W, 3),
            "fresnel": mit["fresnel"].reshape(H, W, 3), "judged": judged.reshape(H, W)}
    return num, figs


def _image_errors(flat, mit, judged, margin, absorbing):
    """The relative RMSEs of Mitsuba's images against ours (``flat``, (P, 3)), and their noise."""
    mean_img = max(float(np.mean(np.abs(flat))), 1e-30)
    line, a, f, obj = mit["line"], mit["path"], mit["fresnel"], mit["obj"]

    def rr(x, sel):
        return relative_rmse(x[sel], flat[sel]) if sel.any() else float("nan")

    return {
        # the target: Mitsuba's parts with the exact tracer's offset, on the judged pixels
        "rel_rmse_judged": rr(line, judged),
        "rel_rmse_line_all": relative_rmse(line, flat),
        "rel_rmse_line_margin": rr(line, margin),
        # Mitsuba's own integrator against ours, and against the loop that spawns as it does
        "rel_rmse_path": relative_rmse(a, flat),
        "rel_rmse_path_judged": rr(a, judged),
        "rel_rmse_path_margin": rr(a, margin),
        "path_vs_loop_max_abs": float(np.nanmax(np.abs(a - mit["loop_sp"]))) if not absorbing else float("nan"),
        "path_vs_loop_rel_rmse": float(np.sqrt(np.mean((a - mit["loop_sp"]) ** 2)) / mean_img),
        "noise_rel": float(np.sqrt(np.mean(mit["path_sem"] ** 2)) / mean_img),
        "fresnel_rel_rmse": relative_rmse(f, flat),
        "fresnel_rel_rmse_judged": rr(f, judged),
        "fresnel_noise_rel": float(np.sqrt(np.mean(mit["fresnel_sem"] ** 2)) / mean_img),
        "fresnel_mean_ratio": float(np.mean(f[obj]) / max(float(np.mean(flat[obj])), 1e-30)) if obj.size else 1.0,
    }


def _spawn_ray_angles(sp_dir, odir, both, env_width):
    """The exit directions of Mitsuba's own ``spawn_ray`` against ours where both exit through the object."""
    ang = angular_error_deg(sp_dir, odir)
    both = both & np.all(np.isfinite(sp_dir), axis=1)
    return {"spawn_ray_median_deg": float(np.median(ang[both])) if both.any() else float("nan"),
            "spawn_ray_p99_deg": float(np.percentile(ang[both], 99)) if both.any() else float("nan"),
            "spawn_ray_over_texel": int(np.count_nonzero(ang[both] > 180.0 / (env_width // 2)))}
