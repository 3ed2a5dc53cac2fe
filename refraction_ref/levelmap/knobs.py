"""The ``levelmap`` and ``water`` knob blocks (Tipprasert 2006), each knob declared once.

Importing this module is cheap (no kernels): scene loading reads it. The
lights of a water scene are checked by :func:`refraction_ref.lights.validate_lights`.

The ``water`` block is absent unless a scene gives it (``"water": null`` is no
water); a given block, and each of its waves, is filled with the declared
defaults by :func:`merge_water`. The height field is
``h(x, z) = height + sum_k a_k sin(2 pi/lambda_k (d_k . (x, z)) + phi_k)``
(:mod:`.water`).

Moved keys (old names keep working as aliases): ``map_size``, ``placement``,
``shadows`` and ``ambient`` are the ``caustics`` block's
(:mod:`refraction_ref.caustics.knobs`: ``caustics.map_size``, ...);
``exact_samples`` and ``exact_seed`` the exact reference's
(``exact.water_samples``, ``exact.photon_seed``).

:func:`levelmap_knobs` builds the one typed value (:class:`LevelMapKnobs`)
the caustics passes take, with the choices resolved here.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.2.1, §4.3, §4.5, §4.7.2, §5.2.1, §6.1, §6.3.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..knobs import Knob, check_knob, declare_block

__all__ = ["merge_water", "LEVELMAP_KNOBS", "WATER_KNOBS", "WAVE_KNOBS", "VARIANTS", "SPACINGS", "CULLINGS",
           "LEVELMAP_DEFAULTS", "WATER_DEFAULTS", "WAVE_DEFAULTS", "max_slope", "check_water_depth", "STEEP_SLOPE",
           "LevelMapKnobs", "levelmap_knobs", "BLOCK", "WATER_BLOCK"]

VARIANTS = ("levelmap", "volumetric", "per_ray")
SPACINGS = ("lattice", "respace")
CULLINGS = ("none", "bounds")

LEVELMAP_KNOBS = (
    Knob("planes", 50,
         "reference **planes** per (receiver, light), the thesis's \"Num Plane\" (Tables 5-1 to 5-5): with "
         "`caustics.placement = component` (or `thesis`) they slice the box into `planes - 1` slices (eq. 4-6: n "
         "slices, n + 1 planes), `D_i = h/2 - s (i - 1)`, `s = h / (planes - 1)` (eqs. 4-7 to 4-9), the first and "
         "last on the box's faces (one plane: at the centre, accepting the whole box); with `tight` at the centres "
         "of `planes` equal slabs. Plane i accepts `[zeta_i - s/2, zeta_i + s/2)` (eq. 4-15)",
         "§4.2.1, eqs. 4-6 to 4-9", kind="int", lo=1, hi=4096),
    Knob("smart_spacing", "respace",
         "smart slicing's planes: \"respace\" (the thesis's) slices each "
         "sub-box anew with `n_i = max(round(hr_i / (2 eps)), 1)` **planes** by eq. 4-22 and §4.2.1's slicing "
         "(texels change; `n_i` counts planes as Table 5-4 does: sphere 3 -> 1, 101 -> 50); \"lattice\" "
         "keeps the normal slicing's planes that meet a sub-box and drops the rest "
         "(no texel changes: Table 5-5's zero by construction)",
         "§4.7.2, eqs. 4-21, 4-22; Table 5-4", kind="choice", choices=SPACINGS, allowed='"respace", "lattice"'),
    Knob("culling", "none",
         "the per-plane work: \"none\" every beam's intersection triangle drawn over the whole map on every plane "
         "drawn, each fragment depth-tested (the thesis's cost, Figs. 4-15, 5-7); \"bounds\" §6.1's bounding-volume "
         "test (beams that cannot reach the box culled, each plane scissored to the texels it accepts). The maps "
         "are identical bit for bit",
         "§4.5, §6.1", kind="choice", choices=CULLINGS),
    Knob("smart_slicing", True, "keep only the planes where light can meet the receiver",
         "§4.7.2, eqs. 4-21, 4-22", kind="bool"),
    Knob("depth_levels", 32, "depth levels of the smart-slicing depth profile", "§4.7.2", kind="int", lo=1,
         hi=65536),
    Knob("variant", "levelmap",
         "the level map (ch. 4); the volumetric slice baseline of Iwasaki et al. 2003 (§5.2.1; unrelated to "
         "`--method volumetric`); or each beam drawn where it hits (§6.3)",
         "ch. 4, §5.2.1, §6.3", kind="choice", choices=VARIANTS),
)

#: the ``levelmap`` block's defaults, in the scene's key order
LEVELMAP_DEFAULTS = {k.name: k.default for k in LEVELMAP_KNOBS}


def _check_size(value, where, data):
    from ..validation import SceneError, check_vector

    size = check_vector(value, 2, where)
    if np.any(size <= 0):
        raise SceneError(f"scene: '{where}' is {value}; both extents must be > 0")


def _check_direction(value, where, data):
    from ..validation import SceneError, check_vector

    d = check_vector(value, 2, where)
    if not np.any(d != 0):
        raise SceneError(f"scene: '{where}' is [0, 0]; give a non-zero [x, z] direction")


WAVE_KNOBS = (
    Knob("amplitude", 0.02, "a_k", "§4.3", kind="float"),
    Knob("wavelength", 0.5, "lambda_k, scene units", "§4.3", kind="float", lo=0.0, lo_open=True),
    Knob("direction", [1.0, 0.0], "d_k, normalised on use", "§4.3", allowed="non-zero [x, z]",
         check=_check_direction),
    Knob("phase", 0.0, "phi_k, radians", "§4.3", kind="float"),
)

#: one wave's defaults (each wave of ``water.waves`` is merged over them)
WAVE_DEFAULTS = {k.name: k.default for k in WAVE_KNOBS}


def _check_waves(waves, where, data):
    """Each wave by :data:`WAVE_KNOBS`, then the waves' summed slope (a height field does not fold)."""
    from ..validation import SceneError

    for k, wave in enumerate(waves):
        for knob in WAVE_KNOBS:
            check_knob(knob, wave[knob.name], f"{where}[{k}].{knob.name}", data)
    slope = max_slope(data["water"])
    if slope >= 1.0:
        raise SceneError(f"scene: the water's waves are too steep: the sum of 2 pi amplitude / wavelength is "
                         f"{slope:.3g} >= 1, where the surface folds over itself and is no height field; "
                         "lower water.waves[k].amplitude or raise the wavelengths")


WATER_KNOBS = (
    Knob("size", [4.0, 4.0], "extents [sx, sz], centred on the origin in x and z", "§4.3",
         allowed="two numbers > 0", check=_check_size),
    Knob("height", 0.0, "mean surface height (world y)", "§4.3", kind="float"),
    Knob("resolution", 128, "quads per side of the water mesh (two triangles each)", "§4.3", kind="int", lo=1,
         hi=4096),
    Knob("ior", 1.33, "index of the water; light enters from `outside_ior`", "§2.6, eq. 2-8", kind="float",
         lo=0.0, lo_open=True),
    Knob("absorption", 0.0, "K, per scene unit: `exp(-K d)` over the distance d in water", "eq. 4-17",
         kind="float", lo=0.0),
    Knob("waves", [], "summed sine waves; [] is a flat surface", "§4.3", allowed="list", check=_check_waves,
         items=WAVE_KNOBS),
)

#: the ``water`` block's defaults (merged only when a scene has one; "water": null means no water)
WATER_DEFAULTS = {k.name: k.default for k in WATER_KNOBS}


def merge_water(data, water_defaults=WATER_DEFAULTS, wave_defaults=WAVE_DEFAULTS):
    """Fill a present ``water`` block (and each wave) with the defaults; idempotent.

    Parameters
    ----------
    data : dict
        The scene being resolved; its ``water`` is replaced by the merged block.
    water_defaults, wave_defaults : dict
        The block's and one wave's defaults.

    Returns
    -------
    dict
        ``data``.
    """
    from ..validation import SceneError, merge_defaults

    w = data.get("water")
    if w is None:
        return data
    w = merge_defaults(water_defaults, w, "water")
    waves = w.get("waves")
    if waves is None:
        waves = []
    if not isinstance(waves, list):
        raise SceneError(f"scene: 'water.waves' must be a list of waves, got {type(waves).__name__}")
    w["waves"] = [merge_defaults(wave_defaults, x, f"water.waves[{k}]") for k, x in enumerate(waves)]
    data["water"] = w
    return data


def _check_camera_above_water(data, base_dir="."):
    """The water methods render a camera above the surface: above the highest crest."""
    from ..validation import SceneError

    w = data["water"]
    top = float(w["height"]) + sum(abs(float(x["amplitude"])) for x in w["waves"])
    eye_y = float(data["camera"]["eye"][1])
    if eye_y <= top:
        raise SceneError(f"scene: camera.eye is at y = {eye_y:g}, not above the water (its crests reach "
                         f"y = {top:g}); the water methods render a camera above the surface: raise camera.eye "
                         "or lower water.height")


#: above this slope (sum of 2 pi a / lambda) the level map's assumptions start to break: beams
#: from neighbouring quads cross before reaching the receivers and the refracted axis of eq. 2-8
#: (flat water) no longer bounds them (Tipprasert 2006, §4.2.1 assumes gentle waves)
STEEP_SLOPE = 0.3


def max_slope(water):
    """The steepest slope the water's waves can reach together: sum of ``2 pi a / lambda``.

    Parameters
    ----------
    water : dict
        The resolved ``water`` block.

    Returns
    -------
    float

    References
    ----------
    Tipprasert (2006), §4.3 (the water surface), §4.2.1 (gentle waves).
    """
    return float(sum(2.0 * np.pi * abs(float(x["amplitude"])) / float(x["wavelength"]) for x in water["waves"]))


def check_water_depth(water, receiver_vertices):
    """Refuse waves that reach a receiver below the water plane (the beams would start inside it).

    Parameters
    ----------
    water : dict
        The resolved ``water`` block.
    receiver_vertices : list of (V, 3) arrays
        Each receiver's world vertices.

    Raises
    ------
    SceneError
        When the sum of the amplitudes is at least the depth from the water
        plane to the highest receiver point below it.
    """
    from ..validation import SceneError

    h = float(water["height"])
    amp = sum(abs(float(x["amplitude"])) for x in water["waves"])
    below = [float(v[:, 1].max()) for v in receiver_vertices if float(v[:, 1].max()) < h]
    if below and amp > 0 and amp >= h - max(below):
        raise SceneError(f"scene: the water's waves (amplitudes summing to {amp:g}) reach down to the highest "
                         f"receiver below the surface (y = {max(below):g}, {h - max(below):g} below water.height "
                         f"= {h:g}); lower water.waves[k].amplitude or the receivers")


class LevelMapKnobs(NamedTuple):
    """The knobs the caustics passes of one scene take, with their choices resolved.

    Attributes
    ----------
    planes : int
        ``levelmap.planes``.
    smart_slicing : bool
        ``levelmap.smart_slicing``.
    depth_levels : int
        ``levelmap.depth_levels``.
    variant : str
        ``levelmap.variant`` (the scene's value: ``"volumetric"`` is the
        thesis's slice-image baseline).
    respace : bool
        ``levelmap.smart_spacing == "respace"``.
    cull : bool
        ``levelmap.culling == "bounds"``.
    placement : str
        ``caustics.placement`` (the plane lattice).
    K : float
        ``water.absorption``.
    """

    planes: int
    smart_slicing: bool
    depth_levels: int
    variant: str
    respace: bool
    cull: bool
    placement: str
    K: float


def levelmap_knobs(levelmap, placement, absorption):
    """The :class:`LevelMapKnobs` of a resolved scene.

    Parameters
    ----------
    levelmap : dict
        The resolved ``levelmap`` block.
    placement : str
        ``caustics.placement``.
    absorption : float
        ``water.absorption``, as the ``water`` stage read it.

    Returns
    -------
    LevelMapKnobs

    References
    ----------
    Tipprasert (2006), §4.2.1, §4.5, §4.7.2, §5.2.1, §6.1, §6.3.
    """
    return LevelMapKnobs(int(levelmap["planes"]), bool(levelmap["smart_slicing"]), int(levelmap["depth_levels"]),
                         levelmap["variant"], levelmap["smart_spacing"] == "respace", levelmap["culling"] == "bounds",
                         placement, float(absorption))


#: keys that moved: the receivers' caustic maps' settings to the ``caustics`` block, the exact water
#: reference's to the ``exact`` block
ALIASES = {"map_size": "caustics.map_size", "placement": "caustics.placement", "shadows": "caustics.shadows",
           "ambient": "caustics.ambient", "exact_samples": "exact.water_samples", "exact_seed": "exact.photon_seed"}

BLOCK = declare_block("levelmap", LEVELMAP_KNOBS, owner="levelmap", aliases=ALIASES)
WATER_BLOCK = declare_block("water", WATER_KNOBS, owner="levelmap", extra=_check_camera_above_water,
                            merge=merge_water, present=False)
