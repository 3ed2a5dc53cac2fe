"""Reference planes: a bounding box aligned with the refracted light (eqs. 4-1 to 4-3)
sliced into equally spaced planes (eqs. 4-6 to 4-9).

Frames used by every pass of the level-map method:

* ``T0`` is the refracted direction of the light at a *flat* water surface
  (the thesis's alignment assumption, §4.2.1): for a parallel light the light
  direction refracted by eq. 2-8; for a point light the ray from the light to
  the receiver's origin (its bounding-box centre), refracted where it meets
  the water plane (Fig. 4-7).
* The box axes are ``V = -T0`` and ``U = V x N``, ``W = U x V`` (eq. 4-1) with
  ``N`` the world z axis (or x when z is nearly parallel to V). The thesis
  picks ``N`` at random; a fixed choice keeps runs reproducible.
* Box extents ``w, h, d`` along ``U, V, W`` (eq. 4-3) are measured about the
  box centre, so ``w = 2 |P_x|`` holds with ``P_0`` at the centre.
* Map coordinates of a world point ``p``: ``col = ((p - c).U / w + 1/2) Wc``,
  ``row = ((p - c).W / d + 1/2) Hc`` (texel units, centres at ``+0.5``) and
  the depth ``zeta = (p - c).T0`` along the light, from ``-h/2`` (the box face
  nearest the light) to ``+h/2``.

Placement (``caustics.placement``; ``levelmap.planes`` counts **planes**, the
thesis's "Num Plane" of Tables 5-1 to 5-5):

* ``"component"`` (the default) and ``"thesis"``:
  the box of eqs. 4-2/4-3 is centred on the receiver's own origin ``P_0``
  (its ``transform.translate``: the point the mesh's local origin is placed
  at; a fitted mesh is centred on its bounding box first), and each extent is
  twice ``|P_a|`` for the vertex ``P_a`` lying farthest from ``P_0`` along
  axis ``a`` (largest ``|coordinate|``), ``w = 2 |P_x|``, ``h = 2 |P_y|``,
  ``d = 2 |P_z|`` (eq. 4-3). ``"component"`` reads ``|P_a|`` as that vertex's
  coordinate along ``a`` (the box's stated purpose: the smallest box about
  ``P_0`` that encloses the receiver along ``U``, ``V``, ``W``; the tight box
  when ``P_0`` is the receiver's middle); ``"thesis"`` reads it as the whole
  vector's length (eq. 4-2's distance literally: a larger box, e.g. a flat
  floor's ``h`` several times its tight depth, so fewer planes fall on the
  receiver). ``planes = n + 1`` planes slice the box into ``n`` slices
  (eq. 4-6): ``D_i = D_max - s (i - 1)``, ``s = h / n``, ``D_max = h / 2``
  (eqs. 4-7 to 4-9), i.e. ``zeta_i = -h/2 + s (i - 1)``, ``i = 1 .. n + 1``,
  the first and last planes on the box's faces; one plane (``n = 0``) sits
  at the centre with ``s = h``. Plane ``i`` accepts ``[zeta_i - s/2,
  zeta_i + s/2)`` (eq. 4-15, ``eps = s / 2``).
* ``"tight"``: the tight bounding box of the
  vertices, centred on its middle; the ``planes`` planes sit at the centres
  of ``planes`` equal slabs, ``zeta_i = -h/2 + s (i + 1/2)``, ``s = h /
  planes`` (``D_max = h/2 - s/2``), so that the acceptance ranges tile the box
  exactly.

In both, the acceptance ranges of consecutive planes are half-open and
contiguous, so a texel is accepted by at most one plane: plane
``floor((zeta - z_lo) / s)`` with ``z_lo = zeta_1 - s / 2``
(:func:`plane_lattice`).

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.2.1.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..caustics.boxes import CENTRED, PLACEMENTS, Box, dir_to_map, frame_of, from_map, reference_box, to_map
from ..optics import refract
from ..validation import SceneError

__all__ = ["Box", "Lattice", "CENTRED", "PLACEMENTS", "refracted_axis", "reference_box", "receiver_origin",
           "plane_lattice", "to_map", "dir_to_map", "from_map", "frame_of"]
# Box, PLACEMENTS, reference_box and the map frame (to_map, dir_to_map, from_map, frame_of) live in
# caustics.boxes: every receiver's caustic map uses them, the level map's planes are laid in them.

def refracted_axis(light, water, eta, target):
    """``T0``: the light refracted at the flat water plane (§4.2.1, Figs. 4-5, 4-7).

    Parameters
    ----------
    light : dict
    water : dict
    eta : float
        ``outside_ior / water.ior``.
    target : (3,) array_like
        The receiver's origin (used for point lights only).

    Returns
    -------
    (3,) float64
        Unit refracted direction ``T0`` (pointing down into the water).

    Raises
    ------
    SceneError
        When the light cannot enter the water from above.

    References
    ----------
    Tipprasert (2006), §4.2.1, Figs. 4-5 and 4-7; §2.6 (Snell's law).
    """
    up = np.array([0.0, 1.0, 0.0])
    if light["type"] == "directional":
        L = np.asarray(light["direction"], dtype=np.float64)
        L = L / np.linalg.norm(L)
    else:
        p = np.asarray(light["position"], dtype=np.float64)
        L = np.asarray(target, dtype=np.float64) - p
        n = np.linalg.norm(L)
        if n == 0 or L[1] >= 0:
            raise SceneError("levelmap: a point light must be above the receivers it lights "
                             f"(light at {p.tolist()}, receiver origin {np.asarray(target).tolist()}); "
                             "raise the light above the water")
        L = L / n
    if L[1] >= 0.0:
        raise SceneError(f"levelmap: light direction {L.tolist()} does not point downward; light from "
                         "below the horizon never enters the water. Give it a negative y component")
    t, tir = refract(L, up, eta)
    if tir or t[1] >= 0.0:
        raise SceneError("levelmap: the light is totally reflected at the water surface "
                         f"(outside_ior / water.ior = {eta}); the water needs an ior above the outside's")
    return t / np.linalg.norm(t)


def receiver_origin(receiver):
    """``P_0`` of eq. 4-2: where a receiver's local origin lands in the world (its ``transform.translate``).

    ``p' = R (scale p) + translate`` maps the mesh's origin (after ``fit``'s
    centring on the bounding-box centre) to ``translate``.

    Parameters
    ----------
    receiver : dict
        A receiver of the scene (its optional ``transform.translate``).

    Returns
    -------
    (3,) float64
        ``P_0`` in world space (the origin when there is no translation).

    References
    ----------
    Tipprasert (2006), §4.2.1, eq. 4-2.
    """
    return np.asarray(receiver.get("transform", {}).get("translate", [0.0, 0.0, 0.0]), dtype=np.float64)


class Lattice(NamedTuple):
    """Equally spaced reference planes and their acceptance slabs.

    Attributes
    ----------
    zeta : (n,) float64, plane depths along ``T0`` from the box centre, nearest the light first
    s : float, spacing (eq. 4-8)
    zlo : float, lower end of the first plane's acceptance slab: plane ``floor((zeta - zlo) / s)``
    """

    zeta: np.ndarray
    s: float
    zlo: float


def plane_lattice(box, n, placement):
    """The ``n`` reference planes of ``box`` (eqs. 4-6 to 4-9; module docstring).

    Parameters
    ----------
    box : Box
        The reference box (its extent ``h`` along ``V``).
    n : int
        Number of planes.
    placement : {"component", "thesis", "tight"}
        ``caustics.placement``: the thesis's ``n - 1`` slices with planes on
        the box faces, or planes at slab centres of the tight box (module
        docstring).

    Returns
    -------
    Lattice
        Plane depths, spacing and the start of the first acceptance slab.

    References
    ----------
    Tipprasert (2006), eqs. 4-6 to 4-9, 4-15.
    """
    n = int(n)
    if placement in CENTRED:
        if n == 1:
            return Lattice(np.zeros(1), box.h, -box.h / 2.0)
        s = box.h / (n - 1)  # n planes, n - 1 slices (eq. 4-8)
        zeta = -box.h / 2.0 + s * np.arange(n)  # D_i = h/2 - s (i - 1) (eqs. 4-7, 4-9)
        return Lattice(zeta, s, -box.h / 2.0 - s / 2.0)
    s = box.h / n
    return Lattice(-box.h / 2.0 + s * (np.arange(n) + 0.5), s, -box.h / 2.0)
