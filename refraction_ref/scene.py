"""Scene loading and validation (the input half of ``docs/oracle.md``).

A scene is a JSON file or a dict. :func:`load_scene` merges it over the
documented defaults, refuses unknown keys and bad values with one message
that names the input, what is wrong and what to do, and returns a
:class:`Scene` whose ``data`` is the fully resolved dict that every run
writes back into its ``meta``.

The defaults of each method's block are the seeds' own settings
(Chaudhari 2008: 5 binary-search iterations, 256 slices, 32 layers, a 256x256
MIP level for the search bounds, perspective-corrected central differences).
"""

from __future__ import annotations

import copy
import json
import os
import re
from dataclasses import dataclass, field

import numpy as np

from .graph import BLOCKS, load_builtin_blocks
from .validation import (SceneError, check_depth, check_dict, check_number, check_vector, merge_defaults,
                         printable, show)

__all__ = ["Scene", "SceneError", "load_scene", "default_scene", "DEFAULTS", "apply_overrides", "BLOCKS",
           "ignored_content", "FOV_MIN"]


DEFAULT_CAMERA = {"eye": [0.0, 0.0, 2.6], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                  "fov_y": 30.0, "width": 512, "height": 512, "near": 0.1, "far": 10.0}

DEFAULT_OBJECT = {"mesh": "bunny", "fit": None, "size": None,
                  "transform": {"scale": 1.0, "rotate": [0.0, 0.0, 0.0], "translate": [0.0, 0.0, 0.0]},
                  "material": {"ior": 1.5, "absorption": [0.0, 0.0, 0.0]},
                  "deform": None, "name": None}

DEFAULT_RECEIVER = {"mesh": "plane", "fit": None, "size": [4.0, 4.0],
                    "transform": {"scale": 1.0, "rotate": [0.0, 0.0, 0.0], "translate": [0.0, 0.0, 0.0]},
                    "albedo": [0.8, 0.8, 0.8], "name": None}

#: 48 squares around the horizon (7.5 degrees each): at the default 30-degree field of view about
#: four squares span the image, so the refraction through an object is visible (16 showed one or two)
DEFAULT_ENVIRONMENT = {"type": "checker", "tiles": 48, "colors": [[0.9, 0.9, 0.9], [0.1, 0.1, 0.1]],
                       "path": None, "intensity": 1.0}

DEFAULT_LIGHT = {"type": "directional", "direction": [0.0, -1.0, 0.0], "position": None,
                 "radiance": [1.0, 1.0, 1.0]}

DEFAULT_DEFORM = {"type": "sine", "amplitude": 0.02, "wavelength": 0.25,
                  "direction": [0.0, 1.0, 0.0], "phase": 0.0}

def _block_defaults():
    """Every registered knob block's defaults (the blocks' own modules hold them)."""
    return {name: (copy.deepcopy(b.defaults) if b.defaults is not None else None) for name, b in BLOCKS.items()}


DEFAULTS = {
    "camera": DEFAULT_CAMERA,
    "objects": [dict(DEFAULT_OBJECT, fit=1.0, material={"ior": 1.2, "absorption": [0.0, 0.0, 0.0]})],
    "outside_ior": 1.0,
    "environment": DEFAULT_ENVIRONMENT,
    "lights": [DEFAULT_LIGHT],
    "receivers": [],          # none by default: caustics run when a scene has receivers and lights
    # the knob blocks (imagespace, exact, volumetric, volume, levelmap, water) are added at the end of
    # this module from the registry: each method's knobs module owns its defaults and checks
}


@dataclass
class Scene:
    """A validated scene.

    Attributes
    ----------
    data : dict
        The resolved scene: every key present, defaults filled in.
    base_dir : str
        Folder against which relative paths (meshes, images) resolve.
    callables : dict
        Python-only inputs that JSON cannot hold (e.g. a ``deform``
        function per object index); empty for scenes read from files.
    """

    data: dict
    base_dir: str = "."
    callables: dict = field(default_factory=dict)

    def to_json(self):
        return json.dumps(self.data, indent=1, sort_keys=True)

    def resolve_path(self, p):
        """A path of the scene, resolved against :attr:`base_dir` when relative.

        Parameters
        ----------
        p : str
            A path from the scene (mesh, image).

        Returns
        -------
        str
            ``p`` if absolute, else ``base_dir / p`` normalised.
        """
        return p if os.path.isabs(p) else os.path.normpath(os.path.join(self.base_dir, p))

    def copy(self):
        return Scene(copy.deepcopy(self.data), self.base_dir, dict(self.callables))


def default_scene():
    """The bundled default scene: a glass bunny (IOR 1.2) in a checker environment, 512x512."""
    return load_scene({})


def _check_mesh_ref(mesh, where, base_dir):
    from .meshes import BUILTIN_MESHES

    if callable(mesh) or isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        return
    if not isinstance(mesh, str):
        raise SceneError(f"scene: '{where}' must be a built-in mesh name ({', '.join(BUILTIN_MESHES)}) "
                         f"or a path to a mesh file, got {show(mesh)}")
    if mesh in BUILTIN_MESHES:
        return
    p = mesh if os.path.isabs(mesh) else os.path.join(base_dir, mesh)
    if not os.path.isfile(p):
        raise SceneError(f"scene: '{where}' names '{mesh}', which is neither a built-in mesh "
                         f"({', '.join(BUILTIN_MESHES)}) nor an existing file (looked for {p}); "
                         "fix the path or use a built-in name")


def _check_transform(t, where):
    check_dict(t, where)
    check_number(t["scale"], f"{where}.scale", 0.0, lo_open=True)
    check_vector(t["rotate"], 3, f"{where}.rotate")
    check_vector(t["translate"], 3, f"{where}.translate")


def validate(data, base_dir="."):
    """Check a merged scene; raise :class:`SceneError` on the first problem.

    Also fills the partially given knob blocks (each block's ``merge``)
    and the objects' ``deform`` defaults in place, reads a ``latlong``
    environment image once, and runs each registered knob block's checks.

    Parameters
    ----------
    data : dict
        The merged scene dictionary (every key present).
    base_dir : str
        Folder for relative mesh and image paths.

    Returns
    -------
    dict
        ``data`` itself.

    Raises
    ------
    SceneError
        Naming the key and the fix.
    """
    c = check_dict(data["camera"], "camera")
    eye = check_vector(c["eye"], 3, "camera.eye")
    target = check_vector(c["target"], 3, "camera.target")
    up = check_vector(c["up"], 3, "camera.up")
    if np.linalg.norm(target - eye) == 0:
        raise SceneError("scene: camera.eye and camera.target coincide; move the target")
    if np.linalg.norm(np.cross(target - eye, up)) < 1e-12 * np.linalg.norm(target - eye) * max(np.linalg.norm(up), 1e-300):
        raise SceneError("scene: camera.up is parallel to the viewing direction; choose another up vector")
    # below 0.1 degree a pixel's footprint falls under the float32 depth and projection precision of the
    # image-space buffers: every pixel reads "missed" there while the exact trace hits
    check_number(c["fov_y"], "camera.fov_y", FOV_MIN, 179.0)
    # the real limit is the pixel count (MAX_PIXELS, checked below); one side alone may take all of it
    check_number(c["width"], "camera.width", 1, MAX_PIXELS, integer=True)
    check_number(c["height"], "camera.height", 1, MAX_PIXELS, integer=True)
    check_number(c["near"], "camera.near", 0.0, lo_open=True)
    check_number(c["far"], "camera.far", c["near"], lo_open=True)
    if np.linalg.norm(target - eye) < 1e-9 * max(1.0, float(np.abs(eye).max())):
        raise SceneError("scene: camera.eye and camera.target nearly coincide (no view direction); move the target")
    if c["width"] * c["height"] > MAX_PIXELS:
        raise SceneError(f"scene: camera.width x camera.height is {c['width']}x{c['height']}, too large for memory; "
                         f"give at most {MAX_PIXELS} pixels in all (16384x16384)")
    check_number(data["outside_ior"], "outside_ior", 0.0, lo_open=True)
    if not isinstance(data["objects"], list):
        raise SceneError("scene: 'objects' must be a list")
    for k, o in enumerate(data["objects"]):
        w = f"objects[{k}]"
        _check_mesh_ref(o["mesh"], f"{w}.mesh", base_dir)
        _check_fit_size(o, w)
        _check_transform(o["transform"], f"{w}.transform")
        m = check_dict(o["material"], f"{w}.material")
        check_number(m["ior"], f"{w}.material.ior", 0.0, lo_open=True)
        a = check_vector(m["absorption"], 3, f"{w}.material.absorption")
        if np.any(a < 0):
            raise SceneError(f"scene: '{w}.material.absorption' is {show(m['absorption'])}; "
                             "absorption coefficients must be >= 0")
        if o["deform"] is not None and not callable(o["deform"]) and o["deform"] != "<python callable>":
            o["deform"] = merge_defaults(DEFAULT_DEFORM, o["deform"], f"{w}.deform")
            d = o["deform"]
            if d["type"] != "sine":
                raise SceneError(f"scene: '{w}.deform.type' is {show(d['type'])}; only \"sine\" is known")
            check_number(d["amplitude"], f"{w}.deform.amplitude")
            check_number(d["wavelength"], f"{w}.deform.wavelength", 0.0, lo_open=True)
            if not np.linalg.norm(check_vector(d["direction"], 3, f"{w}.deform.direction")) > 0:
                raise SceneError(f"scene: '{w}.deform.direction' is zero; give the direction the wave runs along")
            check_number(d["phase"], f"{w}.deform.phase")
    for k, r in enumerate(data["receivers"] or []):
        _check_mesh_ref(r["mesh"], f"receivers[{k}].mesh", base_dir)
        _check_fit_size(r, f"receivers[{k}]")
        _check_transform(r["transform"], f"receivers[{k}].transform")
    env = check_dict(data["environment"], "environment")
    if env["type"] not in ("checker", "latlong", "constant"):
        raise SceneError(f"scene: environment.type is {show(env['type'])}; use 'checker', 'latlong' or 'constant'")
    check_number(env["tiles"], "environment.tiles", 1, 10**6, integer=True)
    colors = env["colors"]
    if not isinstance(colors, list) or not 1 <= len(colors) <= 2:
        raise SceneError(f"scene: 'environment.colors' must be a list of two [r, g, b] colours (constant uses "
                         f"the first), got {show(colors)}")
    for i, col in enumerate(colors):
        if np.any(check_vector(col, 3, f"environment.colors[{i}]") < 0):
            raise SceneError(f"scene: 'environment.colors[{i}]' is {show(col)}; radiances must be >= 0")
    if env["type"] == "checker" and len(colors) != 2:
        raise SceneError("scene: 'environment.colors' has one colour; the checker needs two (or use type "
                         "'constant')")
    check_number(env["intensity"], "environment.intensity", 0.0)
    if env["path"] is not None and not isinstance(env["path"], str):
        raise SceneError(f"scene: 'environment.path' must be a file path (a string) or null, got {show(env['path'])}")
    if env["type"] == "latlong":
        if not env["path"]:
            raise SceneError("scene: environment.type 'latlong' needs environment.path (an image file)")
        p = env["path"] if os.path.isabs(env["path"]) else os.path.join(base_dir, env["path"])
        if not os.path.isfile(p):
            raise SceneError(f"scene: environment.path '{env['path']}' does not exist (looked for {p})")
        from .environment import read_latlong

        read_latlong(p)  # now, not in the shade stage after the geometry work
    from .lights import validate_lights

    for block in BLOCKS.values():  # blocks given partially (water) are filled before the lights are checked
        if block.merge is not None:
            block.merge(data)
    validate_lights(data)
    for k, r in enumerate(data["receivers"] or []):
        alb = check_vector(r["albedo"], 3, f"receivers[{k}].albedo", limit=None)
        if np.any(alb < 0) or np.any(alb > 1):  # a reflectance: a surface reflects at most what reaches it
            raise SceneError(f"scene: 'receivers[{k}].albedo' is {show(r['albedo'])}; each component is a "
                             "reflectance and must be in [0, 1]")
    _check_volume_files(data, base_dir)  # the files first: a folder or a truncated file named as such
    for name, block in BLOCKS.items():  # each method's own checks, beside the code that reads them
        block.validate(data, base_dir)
    return data


#: The most pixels a camera may have (width x height; 16384 x 16384): the buffers of one render fit in memory.
MAX_PIXELS = 16384 * 16384

#: The smallest ``camera.fov_y`` (degrees): below it the image-space buffers' float32 precision no longer
#: separates a pixel's rays (every pixel read "missed" at 1e-6 degree while the exact trace hit).
FOV_MIN = 0.1


def _check_fit_size(o, w):
    """An object's or receiver's ``fit`` (null or > 0) and ``size`` (null or [sx, sz] > 0)."""
    if o["fit"] is not None:
        check_number(o["fit"], f"{w}.fit", 0.0, lo_open=True)
    if o["size"] is not None:
        if np.any(check_vector(o["size"], 2, f"{w}.size") <= 0):
            raise SceneError(f"scene: '{w}.size' is {show(o['size'])}; both extents must be > 0")


def _check_volume_files(data, base_dir):
    """Read every array the ``volume`` block gives (``.npy`` file or inline), now: a truncated file, an object
    array, a folder, a wrong shape or a non-positive index is refused when the scene loads, naming the key and
    the file, not when the volumetric method reaches its first stage."""
    vol = data.get("volume")
    if not isinstance(vol, dict):
        return
    ior_shape = None
    for k in ("ior", "extinction", "scattering"):
        x = vol.get(k)
        if x is None:
            continue
        name = f"'volume.{k}'"
        if isinstance(x, (str, os.PathLike)):
            p = os.fspath(x)
            p = p if os.path.isabs(p) else os.path.join(base_dir, p)
            shown = printable(os.fspath(x))
            name = f"'volume.{k}' ('{shown if len(shown) <= 80 else '...' + shown[-77:]}')"  # the file's own name
            if os.path.isdir(p):
                raise SceneError(f"scene: {name} is a folder; give a .npy file (numpy.save) or an array")
            if not os.path.isfile(p):
                raise SceneError(f"scene: {name} does not exist (looked for {p}); give an existing .npy file or "
                                 "an array")
            with open(p, "rb") as f:
                npy = f.read(6) == b"\x93NUMPY"
            if not npy:  # NumPy would read it as a pickle, and advise loading it unsafely
                from .files import file_kind

                raise SceneError(f"scene: {name} is not a .npy array ({file_kind(p)}); save the array with "
                                 "numpy.save")
            try:
                a = np.load(p, allow_pickle=False, mmap_mode="r")
                a = np.asarray(a)
            except Exception as e:  # NumPy raises several types for a bad file
                raise SceneError(f"scene: {name} cannot be read as a .npy array ({type(e).__name__}: "
                                 f"{str(e)[:80]}); save the array with numpy.save") from None
            if a.dtype.kind not in "fiu":
                raise SceneError(f"scene: {name} holds {a.dtype} values; give real numbers")
        else:
            try:
                a = np.asarray(x, dtype=np.float64)
            except (TypeError, ValueError, OverflowError):
                raise SceneError(f"scene: {name} must be a numeric array or a .npy path, got {show(x, 40)}") from None
        if not np.all(np.isfinite(a)):
            raise SceneError(f"scene: {name} holds NaN or infinite values; give finite numbers")
        if a.size and np.abs(a).max() > 1e6:
            raise SceneError(f"scene: {name} holds values beyond +-1e6; give finite numbers within +-1e6")
        if k == "ior":
            if a.ndim != 3 or min(a.shape) < 4:
                raise SceneError(f"scene: {name} has shape {a.shape}; give a 3D (nx, ny, nz) array with at "
                                 "least 4 voxels along every axis")
            if a.min() <= 0:
                raise SceneError(f"scene: {name} has values <= 0 (min {a.min():g}); an index of refraction "
                                 "must be > 0")
            ior_shape = a.shape
            continue
        if ior_shape is not None and a.shape not in ((), (3,), ior_shape, ior_shape + (3,)):
            raise SceneError(f"scene: {name} has shape {a.shape}; give a number, [r, g, b], {ior_shape} or "
                             f"{ior_shape + (3,)} to match volume.ior")
        if a.size and a.min() < 0:
            raise SceneError(f"scene: {name} has negative values (min {a.min():g}); coefficients must be >= 0")


def ignored_content(data, method):
    """A one-line warning when ``method`` reads none of the scene's content, else None.

    ``imagespace`` and ``exact`` on mesh scenes read ``objects``; ``volumetric`` reads ``objects`` or
    ``volume``, and ``exact`` reads ``volume`` where there is one (the graded-index reference); ``levelmap`` reads ``water`` (and refuses a scene without it). A water-only scene rendered by
    ``imagespace``, or a volume
    scene rendered by a method that cannot read volumes, would otherwise give an empty (or default) picture
    without a word.

    Parameters
    ----------
    data : dict
        The resolved scene.
    method : str
        The method's name.

    Returns
    -------
    str or None
    """
    has_obj = bool(data.get("objects"))
    has_water = data.get("water") is not None
    has_vol = data.get("volume") is not None
    if has_vol and method not in ("volumetric", "exact"):  # exact: the graded-index reference (exact/volume.py)
        return (f"the scene's 'volume' block is read only by --method volumetric (and exact); {method} ignores it"
                + (" and renders the scene's objects (the default bunny where the scene gives no 'objects')" if has_obj
                   else " and renders an empty scene"))
    if method == "imagespace" and has_water and not has_obj:
        return ("--method imagespace ignores the scene's 'water' block and the scene has no objects: the picture is "
                "the environment alone; render water with --method levelmap (or exact)")
    return None


def _coerce_cli_value(v, key="?"):
    if not isinstance(v, str):
        return v
    low = v.lower()
    if low in ("true", "false"):
        return low == "true"
    if low in ("null", "none"):
        return None
    try:
        out = json.loads(v)
    except RecursionError:
        raise SceneError(f"--set value {show(v)} nests lists or objects too deeply; fix the brackets") from None
    except ValueError as e:  # not JSON (a plain word), or an integer beyond Python's int-string limit
        if "digits" in str(e) and v.lstrip("-+").isdigit():
            raise SceneError(f"--set value is a {len(v)}-digit number; give a number within +-1e6") from None
        if v.lstrip()[:1] in ("{", "[", '"'):  # meant as JSON (an object, a list, a quoted string): say it broke
            raise SceneError(f"--set {key}: the value '{printable(v)[:50]}' did not parse as JSON "
                             f"({str(e).split(':')[0]}, character {getattr(e, 'pos', '?')}); fix the JSON "
                             "(double quotes, no trailing comma)") from None
        return v  # a plain word (a mesh name, a path) is a string
    check_depth(out, f"--set value {show(v)}")
    return out


#: An example of a valid value for keys whose default is null and that are not blocks (the --set hint)
_NULL_LEAF_EXAMPLES = {"position": [0.0, 3.0, 0.0], "fit": 1.0, "size": [1.0, 1.0], "name": "glass",
                       "path": "sky.hdr", "bounds": [[-1, -1, -1], [1, 1, 1]]}
#: Keys a block cannot do without, with a valid example: the --set hint for a null block includes them
_REQUIRED = {"volume": {"ior": "vol.npy", "bounds": [[-1, -1, -1], [1, 1, 1]]}}


def _documented(parts):
    """The documented defaults (a dict) of the block at the dotted path ``parts``, or None when it is no block."""
    from .levelmap.knobs import WATER_DEFAULTS, WAVE_DEFAULTS
    from .volumetric.knobs import VOLUME_KEYS

    p = [("#" if x.isdigit() else x) for x in parts]
    items = {"objects": DEFAULT_OBJECT, "receivers": DEFAULT_RECEIVER, "lights": DEFAULT_LIGHT}
    if len(p) == 1:
        if p[0] == "water":
            return WATER_DEFAULTS
        if p[0] == "volume":
            return dict.fromkeys(VOLUME_KEYS)
        d = DEFAULTS.get(p[0])
        return d if isinstance(d, dict) else None
    if len(p) == 2 and p[1] == "#":
        return items.get(p[0])
    if p[:2] == ["water", "waves"] and len(p) == 3:
        return WAVE_DEFAULTS
    if len(p) == 3 and p[1] == "#" and p[0] in items:
        if p[0] == "objects" and p[2] == "deform":
            return DEFAULT_DEFORM
        d = items[p[0]].get(p[2])
        return d if isinstance(d, dict) else None
    return None


def _null_hint(key, full, rest, value):
    """The --set hint for ``key`` run into the null ``full``: a value that is valid when followed."""
    parts = full.split(".")
    doc = _documented(parts)
    shown = value if not isinstance(value, str) else _coerce_cli_value(value, key)
    if doc is None:  # not a block (a position, a fit): the key is set whole, with a value of its own kind
        ex = _NULL_LEAF_EXAMPLES.get(parts[-1])
        eg = f", e.g. --set '{full}={json.dumps(ex)}'" if ex is not None else ""
        return (f"override '{key}': '{full}' is null and holds no keys; set it whole{eg} (docs/oracle.md)")
    block = dict(_REQUIRED.get(full, {}))
    then = ""
    if len(rest) == 1:
        block[rest[0]] = shown
    elif len(rest) == 3 and rest[1] == "0":  # the first item of a list in the block (a wave)
        block[rest[0]] = [{rest[2]: shown}]
    else:  # a key deeper inside (a wave of the water): add the block, then the key is there to set
        then = f", then --set {key}=..."
    text = json.dumps(block, default=str)
    return (f"override '{key}': the scene has no '{full}' block (it is null); add the block itself, e.g. "
            f"--set '{full}={text}'{then} (other keys take their defaults; docs/oracle.md)")


def _brackets_to_dots(key):
    """``objects[0].material.ior`` (how messages name list items) -> ``objects.0.material.ior``."""
    return re.sub(r"\[\s*(\d+)\s*\]", r".\1", key)


def apply_overrides(data, overrides):
    """Set dotted keys, e.g. ``{"imagespace.iterations": 10, "objects.0.material.ior": 1.5}``.

    String values are parsed as JSON where they can be (``"10"`` -> 10,
    ``"[0,0,3]"`` -> a list), so CLI ``--set key=value`` works unchanged; a
    value that starts as JSON (``{``, ``[``, ``"``) and does not parse is refused.
    A list item may be named as error messages name it (``objects[0].fit``).
    A key of a block's documented defaults may be set although the block as
    given leaves it out (``volume.extinction``, ``water.ior``).

    Parameters
    ----------
    data : dict
        A scene dictionary (not modified: a deep copy is changed).
    overrides : dict or None
        Dotted key -> value; list items by index (``objects.0``); a knob
        block's aliases apply to two-part keys.

    Returns
    -------
    dict
        The new scene dictionary.

    Raises
    ------
    SceneError
        An unknown key or a bad list index.
    """
    data = copy.deepcopy(data)
    for key, value in (overrides or {}).items():
        if not isinstance(key, str):
            raise SceneError(f"override {show(key)}: keys are dotted strings, e.g. 'camera.width'")
        parts = _brackets_to_dots(key).split(".")
        key = printable(key)
        if len(parts) == 2:
            parts[0], parts[1] = _alias(parts[0], parts[1])
        node, where = data, ""
        for i, p in enumerate(parts[:-1]):
            if isinstance(node, list):
                node = node[_list_index(node, p, key, where)]
            elif isinstance(node, dict) and p in node:
                if node[p] is None:
                    full = f"{where}.{p}" if where else p
                    raise SceneError(_null_hint(key, full, parts[i + 1:], value))
                node = node[p]
            elif isinstance(node, dict):
                raise SceneError(f"override '{key}': unknown key '{p}'; known keys "
                                 f"{'in ' + repr(where) if where else 'at the top level'}: {', '.join(sorted(node))}")
            else:
                raise SceneError(f"override '{key}': '{where}' is a {type(node).__name__}, not an object; "
                                 f"set '{where}' itself")
            where = f"{where}.{p}" if where else p
        last = parts[-1]
        if isinstance(node, list):
            node[_list_index(node, last, key, where)] = _coerce_cli_value(value, key)
        elif isinstance(node, dict):
            if last not in node:
                doc = _documented(where.split(".")) if where else None
                if doc is not None and last in doc:  # left out of the block as given: its default is documented
                    node[last] = _coerce_cli_value(value, key)
                    continue
                known = sorted(set(node) | set(doc or ()))
                if not known:
                    raise SceneError(f"override '{key}': '{where}' is empty; set it whole, e.g. --set "
                                     f"'{where}={{\"{last}\": ...}}'")
                raise SceneError(f"override '{key}': unknown key '{last}'; known keys here: "
                                 f"{', '.join(known)}")
            node[last] = _coerce_cli_value(value, key)
        else:
            raise SceneError(f"override '{key}': cannot set a key inside a {type(node).__name__}")
    return data


def _list_index(items, p, key, where):
    """``int(p)`` as an index of ``items`` (the list at ``where``), or a SceneError saying how many there are."""
    n = len(items)
    have = f"'{where}' has {n} item{'s' if n != 1 else ''}" + (f" (indices 0 to {n - 1})" if n else "")
    try:
        k = int(p)
    except ValueError:
        raise SceneError(f"override '{key}': '{p}' is not an index; {have}") from None
    if not 0 <= k < n:
        raise SceneError(f"override '{key}': index {k} is out of range; {have}; to add or remove items, "
                         f"set the whole list, e.g. --set '{where}=[...]'") from None
    return k


def _alias(block, key):
    """The current ``(block, key)`` of a knob that moved (``KnobBlock.aliases``), else ``(block, key)``.

    An alias is a key of the same block (``"old": "new"``) or, for a knob that
    moved to another block, a dotted name (``"caustic_map": "caustics.map_size"``).
    """
    b = BLOCKS.get(block)
    new = b.aliases.get(key, key) if b is not None else key
    if "." in new:
        nb, nk = new.split(".", 1)
        return nb, nk
    return block, new


def _unalias(raw):
    """Rename moved knobs in a scene's blocks to their current names (a key keeps its old name as an alias).

    A knob given under its old name in another block moves there; given
    twice (old and new name, or two old names of one knob) with different
    values, it is an error naming both.
    """
    out = dict(raw)
    given_as = {}
    for name, b in BLOCKS.items():
        given = raw.get(name)
        if not (b.aliases and isinstance(given, dict)):
            continue
        out[name] = dict(given)
        for k in given:
            nb, nk = _alias(name, k)
            if (nb, nk) == (name, k):
                continue
            v = out[name].pop(k)
            target = out.get(nb)
            target = dict(target) if isinstance(target, dict) else {}
            if nk in target and target[nk] != v:
                first = given_as.get((nb, nk), f"{nb}.{nk}")
                raise SceneError(f"scene: '{name}.{k}' (now '{nb}.{nk}') is {show(v)} but '{first}' gives "
                                 f"{show(target[nk])}; they are one knob: give it once, as '{nb}.{nk}'")
            target[nk] = v
            given_as[(nb, nk)] = f"{name}.{k}"
            out[nb] = target
    return out


def _resolve(raw, base_dir, callables):
    raw = _unalias(raw)
    data = merge_defaults({k: v for k, v in DEFAULTS.items() if k not in ("objects", "receivers", "lights")},
                  {k: v for k, v in raw.items() if k not in ("objects", "receivers", "lights")}, "")
    for key, default in (("objects", DEFAULT_OBJECT), ("receivers", DEFAULT_RECEIVER), ("lights", DEFAULT_LIGHT)):
        given = raw.get(key, DEFAULTS[key])
        if given is None:
            given = []
        if not isinstance(given, list):
            raise SceneError(f"scene: '{key}' must be a list")
        items = []
        for k, item in enumerate(given):
            item = dict(check_dict(item, f"{key}[{k}]"))
            if key == "objects" and callable(item.get("deform")):
                callables[("deform", k)] = item.pop("deform")
            items.append(merge_defaults(default, item, f"{key}[{k}]"))
        data[key] = items
    for (kind, k), fn in callables.items():
        if kind == "deform":
            data["objects"][k]["deform"] = "<python callable>"
    for block in BLOCKS.values():
        if block.merge is not None:
            block.merge(data)
    return data


class _DuplicateKey(ValueError):
    def __init__(self, key):
        super().__init__(key)
        self.key = key


def _no_duplicate_keys(pairs):
    """``json`` object hook: a dict of ``pairs``, refusing a key given twice (plain JSON keeps the last)."""
    out = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(k)
        out[k] = v
    return out


def load_scene(src=None, overrides=None):
    """Load, default-fill and validate a scene.

    Parameters
    ----------
    src : str, os.PathLike, dict, Scene or None
        A JSON file, a dict in the ``docs/oracle.md`` format, an existing scene,
        or None for the bundled default scene (a glass bunny, IOR 1.2, in a
        checker environment, 512x512).
    overrides : dict, optional
        Dotted keys to set after loading, e.g. ``{"imagespace.iterations": 10}``.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        With a message naming the input, what is wrong and what to do.
    """
    callables = {}
    if isinstance(src, Scene):
        base_dir = src.base_dir
        raw = copy.deepcopy(src.data)
        callables = dict(src.callables)
        for (kind, k) in callables:
            raw["objects"][k]["deform"] = None
    elif src is None:
        raw, base_dir = {}, "."
    elif isinstance(src, dict):
        raw, base_dir = src, "."
    elif not isinstance(src, (str, os.PathLike)):
        raise SceneError(f"load_scene: the scene must be a JSON file path, a dict, a Scene or None, got "
                         f"{type(src).__name__} {show(src)}")
    else:
        path = os.fspath(src)
        if os.path.isdir(path):
            raise SceneError(f"scene file '{path}' is a folder; give the path of a JSON scene file "
                             "(see docs/oracle.md) or omit it to render the default scene")
        if not os.path.isfile(path):
            raise SceneError(f"scene file '{path}' does not exist; give the path of a JSON scene "
                             "(see docs/oracle.md) or omit it to render the default scene")
        try:
            with open(path, encoding="utf-8-sig") as f:  # a byte-order mark (Windows editors) is not an error
                raw = json.load(f, object_pairs_hook=_no_duplicate_keys)
        except _DuplicateKey as e:
            raise SceneError(f"scene file '{path}' gives the key '{e.key}' twice in one object (JSON keeps only "
                             "the last, silently); give each key once") from None
        except UnicodeDecodeError as e:
            raise SceneError(f"scene file '{path}' is not a text (JSON) file ({e.reason}); give a JSON scene") from None
        except json.JSONDecodeError as e:
            raise SceneError(f"scene file '{path}' is not valid JSON: {e}") from None
        except RecursionError:
            raise SceneError(f"scene file '{path}' nests lists or objects too deeply to read; fix the "
                             "brackets") from None
        except ValueError as e:  # an integer beyond Python's int-string limit (4,300 digits)
            raise SceneError(f"scene file '{path}' holds a number that cannot be read ({str(e)[:70]}); give "
                             "numbers within +-1e6") from None
        if not isinstance(raw, dict):
            raise SceneError(f"scene file '{path}' must hold a JSON object at the top level")
        base_dir = os.path.dirname(os.path.abspath(path))
    check_depth(raw, "the scene")
    data = _resolve(raw, base_dir, callables)
    if overrides:
        # a whole block set on the command line (--set 'camera={"width":64}', --set 'objects.0={...}')
        # gets its defaults exactly as the same block in a file would: resolve again after the overrides
        data = _resolve(apply_overrides(data, overrides), base_dir, callables)
    validate(data, base_dir)
    return Scene(data, base_dir, callables)


# The knob blocks register themselves when the graph loads them by name (cheap modules, no kernels);
# then the scene's defaults gain every block.
load_builtin_blocks()
DEFAULTS.update(_block_defaults())
IMAGESPACE_DEFAULTS = BLOCKS["imagespace"].defaults  # for existing imports
