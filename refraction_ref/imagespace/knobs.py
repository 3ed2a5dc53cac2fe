"""The ``imagespace`` knob block (Chaudhari 2008), declared once, and :class:`TraceKnobs`.

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
names ``imagespace.caustic_map`` and ``imagespace.gather`` are aliases of
``caustics.map_size`` and ``caustics.gather``.

Each knob is declared once (:class:`~refraction_ref.knobs.Knob`): the block's
defaults (:data:`IMAGESPACE_DEFAULTS`), its checks and its table in
docs/oracle.md derive from :data:`KNOBS`. The trace takes the checked block
as one typed value, :class:`TraceKnobs` (:func:`trace_knobs`), its choices
resolved here to the kernels' codes (:data:`CODES`).

Importing this module is cheap (no kernels): scene loading reads it.

References
----------
.. [1] docs/oracle.md, "### ``imagespace`` block" (the table generated from :data:`KNOBS`).
"""

from __future__ import annotations

from typing import NamedTuple

from ..knobs import Knob, check_knob, declare_block

__all__ = ["KNOBS", "IMAGESPACE_DEFAULTS", "CHOICES", "CODES", "TRACE_KNOBS", "validate_imagespace", "check_memory",
           "BLOCK", "TraceKnobs", "trace_knobs"]


def _check_slices(value, where, data):
    """``imagespace.slices``: a multiple of 32 (the bitmask's 32-bit words)."""
    from ..validation import SceneError

    if int(value) % 32:
        raise SceneError(f"scene: {where} is {value}; it must be a multiple of 32 "
                         "(slices are stored in 32-bit words)")


def _check_grid(grid, where, data):
    """``imagespace.grid``: null, or [width, height] of integers 1..16384 with the image's aspect."""
    from ..validation import SceneError, check_number

    if grid is None:
        return
    if not isinstance(grid, (list, tuple)) or len(grid) != 2:
        raise SceneError(f"scene: '{where}' is {grid!r}; give [width, height] (integers) or null "
                         "(the image's size)")
    for k, v in zip(("width", "height"), grid):
        check_number(v, f"{where} ({k})", 1, 16384, integer=True)
    camera = data["camera"]
    W, H = int(camera["width"]), int(camera["height"])  # checked before the method blocks
    if int(grid[0]) * H != int(grid[1]) * W:
        raise SceneError(f"scene: '{where}' is {list(grid)}, aspect {grid[0]}:{grid[1]}, but the image is "
                         f"{W}x{H}; the grid must keep the image's aspect (same view): give a grid "
                         f"[w, h] with w * {H} == h * {W}, or null for the image's size")


#: the ``allowed`` cell of ``grid``
GRID_ALLOWED = ("null, or [width, height] of integers 1..16384 with the image's aspect "
                "(`width * camera.height == height * camera.width`)")

#: the block's knobs, in the order of its table (docs/oracle.md)
KNOBS = (
    Knob("iterations", 5,
         "binary-search iterations per interface", "§3.6",
         kind="int", lo=0, hi=64,
         summary="binary-search iterations per interface (§3.6)"),
    Knob("layers", 32,
         "layer limit; never more are peeled than the depth complexity (unless `peel_all`)", "§3.4.2",
         kind="int", lo=1, hi=32,
         summary="layer limit (§3.4.2); never more are peeled than the scene's depth complexity (unless `peel_all`)"),
    Knob("slices", 256,
         "bitmask slices S per pixel", "§3.3",
         kind="int", lo=32, hi=4096, allowed="integer 32..4096, multiple of 32", check=_check_slices,
         summary="bitmask slices S (§3.3), a multiple of 32"),
    Knob("bounds", "mip",
         "search bound: max over a MIP level + margin, or exact global maxima", "§3.7",
         kind="choice", choices=("mip", "global"),
         summary="search bound: max of the 256x256 MIP level + margin (§3.7), or `global` exact maxima"),
    Knob("mip_size", 256,
         "MIP level (texels per side) of the reduction", "§3.7",
         kind="int", lo=1),
    Knob("bound_margin", 0.01,
         "the \"small constant\" added to the bound, as a fraction of the object's depth range", "§3.7",
         kind="float", lo=0.0),
    Knob("blend", "add",
         "bitmask blending: \"add\" the thesis's additive blending, a 32-bit add per word, so two fragments in "
         "one slice carry into the next bit and a carry out of bit 31 is lost (\"Since current Direct3D version"
         " does not support logical OR blending, we employ additive blending\", §3.3); \"or\" a logical OR", "§3.3",
         kind="choice", choices=("add", "or"),
         summary="`add`: the thesis's additive blending with carry (§3.3: Direct3D 10 has no logical-OR blend), or "
                 "`or`"),
    Knob("endpoint", "probe",
         "where each interface's binary search ends: \"probe\" the thesis's R_n, the surface point at the last "
         "probe's texel (the line of sight through the last probe P_n at the layer's sampled depth there; "
         "\"Surface normal of the point R3 is then calculated using the texture coordinate t_P3 of the point "
         "P3\", §3.6), the search failing only where that texel lacks the layer; \"bracket\" the midpoint of the "
         "final bracket (an untested point), testing E when no probe crossed the layer and moving to the "
         "bracket's far end where the midpoint's texel lacks it", "§3.6",
         kind="choice", choices=("probe", "bracket"),
         summary="where a search ends: `probe`, the surface point at the last probe's texel (§3.6), or `bracket`, the "
                 "midpoint of the final bracket with two fallbacks"),
    Knob("filter", "bilinear",
         "depth-image sampling in the search, at the hit and for its normal: \"bilinear\" the hardware filtering"
         " of §3.4.2 (\"hardware filtering can be easily applied while sampling these textures\"), over the four"
         " texels around the position when all four hold the layer, the nearest texel where any of them lacks "
         "it; the normal is the bilinear blend of those four texels' normals (each by the `normals` rule), "
         "renormalised; \"nearest\" the texel under the position and its normal", "§3.2, §3.4.2",
         kind="choice", choices=("bilinear", "nearest"),
         summary="depth-image sampling: `bilinear`, the thesis's hardware filtering (§3.4.2), nearest where one of the"
                 " four texels lacks the layer; or `nearest`"),
    Knob("peel_all", False,
         "peel all `layers` layers whatever the scene's depth complexity (the layers beyond it are `+inf` "
         "everywhere), as the thesis's single pass writes all 32 channels of its render targets: the thesis's "
         "cost (Table 4.1's 16- and 32-layer columns); no output changes, only `stage.peel.ldi` (and "
         "`stage.reduce`'s bounds, `-inf`/`+inf` for the absent layers)", "§3.4.2",
         kind="bool",
         summary="peel all `layers` whatever the depth complexity (the thesis's fixed passes; Table 4.1's cost); no "
                 "output changes"),
    Knob("depth", "bitmask",
         "layer depths from the bitmask, or exact fragment depths (A-buffer; beyond the thesis)", "§3.3",
         kind="choice", choices=("bitmask", "float"),
         summary="`bitmask`, or `float`: exact fragment depths (A-buffer)"),
    Knob("slicing", "local",
         "slices span each pixel's Zmin..Zmax, or the object's global bounds", "§3.3",
         kind="choice", choices=("local", "global"),
         summary="per-pixel Zmin/Zmax, or `global` object bounds (§3.3)"),
    Knob("peeling", "separate",
         "separate peeling pass, or on the fly with 8-bit look-up tables", "§3.4.2, §3.4.1",
         kind="choice", choices=("separate", "lut"),
         summary="separate pass (§3.4.2), or `lut`: on the fly with 8-bit tables (§3.4.1)"),
    Knob("normals", "central",
         "normal estimate from the depth image: eq. 3.1, eq. 3.2, Fig. 3.4, or the cross product of the same "
         "four unprojected neighbours (beyond the thesis)", "§3.5",
         kind="choice", choices=("forward", "central", "mesh3x3", "cross"),
         summary="`forward` (eq. 3.1), `central` (eq. 3.2), `mesh3x3` (Fig. 3.4), `cross` (beyond the thesis: the "
                 "cross product of the same four unprojected neighbours)"),
    Knob("delta", 2,
         "pixel step of the central differences", "eq. 3.2",
         kind="int", lo=1, hi=8,
         summary="step of the central differences (eq. 3.2)"),
    Knob("exit_threshold", 1.0,
         "early termination within this many slices of the backmost depth", "§3.7",
         kind="float", lo=0.0,
         summary="early termination within this many slices of the backmost depth (§3.7)"),
    Knob("tir", False,
         "follow total internal reflection with backward searches (beyond the thesis; sketched in §4.3)", "§4.3",
         kind="bool",
         summary="follow total internal reflection with backward searches (beyond the thesis)"),
    Knob("max_interfaces", 64,
         "event limit per ray (refractions + reflections)",
         kind="int", lo=1, hi=4096),
    Knob("photons", 512,
         "photon texture side per light: one photon per texel of the light's layered depth images", "§4.1",
         kind="int", lo=1, hi=8192),
    Knob("receiver_hit", "eyespace",
         "photon-receiver intersection: march in the camera's depth image (Krüger 2006), or Embree", "§4.1",
         kind="choice", choices=("eyespace", "exact")),
    Knob("record", 0,
         "interfaces per path recorded as the `trace` stage buffers `path_pos`, `path_dir` (H, W, K, 3) with K"
         " = `record` (Stage buffers; kept with `--keep trace`); 0 records none. No other output changes",
         kind="int", lo=0, hi=64,
         summary="interfaces per path kept as stage buffers `stage.trace.path_pos` / `path_dir` (for backend authors; "
                 "`--keep trace`)"),
    Knob("grid", None,
         "the voxel grid's x-y size: the size of the bitmask and layered-depth textures, apart from the "
         "image's (the thesis renders a 512x512 viewport with 256x256 or 512x512 textures); null is the "
         "image's size. The `minmax`, `voxelize`, `peel`, `reduce` and `normals` passes run on a camera with "
         "the image's view (same field of view and aspect) and the grid's pixel count; the trace still casts "
         "one ray per image pixel and samples the layers and bounds at the ray's position in grid coordinates "
         "(the projection of Conventions with the grid's W, H): a primary ray's first hit is layer 0 sampled "
         "(`filter`) at its pixel centre's grid position `((i + 0.5) Hg / H, (j + 0.5) Wg / W)`. "
         "`depth_complexity` (and the caustic final pass's front depth) reads the grid texel under each pixel "
         "centre. Another aspect is refused", "§3.3, §4.1, §4.2",
         nullable=True, allowed=GRID_ALLOWED, check=_check_grid,
         summary="the voxel grid's x-y size `[width, height]` (the bitmask and layer textures; the thesis renders a "
                 "512x512 viewport with a 256 or 512 grid, §3.3, §4.1-4.2); null: the image's size. Same aspect "
                 "as the image; one ray per image pixel, sampled on the grid"),
)

#: keys that moved to the ``caustics`` block (the caustic maps are a service every method reads)
ALIASES = {"caustic_map": "caustics.map_size", "gather": "caustics.gather"}

BLOCK = declare_block("imagespace", KNOBS, owner="imagespace", aliases=ALIASES)

#: the block's defaults, from :data:`KNOBS`
IMAGESPACE_DEFAULTS = BLOCK.defaults

_RECORD = next(k for k in KNOBS if k.name == "record")

#: the block's checks, from :data:`KNOBS`: ``validate_imagespace(data, base_dir=".")`` returns ``data``
#: or raises :class:`~refraction_ref.validation.SceneError` naming the first key out of range
validate_imagespace = BLOCK.validate

#: the accepted values of each choice knob, from :data:`KNOBS`
CHOICES = {k.name: k.choices for k in KNOBS if k.kind == "choice"}

#: the kernels' integer code of each choice the trace reads
CODES = {
    "normals": {"forward": 0, "central": 1, "mesh3x3": 2, "cross": 3},  # eq. 3.1, eq. 3.2, Fig. 3.4, cross
    "filter": {"nearest": 0, "bilinear": 1},  # the texel under a position, or hardware filtering (§3.4.2)
    "endpoint": {"probe": 0, "bracket": 1},  # the last probe's surface point (§3.6), or the final bracket's midpoint
}

#: the knobs the trace reads (:func:`trace_knobs`), besides ``record``
TRACE_KNOBS = ("iterations", "normals", "delta", "tir", "max_interfaces", "layers", "exit_threshold", "slices",
               "endpoint", "filter")


class TraceKnobs(NamedTuple):
    """The ``imagespace`` knobs of one trace as the kernels take them (:func:`trace_knobs`).

    Attributes
    ----------
    iterations : int
        Binary-search iterations per interface (§3.6).
    normals : int
        The normal rule, a :data:`CODES` ``["normals"]`` code (§3.5).
    delta : int
        Pixel step of the differences (eq. 3.2).
    tir : bool
        Follow total internal reflection with backward searches (§4.3).
    max_interfaces : int
        Event limit per ray (refractions plus reflections).
    layer_limit : int
        ``imagespace.layers``: a search for a layer at or beyond it stops the ray (``LIMIT``).
    record : int
        Events kept per path in ``path_pos``, ``path_dir`` (0: none).
    endpoint : int
        Where a search ends, a :data:`CODES` ``["endpoint"]`` code (§3.6).
    filter : int
        Depth-image sampling, a :data:`CODES` ``["filter"]`` code (§3.4.2).
    exit_threshold : float
        Early termination within this many slices of the backmost depth (§3.7).
    slices : int
        Slices S of each pixel's depth range, the unit of ``exit_threshold`` (§3.3).
    """

    iterations: int
    normals: int
    delta: int
    tir: bool
    max_interfaces: int
    layer_limit: int
    record: int
    endpoint: int
    filter: int
    exit_threshold: float
    slices: int


def trace_knobs(block, record=0):
    """The trace's knobs of a checked ``imagespace`` block as one :class:`TraceKnobs`.

    Parameters
    ----------
    block : mapping
        The ``imagespace`` block (``Scene.data["imagespace"]``, or any mapping
        holding :data:`TRACE_KNOBS`); only those keys are read.
    record : int, default 0
        Events kept per path (``imagespace.record`` for the eye's trace; a
        light's photon trace keeps none), checked as ``imagespace.record`` is.

    Returns
    -------
    TraceKnobs
        Numbers as the kernels take them, choices as :data:`CODES`.

    References
    ----------
    .. [1] docs/oracle.md, "### ``imagespace`` block".
    """
    check_knob(_RECORD, record, "imagespace.record")
    return TraceKnobs(int(block["iterations"]), CODES["normals"][block["normals"]], int(block["delta"]),
                      bool(block["tir"]), int(block["max_interfaces"]), int(block["layers"]), int(record),
                      CODES["endpoint"][block["endpoint"]], CODES["filter"][block["filter"]],
                      float(block["exit_threshold"]), int(block["slices"]))


def check_memory(scene):
    """The image-space method's buffers must fit: refuse before any work (a method precondition).

    Per grid texel (``imagespace.grid``, the image's size by default): S/8
    bytes of bitmask and 8 bytes per layer of the LDI; per image pixel the
    trace's outputs and temporaries (about 24 8-byte words).

    Parameters
    ----------
    scene : Scene
        A validated scene.

    Raises
    ------
    SceneError
        When the buffers would need more than 16 GiB.
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
