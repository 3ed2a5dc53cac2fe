"""``--method exact`` on a scene with a ``volume``: the converged graded-index reference as a stage graph.

==================  ===========================================================
stage               pass
==================  ===========================================================
``voxelize``        the volumetric method's: the ``volume`` block read and checked
``gradient``        the volumetric method's: n and its central-difference gradient
                    packed (Sun et al. 2008, eq. 3), the field both integrate
``photons``         the volumetric method's: one photon per light texel on the
                    proxy (§4.3; ``volumetric.photons``, ``proxy``, ``proxy_inflate``)
``receivers``       the volumetric method's (with lights and receivers)
``photon_trace``    every photon by the ray equation (DOP853, converged;
                    :func:`~refraction_ref.exact.grin.trace_photons`)
``caustics``        the volumetric method's splat of the photons that met
                    material, fed the converged hits (with lights and receivers)
``trace``           every pixel's viewing ray by the ray equation
                    (:func:`~refraction_ref.exact.grin.trace_view`)
``shade``           the environment along the exit direction, times the
                    transmittance (no in-scattering)
==================  ===========================================================

The first four stages (and ``caustics``) are the volumetric method's own
functions, so the photons start where the method's start, on the same field,
and their hits are splatted as the method splats its own: only the
integration differs. The tolerances are :data:`~refraction_ref.exact.grin.RTOL`,
:data:`~refraction_ref.exact.grin.ATOL` and
:data:`~refraction_ref.exact.grin.MAX_STEP` (no scene knob: the reference is
the converged answer; :func:`~refraction_ref.exact.grin.tolerance_sweep`
shows it converged).

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive Objects",
   ACM TOG 27(3), 2008, §3 (eqs. 1-3), §4.3-§4.5, Fig. 9.
.. [2] docs/oracle.md, "Exact reference on volume scenes".
"""

from __future__ import annotations

import numpy as np

from ..camera import Camera
from ..environment import environment_lookup
from ..graph import Context, Stage
from ..status import EXITED, LIMIT, LOST, MISSED
from ..volumetric import pipeline as vp
from . import grin

__all__ = ["volume_stages", "volume_skipped", "volume_assemble", "RESULTS"]

_V = "volumetric."
#: what :func:`volume_assemble` reads (``Method.results`` entries)
RESULTS = ("voxelize.ior", "voxelize.bounds", "photon_trace.grin", "caustics.arrays", "trace", "shade")


def _kappa(ctx):
    """The extinction volume the march and the viewing pass read (``volumetric._media``), or None when zero."""
    kappa = vp._media(ctx.buf["voxelize"], ctx.scene.data["volumetric"])[1]
    return kappa if np.any(kappa != 0) else None


def _st_photon_trace(ctx):
    """Every photon of the method's ``photons`` stage by the ray equation, DOP853 converged.

    References
    ----------
    .. [1] Sun et al. (2008), §3 eqs. 1-3 (the ray equation), §4.3 (photon starts), §4.4 eqs. 4-6 (the
       march this converges).
    """
    d = ctx.scene.data
    b = ctx.buf
    voxels = b["voxelize"]
    ph = b["photons"]
    rc = b.get("receivers")
    pos, dirs = ph["start_pos"], ph["start_dir"]
    volume = grin.GrinVolume(b["gradient"]["field"], voxels["bounds"], _kappa(ctx))
    g = grin.trace_photons(volume, pos, dirs, receivers=rc["recv"] if rc is not None else None,
                           outside_ior=float(d["outside_ior"]), entry=ph.get("entry"))
    st = g["status"]
    counts = {name: int(np.count_nonzero(st == code)) for name, code in
              (("exited", EXITED), ("stopped", LIMIT), ("lost", LOST), ("received", grin.RECEIVED))}
    ctx.note(f"{len(pos)} photons by the ray equation (DOP853, rtol {grin.RTOL:g}, atol {grin.ATOL:g}, steps "
             f"<= {grin.MAX_STEP:g} voxel): {g['total_steps']} steps; "
             + ", ".join(f"{v} {k}" for k, v in counts.items() if v)
             + f"; |v| = n drift max {g['drift_max']:.3g}")
    ctx.stats["photon_trace"] = {"photons": int(len(pos)), "solver_steps": g["total_steps"],
                                 "solver_rejected": int(g["rejected"].sum()), "drift_max": g["drift_max"],
                                 "rtol": grin.RTOL, "atol": grin.ATOL, "max_step_voxels": grin.MAX_STEP, **counts}
    return {"grin": g, "exit_pos": g["exit_pos"], "exit_dir": g["exit_dir"], "photon_status": st,
            "hit_pos": g["hit_pos"], "hit_receiver": g["hit_receiver"]}


def _st_caustics(ctx):
    """The volumetric method's ``caustics`` stage, its march replaced by the converged photons."""
    sub = Context(ctx.scene, {**ctx.buf, "march": {"minfo": ctx.buf["photon_trace"]["grin"]}}, ctx.progress)
    out = vp._st_caustics(sub)
    for n in sub.notes:
        ctx.note(n)
    ctx.stats.update(sub.stats)
    return out


def _st_trace(ctx):
    """Every pixel's viewing ray by the ray equation, DOP853 converged.

    References
    ----------
    .. [1] Sun et al. (2008), §4.5 (viewing rays), eqs. 2-3 and 6.
    """
    d = ctx.scene.data
    b = ctx.buf
    voxels = b["voxelize"]
    field = b["gradient"]["field"]
    cam = Camera.from_dict(d["camera"])
    H, W = cam.shape
    origin, rdir = cam.primary_rays()
    volume = grin.GrinVolume(field, voxels["bounds"], _kappa(ctx))
    viewed = grin.trace_view(volume, origin.reshape(-1, 3), rdir.reshape(-1, 3), outside_ior=float(d["outside_ior"]))
    ctx.note(f"{H * W} viewing rays by the ray equation (DOP853, rtol {grin.RTOL:g}): "
             f"{int(viewed['steps'].sum())} steps, {int(np.count_nonzero(viewed['status'] == EXITED))} met material, "
             f"{int(np.count_nonzero(viewed['status'] == MISSED))} status 0")
    ctx.stats["trace"] = {"rays": H * W, "solver_steps": int(viewed["steps"].sum()),
                          "drift_max": float(viewed["drift"].max()) if H * W else 0.0}
    return {"ray_origin": origin, "ray_dir": rdir,
            **vp.ray_images(viewed, (H, W), vp.RAY_IMAGES + ("last_dir", "transmittance"))}


def _st_shade(ctx):
    """The environment along each ray's exit direction times its transmittance (no in-scattering).

    References
    ----------
    .. [1] Sun et al. (2008), §4.5 (viewing rays), eq. 6 (transmittance).
    """
    tr = ctx.buf["trace"]
    H, W = tr["status"].shape
    env = environment_lookup(ctx.scene.data["environment"], tr["last_dir"].reshape(-1, 3), ctx.scene.base_dir)
    img = np.asarray(env, np.float64) * tr["transmittance"].reshape(-1, 3)
    ctx.note("the environment along each ray's direction at the box exit, times its transmittance; no "
             "in-scattering (the reference is of the paths, not of the radiance volume)")
    return {"image": img.reshape(H, W, 3).astype(np.float32)}


def volume_stages(scene):
    """The exact method's stages for a scene with a ``volume`` (module docstring).

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    tuple of Stage

    References
    ----------
    Sun et al. (2008), §3 eqs. 1-3, §4.3-§4.5, Fig. 9.
    """
    rc = vp._has_receivers(scene)
    nr = len(scene.data["receivers"] or []) if rc else 0
    recv = (Stage("receivers", vp._st_receivers, reads=("receivers", "lights", "caustics.map_size"),
                  makes=tuple(f"frame_{r}" for r in range(nr)),
                  doc="diffuse receivers the photons stop on (the volumetric method's stage)"),) if rc else ()
    caus = (Stage("caustics", _st_caustics, reads=("lights", "caustics.map_size"),
                  after=("voxelize", "photons", "photon_trace", "receivers"),
                  makes=tuple(f"{k}_{r}" for k in ("caustic_map", "caustic_frame", "caustic_rgb") for r in range(nr)),
                  doc="the converged photons that met material splatted as the volumetric method splats"),) if rc else ()
    return (
        Stage("voxelize", vp._st_voxelize, reads=("objects", "outside_ior", "volume", _V + "resolution",
                                                   _V + "padding", _V + "supersample", _V + "blur", _V + "bounds"),
              makes=("ior_volume",), doc="the volume block read and checked (the volumetric method's stage)"),
        Stage("gradient", vp._st_gradient, after=("voxelize",), makes=("field",),
              doc="n and its central-difference gradient: the field the reference integrates (eq. 3)"),
        Stage("photons", vp._st_photons, reads=("lights", "outside_ior", _V + "photons", _V + "proxy",
                                                _V + "proxy_inflate"), after=("voxelize",),
              makes=("start_pos", "start_dir", "start_radiance"),
              doc="the volumetric method's photon starts (§4.3)"),
    ) + recv + (
        Stage("photon_trace", _st_photon_trace, reads=("outside_ior", _V + "scattering", _V + "absorption"),
              after=("voxelize", "gradient", "photons") + (("receivers",) if rc else ()),
              makes=("exit_pos", "exit_dir", "photon_status", "hit_pos", "hit_receiver"),
              doc="every photon by the ray equation, DOP853 converged (eqs. 1-3)"),
    ) + caus + (
        Stage("trace", _st_trace, reads=("camera", "outside_ior", _V + "scattering", _V + "absorption"),
              after=("voxelize", "gradient"),
              makes=("hit", "exit_pos", "exit_dir", "interfaces", "path_length", "status", "last_dir",
                     "transmittance"),
              doc="every pixel's viewing ray by the ray equation, DOP853 converged (§4.5)"),
        Stage("shade", _st_shade, reads=("environment",), after=("trace",), makes=("image",),
              doc="the environment along the exit direction times the transmittance"),
    )


def volume_skipped(scene):
    """The plan's entries for ``receivers`` and ``caustics`` when the scene has no lights or no receivers.

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    list of dict

    References
    ----------
    Sun et al. (2008), Fig. 9 (receivers).
    """
    return vp._skipped(scene)


def volume_assemble(scene, bufs, stats):
    """The output keys of the exact reference on a volume scene (docs/oracle.md).

    Parameters
    ----------
    scene : Scene
    bufs : dict
        Stage buffers (:data:`RESULTS`).
    stats : dict

    Returns
    -------
    arrays, info : dict, dict

    References
    ----------
    docs/oracle.md, "Exact reference on volume scenes"; Sun et al. (2008), §4.4-§4.5.
    """
    voxels = bufs["voxelize"]
    g = bufs["photon_trace"]["grin"]
    tr = bufs["trace"]
    arrays = {"ior": voxels["ior"], "volume_bounds": np.asarray(voxels["bounds"], np.float64),
              "photon_exit_pos": g["exit_pos"], "photon_exit_dir": g["exit_dir"], "photon_status": g["status"]}
    arrays.update({k: tr[k] for k in ("ray_origin", "ray_dir", "hit", "exit_pos", "exit_dir", "interfaces",
                                      "path_length", "status")})
    arrays["image"] = bufs["shade"]["image"]
    if "caustics" in bufs:
        arrays.update(bufs["caustics"]["arrays"])
    st = {"volume_shape": list(voxels["ior"].shape), **stats.get("photons", {}), "photon_trace": stats["photon_trace"],
          "trace": stats["trace"]}
    if "caustics" in stats:
        st["caustics"] = stats["caustics"]
    return arrays, {"triangles": 0, "stats": st}
