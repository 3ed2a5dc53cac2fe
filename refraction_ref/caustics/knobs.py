"""The ``caustics`` knob block: the receivers' caustic maps, one setting for every method.

The receivers' caustic maps are a service (:mod:`refraction_ref.caustics`)
that the image-space (Chaudhari 2008, §4.1), volumetric (Sun et al. 2008,
§6.2.2) and level-map (Tipprasert 2006, ch. 4) methods and the exact
reference share, so their settings live in one block read by all of them.
Each knob is declared once in :data:`KNOBS` (type, range or choices,
default, meaning and section: the table of ``docs/oracle.md`` is written
from them). No kernel reads these knobs: ``map_size`` reaches the kernels
as each receiver's map box (``Box.size``), ``gather`` as the gathering
window of :func:`refraction_ref.filters.gather_gaussian`, and the stages
read each knob they declare (``Stage.reads``) on its own.

The old names (``imagespace.caustic_map``, ``imagespace.gather``,
``levelmap.map_size``, ...) keep working as aliases (``KnobBlock.aliases``
of the ``imagespace`` and ``levelmap`` blocks). Importing this module is
cheap (no kernels): scene loading reads it.

References
----------
.. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §2.3.2, §4.1.
.. [2] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.2, §4.6.
"""

from __future__ import annotations

from ..knobs import Knob, declare_block
from ..validation import SceneError

__all__ = ["KNOBS", "CAUSTICS_DEFAULTS", "PLACEMENTS", "BLOCK"]

#: the level map's reference-box placements (as :data:`refraction_ref.caustics.boxes.PLACEMENTS`;
#: this module imports no kernels)
PLACEMENTS = ("component", "thesis", "tight")


def _odd_window(value, where, data=None):
    """A gathering window is a centred square of texels: an odd side."""
    if value % 2 == 0:
        raise SceneError(f"scene: {where} is {value}; the gathering window must be odd "
                         "(a centred square of texels, e.g. 7), or 1 for no gathering")


#: the block's knobs, in the order of the table in ``docs/oracle.md``
KNOBS = (
    Knob("map_size", 512,
         "texels per side of each receiver's caustic map (and of the level map's position, diffuse and caustics "
         "maps), so every method's maps of a receiver have one size; was `imagespace.caustic_map` and "
         "`levelmap.map_size`",
         "Chaudhari §4.1; Tipprasert §4.2.2", kind="int", lo=1, hi=8192, read_by="every method"),
    Knob("gather", 7,
         "Gaussian gathering window in texels (Wyman and Davis 2006); 1 = none; was `imagespace.gather`",
         "Chaudhari §2.3.2", kind="int", lo=1, hi=63, allowed="odd integer 1..63", check=_odd_window,
         read_by="image-space"),
    Knob("placement", "component",
         "the level map's reference box and planes: \"component\" the box "
         "of eqs. 4-2/4-3 centred on the receiver's origin `P_0` (its `transform.translate`), each extent twice "
         "the **component along that axis** of the vertex farthest along it (`w = 2 max |(P - P_0) . U|`, ...: "
         "the smallest box about `P_0` that encloses the receiver along U, V, W, the box's stated purpose; the "
         "tight box when `P_0` is the receiver's middle), planes by eqs. 4-7 to 4-9; \"thesis\" "
         "the same box with eq. 4-3's `|P_a|` read as the whole vector's length "
         "(`w = 2 |P_x - P_0|`, ...; a flat floor is as deep as it is wide); \"tight\" the tight box of the "
         "vertices with planes at slab centres; was `levelmap.placement`",
         "Tipprasert §4.2.1, eqs. 4-2, 4-3, 4-7 to 4-9", kind="choice", choices=PLACEMENTS,
         read_by="level map, exact water"),
    Knob("shadows", True,
         "receivers occlude each other in the level map's maps (the first surface along the light wins); was "
         "`levelmap.shadows`",
         "Tipprasert §4.2.2", kind="bool", read_by="level map, exact water"),
    Knob("ambient", 0.1,
         "`I_a` of eq. 4-19 as a fraction of the albedo; was `levelmap.ambient`",
         "Tipprasert §4.6, eq. 4-19", kind="float", lo=0.0, read_by="level map, exact water"),
)

BLOCK = declare_block("caustics", KNOBS, owner="caustics")

#: every knob's default (the block's, derived from :data:`KNOBS`)
CAUSTICS_DEFAULTS = BLOCK.defaults
