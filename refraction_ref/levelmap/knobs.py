"""The ``levelmap`` and ``water`` knob blocks (Tipprasert 2006): defaults and validation side by side.

Importing this module is cheap (no kernels): scene loading reads it. The
lights of a water scene are checked by :func:`refraction_ref.lights.validate_lights`.

Water fields: ``size`` [sx, sz] (> 0, centred on the origin in x and z),
``height``, ``resolution`` (quads per side), ``ior`` (> 0; above the
outside's for light to enter), ``absorption`` K (>= 0, per unit length),
``waves``: a list of {``amplitude``, ``wavelength`` (> 0), ``direction``
[x, z] (non-zero, normalised on use), ``phase``}.

Level-map knobs: ``planes`` (1..4096), ``smart_slicing`` (bool),
``depth_levels`` (1..65536), ``variant`` (``levelmap`` | ``volumetric`` |
``per_ray``), ``smart_spacing`` (``respace`` | ``lattice``: smart slicing re-spaces
``n_i`` planes in each sub-box by eq. 4-22, the thesis's and the default since
contract_version 5, or drops the normal slicing's empty planes), ``culling`` (``none`` | ``bounds``: every intersection triangle over
the whole map on every plane, the thesis's cost, or §6.1's bounding-volume
test and a scissor per plane; the same maps).

Moved keys (old names keep working as aliases): ``map_size``, ``placement``,
``shadows`` and ``ambient`` are the ``caustics`` block's
(:mod:`refraction_ref.caustics.knobs`: ``caustics.map_size``, ...);
``exact_samples`` and ``exact_seed`` the exact reference's
(``exact.water_samples``, ``exact.photon_seed``).
"""

from __future__ import annotations

import numpy as np

from ..graph import KnobBlock, register_block

__all__ = ["merge_water", "validate_levelmap", "VARIANTS", "LEVELMAP_DEFAULTS", "WATER_DEFAULTS",
           "WAVE_DEFAULTS", "max_slope", "check_water_depth", "STEEP_SLOPE"]

VARIANTS = ("levelmap", "volumetric", "per_ray")
SPACINGS = ("lattice", "respace")
CULLINGS = ("none", "bounds")

LEVELMAP_DEFAULTS = {
    "planes": 50, "smart_slicing": True, "depth_levels": 32, "variant": "levelmap",
    "smart_spacing": "respace", "culling": "none",
}

#: Water block (merged only when a scene has one; "water": null means no water).
WATER_DEFAULTS = {"size": [4.0, 4.0], "height": 0.0, "resolution": 128, "ior": 1.33, "absorption": 0.0,
                  "waves": []}
WAVE_DEFAULTS = {"amplitude": 0.02, "wavelength": 0.5, "direction": [1.0, 0.0], "phase": 0.0}


def merge_water(data, water_defaults=WATER_DEFAULTS, wave_defaults=WAVE_DEFAULTS):
    """Fill a present ``water`` block (and each wave) with the defaults; idempotent."""
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


def validate_levelmap(data, base_dir="."):
    """Check the ``levelmap`` knobs and the ``water`` block (merged with its defaults first)."""
    from ..validation import SceneError, check_number, check_vector

    merge_water(data)
    p = data["levelmap"]
    check_number(p["planes"], "levelmap.planes", 1, 4096, integer=True)
    check_number(p["depth_levels"], "levelmap.depth_levels", 1, 65536, integer=True)
    if not isinstance(p["smart_slicing"], bool):
        raise SceneError(f"scene: levelmap.smart_slicing must be true or false, got {p['smart_slicing']!r}")
    if p["variant"] not in VARIANTS:
        raise SceneError(f"scene: 'levelmap.variant' is {p['variant']!r}; choose one of {', '.join(VARIANTS)}")
    for k, allowed in (("smart_spacing", SPACINGS), ("culling", CULLINGS)):
        if p[k] not in allowed:
            raise SceneError(f"scene: 'levelmap.{k}' is {p[k]!r}; choose one of {', '.join(allowed)}")
    w = data.get("water")
    if w is None:
        return data
    size = check_vector(w["size"], 2, "water.size")
    if np.any(size <= 0):
        raise SceneError(f"scene: 'water.size' is {w['size']}; both extents must be > 0")
    check_number(w["height"], "water.height")
    check_number(w["resolution"], "water.resolution", 1, 4096, integer=True)
    check_number(w["ior"], "water.ior", 0.0, lo_open=True)
    check_number(w["absorption"], "water.absorption", 0.0)
    amp = 0.0
    for k, wave in enumerate(w["waves"]):
        amp += abs(check_number(wave["amplitude"], f"water.waves[{k}].amplitude"))
        check_number(wave["wavelength"], f"water.waves[{k}].wavelength", 0.0, lo_open=True)
        d = check_vector(wave["direction"], 2, f"water.waves[{k}].direction")
        if not np.any(d != 0):
            raise SceneError(f"scene: 'water.waves[{k}].direction' is [0, 0]; give a non-zero [x, z] direction")
        check_number(wave["phase"], f"water.waves[{k}].phase")
    slope = max_slope(w)
    if slope >= 1.0:
        raise SceneError(f"scene: the water's waves are too steep: the sum of 2 pi amplitude / wavelength is "
                         f"{slope:.3g} >= 1, where the surface folds over itself and is no height field; "
                         "lower water.waves[k].amplitude or raise the wavelengths")
    top = float(w["height"]) + amp
    eye_y = float(data["camera"]["eye"][1])
    if eye_y <= top:
        raise SceneError(f"scene: camera.eye is at y = {eye_y:g}, not above the water (its crests reach "
                         f"y = {top:g}); the water methods render a camera above the surface: raise camera.eye "
                         "or lower water.height")
    return data


#: above this slope (sum of 2 pi a / lambda) the level map's assumptions start to break: beams
#: from neighbouring quads cross before reaching the receivers and the refracted axis of eq. 2-8
#: (flat water) no longer bounds them (Tipprasert 2006, §4.2.1 assumes gentle waves)
STEEP_SLOPE = 0.3


def max_slope(water):
    """The steepest slope the water's waves can reach together: sum of ``2 pi a / lambda`` (eq. 2-1)."""
    return float(sum(2.0 * np.pi * abs(float(x["amplitude"])) / float(x["wavelength"]) for x in water["waves"]))


def check_water_depth(water, receiver_vertices):
    """Refuse waves that reach a receiver below the water plane (the beams would start inside it).

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


#: keys that moved: the receivers' caustic maps' settings to the ``caustics`` block, the exact water
#: reference's to the ``exact`` block
ALIASES = {"map_size": "caustics.map_size", "placement": "caustics.placement", "shadows": "caustics.shadows",
           "ambient": "caustics.ambient", "exact_samples": "exact.water_samples", "exact_seed": "exact.photon_seed"}

BLOCK = register_block(KnobBlock("levelmap", LEVELMAP_DEFAULTS, validate_levelmap, owner="levelmap",
                                 aliases=ALIASES))
WATER_BLOCK = register_block(KnobBlock("water", None, lambda data, base_dir=".": data, owner="levelmap",
                                       merge=merge_water))
