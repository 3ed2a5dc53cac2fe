"""``--method exact``: the exact reference as a registered stage graph.

==================  ===========================================================
stage               pass
==================  ===========================================================
``geometry``        the objects' triangles and their shading normals
                    (``exact.normals``: crease, file, smooth or face)
``trace``           every pixel's ray through the real triangles (Embree hits,
                    float64 Möller-Trumbore, Snell / total internal reflection)
``shade``           environment look-up, Beer-Lambert per segment
==================  ===========================================================

With lights and receivers the exact photon reference follows
(:func:`refraction_ref.exact.caustics.exact_caustic_stages`). A scene with
``volume`` is rendered by the converged graded-index reference
(:mod:`refraction_ref.exact.volume`: the ray equation by DOP853 on the
volumetric method's own field, photons and receivers). A scene with
``water`` is rendered by the exact water reference instead: the level map's
``water``, ``planes`` and ``level_map`` stages, then ``trace`` (jittered
samples of the analytic surface, Embree first hits;
:func:`refraction_ref.exact.water.trace_water_photons`; ``exact.water_samples``
squared, jittered by ``exact.photon_seed``) and ``image``.

The method reads its own ``exact`` block and the shared ``caustics`` block
(receiver maps, gathering, placement, shadows, ambient); no other method's.

References
----------
.. [1] docs/oracle.md, "The exact reference" (the contract the outputs follow).
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.8 and §4.1 (the quantities the mesh
   reference reproduces: multi-interface Snell refraction, Beer-Lambert, caustics).
.. [3] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §2.6, §4.5 (the quantities the water reference reproduces).
"""

from __future__ import annotations

import numpy as np

from ..camera import Camera
from ..caustics.pipeline import caustic_arrays, has_caustics, merge_caustics, skip_reason
from ..environment import environment_lookup
from ..graph import Method, Stage, method_renderer, register_method
from ..levelmap.pipeline import IMAGE_BUFFERS, check_water_scene, shade_stage, shared_stages, water_arrays
from ..caustics.boxes import frame_of
from ..meshes import eye_inside, file_vertex_normals, load_mesh, rotation_matrix, scene_geometry
from ..status import MISSED
from ..validation import SceneError
from ..vec3 import affine
from ..warm import warmer
from . import water
from .caustics import exact_caustic_stages
from .knobs import exact_knobs
from .normals import mesh_normals
from .trace import ExactMesh, trace_exact

__all__ = ["render_exact", "render_water_exact", "shading_normals", "check_memory", "METHOD"]


def _object_label(k, o):
    m = o["mesh"]
    return f"objects[{k}] ({m if isinstance(m, str) else 'arrays'})"


def shading_normals(scene, geom, mode, crease_deg, vn=None, mesh=None):
    """The shading normals of the merged objects for ``exact.normals = mode``.

    Parameters
    ----------
    scene : Scene
        The scene (its ``objects``, for ``mode == "file"``: their mesh files and rotations).
    geom : Geometry
        The merged objects (:func:`refraction_ref.meshes.scene_geometry`).
    mode : {"crease", "file", "smooth", "face"}
        ``exact.normals``.
    crease_deg : float
        ``exact.crease_deg``, in ``(0, 180]``.
    vn : (V, 3) ndarray, optional
        The area-weighted vertex normals when already computed.
    mesh : MeshNormals, optional
        The :class:`~refraction_ref.exact.normals.MeshNormals` of ``geom`` with corner
        normals at ``crease_deg`` when already computed (the ``geometry`` stage), else
        computed here (on every thread, bit-identical to the serial functions of
        :mod:`refraction_ref.meshes`).

    Returns
    -------
    normals : (V, 3) or (F, 3, 3) ndarray or None
        What :class:`~refraction_ref.exact.trace.ExactMesh` takes as ``normals``:
        the area-weighted vertex normals (``smooth``; ``vn`` when given), per-corner normals
        (``crease``, ``file``) or None (``face``).
    smooth : bool
        ``ExactMesh``'s ``smooth``: interpolate ``normals`` (False: face normals).
    rule : str
        The rule applied, object by object, for the plan note.
    """
    f = geom.faces
    if mode == "face":
        return None, False, "face normals (flat facets)"
    if mesh is None or (mesh.corner is None and mode != "smooth"):
        mesh = mesh_normals(geom.vertices, f, None if mode == "smooth" else crease_deg)
    ang = mesh.edge_angles
    sharp = int(np.count_nonzero(ang > crease_deg - 1e-6))  # at the crease angle is sharp (corner_normals)
    edges = f"{sharp:,} of the scene's {len(ang):,} edges at {crease_deg:g} deg or sharper"
    if mode == "smooth":
        vn = mesh.vertex if vn is None else vn
        warn = (f"; they round {edges} (exact.normals=crease keeps them sharp)" if sharp else "")
        return vn, True, "smooth normals: area-weighted vertex normals across every edge" + warn
    cn = mesh.corner
    crease = (f"crease normals (smooth where face normals differ by less than {crease_deg:g} deg, "
              f"face normals across sharper edges; {edges})")
    if mode == "crease":
        return cn, True, crease + ", from the triangles alone (exact.normals=file uses a mesh file's own normals)"
    # 'file': per object, the vertex normals its mesh file stores; crease where there are none
    objs = scene.data["objects"]
    used, fell = [], []
    off = 0
    for k, o in enumerate(objs):
        nv = len(load_mesh(o["mesh"], o.get("size"), scene.base_dir)[0])
        n_file = None
        if o.get("deform") is not None:
            why = "deformed: its file's normals describe the undeformed mesh"
        else:
            n_file = file_vertex_normals(o["mesh"], scene.base_dir)
            why = ("its file stores no vertex normals" if isinstance(o["mesh"], str) and o["mesh"] not in
                   ("sphere", "plane") else "generated or given as arrays: no mesh file")
        if n_file is not None and len(n_file) == nv:
            # fit and the uniform scale do not turn normals; the rotation does (p' = R s p + t)
            nw = affine(n_file, rotation_matrix(o["transform"]["rotate"]).T)
            sel = np.flatnonzero(geom.face_object == k)
            cn[sel] = nw[f[sel] - off]
            used.append(_object_label(k, o))
        else:
            fell.append(f"{_object_label(k, o)}: {why}")
        off += nv
    parts = []
    if used:
        parts.append("file normals (the mesh file's vertex normals) for " + ", ".join(used))
    if fell:
        parts.append(crease + " for " + "; ".join(fell))
    return cn, True, "; ".join(parts)


def _st_geometry(ctx):
    """The objects' triangles and the shading normals ``exact.normals`` asks for.

    References
    ----------
    .. [1] docs/oracle.md, Conventions (vertex and shading normals); Max (1999), Hoppe et al. (1994)
       (:mod:`refraction_ref.exact.normals`).
    """
    geom = scene_geometry(ctx.scene)
    ctx.stats["triangles"] = int(len(geom.faces))
    knobs = exact_knobs(ctx.scene.data, "normals", "crease_deg")
    # vertex normals, crease normals and edge angles in one pass on every thread (exact.mesh_normals)
    crease = None if knobs.normals in ("face", "smooth") else knobs.crease_deg
    normals_of_mesh = mesh_normals(geom.vertices, geom.faces, crease) if len(geom.faces) else None
    vn = normals_of_mesh.vertex if normals_of_mesh is not None else None
    if len(geom.faces):
        normals, smooth, rule = shading_normals(ctx.scene, geom, knobs.normals, knobs.crease_deg, vn,
                                                normals_of_mesh)
    else:
        normals, smooth, rule = None, knobs.normals != "face", "no triangles"
    return {"geom": geom, "vertex_normals": vn, "normals": normals, "smooth": smooth, "normals_rule": rule}


def _untraced(rdir, record):
    """:func:`~refraction_ref.exact.trace.trace_exact`'s keys for rays through a scene without triangles."""
    n = len(rdir)
    traced = {"hit": np.zeros(n, bool), "exit_pos": np.full((n, 3), np.nan), "exit_dir": rdir.copy(),
              "interfaces": np.zeros(n, np.int16), "path_length": np.zeros(n), "status": np.full(n, MISSED, np.int8),
              "transmittance": np.ones((n, 3)), "last_dir": rdir.copy()}
    if record:
        traced["path_pos"] = np.full((n, record, 3), np.nan)
        traced["path_dir"] = np.full((n, record, 3), np.nan)
    return traced


def _st_trace(ctx):
    """Every pixel's primary ray through the real triangles (:func:`~refraction_ref.exact.trace.trace_exact`).

    References
    ----------
    .. [1] Chaudhari (2008), §3.6-§3.8 (the quantities reproduced); docs/oracle.md, "Per-pixel keys".
    """
    d = ctx.scene.data
    knobs = exact_knobs(d, "max_bounces", "record")
    g = ctx.buf["geometry"]
    geom = g["geom"]
    cam = Camera.from_dict(d["camera"])
    H, W = cam.shape
    if eye_inside(geom, cam.eye):
        raise SceneError("exact: the camera is inside a refractive object; the reference tracer starts "
                         "every ray in the outside medium. Move camera.eye outside the objects")
    origin, rdir = cam.primary_rays()
    n = H * W
    K = knobs.record
    if len(geom.faces):
        mesh = ExactMesh.of(geom, g["normals"], g["smooth"], d["outside_ior"])
        traced = trace_exact(mesh, origin.reshape(n, 3), rdir.reshape(n, 3), max_bounces=knobs.max_bounces,
                             record=K, progress=ctx.progress)
    else:
        traced = _untraced(rdir.reshape(n, 3), K)
    p = d["exact"]  # as the scene gives them, for the note
    ctx.note(f"Embree, up to {p['max_bounces']} bounces; exact.normals={p['normals']}: {g['normals_rule']}")
    out = {"flat": traced, "ray_origin": origin, "ray_dir": rdir,
           "hit": traced["hit"].reshape(H, W),
           "exit_pos": traced["exit_pos"].reshape(H, W, 3),
           "exit_dir": traced["exit_dir"].reshape(H, W, 3),
           "interfaces": traced["interfaces"].reshape(H, W).astype(np.int16),
           "path_length": traced["path_length"].reshape(H, W),
           "status": traced["status"].reshape(H, W).astype(np.int8),
           "path_pos": None, "path_dir": None}
    if K and "path_pos" in traced:
        out["path_pos"] = traced["path_pos"].reshape(H, W, K, 3)
        out["path_dir"] = traced["path_dir"].reshape(H, W, K, 3)
    return out


def _st_shade(ctx):
    """Environment look-up along each ray's last direction, Beer-Lambert per segment.

    References
    ----------
    .. [1] Chaudhari (2008), §3.8 (absorption); docs/oracle.md, "Per-pixel keys".
    """
    geom = ctx.buf["geometry"]["geom"]
    traced = ctx.buf["trace"]["flat"]
    H, W = ctx.buf["trace"]["status"].shape
    image = environment_lookup(ctx.scene.data["environment"], traced["last_dir"], ctx.scene.base_dir)
    if np.any(geom.absorption > 0):
        image = (image * traced["transmittance"]).astype(np.float32)
        ctx.note("environment look-up; Beer-Lambert per segment")
    else:
        ctx.note("environment look-up; absorption is zero")
    return {"image": image.reshape(H, W, 3).astype(np.float32)}


def _mesh_stages():
    return (
        Stage("geometry", _st_geometry, reads=("objects", "outside_ior", "exact.normals", "exact.crease_deg"),
              makes=("geom", "vertex_normals", "normals", "smooth", "normals_rule"),
              doc="the objects' triangles and shading normals (crease, file, smooth or face)"),
        Stage("trace", _st_trace, reads=("camera", "outside_ior", "exact.normals", "exact.max_bounces",
                                         "exact.record"), after=("geometry",),
              makes=("hit", "exit_pos", "exit_dir", "interfaces", "path_length", "status", "path_pos", "path_dir"),
              doc="every pixel's ray through the real triangles (Embree, float64 Snell)"),
        Stage("shade", _st_shade, reads=("environment",), after=("geometry", "trace"), makes=("image",),
              doc="environment look-up, Beer-Lambert per segment"),
    )


# --------------------------------------------------------------------- water scenes
def _st_water_trace(ctx):
    """Exact water photons: jittered samples of the analytic surface, Embree first hits, per light.

    References
    ----------
    .. [1] Tipprasert (2006), §2.6, §4.5 (the quantities reproduced; :mod:`refraction_ref.exact.water`).
    """
    d = ctx.scene.data
    knobs = exact_knobs(d, "water_samples", "photon_seed")
    w = ctx.buf["water"]
    pairs = ctx.buf["level_map"]["pairs"]
    wctx = {"mesh": w["mesh"], "vols": w["vols"], "receivers": ctx.buf["planes"]["receivers"], "pairs": pairs,
            "eta": w["eta"], "K": w["K"]}
    R = len(pairs)
    out = [np.zeros(pairs[r][0].box.size) for r in range(R)]
    # through the module (tests replace water.trace_water_photons by a serial reference)
    M = knobs.water_samples
    stats = [water.trace_water_photons(ctx.scene, wctx, l, M, knobs.photon_seed, out, ctx.progress)
             for l in range(len(d["lights"]))]
    ctx.stats["water_stats"] = stats
    ctx.note(f"{M}x{M} jittered samples of the analytic surface per light, Embree first hits")
    res = {}
    for r in range(R):
        res[f"caustic_map_{r}"] = np.nan_to_num(out[r]).astype(np.float32)
        res[f"caustic_frame_{r}"] = frame_of(pairs[r][0].box)
    return res


def _water_stages(scene):
    R = len(scene.data["receivers"])
    return shared_stages(scene) + (
        Stage("trace", _st_water_trace,
              reads=("water", "lights", "outside_ior", "exact.water_samples", "exact.photon_seed"),
              after=("water", "planes", "level_map"), makes=tuple(f"caustic_map_{r}" for r in range(R)),
              doc="exact water photons: jittered samples of the analytic surface, Embree first hits"),
        Stage("image", lambda ctx: shade_stage(ctx, "trace"), reads=("camera", "caustics.ambient"),
              after=("planes", "level_map", "trace"), makes=IMAGE_BUFFERS,
              doc="eq. 4-19 with the exact maps, seen through the analytic water surface and directly"),
    )


# --------------------------------------------------------------------- the method
def _stages(scene):
    if scene.data.get("water") is not None:
        check_water_scene(scene)
        return _water_stages(scene)
    if scene.data.get("volume") is not None:  # the graded-index reference (exact/volume.py)
        from .volume import volume_stages

        return volume_stages(scene)
    return _mesh_stages() + (exact_caustic_stages(scene) if has_caustics(scene) else ())


def _skipped(scene):
    if scene.data.get("water") is not None:
        return []
    if scene.data.get("volume") is not None:
        from .volume import volume_skipped

        return volume_skipped(scene)
    return [] if has_caustics(scene) else [{"stage": "caustics", "ran": False, "why": skip_reason(scene)}]


def _assemble(scene, bufs, stats):
    if "water" in bufs:
        return water_arrays(bufs, "trace"), {"stats": stats["water_stats"], "triangles": stats["triangles"]}
    if "photon_trace" in bufs and "grin" in bufs["photon_trace"]:
        from .volume import volume_assemble

        return volume_assemble(scene, bufs, stats)
    trace_bufs = bufs["trace"]
    arrays = {k: trace_bufs[k] for k in ("ray_origin", "ray_dir", "hit", "exit_pos", "exit_dir", "interfaces",
                                 "path_length", "status")}
    arrays["image"] = bufs["shade"]["image"]
    info = {"triangles": stats["triangles"]}
    if "caustic_final" in bufs:
        c_arrays, info["caustics"] = caustic_arrays(scene, "exact", bufs, stats)
        merge_caustics(arrays, c_arrays)
    return arrays, info


def check_memory(scene):
    """Refuse a camera the exact trace cannot hold (about 60 float64 words per pixel: rays, hits, outputs).

    Parameters
    ----------
    scene : Scene
        The scene (``camera.width``, ``camera.height``, ``exact.record``).

    Raises
    ------
    SceneError
        When the trace would need more than 16 GiB.
    """
    c = scene.data["camera"]
    W, H = c["width"], c["height"]
    K = int(scene.data["exact"]["record"])
    need = W * H * 8 * (60 + 6 * K)
    if need > 16 * 2**30:
        raise SceneError(f"exact: {W}x{H} pixels need about {need / 2**30:.1f} GiB for the exact trace; lower "
                         "camera.width and camera.height" + (" or exact.record" if K else ""))


def _tiny(scene):
    """Warm-up overrides (:attr:`~refraction_ref.graph.Method.tiny`): a few pixels and photons, same kernels."""
    over = {"camera.width": 16, "camera.height": 16, "exact.photons": 8, "caustics.map_size": 8}
    if scene.data.get("water") is not None:
        over.update({"water.resolution": 4, "exact.water_samples": 16})
    if scene.data.get("volume") is not None:
        over.update({"volumetric.photons": 4})
    return over


def _params(scene):
    """The blocks of ``meta["params"]``: the exact block, and the water's on a water scene (the volumetric
    block on a volume scene: its photons)."""
    if scene.data.get("water") is not None:
        return ("exact", "water")
    return ("exact", "volumetric") if scene.data.get("volume") is not None else ("exact",)


METHOD = register_method(Method(
    "exact", blocks=("exact",), stages=_stages, assemble=_assemble, skipped=_skipped, check=check_memory,
    warm=warmer("exact"), tiny=_tiny, params=_params, label="Embree reference",
    results=("trace", "shade", "level_map.pairs", "image", "receivers.rs", "gather", "caustic_final",
             "voxelize.ior", "voxelize.bounds", "photon_trace.grin", "caustics.arrays"),
    doc="the exact reference: Embree mesh tracing; for water scenes exact sampling of the analytic surface; for "
        "volume scenes the ray equation by DOP853, converged"))


render_exact = method_renderer(
    METHOD, "render_exact",
    "Trace every pixel's primary ray exactly (Embree; a water scene: the exact water reference; a volume "
    "scene: the converged graded-index reference).")

render_water_exact = method_renderer(
    METHOD, "render_water_exact",
    "Exact reference caustics maps for a water scene (same keys as the level map): the exact method's graph.")
