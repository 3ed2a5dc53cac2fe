"""The volumetric relighting pipeline (Sun et al. 2008, Fig. 2), stage by stage, with reuse.

Stages, in order, with what each one depends on (its *inputs*; a stage
re-runs when its inputs or an upstream stage changed, and is otherwise
reused from ``cache``):

================  ===================================================  ===============
stage             inputs                                               section
================  ===================================================  ===============
``voxelize``      objects (meshes, transforms, materials), outside      §4.1
                  ior, ``volume`` block, resolution, padding,
                  supersample, blur, bounds
``gradient``      voxelize                                             §3, eq. 3
``octree``        voxelize; eps, eps2, ds_max, stepping                §4.2, §5.3
``photons``       voxelize (bounds, meshes); lights; photons, proxy,   §4.3
                  proxy_inflate, outside_ior
``receivers``     receivers, lights, caustics.map_size (only           §6.2.2, Fig. 9
                  with lights and receivers)
``march``         gradient, octree, photons, (receivers); ds_min,      §4.4, eqs. 4-6
                  stiff, integrator, max_steps, min_radiance,
                  stop_fraction, scattering, absorption, stepping,
                  outside_ior
``caustics``      march, receivers; lights (only with receivers)       §6.2.2, Fig. 9
``photon_paths``  the march's inputs; only when kept: a fixed sample   §4.4
                  of photon paths, step by step, for inspection
``smooth``        march (and, for the viewing pass, the source volume  §4.4
                  sigma L, direction, kappa, which no camera change
                  alters)
``view``          gradient, octree, smooth; camera, environment,       §4.5
                  phase_g, integrator, scattering, absorption
================  ===================================================  ===============

So a camera change re-runs ``view`` only, a light change ``photons``,
``march``, ``smooth`` and ``view``, and a geometry or material change
everything (Sun et al. 2008, §3: "only some of the stages need to be
executed if the application changes just the viewing parameters, just
the lighting parameters, or just the geometry and materials").

References
----------
.. [1] X. Sun, K. Zhou, E. Stollnitz, J. Shi, B. Guo, "Interactive
   Relighting of Dynamic Refractive Objects", ACM TOG 27(3), Article 35,
   2008.
"""

from __future__ import annotations

import os

import numba as nb
import numpy as np

from ..camera import Camera
from ..environment import environment_lookup
from ..graph import Method, Stage, describe, method_renderer, register_method
from ..validation import SceneError
from ..warm import warmer
from .gradient import gradient_field
from .knobs import march_knobs, octree_dilations, view_knobs
from .march import march_grid, march_photons
from .octree import build_octree
from .photons import entry_points, generate_photons, inflate_mesh, occupied_box
from .receivers import receiver_tuple
from .smooth import smooth_radiance
from .view import source_volume, view_grid, view_volume

__all__ = ["render_volumetric", "load_volume", "ray_images", "RAY_IMAGES", "STAGES", "METHOD"]

STAGES = ("voxelize", "gradient", "octree", "photons", "march", "smooth", "view")


# --------------------------------------------------------------------- volume input
def _load_array(x, where, base_dir):
    if isinstance(x, (str, os.PathLike)):
        p = os.fspath(x)
        p = p if os.path.isabs(p) else os.path.join(base_dir, p)
        try:
            a = np.load(p, allow_pickle=False)
        except Exception as e:  # numpy raises several types
            raise SceneError(f"volume.{where}: '{x}' could not be read as a .npy array ({type(e).__name__}: {e}); "
                             "save it with numpy.save") from None
    else:
        try:
            a = np.asarray(x, dtype=np.float64)
        except (TypeError, ValueError):
            raise SceneError(f"volume.{where} must be a numeric array or a .npy path") from None
    if a.dtype.kind not in "fiu":
        raise SceneError(f"volume.{where} has dtype {a.dtype}; give real numbers")
    return np.asarray(a, dtype=np.float64)


def load_volume(scene):
    """Read and check the ``volume`` block (volumetric input, §3).

    Returns
    -------
    ior : (nx, ny, nz) float64
    extinction, scattering : (nx, ny, nz, 3) float64 or None
    bounds : (2, 3) float64

    Raises
    ------
    SceneError
        Naming the array and what is wrong: not 3D, fewer than 4 voxels
        along an axis, NaN/inf, an index <= 0, negative coefficients,
        mismatched shapes.
    """
    vol = scene.data["volume"]
    ior = _load_array(vol["ior"], "ior", scene.base_dir)
    if ior.ndim != 3:
        raise SceneError(f"volume.ior has shape {ior.shape}; give a 3D (nx, ny, nz) array")
    if min(ior.shape) < 4:
        raise SceneError(f"volume.ior has shape {ior.shape}; every axis needs at least 4 voxels")
    if not np.all(np.isfinite(ior)):
        raise SceneError(f"volume.ior holds {int(np.count_nonzero(~np.isfinite(ior)))} NaN or infinite values; "
                         "give finite indices")
    if ior.min() <= 0:
        raise SceneError(f"volume.ior has values <= 0 (min {ior.min():g}); an index of refraction must be > 0")
    out = [ior]
    for k in ("extinction", "scattering"):
        if vol[k] is None:
            out.append(None)
            continue
        a = _load_array(vol[k], k, scene.base_dir)
        if a.shape in ((), (3,)):
            a = np.broadcast_to(a, ior.shape + (3,))
        elif a.shape == ior.shape:
            a = np.broadcast_to(a[..., None], ior.shape + (3,))
        elif a.shape != ior.shape + (3,):
            raise SceneError(f"volume.{k} has shape {a.shape}; give a number, [r, g, b], {ior.shape} or "
                             f"{ior.shape + (3,)} to match volume.ior")
        if not np.all(np.isfinite(a)):
            raise SceneError(f"volume.{k} holds NaN or infinite values; give finite coefficients")
        if a.min() < 0:
            raise SceneError(f"volume.{k} has negative values (min {a.min():g}); coefficients must be >= 0")
        out.append(np.ascontiguousarray(a))
    b = np.asarray(vol["bounds"], dtype=np.float64)
    return out[0], out[1], out[2], b


# --------------------------------------------------------------------- media
def _media(voxels, v):
    """Scattering sigma and extinction kappa volumes (float32, (nx, ny, nz, 3)) from the ``voxelize`` buffers."""
    shape = voxels["ior"].shape
    sig_k = np.broadcast_to(np.asarray(v["scattering"], dtype=np.float64), (3,))
    abs_k = np.broadcast_to(np.asarray(v["absorption"], dtype=np.float64), (3,))
    if voxels["scattering"] is not None:
        sigma = voxels["scattering"].astype(np.float32)
    else:
        sigma = np.broadcast_to(sig_k.astype(np.float32), shape + (3,))
    if voxels["extinction"] is not None:
        kappa = voxels["extinction"].astype(np.float32)
    else:
        # = (sigma + abs_k).astype(float32), then += absorption.astype(float32), in parallel
        kappa = np.empty(shape + (3,), np.float32)
        absn = voxels["absorption"]
        _kappa(np.broadcast_to(sigma, shape + (3,)), abs_k.copy(),
               np.zeros((1, 1, 1, 3)) if absn is None else np.ascontiguousarray(absn, dtype=np.float64),
               absn is not None, kappa)
    return sigma, kappa


@nb.njit(cache=True, parallel=True)
def _kappa(sigma, abs_k, absn, has_absn, kappa):
    """``float32(float64(sigma) + abs_k)`` (+ ``float32(absn)`` in float32), parallel over x slabs."""
    nx, ny, nz = kappa.shape[0], kappa.shape[1], kappa.shape[2]
    for i in nb.prange(nx):
        for j in range(ny):
            for k in range(nz):
                for c in range(3):
                    x = np.float32(np.float64(sigma[i, j, k, c]) + abs_k[c])
                    if has_absn:
                        x = x + np.float32(absn[i, j, k, c])
                    kappa[i, j, k, c] = x


# --------------------------------------------------------------------- stages
def _run_voxelize(scene):
    from ..meshes import scene_geometry
    from .voxelize import voxelize_objects

    d = scene.data
    v = d["volumetric"]
    if d["volume"] is not None:
        ior, ext, sca, b = load_volume(scene)
        note = (f"volumetric input bypasses voxelization: volume.ior {ior.shape}"
                + ("" if not d["objects"] else f"; the {len(d['objects'])} scene objects are ignored"))
        return {"ior": ior, "extinction": ext, "scattering": sca, "absorption": None, "bounds": b,
                "triangles": 0, "notes": [note], "ran": False, "mesh": None}
    geom = scene_geometry(scene)
    if len(geom.faces) == 0:
        raise SceneError("volumetric: the scene has no objects and no 'volume'; add an object or give "
                         "volume.ior and volume.bounds")
    ior, absn, b, notes = voxelize_objects(geom, float(d["outside_ior"]), int(v["resolution"]),
                                           int(v["padding"]), int(v["supersample"]), int(v["blur"]),
                                           v["bounds"])
    blur = f"Gaussian {v['blur']}^3, sigma = {format(v['blur'] / 6, 'g')}" if v["blur"] > 1 else "no blur"
    notes.append(f"coverage -> IOR, {blur}")
    return {"ior": ior, "extinction": None, "scattering": None,
            "absorption": absn if np.any(absn > 0) else None, "bounds": b,
            "triangles": int(len(geom.faces)), "notes": notes, "ran": True,
            "mesh": (geom.vertices, geom.faces)}


def _tiny(scene):
    """Warm-up overrides (:attr:`~refraction_ref.graph.Method.tiny`): a 16^3 volume, a few photons and pixels."""
    return {"camera.width": 4, "camera.height": 4, "volumetric.photons": 4, "volumetric.resolution": 16,
            "volumetric.padding": 2, "imagespace.photons": 8, "caustics.map_size": 8}


# --------------------------------------------------------------------- the stage graph
_V = "volumetric."


def _st_voxelize(ctx):
    voxels = _run_voxelize(ctx.scene)
    for n in voxels["notes"]:
        ctx.note(n)
    ctx.stats["triangles"] = voxels["triangles"]
    return dict(voxels, ior_volume=voxels["ior"])


def _st_gradient(ctx):
    voxels = ctx.buf["voxelize"]
    return {"field": gradient_field(voxels["ior"], voxels["bounds"])}


def _st_octree(ctx):
    """The octrees the march and the viewing pass read, each built once (:func:`~.knobs.octree_dilations`)."""
    v = ctx.scene.data["volumetric"]
    march_dilate, view_dilate = octree_dilations(v["stepping"])
    octrees = {}
    for dilate in (march_dilate, view_dilate):
        if dilate not in octrees:
            octrees[dilate] = build_octree(ctx.buf["voxelize"]["ior"], v["eps"], v["eps2"], v["ds_max"],
                                           dilate=dilate)
    level, step_max, stats = octrees[march_dilate]
    msg = (f"{100 * stats['constant_fraction']:.1f}% of voxels in constant nodes ("
           + ("crossed in one straight step" if march_dilate else "stepped to their boundary") + "), "
           f"{100 * stats['limited_fraction']:.1f}% limited to ds_max = {v['ds_max']} voxels")
    if stats["constant_index"]:
        msg += "; the index is constant everywhere: photons and rays go straight"
    msg += ("; stepping 'robust': level-0 ranges dilated over 26 neighbours" if march_dilate
            else "; stepping 'paper': level-0 ranges are single voxels (§4.2), no stiffness cap or halving")
    ctx.note(msg)
    ctx.stats["octree"] = {k: stats[k] for k in ("constant_fraction", "limited_fraction", "levels", "constant_index")}
    return {"level": level, "step_max": step_max, "view_step_max": octrees[view_dilate][1], "info": stats}


def _proxy(ctx):
    """The proxy geometry of §4.3 (None: the volume's box) and a sentence saying what it is."""
    d = ctx.scene.data
    v = d["volumetric"]
    voxels = ctx.buf["voxelize"]
    if v["proxy"] == "box":
        return None, "proxy 'box': photons start on the volume's bounding box"
    b = np.asarray(voxels["bounds"], dtype=np.float64)
    shape = voxels["ior"].shape
    hmin = float(np.min((b[1] - b[0]) / np.asarray(shape, dtype=np.float64)))
    grow = float(v["proxy_inflate"])
    if voxels["mesh"] is not None:
        tris, pts, welded = inflate_mesh(voxels["mesh"][0], voxels["mesh"][1], grow * hmin, indexed=True)
        return ("mesh", (tris, pts, welded)), (f"proxy 'inflated': the objects' meshes inflated by {grow:g} voxels "
                                f"({len(tris)} triangles), nearest front face per texel (§4.3)")
    box = occupied_box(voxels["ior"], b, float(d["outside_ior"]), 1e-6, grow)
    if box is None:
        return None, ("proxy 'inflated' on volume input: no voxel differs from outside_ior, so photons start "
                      "on the volume's bounding box")
    return ("box", box), (f"proxy 'inflated' on volume input: the box of the voxels whose index differs from "
                          f"outside_ior, grown by {grow:g} voxels, {np.round(box, 4).tolist()} (§4.3)")


def _st_photons(ctx):
    d = ctx.scene.data
    voxels = ctx.buf["voxelize"]
    M = int(d["volumetric"]["photons"])
    if not d["lights"]:
        z = np.zeros((0, 3))
        ph = (z, z.copy(), z.copy(), np.zeros(0, np.int32), ["no lights: no photons"])
    else:
        geometry, what = _proxy(ctx)
        ctx.note(what)
        ph = generate_photons(d["lights"], voxels["bounds"], voxels["ior"].shape, M, proxy_geometry=geometry)
    for n in ph[4]:
        ctx.note(n)
    ctx.stats["photons"] = {"photons_initial": M * M * len(d["lights"]), "photons_generated": int(len(ph[0])),
                            "proxy": d["volumetric"]["proxy"]}
    entry = None
    if d["volumetric"]["proxy"] != "box" and len(ph[0]):
        # where each texel ray entered the volume: the march attenuates the photon over the skipped segment
        # (= ph[0] - where(isfinite(t), max(t, 0), 0) ph[1], t = box_entry(ph[0], -ph[1])'s exit, in parallel)
        entry = np.empty_like(ph[0])
        entry_points(np.ascontiguousarray(ph[0]), np.ascontiguousarray(ph[1]),
                     np.ascontiguousarray(voxels["bounds"], dtype=np.float64), entry)
    return {"ph": ph, "start_pos": ph[0], "start_dir": ph[1], "start_radiance": ph[2], "entry": entry}


def _st_receivers(ctx):
    from ..caustics.receivers import receiver_set

    d = ctx.scene.data
    rs = receiver_set(ctx.scene, d["lights"][0], int(d["caustics"]["map_size"]))
    recv = receiver_tuple(rs.tris, rs.owner)
    ctx.note(f"{len(rs.boxes)} diffuse receiver(s), {len(rs.tris)} triangles: photons stop on them (inside the "
             f"volume, or straight on after leaving it); {d['caustics']['map_size']}^2 caustic maps")
    return {"rs": rs, "recv": recv, **{f"frame_{r}": rs.frame(r).astype(np.float64) for r in range(len(rs.boxes))}}


#: the knobs the ``march`` stage reads (``photon_paths`` reads the same)
MARCH_KNOBS = ("ds_min", "stiff", "integrator", "max_steps", "min_radiance", "stop_fraction", "scattering",
               "absorption", "stepping")


def _march_grid(ctx):
    """The volume the march reads (:func:`~.march.march_grid`): field, kappa, the march's octree, bounds."""
    voxels, octree = ctx.buf["voxelize"], ctx.buf["octree"]
    kappa = _media(voxels, ctx.scene.data["volumetric"])[1]
    return march_grid(ctx.buf["gradient"]["field"], kappa, octree["level"], octree["step_max"], voxels["bounds"])


def _march_inputs(ctx, idx=None):
    """The march's keyword arguments beside the knobs (entry points, receivers, outside index), for photons
    ``idx`` (None: all)."""
    receivers = ctx.buf.get("receivers")
    entry = ctx.buf["photons"].get("entry")
    if entry is not None and idx is not None:
        entry = entry[idx]
    return dict(entry=entry, receivers=receivers["recv"] if receivers is not None else None,
                outside_ior=float(ctx.scene.data["outside_ior"]))


def _st_march(ctx):
    v = ctx.scene.data["volumetric"]
    ph = ctx.buf["photons"]["ph"]
    pos = ph[0]
    sums, minfo = march_photons(_march_grid(ctx), ph[:3], march_knobs(v), **_march_inputs(ctx))
    ctx.note(f"{len(pos)} photons, {minfo['total_steps']} steps ({v['integrator']}), "
             f"{minfo['truncated']} cut by the 1/{round(1 / v['stop_fraction']) if v['stop_fraction'] else 'inf'} "
             f"stopping rule, |v| = n drift max {minfo['drift_max']:.3g} (p99 {minfo['drift_p99']:.3g})")
    ctx.stats["march"] = {"photons": int(len(pos)), "photons_propagated": minfo["propagated"],
                          "photon_steps": minfo["total_steps"], "stepping": v["stepping"],
                          "photons_truncated": minfo["truncated"], "drift_max": minfo["drift_max"],
                          "drift_median": minfo["drift_median"], "drift_p99": minfo["drift_p99"],
                          "deposit_buffers": minfo["buffers"]}
    # the deposits before smoothing, so that a deposit or extinction error is named here, not in `smooth`
    deposit = sums[..., :3].astype(np.float32)
    return {"sums": sums, "minfo": minfo, "exit_pos": minfo["exit_pos"], "exit_dir": minfo["exit_dir"],
            "photon_status": minfo["status"], "hit_pos": minfo["hit_pos"], "hit_receiver": minfo["hit_receiver"],
            "deposit": deposit}


#: photons in the ``photon_paths`` sample, and the steps recorded of each
PATH_SAMPLE = 64
PATH_STEPS = 256


def path_sample(P, count=PATH_SAMPLE):
    """Indices of the photons whose paths ``photon_paths`` records: evenly spaced, all when P < count."""
    if P <= count:
        return np.arange(P, dtype=np.int64)
    return np.unique(np.linspace(0, P - 1, count).round().astype(np.int64))


def _st_photon_paths(ctx):
    """A fixed sample of photon paths, step by step, for diffing a port's march pass by pass (§4.4).

    The sample is :data:`PATH_SAMPLE` photons of the ``photons`` stage at
    evenly spaced indices (:func:`path_sample`; all of them when there are
    fewer), marched with the ``march`` stage's knobs, recording their first
    :data:`PATH_STEPS` steps. Photons do not interact, so each path is the
    one the photon follows in the full march, with one difference: the
    sample is marched alone, so the ensemble stopping rule
    (``stop_fraction``, which cuts the photons still active when too few
    of *all* photons are) does not cut it; a photon the full march cut
    goes on here to its own end. The sample's deposits are discarded.

    Buffers: ``paths`` (S, PATH_STEPS + 1, 3) float64, world: the start
    point, then the position after each step (a step leaving the volume
    ends on its face), NaN after the photon stopped; ``path_index`` (S,)
    int64, the photons' indices in ``stage.photons.start_pos`` (and
    ``photon_exit_pos``, ``photon_status``).
    """
    ph = ctx.buf["photons"]["ph"]
    idx = path_sample(len(ph[0]))
    knobs = march_knobs(ctx.scene.data["volumetric"])._replace(stop_fraction=0.0)  # marched alone: no stopping rule
    _, info = march_photons(_march_grid(ctx), (ph[0][idx], ph[1][idx], ph[2][idx]), knobs,
                            **_march_inputs(ctx, idx), record=PATH_STEPS)
    longer = int(np.count_nonzero(info["steps"] > PATH_STEPS))
    ctx.note(f"{len(idx)} of {len(ph[0])} photons, their first {PATH_STEPS} steps ({longer} take more), "
             "marched alone (no stopping rule), deposits discarded")
    return {"paths": info["paths"], "path_index": idx}


def _st_caustics(ctx):
    """Irradiance of the photons that met refractive material, splatted into each receiver's map.

    Each photon of light l carries the flux of its texel for a light of unit
    strength (texel area, or solid angle) times its transmittance; where it
    met receiver r (inside the volume, or straight on after leaving it),
    that flux times the cosine with the receiver's face normal over the
    texel area is splatted bilinearly into ``caustic_map_r`` (mean over
    channels, summed over lights) and ``caustic_rgb_r`` (each light's
    radiance), as the image-space and exact methods write them
    (docs/oracle.md, "Caustics on receivers"). Photons that never crossed
    the half-contrast level of the index (direct light) are left out.
    """
    from ..caustics.pipeline import collect_maps, splat_maps

    d = ctx.scene.data
    rs = ctx.buf["receivers"]["rs"]
    ph = ctx.buf["photons"]["ph"]
    minfo = ctx.buf["march"]["minfo"]
    voxels = ctx.buf["voxelize"]
    b = np.asarray(voxels["bounds"], dtype=np.float64)
    h = (b[1] - b[0]) / np.asarray(voxels["ior"].shape, dtype=np.float64)
    h2 = float(np.prod(h)) ** (2.0 / 3.0)
    size = int(d["caustics"]["map_size"])
    light = ph[3]
    per_light = []
    landed = 0
    for li, L in enumerate(d["lights"]):
        rad = np.asarray(L["radiance"], dtype=np.float64)
        sel = np.flatnonzero((light == li) & minfo["touched"] & (minfo["hit_tri"] >= 0))
        if len(sel) == 0 or rad.max() <= 0:
            per_light.append([np.zeros(bx.size + (3,)) for bx in rs.boxes])
            continue
        unit = ph[2][sel].max(axis=1) * h2 / rad.max()  # the texel's flux for a light of unit strength
        flux = unit[:, None] * minfo["hit_trans"][sel]
        per_light.append(splat_maps(rs, minfo["hit_pos"][sel], minfo["hit_tri"][sel], flux, size))
        landed += len(sel)
    arrays = {}
    collect_maps(d["lights"], rs, per_light, arrays, 1)
    ctx.note(f"{landed} photons that met refractive material landed on the receivers; bilinear splat, no gathering")
    ctx.stats["caustics"] = {"photons_on_receivers": int(landed), "caustic_map": size,
                             "receivers": len(rs.boxes)}
    return {"arrays": arrays, **arrays}


def _st_smooth(ctx):
    v = ctx.scene.data["volumetric"]
    rad, dirn = smooth_radiance(ctx.buf["march"]["sums"])
    # what a viewing ray reads per voxel (sigma L, direction, kappa): it does not depend on the
    # camera, so it is packed once here rather than on every camera change
    src = source_volume(rad, dirn, *_media(ctx.buf["voxelize"], v))
    return {"radiance": rad, "direction": dirn, "source": src}


#: the per-ray outputs of a viewing pass that are images (docs/oracle.md's output keys)
RAY_IMAGES = ("hit", "exit_pos", "exit_dir", "interfaces", "path_length", "status")


def ray_images(rays, shape, names=RAY_IMAGES):
    """The per-ray outputs ``names`` of a viewing pass as images: each ``(R, ...)`` array reshaped to ``shape + (...)``.

    Parameters
    ----------
    rays : dict of ndarray
        Per-ray outputs, ``R = prod(shape)`` rows, in pixel order.
    shape : tuple of int
        The image's ``(H, W)``.
    names : sequence of str
        The keys to reshape, in the order the result lists them.

    Returns
    -------
    dict of ndarray

    References
    ----------
    Sun et al. (2008), §4.5 (one viewing ray per pixel).
    """
    return {k: rays[k].reshape(tuple(shape) + rays[k].shape[1:]) for k in names}


def _st_view(ctx):
    d = ctx.scene.data
    buf = ctx.buf
    octree_stats = buf["octree"]["info"]
    cam = Camera.from_dict(d["camera"])
    H, W = cam.shape
    origin, rdir = cam.primary_rays()
    volume = view_grid(buf["gradient"]["field"], buf["smooth"]["source"], buf["octree"]["view_step_max"],
                       buf["voxelize"]["bounds"])
    rays = view_volume(volume, origin.reshape(-1, 3), rdir.reshape(-1, 3), view_knobs(d["volumetric"]),
                       outside_ior=float(d["outside_ior"]), n_range=(octree_stats["n_min"], octree_stats["n_max"]))
    env = environment_lookup(d["environment"], rays["last_dir"], ctx.scene.base_dir).astype(np.float64)
    img = rays["inscatter"] + rays["transmittance"] * env
    return {
        "ray_origin": origin, "ray_dir": rdir, **ray_images(rays, (H, W)),
        "image": img.reshape(H, W, 3).astype(np.float32),
    }


def _has_receivers(scene):
    return bool(scene.data["lights"]) and bool(scene.data["receivers"])


def _skipped(scene):
    if _has_receivers(scene):
        return []
    missing = [k for k in ("lights", "receivers") if not scene.data[k]]
    why = f"the scene has no {' and no '.join(missing)}: no receivers to voxelize, no caustic maps"
    return [{"stage": "receivers", "ran": False, "why": why}, {"stage": "caustics", "ran": False, "why": why}]


def _stages(scene):
    with_receivers = _has_receivers(scene)
    nr = len(scene.data["receivers"] or []) if with_receivers else 0
    receivers_stage = (Stage("receivers", _st_receivers, reads=("receivers", "lights", "caustics.map_size"),
                             makes=tuple(f"frame_{r}" for r in range(nr)),
                             doc="diffuse receivers the photons stop on, and their caustic-map frames (Fig. 9)"),)
    caustics_stage = (Stage("caustics", _st_caustics, reads=("lights", "caustics.map_size"),
                            after=("voxelize", "photons", "march", "receivers"),
                            makes=tuple(f"{k}_{r}" for k in ("caustic_map", "caustic_frame", "caustic_rgb")
                                        for r in range(nr)),
                            doc="irradiance of the refracted photons on each receiver (Fig. 9)"),)
    if not with_receivers:
        receivers_stage = caustics_stage = ()
    after_march = ("voxelize", "gradient", "octree", "photons") + (("receivers",) if with_receivers else ())
    return (
        Stage("voxelize", _st_voxelize, reads=("objects", "outside_ior", "volume", _V + "resolution", _V + "padding",
                                                _V + "supersample", _V + "blur", _V + "bounds"),
              makes=("ior_volume",), doc="solid voxelization, coverage -> index, Gaussian blur (§4.1)"),
        Stage("gradient", _st_gradient, after=("voxelize",), makes=("field",),
              doc="central differences of n (§3, eq. 3)"),
        Stage("octree", _st_octree, reads=(_V + "eps", _V + "eps2", _V + "ds_max", _V + "stepping"),
              after=("voxelize",), makes=("level", "step_max", "view_step_max"),
              doc="min/max pyramid, leaf levels, step-size map (§4.2, §5.3)"),
        Stage("photons", _st_photons, reads=("lights", "outside_ior", _V + "photons", _V + "proxy",
                                             _V + "proxy_inflate"), after=("voxelize",),
              makes=("start_pos", "start_dir", "start_radiance"),
              doc="one photon per light texel covered by the proxy geometry (§4.3)"),
    ) + receivers_stage + (
        Stage("march", _st_march, reads=("outside_ior",) + tuple(_V + k for k in MARCH_KNOBS),
              after=after_march, makes=("exit_pos", "exit_dir", "photon_status", "hit_pos", "hit_receiver", "deposit"),
              doc="adaptive marching and deposition (§4.4, eqs. 4-6)"),
        Stage("photon_paths", _st_photon_paths, reads=("outside_ior",) + tuple(_V + k for k in MARCH_KNOBS),
              after=after_march, makes=("paths", "path_index"), diagnostic=True,
              doc=f"the first {PATH_STEPS} steps of {PATH_SAMPLE} evenly spaced photons, marched alone (§4.4); "
                  "only when kept"),
        Stage("smooth", _st_smooth, reads=(_V + "scattering", _V + "absorption"), after=("voxelize", "march"),
              makes=("radiance", "direction"), doc="3x3x3 smoothing of the radiance (§4.4)"),
        Stage("view", _st_view, reads=("camera", "environment", "outside_ior") + tuple(
            _V + k for k in ("phase_g", "integrator")), after=("voxelize", "gradient", "octree", "smooth"),
              makes=("hit", "exit_pos", "exit_dir", "status", "image"),
              doc="curved viewing rays, Henyey-Greenstein in-scattering (§4.5)"),
    ) + caustics_stage


def _assemble(scene, bufs, stats):
    d = scene.data
    voxels, march = bufs["voxelize"], bufs["march"]
    minfo = march["minfo"]
    ior = voxels["ior"]
    arrays = {
        "ior": ior, "radiance": bufs["smooth"]["radiance"], "direction": bufs["smooth"]["direction"],
        "volume_bounds": np.asarray(voxels["bounds"], np.float64),
        "photon_exit_pos": minfo["exit_pos"], "photon_exit_dir": minfo["exit_dir"],
        "photon_steps": np.asarray(minfo["total_steps"], np.int64), "photon_status": minfo["status"],
    }
    arrays.update(bufs["view"])
    if "caustics" in bufs:
        arrays.update(bufs["caustics"]["arrays"])
    st = {"volume_shape": list(ior.shape), "triangles": voxels["triangles"], **stats.get("photons", {}),
          **stats["march"],
          "occupied_voxels": int(np.count_nonzero(np.abs(ior - float(d["outside_ior"])) > 1e-6)),
          "octree": stats["octree"]}
    if "caustics" in stats:
        st["caustics"] = stats["caustics"]
    return arrays, {"triangles": voxels["triangles"], "stats": st, "scene": _summary(d)}


METHOD = register_method(Method(
    "volumetric", blocks=("volumetric", "volume"), stages=_stages, assemble=_assemble,
    warm=warmer("volumetric"), tiny=_tiny, label="Sun et al. 2008",
    skipped=_skipped,
    results=("voxelize.ior", "voxelize.bounds", "voxelize.triangles", "march.minfo", "smooth.radiance",
             "smooth.direction", "view", "caustics"),
    doc="Sun et al. (2008): index volume, octree, curved photon paths with adaptive steps, curved viewing"))


render_volumetric = method_renderer(
    METHOD, "render_volumetric",
    "Render a scene with the volumetric method of Sun et al. (2008), §3-§5: index volume, octree, curved photon "
    "paths, curved viewing rays.")


def _summary(d):
    """The resolved scene for ``meta``, with volume arrays replaced by a description."""
    if d["volume"] is None:
        return d
    s = dict(d)
    s["volume"] = {k: (x if x is None or isinstance(x, (str, list)) else describe(x))
                   for k, x in d["volume"].items()}
    return s
