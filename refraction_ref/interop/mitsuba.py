"""Any scene of ours as a Mitsuba 3 scene: a dictionary for ``mi.load_dict`` or an XML file for ``mi.load_file``.

=========================  =====================================================================
ours                       Mitsuba 3
=========================  =====================================================================
``camera`` (perspective)   ``perspective``, ``fov_axis="y"``, ``to_world = look_at(eye, target,
                           up)``, a ``box`` pixel filter; pixel (row i, col j) is Mitsuba's film
                           position ``((j + 0.5) / W, (i + 0.5) / H)`` (row 0 at the top in both;
                           checked to float32 precision by :mod:`refraction_ref.interop.paths`)
object                     ``ply`` mesh with the exact reference's shading normals written into
                           it (``exact.normals``: crease and file normals split the vertices per
                           corner, smooth normals per vertex, face normals as ``face_normals``)
material ``ior``           ``dielectric`` (``int_ior = ior``, ``ext_ior = outside_ior``), or the
                           Fresnel-free ``refraction_ref_refract`` plugin of this module
material ``absorption``    an ``interior`` ``homogeneous`` medium, ``albedo = 0``, ``sigma_t =
                           absorption * ior`` (our Beer-Lambert factor ``exp(-a l ior)``, Chaudhari
                           2008 §3.8); media need the ``volpath`` integrator
``environment``            ``envmap`` of a bitmap sampled at Mitsuba's own texel directions
                           (rows at ``v = i / (H - 1)``, columns at ``u = (j + 1/2) / W`` with
                           Mitsuba's ``u`` half a turn from ours), or ``constant``
directional / point light  ``directional`` (``irradiance``) / ``point`` (``intensity``)
receiver                   ``ply`` with face normals and a ``diffuse`` BSDF of its ``albedo``
``water``                  a dense height-field ``ply`` of the analytic surface (its analytic
                           normals as vertex normals), ``dielectric`` of ``water.ior``, an
                           ``interior`` medium of ``sigma_t = water.absorption`` (eq. 4-17:
                           ``exp(-K d)``)
=========================  =====================================================================

The export is a plain *spec* (nested dicts, numbers, file names, 4x4
matrices) written once (:func:`export`); :func:`to_dict` turns it into
Mitsuba objects and :func:`to_xml` into Mitsuba's XML, so the dictionary and
the file describe one scene.

References
----------
.. [1] W. Jakob, S. Speierer, N. Roussel, M. Nimier-David, D. Vicini,
   T. Zeltner, B. Nicolet, M. Crespo, V. Leroy, Z. Zhang, "Mitsuba 3
   renderer", 2022, https://mitsuba-renderer.org (plugin reference:
   ``perspective``, ``ply``, ``dielectric``, ``envmap``, ``homogeneous``).
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §3.8 (absorption).
.. [3] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, 2006, eq. 4-17.
"""

from __future__ import annotations

import os
from xml.sax.saxutils import quoteattr

import numpy as np
import trimesh
from trimesh.exchange.ply import export_ply

from ..camera import Camera
from ..environment import environment_lookup
from ..exact.pipeline import shading_normals
from ..files import check_out_file
from ..levelmap.water import water_mesh
from ..meshes import object_mesh, scene_geometry

# Mitsuba and Dr.Jit are the optional ``crosscheck`` extra: they are imported inside the functions that need
# them (require(), to_dict(), register_refract_bsdf(), the variant of the bitmap writer), so that this module
# and the export's spec import without them

__all__ = ["require", "export", "export_files", "to_dict", "to_xml", "write_xml", "load", "object_meshes",
           "envmap_bitmap", "register_refract_bsdf", "REFRACT_PLUGIN", "write_ply", "ENV_WIDTH",
           "export_water_mesh", "NEAR_CLIP", "SIGMA_T_MIN"]

#: name under which :func:`register_refract_bsdf` registers the Fresnel-free BSDF
REFRACT_PLUGIN = "refraction_ref_refract"
#: default envmap width: 64 texels per checker square of the default 48-square checker
ENV_WIDTH = 3072
#: the sensor's near clip (world units): our primary rays start at the eye, Mitsuba's on this plane, on the
#: same line
NEAR_CLIP = 1e-4
_INSTALL = 'pip install -e ".[crosscheck]"  (or: pip install "mitsuba>=3.5")'


def require(variant="scalar_rgb"):
    """Import Mitsuba 3 and set ``variant``; a clear ImportError when it is absent.

    Parameters
    ----------
    variant : str
        Mitsuba variant to set (``"scalar_rgb"``, ``"llvm_ad_rgb"``, ...).

    Returns
    -------
    module
        The ``mitsuba`` module with ``variant`` active.

    Raises
    ------
    ImportError
        Mitsuba is not installed, or the variant is not available.
    """
    try:
        import mitsuba as mi
    except ImportError as e:
        raise ImportError(f"Mitsuba 3 is not installed; install the crosscheck extra: {_INSTALL}") from e
    if mi.variant() != variant:
        if variant not in mi.variants():
            raise ImportError(f"Mitsuba variant {variant!r} is not available here (have: {', '.join(mi.variants())})")
        mi.set_variant(variant)
    return mi


# --------------------------------------------------------------------------- files
def write_ply(path, vertices, faces, normals=None):
    """A binary little-endian PLY (trimesh's writer): float32 ``x y z`` (and ``nx ny nz``), ``uchar``/``int``
    face lists, the vertices and normals as given (no processing).

    Parameters
    ----------
    path : str
        The file to write.
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles (vertex indices).
    normals : (V, 3) array_like of float, optional
        Vertex normals; none written when None.

    Returns
    -------
    None
    """
    m = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int64), process=False,
                        vertex_normals=None if normals is None else np.asarray(normals, np.float64))
    with open(path, "wb") as fh:
        fh.write(export_ply(m, encoding="binary", vertex_normal=normals is not None, include_attributes=False))


def _split_corners(faces, corner_normals):
    """Vertices per (vertex, normal) pair: a crease vertex carries one normal per side (Mitsuba's PLY
    holds one normal per vertex). Returns (source vertex of each new vertex, its normal, new faces)."""
    vid = faces.ravel().astype(np.float64)
    n = corner_normals.reshape(-1, 3)
    key = np.column_stack([vid, n])
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    return uniq[:, 0].astype(np.int64), uniq[:, 1:], inv.reshape(-1, 3)


def object_meshes(scene):
    """Each refractive object's world triangles with the exact reference's shading normals.

    Parameters
    ----------
    scene : Scene
        A loaded scene (its ``exact.normals`` and ``exact.crease_deg`` choose
        the normals).

    Returns
    -------
    list of dict
        ``vertices`` (V, 3), ``faces`` (F, 3), ``normals`` (V, 3) or None (face
        normals), ``ior``, ``absorption`` (3,), ``rule`` (the normals rule).
    """
    geom = scene_geometry(scene)
    if not len(geom.faces):
        return []
    p = scene.data["exact"]
    nrm, smooth, rule = shading_normals(scene, geom, p["normals"], float(p["crease_deg"]))
    out = []
    for k in range(len(geom.ior)):
        sel = np.flatnonzero(geom.face_object == k)
        f = geom.faces[sel]
        used = np.unique(f)
        remap = np.full(len(geom.vertices), -1, np.int64)
        remap[used] = np.arange(len(used))
        if not smooth or nrm is None:
            v, fk, nk = geom.vertices[used], remap[f], None
        elif nrm.ndim == 2:
            v, fk, nk = geom.vertices[used], remap[f], nrm[used]
        else:
            src, nk, fk = _split_corners(f, nrm[sel])
            v = geom.vertices[src]
        out.append({"vertices": v, "faces": fk, "normals": nk, "ior": float(geom.ior[k]),
                    "absorption": np.asarray(geom.absorption[k], dtype=np.float64), "rule": rule})
    return out


def envmap_bitmap(env, width=ENV_WIDTH, base_dir="."):
    """Our environment sampled at the texel directions of Mitsuba's ``envmap``: (H, W, 3) float32.

    Mitsuba's ``envmap`` reads texel column ``j`` at ``u_mi = (j + 1/2) / W``
    and row ``i`` at ``v = i / (H - 1)`` (first and last rows on the poles),
    bilinearly, with ``u_mi = u - 1/2`` for our ``u`` (its seam looks down -z,
    ours down +z; measured with ``emitter.eval``). Point samples of ours at
    those directions, so every texel is exact and only Mitsuba's bilinear
    blend between texels differs from ours: within one texel of a sharp
    edge (a checker's), i.e. ``width`` sets the error.

    Parameters
    ----------
    env : dict
        The scene's ``environment`` block.
    width : int
        Bitmap width ``W``; the height is ``W // 2 + 1``.
    base_dir : str
        Folder for a relative ``latlong`` image path.

    Returns
    -------
    (W // 2 + 1, W, 3) float32 ndarray
        Linear RGB.
    """
    W = int(width)
    H = W // 2 + 1
    u = (np.arange(W) + 0.5) / W + 0.5
    v = np.arange(H) / (H - 1)
    phi = (u - 0.5) * 2 * np.pi  # ours: u = atan2(x, -z) / (2 pi) + 1/2
    theta = v * np.pi
    P, T = np.meshgrid(phi, theta)
    d = np.stack([np.sin(T) * np.sin(P), np.cos(T), -np.sin(T) * np.cos(P)], axis=-1)
    return environment_lookup(env, d, base_dir).astype(np.float32)


def export_water_mesh(water, resolution=None):
    """The water surface as exported: a dense height-field mesh with the analytic normals at its vertices.

    Parameters
    ----------
    water : dict
        The scene's resolved ``water`` block.
    resolution : int, optional
        Quads per side (default ``max(512, 4 * water.resolution)``).

    Returns
    -------
    mesh : WaterMesh
        ``vertices``, ``faces`` and the analytic unit ``normals`` per vertex
        (:func:`refraction_ref.levelmap.water.water_mesh`).
    resolution : int
        The quads per side used.
    """
    res = int(resolution) if resolution else max(512, 4 * int(water["resolution"]))
    return water_mesh({**water, "resolution": res}), res


def _lookat(eye, target, up):
    return {"lookat": {"origin": [float(x) for x in eye], "target": [float(x) for x in target],
                       "up": [float(x) for x in up]}}


def _bsdf(kind, ior, outside_ior):
    if kind == "refract":
        return {"type": REFRACT_PLUGIN, "int_ior": float(ior), "ext_ior": float(outside_ior)}
    if kind == "dielectric":
        return {"type": "dielectric", "int_ior": float(ior), "ext_ior": float(outside_ior)}
    raise ValueError(f"mitsuba export: bsdf must be 'dielectric' or 'refract', got {kind!r}")


#: the smallest ``sigma_t`` a medium channel is exported with: ``volpath`` samples a channel's free
#: flight by its majorant, and a channel of zero gives 0 / 0 (NaN pixels); 1e-6 per unit length moves a
#: transmittance by 1e-6 relative over a path of length one
SIGMA_T_MIN = 1e-6


def _medium(sigma_t):
    return {"type": "homogeneous", "albedo": {"type": "rgb", "value": [0.0, 0.0, 0.0]},
            "sigma_t": {"type": "rgb", "value": [max(float(s), SIGMA_T_MIN) for s in sigma_t]}, "scale": 1.0}


def export(scene, folder, *, bsdf="dielectric", env_width=ENV_WIDTH, water_resolution=None,
           integrator=None, max_depth=None, prefix=""):
    """Write a scene's meshes and environment into ``folder``; the scene spec (plain data).

    Parameters
    ----------
    scene : Scene
    folder : str
        Mesh files (``object_k.ply``, ``receiver_k.ply``, ``water.ply``) and
        the environment bitmap (``environment.exr``) go here.
    bsdf : {'dielectric', 'refract'}
        Mitsuba's own Fresnel dielectric (default), or the Fresnel-free
        refraction of the exact references (:func:`register_refract_bsdf`).
    env_width : int
        Width of the environment bitmap (height ``width / 2 + 1``).
    water_resolution : int, optional
        Quads per side of the water's height-field mesh (default
        ``max(512, 4 * water.resolution)``).
    integrator : str, optional
        ``path`` (default) or ``volpath`` (default when an object absorbs);
        ``ptracer`` for caustics.
    max_depth : int, optional
        Default ``exact.max_bounces + 2`` (camera segment, every event, the
        segment to the environment), Russian roulette off (``rr_depth`` the same).
    prefix : str
        Put before every file name (:func:`write_xml` gives the XML's stem and ``_``, so that two exports
        into one folder do not share ``object_0.ply``).

    Returns
    -------
    dict
        The spec: ``{name: {"type": ..., ...}}`` with ``"file"`` entries
        relative to ``folder``.
    """
    os.makedirs(folder, exist_ok=True)
    d = scene.data
    out_ior = float(d["outside_ior"])
    cam = Camera.from_dict(d["camera"])
    if cam.ortho:
        raise ValueError("mitsuba export: an orthographic scene camera is not exported (perspective only)")
    absorbing = False
    spec = {"type": "scene"}
    depth = int(max_depth) if max_depth is not None else int(d["exact"]["max_bounces"]) + 2
    spec["sensor"] = {
        "type": "perspective", "fov": float(cam.fov_y), "fov_axis": "y", "near_clip": NEAR_CLIP,
        "far_clip": max(1e4, float(cam.far)), "to_world": _lookat(cam.eye, cam.target, cam.up),
        "film": {"type": "hdrfilm", "width": int(cam.width), "height": int(cam.height), "pixel_format": "rgb",
                 "rfilter": {"type": "box"}, "sample_border": False},
        "sampler": {"type": "independent", "sample_count": 64}}
    for k, m in enumerate(object_meshes(scene)):
        fn = f"{prefix}object_{k}.ply"
        write_ply(os.path.join(folder, fn), m["vertices"], m["faces"], m["normals"])
        e = {"type": "ply", "file": fn, "face_normals": m["normals"] is None,
             "bsdf": _bsdf(bsdf, m["ior"], out_ior)}
        if np.any(m["absorption"] > 0):
            absorbing = True
            e["interior"] = _medium(m["absorption"] * m["ior"])
        spec[f"object_{k}"] = e
    for k, rc in enumerate(d.get("receivers") or []):
        v, f = object_mesh(rc, scene.base_dir)
        fn = f"{prefix}receiver_{k}.ply"
        write_ply(os.path.join(folder, fn), v, f)
        spec[f"receiver_{k}"] = {"type": "ply", "file": fn, "face_normals": True,
                                 "bsdf": {"type": "diffuse",
                                          "reflectance": {"type": "rgb", "value": [float(a) for a in rc["albedo"]]}}}
    w = d.get("water")
    if w is not None:
        wm, res = export_water_mesh(w, water_resolution)
        write_ply(os.path.join(folder, f"{prefix}water.ply"), wm.vertices, wm.faces, wm.normals)
        e = {"type": "ply", "file": f"{prefix}water.ply", "face_normals": False,
             "bsdf": _bsdf(bsdf, float(w["ior"]), out_ior), "resolution": res}
        if float(w["absorption"]) > 0:
            absorbing = True
            e["interior"] = _medium([float(w["absorption"])] * 3)
        spec["water"] = e
    for k, lt in enumerate(d.get("lights") or []):
        rad = [float(x) for x in lt["radiance"]]
        if lt["type"] == "directional":
            spec[f"light_{k}"] = {"type": "directional", "direction": [float(x) for x in lt["direction"]],
                                  "irradiance": {"type": "rgb", "value": rad}}
        else:
            spec[f"light_{k}"] = {"type": "point", "position": [float(x) for x in lt["position"]],
                                  "intensity": {"type": "rgb", "value": rad}}
    env = d["environment"]
    if env.get("type", "checker") == "constant":
        c = np.asarray(env.get("colors", [[0.9, 0.9, 0.9]])[0], dtype=np.float64) * float(env.get("intensity", 1.0))
        spec["environment"] = {"type": "constant", "radiance": {"type": "rgb", "value": [float(x) for x in c]}}
    else:
        img = envmap_bitmap(env, env_width, scene.base_dir)
        _write_exr(os.path.join(folder, f"{prefix}environment.exr"), img)
        spec["environment"] = {"type": "envmap", "file": f"{prefix}environment.exr", "scale": 1.0}
    kind = integrator or ("volpath" if absorbing else "path")
    spec["integrator"] = {"type": kind, "max_depth": depth}
    if kind in ("path", "volpath"):
        spec["integrator"]["rr_depth"] = depth
    return spec


def _write_exr(path, img):
    mi = require(_variant_or_scalar())
    mi.Bitmap(np.ascontiguousarray(img, dtype=np.float32)).write(path)


def _variant_or_scalar():
    try:
        import mitsuba as mi

        return mi.variant() or "scalar_rgb"
    except ImportError:
        return "scalar_rgb"


# --------------------------------------------------------------------------- spec -> Mitsuba
def to_dict(spec, folder):
    """The spec as a ``mi.load_dict`` dictionary (Mitsuba imported, its variant set by the caller).

    File entries become absolute ``filename`` s in ``folder``; look-at entries
    ``mi.ScalarTransform4f`` s. A ``refraction_ref_refract`` BSDF needs
    :func:`register_refract_bsdf` first.

    Parameters
    ----------
    spec : dict
        The spec of :func:`export`.
    folder : str
        The folder the spec's files were written into.

    Returns
    -------
    dict
        Nested dictionary for ``mi.load_dict`` (``resolution`` entries dropped).
    """
    import mitsuba as mi

    def conv(x, key=None):
        if isinstance(x, dict):
            if key == "to_world" and "lookat" in x:
                la = x["lookat"]
                return mi.ScalarTransform4f().look_at(origin=la["origin"], target=la["target"], up=la["up"])
            out = {}
            for k, v in x.items():
                if k == "file":
                    out["filename"] = os.path.abspath(os.path.join(folder, v))
                elif k == "resolution":
                    continue
                else:
                    out[k] = conv(v, k)
            return out
        return x

    return conv(spec)


def _xml_value(name, v):
    if isinstance(v, bool):
        return f'<boolean name="{name}" value="{str(v).lower()}"/>'
    if isinstance(v, int):
        return f'<integer name="{name}" value="{v}"/>'
    if isinstance(v, float):
        return f'<float name="{name}" value="{v!r}"/>'
    if isinstance(v, str):
        return f"<string name={quoteattr(name)} value={quoteattr(v)}/>"
    if isinstance(v, (list, tuple)) and len(v) == 3:
        return f'<vector name="{name}" value="{", ".join(repr(float(x)) for x in v)}"/>'
    raise ValueError(f"mitsuba xml: cannot write {name}={v!r}")


_TAGS = {"perspective": "sensor", "hdrfilm": "film", "box": "rfilter", "independent": "sampler", "ply": "shape",
         "dielectric": "bsdf", "diffuse": "bsdf", REFRACT_PLUGIN: "bsdf", "homogeneous": "medium",
         "directional": "emitter", "point": "emitter", "envmap": "emitter", "constant": "emitter",
         "path": "integrator", "volpath": "integrator", "ptracer": "integrator"}


def _xml_node(d, name=None, indent="    "):
    t = d["type"]
    if t == "rgb":
        return f'{indent}<rgb name="{name}" value="{", ".join(repr(float(x)) for x in d["value"])}"/>'
    tag = _TAGS[t]
    attrs = f' type="{t}"' + (f' name="{name}"' if name and tag in ("medium", "rfilter") and name != tag else "")
    if tag == "medium":
        attrs = f' type="{t}" name="{name}"'
    lines = [f"{indent}<{tag}{attrs}>"]
    for k, v in d.items():
        if k in ("type", "resolution"):
            continue
        if k == "file":
            lines.append(f"{indent}    " + _xml_value("filename", v))
        elif k == "to_world":
            la = v["lookat"]
            lines.append(f'{indent}    <transform name="to_world">')
            lines.append(f'{indent}        <lookat origin="{", ".join(map(repr, la["origin"]))}" '
                         f'target="{", ".join(map(repr, la["target"]))}" up="{", ".join(map(repr, la["up"]))}"/>')
            lines.append(f"{indent}    </transform>")
        elif isinstance(v, dict):
            lines.append(_xml_node(v, k, indent + "    "))
        elif k == "direction" or k == "position":
            tagv = "vector" if k == "direction" else "point"
            lines.append(f'{indent}    <{tagv} name="{k}" value="{", ".join(repr(float(x)) for x in v)}"/>')
        else:
            lines.append(f"{indent}    " + _xml_value(k, v))
    lines.append(f"{indent}</{tag}>")
    return "\n".join(lines)


def to_xml(spec):
    """The spec as Mitsuba 3 XML (``<scene version="3.0.0">``; file names relative to the XML file).

    Parameters
    ----------
    spec : dict
        The spec of :func:`export`.

    Returns
    -------
    str
        The XML document.
    """
    body = [_xml_node(v, k) for k, v in spec.items() if k != "type"]
    return '<?xml version="1.0" encoding="utf-8"?>\n<!-- written by refraction-ref (refraction_ref.interop.mitsuba) -->\n' \
           '<scene version="3.0.0">\n' + "\n".join(body) + "\n</scene>\n"


def export_files(scene, path):
    """The files :func:`write_xml` writes for ``scene`` at ``path``: the XML and, beside it, its side files
    named after the XML's stem (``OUT_object_0.ply``, ``OUT_receiver_0.ply``, ``OUT_water.ply``,
    ``OUT_environment.exr``).

    Parameters
    ----------
    scene : Scene
        The scene to export.
    path : str
        The XML file.

    Returns
    -------
    list of str
    """
    folder = os.path.dirname(os.path.abspath(path))
    prefix = os.path.splitext(os.path.basename(path))[0] + "_"
    d = scene.data
    names = [f"{prefix}object_{k}.ply" for k in range(len(d["objects"] or []))]
    names += [f"{prefix}receiver_{k}.ply" for k in range(len(d.get("receivers") or []))]
    names += [f"{prefix}water.ply"] if d.get("water") is not None else []
    names += [f"{prefix}environment.exr"] if d["environment"].get("type") != "constant" else []
    return [os.fspath(path)] + [os.path.join(folder, n) for n in names]


def write_xml(scene, path, force=False, **kw):
    """Export ``scene`` as ``path`` (Mitsuba XML) with its mesh and bitmap files beside it; the spec.

    The side files are named after the XML's stem (:func:`export_files`), so exports of two scenes into one
    folder keep apart; an existing file is refused (``FileExistsError``, before anything is written) unless
    ``force``. Keyword arguments are those of :func:`export`.

    Parameters
    ----------
    scene : Scene
        The scene to export.
    path : str
        The XML file; the mesh and bitmap files go into its folder.
    force : bool
        Replace existing files.
    **kw
        Passed to :func:`export` (``bsdf``, ``env_width``, ...).

    Returns
    -------
    dict
        The spec (:func:`export`).
    """
    check_out_file(path, "the Mitsuba scene (--to mitsuba OUT.xml)")
    there = [p for p in export_files(scene, path) if os.path.exists(p)]
    if there and not force:
        raise FileExistsError(f"'{there[0]}' exists; choose another OUT.xml or pass --force to replace "
                              f"{'it' if len(there) == 1 else f'the {len(there)} files'}")
    folder = os.path.dirname(os.path.abspath(path))
    kw.setdefault("prefix", os.path.splitext(os.path.basename(path))[0] + "_")
    spec = export(scene, folder, **kw)
    with open(path, "w") as f:
        f.write(to_xml(spec))
    return spec


def load(scene, folder, variant="scalar_rgb", **kw):
    """The scene as a loaded ``mi.Scene`` (files written into ``folder``); (mi.Scene, spec).

    Parameters
    ----------
    scene : Scene
        The scene to export.
    folder : str
        Folder for the mesh and bitmap files.
    variant : str
        Mitsuba variant to set (:func:`require`).
    **kw
        Passed to :func:`export`; ``bsdf="refract"`` also registers the
        Fresnel-free BSDF.

    Returns
    -------
    mi_scene : mitsuba.Scene
        The loaded scene.
    spec : dict
        The spec (:func:`export`).
    """
    mi = require(variant)
    spec = export(scene, folder, **kw)
    if kw.get("bsdf") == "refract":
        register_refract_bsdf()
    return mi.load_dict(to_dict(spec, folder)), spec


# --------------------------------------------------------------------------- the Fresnel-free BSDF
_REGISTERED = set()


def register_refract_bsdf():
    """Register the Fresnel-free refractive BSDF ``refraction_ref_refract`` with the current variant.

    Refraction only, as the exact references trace it: Snell's law with the
    shading normal flipped to the geometric normal's side, the geometric
    normal instead when the shading normal would send the ray to the wrong
    side of the triangle, the mirror direction under total internal
    reflection, and a weight of one (no Fresnel split, no ``1 / eta^2``
    radiance scaling: the exact image is the environment along the exit
    direction). The medium is decided by the geometric normal
    (``dot(wi, n_g) > 0``: outside, ``ext_ior``), as the exact tracer does.
    Parameters: ``int_ior``, ``ext_ior`` (floats).
    """
    import drjit as dr
    import mitsuba as mi

    if mi.variant() in _REGISTERED:
        return REFRACT_PLUGIN

    class RefractBSDF(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.int_ior = float(props.get("int_ior", 1.5)) if hasattr(props, "get") else float(props["int_ior"])
            self.ext_ior = float(props.get("ext_ior", 1.0)) if hasattr(props, "get") else float(props["ext_ior"])
            flags = (mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide)
            tflags = (mi.BSDFFlags.DeltaTransmission | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
                      | mi.BSDFFlags.NonSymmetric)
            self.m_components = [flags, tflags]
            self.m_flags = flags | tflags

        def sample(self, ctx, si, sample1, sample2, active=True):
            fr = si.sh_frame
            wi = fr.to_world(si.wi)  # towards where the ray came from
            d = -wi
            ng = si.n
            cos_g = dr.dot(d, ng)
            entering = cos_g < 0
            ns = fr.n
            ns = dr.select(dr.dot(ns, ng) < 0, -ns, ns)
            eta = dr.select(entering, self.ext_ior / self.int_ior, self.int_ior / self.ext_ior)

            def refract(n):
                nf = dr.select(dr.dot(d, n) < 0, n, -n)  # facing the incoming ray
                ci = -dr.dot(d, nf)
                k = 1 - eta * eta * (1 - ci * ci)
                tir = k < 0
                t = eta * d + (eta * ci - dr.safe_sqrt(k)) * nf
                r = d + 2 * ci * nf
                return dr.select(tir, r, dr.normalize(t)), tir

            out, tir = refract(ns)
            sn = dr.dot(out, ng)
            wrong = dr.select(tir, (sn < 0) == (cos_g < 0), (sn < 0) != (cos_g < 0))
            out2, tir2 = refract(ng)
            out = dr.select(wrong, out2, out)
            tir = dr.select(wrong, tir2, tir)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = fr.to_local(out)
            bs.pdf = 1.0
            bs.eta = dr.select(tir, 1.0, 1.0 / eta)
            bs.sampled_type = dr.select(tir, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                                        mi.UInt32(+mi.BSDFFlags.DeltaTransmission))
            bs.sampled_component = dr.select(tir, mi.UInt32(0), mi.UInt32(1))
            return bs, mi.Color3f(1.0)

        def eval(self, ctx, si, wo, active=True):
            return mi.Color3f(0.0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return mi.Color3f(0.0), mi.Float(0.0)

        def to_string(self):
            return f"RefractBSDF[int_ior={self.int_ior}, ext_ior={self.ext_ior}]"

    mi.register_bsdf(REFRACT_PLUGIN, lambda props: RefractBSDF(props))
    _REGISTERED.add(mi.variant())
    return REFRACT_PLUGIN
