"""Scene loading and validation (the input half of ``ORACLE.md``).

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
import math
import os
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Scene", "SceneError", "load_scene", "default_scene", "DEFAULTS", "apply_overrides"]


class SceneError(ValueError):
    """A scene that cannot be rendered, with a message saying what to change."""


DEFAULT_CAMERA = {"eye": [0.0, 0.0, 2.6], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                  "fov_y": 30.0, "width": 512, "height": 512, "near": 0.1, "far": 10.0}

DEFAULT_OBJECT = {"mesh": "bunny", "fit": None, "size": None,
                  "transform": {"scale": 1.0, "rotate": [0.0, 0.0, 0.0], "translate": [0.0, 0.0, 0.0]},
                  "material": {"ior": 1.5, "absorption": [0.0, 0.0, 0.0]},
                  "deform": None, "name": None}

DEFAULT_RECEIVER = {"mesh": "plane", "fit": None, "size": [4.0, 4.0],
                    "transform": {"scale": 1.0, "rotate": [0.0, 0.0, 0.0], "translate": [0.0, 0.0, 0.0]},
                    "albedo": [0.8, 0.8, 0.8], "name": None}

DEFAULT_ENVIRONMENT = {"type": "checker", "tiles": 16, "colors": [[0.9, 0.9, 0.9], [0.1, 0.1, 0.1]],
                       "path": None, "intensity": 1.0}

DEFAULT_LIGHT = {"type": "directional", "direction": [0.0, -1.0, 0.0], "position": None,
                 "radiance": [1.0, 1.0, 1.0]}

DEFAULT_DEFORM = {"type": "sine", "amplitude": 0.02, "wavelength": 0.25,
                  "direction": [0.0, 1.0, 0.0], "phase": 0.0}

#: Image-space method (Chaudhari 2008). Every key is a knob; see docs of
#: :mod:`refraction_ref.imagespace`.
IMAGESPACE_DEFAULTS = {
    "iterations": 5,          # binary-search iterations per interface (§3.6)
    "layers": 32,             # depth layers peeled (§3.4.2)
    "slices": 256,            # bitmask slices S (§3.3)
    "bounds": "mip",          # search bound: 'mip' (256x256 MIP + margin, §3.7) | 'global' (exact max)
    "mip_size": 256,          # MIP level used for the reduction (§3.7)
    "bound_margin": 0.01,     # the "small constant", as a fraction of the object's depth range
    "blend": "or",            # 'or' | 'add' (GPU additive blending with carry, §3.3)
    "depth": "bitmask",       # 'bitmask' | 'float' (A-buffer of exact fragment depths)
    "slicing": "local",       # 'local' per-pixel Zmin/Zmax | 'global' object bounds (§3.3)
    "peeling": "separate",    # 'separate' pass (§3.4.2) | 'lut' on-the-fly look-up tables (§3.4.1)
    "normals": "central",     # 'forward' (eq. 3.1) | 'central' (eq. 3.2) | 'mesh3x3' (Fig. 3.4) | 'cross'
    "delta": 2,               # pixel step of the central differences (eq. 3.2; smoother than 1, Fig. 3.4)
    "exit_threshold": 1.0,    # early termination near the backmost depth, in slices (§3.7)
    "tir": False,             # follow total internal reflection back to preceding layers
    "max_interfaces": 64,     # bounce limit of one ray (TIR reflections included)
    # caustics (§4.1; see refraction_ref.caustics), used when the scene has lights and receivers
    "photons": 512,           # photon texture per side: one photon per texel of the light's LDI
    "gather": 7,              # Gaussian gathering window in texels (Wyman & Davis 2006); 1 = none
    "receiver_hit": "eyespace",  # 'eyespace' march in the camera's depth image (Krueger 2006) | 'exact' (Embree)
    "caustic_map": 512,       # texels per side of each receiver's caustic map (exact reference too)
}

EXACT_DEFAULTS = {
    "normals": "smooth",      # 'smooth' interpolated vertex normals | 'face'
    "max_bounces": 64,
    "photons": 1024,          # caustics reference: jittered photons per side of the light's window
    "photon_seed": 0,         # seed of the jitter (the reference is deterministic)
}

#: Water block (merged only when a scene has one; "water": null means no water).
WATER_DEFAULTS = {"size": [4.0, 4.0], "height": 0.0, "resolution": 128, "ior": 1.33, "absorption": 0.0,
                  "waves": []}
WAVE_DEFAULTS = {"amplitude": 0.02, "wavelength": 0.5, "direction": [1.0, 0.0], "phase": 0.0}

DEFAULTS = {
    "camera": DEFAULT_CAMERA,
    "objects": [dict(DEFAULT_OBJECT, fit=1.0, material={"ior": 1.2, "absorption": [0.0, 0.0, 0.0]})],
    "outside_ior": 1.0,
    "environment": DEFAULT_ENVIRONMENT,
    "lights": [DEFAULT_LIGHT],
    "receivers": [],          # none by default: caustics run when a scene has receivers and lights
    "water": None,
    "volume": None,
    "imagespace": IMAGESPACE_DEFAULTS,
    "volumetric": {           # Sun et al. 2008; see refraction_ref.volumetric.knobs
        "resolution": 128, "photons": 1024, "ds_min": 1.0, "ds_max": 8.0, "eps": 0.005, "eps2": 0.02,
        "integrator": "euler", "phase_g": 0.0, "scattering": 0.2, "absorption": 0.0,
        "supersample": 4, "blur": 9, "padding": 6, "bounds": None, "max_steps": 0,
        "min_radiance": 1e-3, "stop_fraction": 1e-3, "stiff": 0.25,
    },
    "levelmap": {             # Tipprasert 2006; see refraction_ref.levelmap.knobs
        "planes": 50, "smart_slicing": True, "depth_levels": 32, "variant": "levelmap",
        "map_size": 512, "shadows": True, "ambient": 0.1, "exact_samples": 2048, "exact_seed": 0,
    },
    "exact": EXACT_DEFAULTS,
}

_CHOICES = {
    ("imagespace", "bounds"): ("mip", "global"),
    ("imagespace", "blend"): ("or", "add"),
    ("imagespace", "depth"): ("bitmask", "float"),
    ("imagespace", "slicing"): ("local", "global"),
    ("imagespace", "peeling"): ("separate", "lut"),
    ("imagespace", "normals"): ("forward", "central", "mesh3x3", "cross"),
    ("exact", "normals"): ("smooth", "face"),
    ("imagespace", "receiver_hit"): ("eyespace", "exact"),
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
        return p if os.path.isabs(p) else os.path.normpath(os.path.join(self.base_dir, p))

    def copy(self):
        return Scene(copy.deepcopy(self.data), self.base_dir, dict(self.callables))


def default_scene():
    """The bundled default scene: a glass bunny (IOR 1.2) in a checker environment, 512x512."""
    return load_scene({})


def _merge(default, given, path):
    """Merge ``given`` over ``default``; unknown keys are errors naming the key."""
    if default is None or not isinstance(default, dict) or not default:
        return copy.deepcopy(given)
    if given is None:
        return copy.deepcopy(default)
    if not isinstance(given, dict):
        raise SceneError(f"scene: '{path}' must be an object (a JSON dict), got {type(given).__name__}")
    out = copy.deepcopy(default)
    for k, v in given.items():
        if k not in default:
            name = f"{path}.{k}" if path else k
            raise SceneError(f"scene: unknown key '{name}'; known keys here: {', '.join(sorted(default))}")
        sub = default[k]
        if isinstance(sub, dict) and sub and v is not None:
            out[k] = _merge(sub, v, f"{path}.{k}" if path else k)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _vec(x, n, where, finite=True):
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"scene: '{where}' must be a list of {n} numbers, got {x!r}") from None
    if a.shape != (n,):
        raise SceneError(f"scene: '{where}' must be a list of {n} numbers, got {x!r}")
    if finite and not np.all(np.isfinite(a)):
        raise SceneError(f"scene: '{where}' holds a NaN or infinite value ({x!r}); give finite numbers")
    return a


def _num(x, where, lo=None, hi=None, lo_open=False, integer=False):
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise SceneError(f"scene: '{where}' must be a number, got {x!r}")
    if not math.isfinite(float(x)):
        raise SceneError(f"scene: '{where}' is {x!r}; give a finite number")
    if integer and int(x) != x:
        raise SceneError(f"scene: '{where}' must be a whole number, got {x!r}")
    if lo is not None and (x <= lo if lo_open else x < lo):
        raise SceneError(f"scene: '{where}' is {x!r}; it must be {'>' if lo_open else '>='} {lo}")
    if hi is not None and x > hi:
        raise SceneError(f"scene: '{where}' is {x!r}; it must be <= {hi}")
    return x


def _check_mesh_ref(mesh, where, base_dir):
    from .meshes import BUILTIN_MESHES

    if callable(mesh) or isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        return
    if not isinstance(mesh, str):
        raise SceneError(f"scene: '{where}' must be a built-in mesh name ({', '.join(BUILTIN_MESHES)}) "
                         f"or a path to a mesh file, got {mesh!r}")
    if mesh in BUILTIN_MESHES:
        return
    p = mesh if os.path.isabs(mesh) else os.path.join(base_dir, mesh)
    if not os.path.isfile(p):
        raise SceneError(f"scene: '{where}' names '{mesh}', which is neither a built-in mesh "
                         f"({', '.join(BUILTIN_MESHES)}) nor an existing file (looked for {p}); "
                         "fix the path or use a built-in name")


def _check_transform(t, where):
    _num(t["scale"], f"{where}.scale", 0.0, lo_open=True)
    _vec(t["rotate"], 3, f"{where}.rotate")
    _vec(t["translate"], 3, f"{where}.translate")


def validate(data, base_dir="."):
    """Check a merged scene; raise :class:`SceneError` on the first problem."""
    c = data["camera"]
    eye = _vec(c["eye"], 3, "camera.eye")
    target = _vec(c["target"], 3, "camera.target")
    up = _vec(c["up"], 3, "camera.up")
    if np.linalg.norm(target - eye) == 0:
        raise SceneError("scene: camera.eye and camera.target coincide; move the target")
    if np.linalg.norm(np.cross(target - eye, up)) < 1e-12 * np.linalg.norm(target - eye) * max(np.linalg.norm(up), 1e-300):
        raise SceneError("scene: camera.up is parallel to the viewing direction; choose another up vector")
    _num(c["fov_y"], "camera.fov_y", 0.0, 179.0, lo_open=True)
    _num(c["width"], "camera.width", 1, integer=True)
    _num(c["height"], "camera.height", 1, integer=True)
    _num(c["near"], "camera.near", 0.0, lo_open=True)
    _num(c["far"], "camera.far", c["near"], lo_open=True)
    if c["width"] * c["height"] > 16384 * 16384:
        raise SceneError(f"scene: camera {c['width']}x{c['height']} is too large for memory; "
                         "use at most 16384x16384 pixels")
    _num(data["outside_ior"], "outside_ior", 0.0, lo_open=True)
    if not isinstance(data["objects"], list):
        raise SceneError("scene: 'objects' must be a list")
    for k, o in enumerate(data["objects"]):
        w = f"objects[{k}]"
        _check_mesh_ref(o["mesh"], f"{w}.mesh", base_dir)
        if o["fit"] is not None:
            _num(o["fit"], f"{w}.fit", 0.0, lo_open=True)
        _check_transform(o["transform"], f"{w}.transform")
        m = o["material"]
        _num(m["ior"], f"{w}.material.ior", 0.0, lo_open=True)
        a = _vec(m["absorption"], 3, f"{w}.material.absorption")
        if np.any(a < 0):
            raise SceneError(f"scene: '{w}.material.absorption' is {m['absorption']}; "
                             "absorption coefficients must be >= 0")
        if o["deform"] is not None and not callable(o["deform"]) and o["deform"] != "<python callable>":
            o["deform"] = _merge(DEFAULT_DEFORM, o["deform"], f"{w}.deform")
            d = o["deform"]
            if d["type"] != "sine":
                raise SceneError(f"scene: '{w}.deform.type' is {d['type']!r}; only 'sine' is known")
            _num(d["amplitude"], f"{w}.deform.amplitude")
            _num(d["wavelength"], f"{w}.deform.wavelength", 0.0, lo_open=True)
            _vec(d["direction"], 3, f"{w}.deform.direction")
            _num(d["phase"], f"{w}.deform.phase")
    for k, r in enumerate(data["receivers"] or []):
        _check_mesh_ref(r["mesh"], f"receivers[{k}].mesh", base_dir)
        _check_transform(r["transform"], f"receivers[{k}].transform")
    env = data["environment"]
    if env["type"] not in ("checker", "latlong", "constant"):
        raise SceneError(f"scene: environment.type is {env['type']!r}; use 'checker', 'latlong' or 'constant'")
    if env["type"] == "checker":
        _num(env["tiles"], "environment.tiles", 1, integer=True)
    if env["type"] == "latlong":
        if not env["path"]:
            raise SceneError("scene: environment.type 'latlong' needs environment.path (an image file)")
        p = env["path"] if os.path.isabs(env["path"]) else os.path.join(base_dir, env["path"])
        if not os.path.isfile(p):
            raise SceneError(f"scene: environment.path '{env['path']}' does not exist (looked for {p})")
    for (blk, key), choices in _CHOICES.items():
        if data[blk][key] not in choices:
            raise SceneError(f"scene: '{blk}.{key}' is {data[blk][key]!r}; choose one of {', '.join(choices)}")
    im = data["imagespace"]
    _num(im["iterations"], "imagespace.iterations", 0, 64, integer=True)
    _num(im["layers"], "imagespace.layers", 1, 32, integer=True)
    _num(im["slices"], "imagespace.slices", 32, 4096, integer=True)
    if im["slices"] % 32:
        raise SceneError(f"scene: imagespace.slices is {im['slices']}; it must be a multiple of 32 "
                         "(slices are stored in 32-bit words)")
    _num(im["mip_size"], "imagespace.mip_size", 1, integer=True)
    _num(im["bound_margin"], "imagespace.bound_margin", 0.0)
    _num(im["delta"], "imagespace.delta", 1, 8, integer=True)
    _num(im["exit_threshold"], "imagespace.exit_threshold", 0.0)
    _num(im["max_interfaces"], "imagespace.max_interfaces", 1, 4096, integer=True)
    if not isinstance(im["tir"], bool):
        raise SceneError(f"scene: imagespace.tir must be true or false, got {im['tir']!r}")
    _num(data["exact"]["max_bounces"], "exact.max_bounces", 1, 100000, integer=True)
    _num(im["photons"], "imagespace.photons", 1, 8192, integer=True)
    _num(im["gather"], "imagespace.gather", 1, 63, integer=True)
    if im["gather"] % 2 == 0:
        raise SceneError(f"scene: imagespace.gather is {im['gather']}; the gathering window must be odd "
                         "(a centred square of texels, e.g. 7), or 1 for no gathering")
    _num(im["caustic_map"], "imagespace.caustic_map", 1, 8192, integer=True)
    _num(data["exact"]["photons"], "exact.photons", 1, 16384, integer=True)
    _num(data["exact"]["photon_seed"], "exact.photon_seed", 0, integer=True)
    for k, lt in enumerate(data["lights"] or [] if data.get("water") is None else []):  # water: levelmap checks
        if lt["type"] not in ("directional", "point"):
            raise SceneError(f"scene: 'lights[{k}].type' is {lt['type']!r}; use 'directional' or 'point'")
        if lt["type"] == "directional":
            d = _vec(lt["direction"], 3, f"lights[{k}].direction")
            if not np.linalg.norm(d) > 0:
                raise SceneError(f"scene: 'lights[{k}].direction' is zero; give the direction the light travels")
        else:
            if lt["position"] is None:
                raise SceneError(f"scene: 'lights[{k}]' is a point light without 'position'; give its position")
            _vec(lt["position"], 3, f"lights[{k}].position")
        rad = _vec(lt["radiance"], 3, f"lights[{k}].radiance")
        if np.any(rad < 0):
            raise SceneError(f"scene: 'lights[{k}].radiance' is {lt['radiance']}; it must be >= 0")
    for k, r in enumerate(data["receivers"] or []):
        alb = _vec(r["albedo"], 3, f"receivers[{k}].albedo")
        if np.any(alb < 0):
            raise SceneError(f"scene: 'receivers[{k}].albedo' is {r['albedo']}; it must be >= 0")
    W, H = c["width"], c["height"]
    need = W * H * (im["slices"] // 8 + 8 * (im["layers"] + 24))
    if need > 16 * 2**30:
        raise SceneError(f"scene: {W}x{H} with {im['slices']} slices and {im['layers']} layers needs "
                         f"about {need / 2**30:.1f} GiB; lower the resolution")
    from .volumetric.knobs import validate_volumetric  # volumetric knobs and the 'volume' block

    validate_volumetric(data, base_dir)
    from .levelmap.knobs import merge_water, validate_levelmap  # water block and level-map knobs

    validate_levelmap(merge_water(data, WATER_DEFAULTS, WAVE_DEFAULTS))
    return data


def _coerce_cli_value(v):
    if not isinstance(v, str):
        return v
    low = v.lower()
    if low in ("true", "false"):
        return low == "true"
    if low in ("null", "none"):
        return None
    try:
        return json.loads(v)
    except json.JSONDecodeError:
        return v


def apply_overrides(data, overrides):
    """Set dotted keys, e.g. ``{"imagespace.iterations": 10, "objects.0.material.ior": 1.5}``.

    String values are parsed as JSON where they can be (``"10"`` -> 10,
    ``"[0,0,3]"`` -> a list), so CLI ``--set key=value`` works unchanged.
    """
    data = copy.deepcopy(data)
    for key, value in (overrides or {}).items():
        parts = key.split(".")
        node = data
        for p in parts[:-1]:
            if isinstance(node, list):
                try:
                    node = node[int(p)]
                except (ValueError, IndexError):
                    raise SceneError(f"override '{key}': '{p}' is not a valid index") from None
            elif isinstance(node, dict) and p in node:
                if node[p] is None:
                    node[p] = {}
                node = node[p]
            else:
                raise SceneError(f"override '{key}': unknown key '{p}'")
        last = parts[-1]
        if isinstance(node, list):
            try:
                node[int(last)] = _coerce_cli_value(value)
            except (ValueError, IndexError):
                raise SceneError(f"override '{key}': '{last}' is not a valid index") from None
        elif isinstance(node, dict):
            if last not in node:
                raise SceneError(f"override '{key}': unknown key '{last}'; known keys here: "
                                 f"{', '.join(sorted(node))}")
            node[last] = _coerce_cli_value(value)
        else:
            raise SceneError(f"override '{key}': cannot set a key inside a {type(node).__name__}")
    return data


def _resolve(raw, base_dir, callables):
    data = _merge({k: v for k, v in DEFAULTS.items() if k not in ("objects", "receivers", "lights")},
                  {k: v for k, v in raw.items() if k not in ("objects", "receivers", "lights")}, "")
    for key, default in (("objects", DEFAULT_OBJECT), ("receivers", DEFAULT_RECEIVER), ("lights", DEFAULT_LIGHT)):
        given = raw.get(key, DEFAULTS[key])
        if given is None:
            given = []
        if not isinstance(given, list):
            raise SceneError(f"scene: '{key}' must be a list")
        items = []
        for k, item in enumerate(given):
            item = dict(item)
            if key == "objects" and callable(item.get("deform")):
                callables[("deform", k)] = item.pop("deform")
            items.append(_merge(default, item, f"{key}[{k}]"))
        data[key] = items
    for (kind, k), fn in callables.items():
        if kind == "deform":
            data["objects"][k]["deform"] = "<python callable>"
    if data.get("water") is not None:
        from .levelmap.knobs import merge_water

        merge_water(data, WATER_DEFAULTS, WAVE_DEFAULTS)
    return data


def load_scene(src=None, overrides=None):
    """Load, default-fill and validate a scene.

    Parameters
    ----------
    src : str, os.PathLike, dict, Scene or None
        A JSON file, a dict in the ``ORACLE.md`` format, an existing scene,
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
    else:
        path = os.fspath(src)
        if not os.path.isfile(path):
            raise SceneError(f"scene file '{path}' does not exist; give the path of a JSON scene "
                             "(see ORACLE.md) or omit it to render the default scene")
        try:
            with open(path) as f:
                raw = json.load(f)
        except json.JSONDecodeError as e:
            raise SceneError(f"scene file '{path}' is not valid JSON: {e}") from None
        if not isinstance(raw, dict):
            raise SceneError(f"scene file '{path}' must hold a JSON object at the top level")
        base_dir = os.path.dirname(os.path.abspath(path))
    data = _resolve(raw, base_dir, callables)
    if overrides:
        data = apply_overrides(data, overrides)
    validate(data, base_dir)
    return Scene(data, base_dir, callables)
