"""The water cross-checks: the exact water reference against Mitsuba 3 on the exported height-field mesh.

The water is the exported dense height-field mesh with the analytic normals
at its vertices (:func:`~refraction_ref.interop.mitsuba.export_water_mesh`);
the paths compare the eye rays refracted at the water (our ``water_dir`` at
the analytic surface against Snell at Mitsuba's hit,
:func:`water_paths_case`), the caustics Mitsuba's photons through the mesh
(:func:`mitsuba_water_photons`) against our K batches
(:func:`~refraction_ref.interop.caustics.caustics_case`).

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, eq. 2-8, §4.5, §4.6, eqs. 4-17, 4-18.
.. [2] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org.
"""

from __future__ import annotations

import os
import time

import numpy as np

from ..camera import Camera
from ..compare import angular_error_deg
from ..golden.build import case_scene
from ..meshes import object_mesh
from ..render import render
from ..status import VIEW_LOST, VIEW_THROUGH, VIEW_TIR
from . import mitsuba as M
from .rays import (cross_interface, map_coords, merged_mesh, mitsuba_ray, pixel_centre_rays, ply_scene, points,
                   receiver_soup, sensor_dict)

__all__ = ["mitsuba_water_photons", "water_paths_case", "water_mesh_normal_error_deg"]


def _map_visibility(mi, rscene, owner, frame, shape, reach):
    """Receiver ``r``'s map visibility by Mitsuba's ray caster: per texel centre, the first receiver
    surface along ``-V`` from ``reach`` above the map plane (its owner, or -1) and its depth ``p . V``."""
    fr = np.asarray(frame, np.float64)
    Hc, Wc = shape
    a, b = np.meshgrid(np.arange(Hc), np.arange(Wc), indexing="ij")
    pts = fr[0] + ((b.ravel() + 0.5) / Wc)[:, None] * fr[1] + ((a.ravel() + 0.5) / Hc)[:, None] * fr[2]
    Vn = fr[3] / np.linalg.norm(fr[3])
    si = rscene.ray_intersect(mitsuba_ray(mi, pts + reach * Vn, np.tile(-Vn, (len(pts), 1))))
    ok = np.array(si.is_valid(), dtype=bool)
    own = np.where(ok, owner[np.where(ok, np.array(si.prim_index, dtype=np.int64), 0)], -1)
    depth = np.where(ok, points(si.p) @ Vn, np.nan)
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


def _receivers(mi, scene, folder, frames, shapes, reach_of):
    """The receivers as one Mitsuba scene: (scene, face owner, face normals, per map its visibility)."""
    recv = [receiver_soup(*object_mesh(rc, scene.base_dir)) for rc in scene.data["receivers"]]
    rv, rf, _, owner = merged_mesh([dict(r, normals=None) for r in recv])
    rscene = ply_scene(mi, os.path.join(folder, "receivers.ply"), rv, rf, None)
    rn = np.cross(rv[rf[:, 1]] - rv[rf[:, 0]], rv[rf[:, 2]] - rv[rf[:, 0]])
    rn /= np.linalg.norm(rn, axis=1, keepdims=True)
    reach = reach_of(rv)
    vis = [_map_visibility(mi, rscene, owner, frames[r], shapes[r], reach) for r in range(len(recv))]
    return rscene, owner, rn, vis


def _deposit(maps, hits, frames, shapes, vis):
    """Splat the photons' receiver hits into the maps they are seen by; the number seen.

    ``hits``: (points, face owner, face normal, value) of the photons that met a receiver. A photon
    deposits ``value |n_r . V| / A_texel`` where the map sees its point: the first receiver surface along
    ``-V`` through the photon's texel centre is the photon's receiver, within
    ``2 texel / max(|n_r . V|, 0.05)`` of its depth.
    """
    p, own, nrm, val = hits
    seen_all = 0
    for r in range(len(maps)):
        m = own == r
        fr = np.asarray(frames[r], np.float64)
        Hc, Wc = shapes[r]
        Vn = fr[3] / np.linalg.norm(fr[3])
        col, row = map_coords(p[m], fr, (Hc, Wc))
        jn = np.clip(np.floor(col).astype(np.int64), 0, Wc - 1)
        in_ = np.clip(np.floor(row).astype(np.int64), 0, Hc - 1)
        cosv = np.abs(nrm[m] @ Vn)
        texel = max(np.linalg.norm(fr[1]) / Wc, np.linalg.norm(fr[2]) / Hc)
        seen = (vis[r][0][in_, jn] == r) & (np.abs(p[m] @ Vn - vis[r][1][in_, jn])
                                           <= 2.0 * texel / np.maximum(cosv, 0.05))
        area = np.linalg.norm(fr[1]) * np.linalg.norm(fr[2]) / (Wc * Hc)
        maps[r] += _splat_on_map(col[seen], row[seen], (val[m] * cosv / area)[seen], (Hc, Wc))
        seen_all += int(seen.sum())
    return seen_all


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
    mi = M.require(variant)
    d = scene.data
    w = d["water"]
    wm, res = M.export_water_mesh(w, water_resolution)
    os.makedirs(folder, exist_ok=True)
    wscene = ply_scene(mi, os.path.join(folder, "water.ply"), wm.vertices, wm.faces, wm.normals)

    def reach_of(rv):
        allv = np.concatenate([wm.vertices, rv])
        return 4.0 * float(np.linalg.norm(allv.max(0) - allv.min(0)))

    rscene, owner, rn, vis = _receivers(mi, scene, folder, frames, shapes, reach_of)
    top = float(wm.vertices[:, 1].max()) + 1e-3 * max(float(s) for s in w["size"])
    low = float(wm.vertices[:, 1].min())
    eta = float(d["outside_ior"]) / float(w["ior"])
    absorption = float(w["absorption"])
    out, stats = [], {"photons": 0, "water": 0, "deposited": 0, "window": 0.0}
    for seed in seeds:
        rng = np.random.default_rng(int(seed))
        maps = [np.zeros(tuple(sh)) for sh in shapes]
        for lt in d["lights"]:
            o, dirn, flux, window = _water_light_photons(lt, w, top, low, density, rng)
            si = wscene.ray_intersect(mitsuba_ray(mi, o, dirn))
            hit = np.flatnonzero(np.array(si.is_valid(), dtype=bool))
            stats["photons"] += len(flux)
            stats["window"] += window
            stats["water"] += int(hit.size)
            t, tir, lost = cross_interface(dirn[hit], points(si.sh_frame.n)[hit], points(si.n)[hit],
                                           np.full(hit.size, eta))
            go = ~tir & ~lost & (t[:, 1] < 0)
            pw, t, f = points(si.p)[hit][go], t[go], flux[hit][go]
            sr = rscene.ray_intersect(mitsuba_ray(mi, pw, t))
            ok = np.array(sr.is_valid(), dtype=bool)
            prim = np.array(sr.prim_index, dtype=np.int64)[ok]
            p = points(sr.p)[ok]
            val = f[ok] * np.exp(-absorption * np.linalg.norm(p - pw[ok], axis=1))
            stats["deposited"] += _deposit(maps, (p, owner[prim], rn[prim], val), frames, shapes, vis)
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
    variant, water_resolution
        As :func:`mitsuba_water_photons`.

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
    scene = case_scene(case, os.path.join(folder, "scene"))
    t0 = time.perf_counter()
    a = render(scene, method="exact", keep="image").arrays
    t1 = time.perf_counter()
    ours = np.isin(a["stage.image.view_status"], (VIEW_THROUGH, VIEW_LOST, VIEW_TIR))
    mi = M.require(variant)
    d = scene.data
    w = d["water"]
    cam = Camera.from_dict(d["camera"])
    H, W = cam.height, cam.width
    wm, res = M.export_water_mesh(w, water_resolution)
    os.makedirs(folder, exist_ok=True)
    wscene = ply_scene(mi, os.path.join(folder, "water.ply"), wm.vertices, wm.faces, wm.normals)
    ray = pixel_centre_rays(mi, mi.load_dict(sensor_dict(mi, cam)), W, H)
    si = wscene.ray_intersect(ray)
    t2 = time.perf_counter()
    mit = np.array(si.is_valid(), dtype=bool)
    dd = points(ray.d)
    dd /= np.linalg.norm(dd, axis=1, keepdims=True)
    eta = np.full(len(dd), float(d["outside_ior"]) / float(w["ior"]))
    t, tir, _ = cross_interface(dd, points(si.sh_frame.n), points(si.n), eta)
    water_dir = a["stage.image.water_dir"].reshape(-1, 3)
    both = ours.ravel() & mit & ~tir & np.all(np.isfinite(water_dir), axis=1)
    ang = np.full(H * W, np.nan)
    ang[both] = angular_error_deg(water_dir[both], t[both])
    dp = np.linalg.norm(a["stage.image.water_pos"].reshape(-1, 3)[both] - points(si.p)[both], axis=1)
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
