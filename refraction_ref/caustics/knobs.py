"""The ``caustics`` knob block: the receivers' caustic maps, one setting for every method.

The receivers' caustic maps are a service (:mod:`refraction_ref.caustics`)
that the image-space (Chaudhari 2008, §4.1), volumetric (Sun et al. 2008,
§6.2.2) and level-map (Tipprasert 2006, ch. 4) methods and the exact
reference share, so their settings live in one block read by all of them:

``map_size``
    Texels per side of each receiver's caustic map, 1..8192 (was
    ``imagespace.caustic_map`` and ``levelmap.map_size``, both 512).
``gather``
    Gaussian gathering window in texels (Wyman & Davis 2006), odd, 1..63;
    1 = none (was ``imagespace.gather``; the image-space method's maps).
``placement``
    ``component`` | ``thesis`` | ``tight``: the level map's reference box and
    planes. ``component`` (the default since contract_version 5): eq. 4-3
    read per axis, extents twice the farthest vertex's component along each
    box axis, centred on the receiver's origin, planes of eqs. 4-7 to 4-9;
    ``thesis`` (the default of contract_version 4): the same with eq. 4-3's
    ``|P_a|`` read as the whole vector's length (a larger box); ``tight``:
    the tight box with planes at slab centres (was ``levelmap.placement``).
``shadows``
    Receivers occlude each other in the level map's position maps (bool;
    was ``levelmap.shadows``).
``ambient``
    Eq. 4-19's ``I_a`` as a fraction of the albedo, >= 0 (was
    ``levelmap.ambient``; the water scenes' shading).

The old names keep working as aliases (``KnobBlock.aliases`` of the
``imagespace`` and ``levelmap`` blocks). Importing this module is cheap (no
kernels): scene loading reads it.
"""

from __future__ import annotations

from ..graph import KnobBlock, register_block
from ..validation import SceneError, check_number

__all__ = ["CAUSTICS_DEFAULTS", "PLACEMENTS", "validate_caustics", "BLOCK"]

#: Every key is a knob; see the table in ``docs/oracle.md``.
CAUSTICS_DEFAULTS = {
    "map_size": 512,          # texels per side of each receiver's caustic map (every method, exact reference too)
    "gather": 7,              # Gaussian gathering window in texels (Wyman & Davis 2006); 1 = none
    "placement": "component",  # reference box: 'component' (eq. 4-3 per axis) | 'thesis' (full |P_a|) | 'tight'
    "shadows": True,          # receivers occlude each other (level map's position maps)
    "ambient": 0.1,           # eq. 4-19's I_a as a fraction of the albedo
}

PLACEMENTS = ("component", "thesis", "tight")  # as caustics.boxes.PLACEMENTS (this module imports no kernels)


def validate_caustics(data, base_dir="."):
    """Check ``data['caustics']``; raise :class:`~refraction_ref.validation.SceneError` naming the key.

    Parameters
    ----------
    data : dict
        The merged scene (every block filled with its defaults).
    base_dir : str
        The scene file's folder (unused: no key names a file).

    Returns
    -------
    dict
        ``data``, unchanged.
    """
    p = data["caustics"]
    check_number(p["map_size"], "caustics.map_size", 1, 8192, integer=True)
    check_number(p["gather"], "caustics.gather", 1, 63, integer=True)
    if p["gather"] % 2 == 0:
        raise SceneError(f"scene: caustics.gather is {p['gather']}; the gathering window must be odd "
                         "(a centred square of texels, e.g. 7), or 1 for no gathering")
    if p["placement"] not in PLACEMENTS:
        raise SceneError(f"scene: 'caustics.placement' is {p['placement']!r}; choose one of {', '.join(PLACEMENTS)}")
    if not isinstance(p["shadows"], bool):
        raise SceneError(f"scene: caustics.shadows must be true or false, got {p['shadows']!r}")
    check_number(p["ambient"], "caustics.ambient", 0.0)
    return data


BLOCK = register_block(KnobBlock("caustics", CAUSTICS_DEFAULTS, validate_caustics, owner="caustics"))
