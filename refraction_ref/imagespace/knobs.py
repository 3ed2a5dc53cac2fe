"""The ``imagespace`` knob block (Chaudhari 2008): defaults and validation side by side.

Defaults are the thesis's own settings where it states one (5 binary-search
iterations, §3.6; 256 slices, §3.3; 32 layers, §3.4.2; a 256x256 MIP level
for the search bounds, §3.7; perspective-corrected central differences,
eq. 3.2; additive blending, §3.3: "Since current Direct3D version does not
support logical OR blending, we employ additive blending"; the search ends
at its last probe's texel, §3.6: "Surface normal of the point R3 is then
calculated using the texture coordinate t_P3 of the point P3"; depth images
sampled with hardware (bilinear) filtering, §3.4.2: "hardware filtering can
be easily applied while sampling these textures"). The caustic knobs (``photons``, ``receiver_hit``)
are read by the caustic stages (§4.1) that the image-space method adds when
a scene has lights and receivers; the caustic maps' size and gathering window
are the ``caustics`` block's (:mod:`refraction_ref.caustics.knobs`), and the
old names ``imagespace.caustic_map`` and ``imagespace.gather`` are aliases of
``caustics.map_size`` and ``caustics.gather``.

Importing this module is cheap (no kernels): scene loading reads it.
"""

from __future__ import annotations

from ..graph import KnobBlock, register_block

__all__ = ["IMAGESPACE_DEFAULTS", "CHOICES", "validate_imagespace", "check_memory", "BLOCK"]

#: Every key is a knob; see the table in ``docs/oracle.md``.
IMAGESPACE_DEFAULTS = {
    "iterations": 5,          # binary-search iterations per interface (§3.6)
    "layers": 32,             # depth layers peeled (§3.4.2)
    "slices": 256,            # bitmask slices S (§3.3)
    "bounds": "mip",          # search bound: 'mip' (256x256 MIP + margin, §3.7) | 'global' (exact max)
    "mip_size": 256,          # MIP level used for the reduction (§3.7)
    "bound_margin": 0.01,     # the "small constant", as a fraction of the object's depth range
    "blend": "add",           # 'add' (the thesis's additive blending with carry, §3.3) | 'or'
    "endpoint": "probe",      # 'probe': the surface point at the last probe's texel (§3.6) | 'bracket'
    "filter": "bilinear",     # depth-image sampling: 'bilinear' (hardware filtering, §3.2, §3.4.2) | 'nearest'
    "peel_all": False,        # peel all `layers` whatever the depth complexity (the thesis's fixed passes)
    "depth": "bitmask",       # 'bitmask' | 'float' (A-buffer of exact fragment depths)
    "slicing": "local",       # 'local' per-pixel Zmin/Zmax | 'global' object bounds (§3.3)
    "peeling": "separate",    # 'separate' pass (§3.4.2) | 'lut' on-the-fly look-up tables (§3.4.1)
    "normals": "central",     # 'forward' (eq. 3.1) | 'central' (eq. 3.2) | 'mesh3x3' (Fig. 3.4) | 'cross'
    "delta": 2,               # pixel step of the central differences (eq. 3.2; smoother than 1, Fig. 3.4)
    "exit_threshold": 1.0,    # early termination near the backmost depth, in slices (§3.7)
    "tir": False,             # follow total internal reflection back to preceding layers
    "max_interfaces": 64,     # bounce limit of one ray (TIR reflections included)
    "record": 0,              # interfaces per path kept as stage buffers (stage.trace.path_pos/path_dir)
    "grid": None,             # the voxel grid's x-y size [width, height]; null: the image's (§3.3, §4.1-4.2)
    # caustics (§4.1; see refraction_ref.caustics), used when the scene has lights and receivers
    "photons": 512,           # photon texture per side: one photon per texel of the light's LDI
    "receiver_hit": "eyespace",  # 'eyespace' march in the camera's depth image (Krueger 2006) | 'exact' (Embree)
}

CHOICES = {
    "bounds": ("mip", "global"),
    "blend": ("add", "or"),
    "endpoint": ("probe", "bracket"),
    "filter": ("bilinear", "nearest"),
    "depth": ("bitmask", "float"),
    "slicing": ("local", "global"),
    "peeling": ("separate", "lut"),
    "normals": ("forward", "central", "mesh3x3", "cross"),
    "receiver_hit": ("eyespace", "exact"),
}


def validate_imagespace(data, base_dir="."):
    """Check ``data['imagespace']``; raise :class:`~refraction_ref.scene.SceneError` naming the key."""
    from ..validation import SceneError, check_number

    im = data["imagespace"]
    for key, choices in CHOICES.items():
        if im[key] not in choices:
            raise SceneError(f"scene: 'imagespace.{key}' is {im[key]!r}; choose one of {', '.join(choices)}")
    check_number(im["iterations"], "imagespace.iterations", 0, 64, integer=True)
    check_number(im["layers"], "imagespace.layers", 1, 32, integer=True)
    check_number(im["slices"], "imagespace.slices", 32, 4096, integer=True)
    if im["slices"] % 32:
        raise SceneError(f"scene: imagespace.slices is {im['slices']}; it must be a multiple of 32 "
                         "(slices are stored in 32-bit words)")
    check_number(im["mip_size"], "imagespace.mip_size", 1, integer=True)
    check_number(im["bound_margin"], "imagespace.bound_margin", 0.0)
    check_number(im["delta"], "imagespace.delta", 1, 8, integer=True)
    check_number(im["exit_threshold"], "imagespace.exit_threshold", 0.0)
    check_number(im["max_interfaces"], "imagespace.max_interfaces", 1, 4096, integer=True)
    check_number(im["record"], "imagespace.record", 0, 64, integer=True)
    for key in ("tir", "peel_all"):
        if not isinstance(im[key], bool):
            raise SceneError(f"scene: imagespace.{key} must be true or false, got {im[key]!r}")
    check_number(im["photons"], "imagespace.photons", 1, 8192, integer=True)
    _check_grid(im["grid"], data["camera"])
    return data


def _check_grid(grid, camera):
    """``imagespace.grid``: null, or [width, height] of integers 1..16384 with the image's aspect."""
    from ..validation import SceneError, check_number

    if grid is None:
        return
    if not isinstance(grid, (list, tuple)) or len(grid) != 2:
        raise SceneError(f"scene: 'imagespace.grid' is {grid!r}; give [width, height] (integers) or null "
                         "(the image's size)")
    for k, v in zip(("width", "height"), grid):
        check_number(v, f"imagespace.grid ({k})", 1, 16384, integer=True)
    W, H = int(camera["width"]), int(camera["height"])  # checked before the method blocks
    if int(grid[0]) * H != int(grid[1]) * W:
        raise SceneError(f"scene: 'imagespace.grid' is {list(grid)}, aspect {grid[0]}:{grid[1]}, but the image is "
                         f"{W}x{H}; the grid must keep the image's aspect (same view): give a grid "
                         f"[w, h] with w * {H} == h * {W}, or null for the image's size")


def check_memory(scene):
    """The image-space method's buffers must fit: refuse before any work (a method precondition).

    Per grid texel (``imagespace.grid``, the image's size by default): S/8
    bytes of bitmask and 8 bytes per layer of the LDI; per image pixel the
    trace's outputs and temporaries (about 24 8-byte words).
    """
    from ..validation import SceneError

    from .grid import grid_size

    im = scene.data["imagespace"]
    c = scene.data["camera"]
    W, H = c["width"], c["height"]
    gw, gh = grid_size(im["grid"], W, H)
    # the bitmask and the layers on the grid, the trace's outputs on the image
    need = gw * gh * (im["slices"] // 8 + 8 * im["layers"]) + W * H * 8 * 24
    if need > 16 * 2**30:
        raise SceneError(f"imagespace: {W}x{H} pixels (a {gw}x{gh} grid) with {im['slices']} slices and "
                         f"{im['layers']} layers need about {need / 2**30:.1f} GiB; lower camera.width and "
                         "camera.height, imagespace.grid, imagespace.slices or imagespace.layers")


#: keys that moved to the ``caustics`` block (the caustic maps are a service every method reads)
ALIASES = {"caustic_map": "caustics.map_size", "gather": "caustics.gather"}

BLOCK = register_block(KnobBlock("imagespace", IMAGESPACE_DEFAULTS, validate_imagespace, owner="imagespace",
                                 aliases=ALIASES))
