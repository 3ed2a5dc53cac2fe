"""The volumetric relighting pipeline (Sun et al. 2008, Fig. 2), stage by stage, with reuse.

Stages, in order, with what each one depends on (its *inputs*; a stage
re-runs when its inputs or an upstream stage changed, and is otherwise
reused from ``cache``):

==============  ===================================================  ===============
stage           inputs                                               section
==============  ===================================================  ===============
``voxelize``    objects (meshes, transforms, materials), outside      §4.1
                ior, ``volume`` block, resolution, padding,
                supersample, blur, bounds
``gradient``    voxelize                                             §3, eq. 3
``octree``      voxelize; eps, eps2, ds_max                          §4.2, §5.3
``photons``     voxelize (bounds); lights; photons                   §4.3
``march``       gradient, octree, photons; ds_min, stiff,            §4.4, eqs. 4-6
                integrator, max_steps, min_radiance, stop_fraction,
                scattering, absorption
``smooth``      march (and, for the viewing pass, the source volume  §4.4
                sigma L, direction, kappa, which no camera change
                alters)
``view``        gradient, octree, smooth; camera, environment,       §4.5
                phase_g, integrator, scattering, absorption
==============  ===================================================  ===============

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

import copy
import hashlib
import json
import os
import time

import numpy as np

from ..camera import Camera
from ..environment import environment_lookup
from ..scene import SceneError
from .gradient import gradient_field
from .march import march_photons, smooth_radiance
from .octree import build_octree
from .photons import generate_photons
from .view import source_volume, view_volume

__all__ = ["render_volumetric", "load_volume", "STAGES"]

STAGES = ("voxelize", "gradient", "octree", "photons", "march", "smooth", "view")
_UPSTREAM = {
    "voxelize": (),
    "gradient": ("voxelize",),
    "octree": ("voxelize",),
    "photons": ("voxelize",),
    "march": ("voxelize", "gradient", "octree", "photons"),
    "smooth": ("march",),
    "view": ("voxelize", "gradient", "octree", "smooth"),
}


# --------------------------------------------------------------------- inputs
def _array_descr(x):
    if x is None:
        return None
    if isinstance(x, (str, os.PathLike)):
        p = os.fspath(x)
        st = os.stat(p) if os.path.exists(p) else None
        return {"path": p, "mtime": st.st_mtime if st else None, "size": st.st_size if st else None}
    a = np.ascontiguousarray(x)
    if a.ndim == 0 or a.size <= 3:
        return a.tolist()
    return {"array": list(a.shape), "dtype": str(a.dtype), "sha1": hashlib.sha1(a.view(np.uint8)).hexdigest()}


def _stage_inputs(scene):
    d = scene.data
    v = d["volumetric"]
    vol = d["volume"]
    objects = copy.deepcopy(d["objects"]) if vol is None else "ignored (volume given)"
    if vol is None:
        for (kind, k), fn in scene.callables.items():
            if kind == "deform":
                objects[k]["deform"] = f"<callable {id(fn)}>"
    return {
        "voxelize": {"objects": objects, "outside_ior": d["outside_ior"],
                     "volume": None if vol is None else {k: _array_descr(vol[k]) for k in vol},
                     **({k: v[k] for k in ("resolution", "padding", "supersample", "blur", "bounds")}
                        if vol is None else {})},
        "gradient": {},
        "octree": {k: v[k] for k in ("eps", "eps2", "ds_max")},
        "photons": {"lights": d["lights"], "photons": v["photons"]},
        "march": {k: v[k] for k in ("ds_min", "stiff", "integrator", "max_steps", "min_radiance",
                                     "stop_fraction", "scattering", "absorption")},
        "smooth": {},
        "view": {"camera": d["camera"], "environment": d["environment"], "outside_ior": d["outside_ior"],
                 **{k: v[k] for k in ("phase_g", "integrator", "scattering", "absorption")}},
    }


def _diff(old, new, prefix=""):
    """Dotted names of the entries that differ between two JSON-like dicts."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k in sorted(set(old) | set(new)):
            name = f"{prefix}.{k}" if prefix else str(k)
            if k not in old or k not in new:
                out.append(name)
            else:
                out += _diff(old[k], new[k], name)
        return out
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        out = []
        for k, (a, b) in enumerate(zip(old, new)):
            out += _diff(a, b, f"{prefix}.{k}" if prefix else str(k))
        return out
    return [] if old == new else [prefix or "(all)"]


def _canon(x):
    return json.loads(json.dumps(x, sort_keys=True, default=str))


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
def _media(vox, v):
    """Scattering sigma and extinction kappa volumes (float32, (nx, ny, nz, 3))."""
    shape = vox["ior"].shape
    sig_k = np.broadcast_to(np.asarray(v["scattering"], dtype=np.float64), (3,))
    abs_k = np.broadcast_to(np.asarray(v["absorption"], dtype=np.float64), (3,))
    if vox["scattering"] is not None:
        sigma = vox["scattering"].astype(np.float32)
    else:
        sigma = np.broadcast_to(sig_k.astype(np.float32), shape + (3,))
    if vox["extinction"] is not None:
        kappa = vox["extinction"].astype(np.float32)
    else:
        kappa = np.empty(shape + (3,), np.float32)
        kappa[...] = (sigma + abs_k).astype(np.float32)
        if vox["absorption"] is not None:
            kappa += vox["absorption"].astype(np.float32)
    return sigma, kappa


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
                "triangles": 0, "notes": [note], "ran": False}
    geom = scene_geometry(scene)
    if len(geom.faces) == 0:
        raise SceneError("volumetric: the scene has no objects and no 'volume'; add an object or give "
                         "volume.ior and volume.bounds")
    ior, absn, b, notes = voxelize_objects(geom, float(d["outside_ior"]), int(v["resolution"]),
                                           int(v["padding"]), int(v["supersample"]), int(v["blur"]),
                                           v["bounds"])
    notes.append(f"coverage -> IOR, {'Gaussian ' + str(v['blur']) + '^3, sigma = ' + format(v['blur'] / 6, 'g') if v['blur'] > 1 else 'no blur'}")
    return {"ior": ior, "extinction": None, "scattering": None,
            "absorption": absn if np.any(absn > 0) else None, "bounds": b,
            "triangles": int(len(geom.faces)), "notes": notes, "ran": True}


def _warm():
    """Compile (or load from numba's cache) every kernel on a tiny volume, once per process."""
    if _warm.done:
        return
    _warm.done = True
    from ..scene import load_scene

    n = np.ones((8, 8, 8))
    n[3:5, 3:5, 3:5] = 1.2
    for integ in ("euler", "rk4"):
        sc = load_scene({"camera": {"width": 4, "height": 4}, "objects": [],
                         "volume": {"ior": n, "bounds": [[-1, -1, -1], [1, 1, 1]]},
                         "volumetric": {"photons": 4, "integrator": integ, "phase_g": 0.3}})
        render_volumetric(sc, warm=False)
    sc = load_scene({"camera": {"width": 4, "height": 4},
                     "objects": [{"mesh": "sphere", "fit": 1.0}],
                     "volumetric": {"photons": 4, "resolution": 16, "padding": 2}})
    render_volumetric(sc, warm=False)


_warm.done = False


def render_volumetric(scene, cache=None, warm=True):
    """Render a scene with the volumetric method of Sun et al. (2008).

    Parameters
    ----------
    scene : Scene
        A validated scene.
    cache : dict, optional
        Stage outputs of an earlier render (filled in by this call). Stages
        whose inputs did not change are reused from it
        (:class:`refraction_ref.session.Session` keeps one).
    warm : bool
        Compile every kernel first so that ``timings_ms`` exclude JIT time.

    Returns
    -------
    arrays : dict
        ORACLE.md keys: ``ior``, ``radiance``, ``direction``,
        ``volume_bounds``, ``photon_exit_pos``, ``photon_exit_dir``,
        ``photon_steps`` (total), plus ``photon_status`` and the per-pixel
        keys ``ray_origin``, ``ray_dir``, ``hit``, ``exit_pos``,
        ``exit_dir``, ``interfaces``, ``path_length``, ``status``,
        ``image``.
    info : dict
        ``timings_ms`` per stage, ``plan`` (ran or reused, and why), and
        statistics (photons, steps, drift, octree).

    References
    ----------
    Sun et al. (2008), §3-§5.
    """
    if warm:
        _warm()
    if cache is None:
        cache = {}
    d = scene.data
    v = d["volumetric"]
    inputs = _canon(_stage_inputs(scene))
    timings, plan, stats = {}, [], {}
    ran = {}
    out = {}
    tic = time.perf_counter

    def step(name, fn):
        prev = cache.get(name)
        up = [u for u in _UPSTREAM[name] if ran.get(u)]
        if prev is not None and prev["inputs"] == inputs[name] and not up:
            out[name] = prev["out"]
            ran[name] = False
            timings[name] = 0.0
            plan.append({"stage": name, "ran": False, "why": "reused: its inputs and upstream stages are unchanged"})
            return out[name]
        if prev is None:
            why = "no earlier result"
        else:
            changed = _diff(prev["inputs"], inputs[name])
            why = ("changed: " + ", ".join(changed[:6]) + (" ..." if len(changed) > 6 else "")) if changed else ""
            if up:
                why = (why + "; " if why else "") + "upstream re-ran: " + ", ".join(up)
        t0 = tic()
        res = fn()
        timings[name] = (tic() - t0) * 1e3
        cache[name] = {"inputs": inputs[name], "out": res}
        out[name] = res
        ran[name] = True
        plan.append({"stage": name, "ran": True, "why": why})
        return res

    vox = step("voxelize", lambda: _run_voxelize(scene))
    if ran["voxelize"]:
        plan[-1]["why"] += " | " + "; ".join(vox["notes"])
        if not vox["ran"]:
            plan[-1]["why"] = plan[-1]["why"].replace("no earlier result | ", "")
    ior, bounds = vox["ior"], vox["bounds"]
    shape = ior.shape
    field = step("gradient", lambda: gradient_field(ior, bounds))
    octv = step("octree", lambda: build_octree(ior, v["eps"], v["eps2"], v["ds_max"]))
    level, smax, ost = octv
    if ran["octree"]:
        msg = (f"{100 * ost['constant_fraction']:.1f}% of voxels in constant nodes (crossed in one step), "
               f"{100 * ost['limited_fraction']:.1f}% limited to ds_max = {v['ds_max']} voxels")
        if ost["constant_index"]:
            msg += "; the index is constant everywhere: photons and rays go straight"
        elif d["volume"] is None and len(d["objects"]):
            msg += "; every object has a constant index: only the blurred boundary shells bend light"
        plan[-1]["why"] += " | " + msg
    media = {}

    def _sigma_kappa():  # only the stages that run need them (not a camera-only re-render)
        if not media:
            media["sk"] = _media(vox, v)
        return media["sk"]

    def _photons():
        if not d["lights"]:
            z = np.zeros((0, 3))
            return z, z.copy(), z.copy(), np.zeros(0, np.int32), ["no lights: no photons"]
        return generate_photons(d["lights"], bounds, shape, int(v["photons"]))

    ph = step("photons", _photons)
    if ran["photons"]:
        plan[-1]["why"] += " | " + "; ".join(ph[4])
    pos, dirs, rad = ph[0], ph[1], ph[2]

    def _march():
        return march_photons(field, _sigma_kappa()[1], level, smax, bounds, pos, dirs, rad, ds_min=float(v["ds_min"]),
                             stiff=float(v["stiff"]), integrator=v["integrator"], max_steps=int(v["max_steps"]),
                             min_radiance=float(v["min_radiance"]), stop_fraction=float(v["stop_fraction"]))

    sums, minfo = step("march", _march)
    if ran["march"]:
        plan[-1]["why"] += (f" | {len(pos)} photons, {minfo['total_steps']} steps ({v['integrator']}), "
                            f"{minfo['truncated']} cut by the 1/{round(1 / v['stop_fraction']) if v['stop_fraction'] else 'inf'} "
                            f"stopping rule, |v| = n drift max {minfo['drift_max']:.3g} (p99 {minfo['drift_p99']:.3g})")
    def _smooth():
        rad, dirn = smooth_radiance(sums)
        # what a viewing ray reads per voxel (sigma L, direction, kappa): it does not depend on the
        # camera, so it is packed once here rather than on every camera change
        return rad, dirn, source_volume(rad, dirn, *_sigma_kappa())

    rad_v, dir_v, src = step("smooth", _smooth)

    cam = Camera.from_dict(d["camera"])
    H, W = cam.shape

    def _view():
        origin, rdir = cam.primary_rays()
        vw = view_volume(field, src, smax, bounds, origin.reshape(-1, 3), rdir.reshape(-1, 3),
                         integrator=v["integrator"], phase_g=float(v["phase_g"]),
                         outside_ior=float(d["outside_ior"]), n_range=(ost["n_min"], ost["n_max"]))
        env = environment_lookup(d["environment"], vw["last_dir"], scene.base_dir).astype(np.float64)
        img = vw["inscatter"] + vw["transmittance"] * env
        return {
            "ray_origin": origin, "ray_dir": rdir,
            "hit": vw["hit"].reshape(H, W),
            "exit_pos": vw["exit_pos"].reshape(H, W, 3),
            "exit_dir": vw["exit_dir"].reshape(H, W, 3),
            "interfaces": vw["interfaces"].reshape(H, W),
            "path_length": vw["path_length"].reshape(H, W),
            "status": vw["status"].reshape(H, W),
            "image": img.reshape(H, W, 3).astype(np.float32),
        }

    px = step("view", _view)

    arrays = {
        "ior": ior, "radiance": rad_v, "direction": dir_v, "volume_bounds": np.asarray(bounds, np.float64),
        "photon_exit_pos": minfo["exit_pos"], "photon_exit_dir": minfo["exit_dir"],
        "photon_steps": np.asarray(minfo["total_steps"], np.int64), "photon_status": minfo["status"],
    }
    arrays.update(px)
    stats = {
        "volume_shape": list(shape), "triangles": vox["triangles"], "photons": int(len(pos)),
        "photon_steps": minfo["total_steps"], "photons_truncated": minfo["truncated"],
        "drift_max": minfo["drift_max"], "drift_median": minfo["drift_median"], "drift_p99": minfo["drift_p99"],
        "occupied_voxels": int(np.count_nonzero(np.abs(ior - float(d["outside_ior"])) > 1e-6)),
        "octree": {k: ost[k] for k in ("constant_fraction", "limited_fraction", "levels", "constant_index")},
        "deposit_buffers": minfo["buffers"],
    }
    return arrays, {"timings_ms": timings, "plan": plan, "triangles": vox["triangles"], "stats": stats,
                    "scene": _summary(d)}


def _summary(d):
    """The resolved scene for ``meta``, with volume arrays replaced by a description."""
    if d["volume"] is None:
        return d
    s = dict(d)
    s["volume"] = {k: (x if x is None or isinstance(x, (str, list)) else _array_descr(x))
                   for k, x in d["volume"].items()}
    return s
