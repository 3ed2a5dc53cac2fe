"""Caustics from multiply-refracted photons onto diffuse receivers (Chaudhari 2008, §4.1), pass by pass.

==========================  =====================================================  ===========
stage (``caustics.timings``)  pass                                                 section
==========================  =====================================================  ===========
``light_minmax`` ...        the light's min/max, voxelization, peeling, reduction   §3.3-3.7
``photon_trace``            one photon per texel through every layer (eye kernels)  §3.6-3.8
``receiver_hit``            eye-space march (Krüger 2006) or Embree                 §4.1
``splat``                   bilinear splat of irradiance into each receiver's map   §2.3.2
``gather``                  Gaussian gathering in a window (Wyman & Davis 2006)     §2.3.2
``final``                   receivers lit directly (shadow test) and by caustics;   §4.1
                            the object with single-surface and multi-layer passes
==========================  =====================================================  ===========

Outputs (ORACLE.md, per receiver ``r``): ``caustic_map_r`` (Hc, Wc) float32,
the irradiance carried by photons that passed through a refractive object,
for lights of unit strength (unit irradiance perpendicular to a directional
light, unit intensity of a point light), averaged over the three colour
channels of the absorption and summed over lights; ``caustic_frame_r``
(4, 3). Added: ``caustic_rgb_r`` (Hc, Wc, 3) float32, the same per channel
with each light's radiance (what the final image uses);
``image_caustics`` (H, W, 3) float32, the final image with the full
multi-layer pass through the object; ``image_caustics_single``, the
thesis's final pass (single-surface refraction, image-space method only).
``image`` keeps its meaning (the object's refraction of the environment).

The exact reference (``--method exact``) emits ``exact.photons`` squared
jittered photons through the same window, traces them through the real
triangles (:func:`~refraction_ref.exact.trace_exact`), meets the receivers
with Embree and splats them into the same maps without gathering; the
relative L1 difference of its two interleaved halves (blurred one texel),
halved, is its own noise, reported per receiver in ``meta['caustics']``.
"""

from __future__ import annotations

import time

import numpy as np

from ..environment import environment_lookup
from ..optics import beer_lambert, refract
from .light import light_camera, texel_flux, window_samples
from .receivers import eye_buffers, hit_exact, map_position, march_eyespace, receiver_set
from .shade import exact_visibility, shade_points, shadow_map_visibility
from .splat import gather_gaussian, splat_bilinear

__all__ = ["has_caustics", "caustics_imagespace", "caustics_exact", "receiver_hits", "splat_maps"]


def has_caustics(scene):
    """A scene casts caustics when it has at least one light and one receiver."""
    return bool(scene.data["lights"]) and bool(scene.data["receivers"])


def merge_caustics(arrays, c_arrays):
    """Add the caustic outputs to a run's arrays; ``image`` becomes the full scene.

    With receivers, the rendered colour is the final pass of §4.1 (receivers
    lit directly and by the caustics, seen through the object); the
    refraction-only view of the environment is kept as ``image_refraction``.
    Both the image-space method and the exact reference call this.
    """
    arrays.update(c_arrays)
    arrays["image_refraction"] = arrays["image"]
    arrays["image"] = arrays["image_caustics"]
    return arrays


def skip_reason(scene):
    missing = [k for k in ("lights", "receivers") if not scene.data[k]]
    return f"the scene has no {' and no '.join(missing)}: no caustics to map"


def receiver_hits(rs, origins, dirs, mode, cam=None, eyebuf=None):
    """Where world rays meet the receivers: eye-space march or Embree.

    Returns
    -------
    points : (N, 3) float64
        Hit points (NaN where none).
    face : (N,) int64
        Receiver triangle hit, ``-1`` where none.
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    if mode == "exact":
        t, face = hit_exact(rs.tris, o, d)
    else:
        t, pix = march_eyespace(cam.world_to_view(o), cam.dir_world_to_view(d), eyebuf[0], cam)
        ok = pix[:, 0] >= 0
        face = np.full(len(o), -1, np.int64)
        face[ok] = eyebuf[1][pix[ok, 0], pix[ok, 1]]
    P = o + t[:, None] * d
    face = np.where(np.isfinite(t) & (face >= 0), face, -1)
    return P, face


def splat_maps(rs, P, face, flux, size):
    """Irradiance maps (Hc, Wc, C) per receiver from photon hits (see :mod:`.splat`)."""
    maps = []
    flux = np.asarray(flux, dtype=np.float64)
    if flux.ndim == 1:
        flux = flux[:, None]
    for r, box in enumerate(rs.boxes):
        sel = (face >= 0)
        sel[sel] = rs.owner[face[sel]] == r
        cosv = np.abs(rs.normals[face[sel]] @ box.V)
        col, row = map_position(rs, r, P[sel])
        val = flux[sel] * (cosv / box.texel_area)[:, None]
        maps.append(splat_bilinear(col, row, val, box.size))
    return maps


def _photon_stats(flux0, status, trans_exit, landed):
    """Energy book-keeping of one light's photons (unit light, mean over channels).

    ``flux_silhouette`` entered the objects; of it, ``flux_absorbed`` was
    absorbed, ``flux_lost_in_object`` stopped inside (status 2-4),
    ``flux_exited`` left, and of that ``flux_missed_receivers`` met no
    receiver; the caller adds ``flux_on_receivers`` (what was splatted).
    """
    f = flux0
    ex = status == 1
    t = trans_exit.mean(axis=1)
    return {
        "flux_silhouette": float(f[status != 0].sum()),
        "flux_absorbed": float((f[ex] * (1.0 - t)).sum()),
        "flux_lost_in_object": float(f[(status >= 2)].sum()),
        "flux_exited": float((f[ex] * t).sum()),
        "flux_missed_receivers": float((f[ex] * t)[~landed].sum()),
        "photons_in_silhouette": int(np.count_nonzero(status != 0)),
        "photons_lost_in_object": int(np.count_nonzero(status >= 2)),
        "photons_missed_receivers": int(np.count_nonzero(~landed)),
    }


def _collect(scene, rs, per_light, arrays, gather):
    """Sum per-light unit maps into ``caustic_map_r`` / ``caustic_rgb_r``; returns the RGB maps."""
    lights = scene.data["lights"]
    rgb_maps = []
    for r, box in enumerate(rs.boxes):
        unit = np.zeros(box.size)
        rgb = np.zeros(box.size + (3,))
        for l, maps in enumerate(per_light):
            m = maps[r]
            if gather > 1:
                m = gather_gaussian(m, gather)
            unit += m.mean(axis=2)
            rgb += m * np.asarray(lights[l]["radiance"], dtype=np.float64)
        unit = np.nan_to_num(unit, nan=0.0, posinf=0.0, neginf=0.0)
        rgb = np.nan_to_num(rgb, nan=0.0, posinf=0.0, neginf=0.0)
        arrays[f"caustic_map_{r}"] = unit.astype(np.float32)
        arrays[f"caustic_frame_{r}"] = rs.frame(r).astype(np.float64)
        arrays[f"caustic_rgb_{r}"] = rgb.astype(np.float32)
        rgb_maps.append(rgb)
    return rgb_maps


# ---------------------------------------------------------------------------
# image-space method
# ---------------------------------------------------------------------------

def caustics_imagespace(scene, geom, cam, eye, ior, outside, absorption):
    """Photon pass per light, receiver hits, splat, gather and the final images.

    Parameters
    ----------
    scene : Scene
    geom : Geometry
    cam : Camera
        The eye.
    eye : dict
        :func:`~refraction_ref.imagespace.pipeline.layered_trace` of the eye.
    ior, outside : float
    absorption : (3,) float64

    Returns
    -------
    arrays : dict
        ``caustic_map_r``, ``caustic_frame_r``, ``caustic_rgb_r``,
        ``image_caustics``, ``image_caustics_single``.
    info : dict
        ``timings_ms`` per stage, per-light energy ``lights``, knobs used.
    """
    from ..imagespace.pipeline import layered_trace

    p = scene.data["imagespace"]
    lights = scene.data["lights"]
    tic = time.perf_counter
    timings = {}
    size = int(p["caustic_map"])
    mode = p["receiver_hit"]
    rs = receiver_set(scene, lights[0], size)

    def add(k, t0):
        timings[k] = timings.get(k, 0.0) + (tic() - t0) * 1e3

    t0 = tic()
    eyebuf = eye_buffers(rs, cam)  # the eye-space march and the final pass both read it
    add("receiver_depth", t0)
    per_light, stats, shadow = [], [], []
    for light in lights:
        lcam = light_camera(light, geom.vertices, int(p["photons"])) if len(geom.faces) else None
        if lcam is None:
            per_light.append([np.zeros(b.size + (3,)) for b in rs.boxes])
            shadow.append(None)
            stats.append({"photons": 0})
            continue
        lt, lp = {}, []
        tv = layered_trace(geom, lcam, p, ior, outside, lt, lp)
        for k, v in lt.items():
            timings["photon_trace" if k == "trace" else f"light_{k}"] = \
                timings.get("photon_trace" if k == "trace" else f"light_{k}", 0.0) + v
        t0 = tic()
        tr = tv["trace"]
        st = tr["status"].ravel()
        N = lcam.width
        cols = np.tile(np.arange(N) + 0.5, N)
        rows = np.repeat(np.arange(N) + 0.5, N)
        flux0 = texel_flux(lcam, cols, rows)
        ex = np.flatnonzero(st == 1)
        trans = beer_lambert(absorption, tr["path_length"].ravel()[ex], ior)
        o = tr["exit_pos"].reshape(-1, 3)[ex]  # world space (layered_trace)
        d = tr["exit_dir"].reshape(-1, 3)[ex]
        add("photon_trace", t0)
        t0 = tic()
        P, face = receiver_hits(rs, o, d, mode, cam, eyebuf)
        add("receiver_hit", t0)
        t0 = tic()
        flux = flux0[ex, None] * trans
        per_light.append(splat_maps(rs, P, face, flux, size))
        add("splat", t0)
        s = _photon_stats(flux0, st, trans, face >= 0)
        s["flux_on_receivers"] = float(flux[face >= 0].mean(axis=1).sum())
        s["photon_texture"] = [N, N]
        s["projection"] = lcam.projection
        stats.append(s)
        zmin = tv["zmin"]
        shadow.append((lcam, zmin, 1e-3 * (lcam.far - lcam.near) + 2.0 * 2.0 * lcam.sy / N))
    t0 = tic()
    arrays = {}
    rgb_maps = _collect(scene, rs, per_light, arrays, int(p["gather"]))
    add("gather", t0)

    t0 = tic()

    def vis(l, pts, nrm):
        if shadow[l] is None:
            return np.ones(len(pts))
        lcam, zmin, bias = shadow[l]
        return shadow_map_visibility(lcam, zmin, pts, bias)

    img, img1 = _final_imagespace(scene, rs, cam, eye, eyebuf, rgb_maps, vis, mode, ior, outside, absorption, p)
    arrays["image_caustics"] = img
    arrays["image_caustics_single"] = img1
    add("final", t0)
    info = {"timings_ms": timings, "lights": stats, "receivers": len(rs.boxes), "receiver_hit": mode,
            "gather": int(p["gather"]), "photons": int(p["photons"]), "caustic_map": size}
    return arrays, info


def _shade_rays(scene, rs, cam, o, d, mode, eyebuf, rgb_maps, vis):
    """Colour seen along world rays: the receiver they meet (shaded), else the environment."""
    out = np.zeros((len(o), 3))
    if len(o) == 0:
        return out
    P, face = receiver_hits(rs, o, d, mode, cam, eyebuf)
    hit = face >= 0
    out[hit] = shade_points(rs, scene.data["lights"], rgb_maps, P[hit], face[hit], d[hit], vis)
    if (~hit).any():
        out[~hit] = environment_lookup(scene.data["environment"], d[~hit], scene.base_dir)
    return out


def _final_imagespace(scene, rs, cam, eye, eyebuf, rgb_maps, vis, mode, ior, outside, absorption, p):
    from ..imagespace.normals import layer_normals

    H, W = cam.shape
    tr = eye["trace"]
    zfront = eye["zmin"]
    rdepth, rtri = eyebuf
    origin, rdir = cam.primary_rays()
    env = scene.data["environment"]
    obj = np.isfinite(zfront)
    rec = np.isfinite(rdepth) & (rdepth < np.where(obj, zfront, np.inf))
    obj &= ~rec
    base = np.zeros((H, W, 3))
    # receivers seen directly
    if rec.any():
        dirs = rdir[rec]
        fwd = -cam.basis[2]
        P = origin[rec] + dirs * (rdepth[rec] / (dirs @ fwd))[:, None]
        base[rec] = shade_points(rs, scene.data["lights"], rgb_maps, P, rtri[rec], dirs, vis)
    bg = ~rec & ~obj
    if bg.any():
        base[bg] = environment_lookup(env, rdir[bg], scene.base_dir)
    full = base.copy()
    single = base.copy()
    if obj.any():
        # the multi-layer pass: exit rays on to the receivers, else the environment (§3.6-3.8)
        st = tr["status"]
        ex = obj & (st == 1)
        trans = beer_lambert(absorption, tr["path_length"], ior)
        if ex.any():
            o = tr["exit_pos"][ex]  # world space (layered_trace)
            d = tr["exit_dir"][ex]
            full[ex] = _shade_rays(scene, rs, cam, o, d, mode, eyebuf, rgb_maps, vis)
        stuck = obj & (st != 1)
        if stuck.any():
            full[stuck] = environment_lookup(env, tr["last_dir"][stuck], scene.base_dir)
        full[obj] *= trans[obj]
        # the thesis's final pass: refraction at the front surface only
        nrm = layer_normals(np.where(np.isfinite(zfront), zfront, np.inf), cam, p["normals"], int(p["delta"]))
        dv = cam.primary_rays_view()[obj]
        t, _ = refract(dv, nrm[obj], outside / ior)
        t = np.where(np.all(np.isfinite(t), axis=1)[:, None], t, dv)
        xs = (np.arange(W) + 0.5)[None, :].repeat(H, 0)[obj]
        ys = (np.arange(H) + 0.5)[:, None].repeat(W, 1)[obj]
        x = (xs / W * 2.0 - 1.0) * cam.sx
        y = (1.0 - ys / H * 2.0) * cam.sy
        dfront = zfront[obj]
        if cam.ortho:
            pv = np.stack([x, y, -dfront], axis=1)
        else:
            pv = np.stack([x * dfront, y * dfront, -dfront], axis=1)
        single[obj] = _shade_rays(scene, rs, cam, cam.view_to_world(pv), cam.dir_view_to_world(t), mode, eyebuf,
                                  rgb_maps, vis)
    return full.astype(np.float32), single.astype(np.float32)


# ---------------------------------------------------------------------------
# exact photon reference
# ---------------------------------------------------------------------------

def caustics_exact(scene, geom, cam, eye_tr, origin, rdir, vn):
    """The exact photon reference and the exact final image (see the module docstring).

    Parameters
    ----------
    scene, geom, cam :
    eye_tr : dict
        :func:`~refraction_ref.exact.trace_exact` of the primary rays (flat, N rows).
    origin, rdir : (H, W, 3)
        Primary rays.
    vn : (V, 3) vertex normals of the objects.

    Returns
    -------
    arrays, info : dict, dict
    """
    from ..exact import trace_exact
    from ..levelmap.metrics import relative_l1

    pe = scene.data["exact"]
    pi = scene.data["imagespace"]
    lights = scene.data["lights"]
    size = int(pi["caustic_map"])
    tic = time.perf_counter
    timings = {}
    rs = receiver_set(scene, lights[0], size)
    obj_tris = geom.vertices[geom.faces] if len(geom.faces) else np.zeros((0, 3, 3))
    per_light, stats, halves = [], [], []
    n = int(pe["photons"])
    for l, light in enumerate(lights):
        if not len(geom.faces):
            per_light.append([np.zeros(b.size + (3,)) for b in rs.boxes])
            stats.append({"photons": 0})
            continue
        lcam = light_camera(light, geom.vertices, n)
        t0 = tic()
        o, d, flux0, half = window_samples(lcam, n, int(pe["photon_seed"]) + l)
        tr = trace_exact(geom.vertices, geom.faces, geom.face_object, geom.ior, geom.absorption, o, d,
                         vertex_normals=vn, smooth=pe["normals"] == "smooth",
                         outside_ior=float(scene.data["outside_ior"]), max_bounces=int(pe["max_bounces"]))
        timings["photon_trace"] = timings.get("photon_trace", 0.0) + (tic() - t0) * 1e3
        st = tr["status"].astype(np.int8)
        ex = np.flatnonzero(st == 1)
        t0 = tic()
        t_hit, face = hit_exact(rs.tris, tr["exit_pos"][ex], tr["exit_dir"][ex])
        P = tr["exit_pos"][ex] + t_hit[:, None] * tr["exit_dir"][ex]
        timings["receiver_hit"] = timings.get("receiver_hit", 0.0) + (tic() - t0) * 1e3
        t0 = tic()
        flux = flux0[ex, None] * tr["transmittance"][ex]
        maps = splat_maps(rs, P, face, flux, size)
        hv = half[ex]
        hA = splat_maps(rs, P, np.where(hv == 0, face, -1), flux, size)
        hB = splat_maps(rs, P, np.where(hv == 1, face, -1), flux, size)
        timings["splat"] = timings.get("splat", 0.0) + (tic() - t0) * 1e3
        per_light.append(maps)
        halves.append((hA, hB))
        s = _photon_stats(flux0, st, tr["transmittance"][ex], face >= 0)
        s["flux_on_receivers"] = float(flux[face >= 0].mean(axis=1).sum())
        s["photons"] = [n, n]
        stats.append(s)
    arrays = {}
    rgb_maps = _collect(scene, rs, per_light, arrays, 1)
    noise = []
    for r in range(len(rs.boxes)):
        a = sum(h[0][r].mean(axis=2) for h in halves) if halves else np.zeros(rs.boxes[r].size)
        b = sum(h[1][r].mean(axis=2) for h in halves) if halves else np.zeros(rs.boxes[r].size)
        noise.append(0.5 * relative_l1(a, b, blur=1.0) if np.abs(b).sum() > 0 else 0.0)

    t0 = tic()

    def vis(l, pts, nrm):
        return exact_visibility(obj_tris, lights[l], pts, nrm)

    H, W = cam.shape
    o = origin.reshape(-1, 3)
    d = rdir.reshape(-1, 3)
    t_rec, f_rec = hit_exact(rs.tris, o, d)
    hp = eye_tr.get("hit_pos")
    t_obj = np.full(len(o), np.inf) if hp is None else np.where(np.isfinite(hp[:, 0]),
                                                              np.linalg.norm(hp - o, axis=1), np.inf)
    rec = np.isfinite(t_rec) & (t_rec < t_obj)
    img = np.zeros((len(o), 3))
    if rec.any():
        img[rec] = shade_points(rs, lights, rgb_maps, o[rec] + t_rec[rec, None] * d[rec], f_rec[rec], d[rec], vis)
    obj = np.isfinite(t_obj) & ~rec
    bg = ~rec & ~obj
    env = scene.data["environment"]
    if bg.any():
        img[bg] = environment_lookup(env, d[bg], scene.base_dir)
    st = eye_tr["status"]
    ex = obj & (st == 1)
    if ex.any():
        img[ex] = _shade_rays(scene, rs, None, eye_tr["exit_pos"][ex], eye_tr["exit_dir"][ex], "exact", None,
                              rgb_maps, vis)
    stuck = obj & (st != 1)
    if stuck.any():
        img[stuck] = environment_lookup(env, eye_tr["last_dir"][stuck], scene.base_dir)
    img[obj] *= eye_tr["transmittance"][obj]
    arrays["image_caustics"] = img.reshape(H, W, 3).astype(np.float32)
    timings["final"] = (tic() - t0) * 1e3
    info = {"timings_ms": timings, "lights": stats, "receivers": len(rs.boxes), "receiver_hit": "exact",
            "gather": 1, "photons": n, "caustic_map": size, "reference_noise_rel_l1": noise}
    return arrays, info
