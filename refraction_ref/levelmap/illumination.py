"""Illumination volumes: the refracted light beam below every water triangle (eq. 4-14).

The beam of water triangle ``F_j = (l, m, n)`` is bounded by the three refracted
rays ``IL_j = {T_l, T_m, T_n}`` leaving its vertices. It carries the flux that
the light pours through the triangle,

.. math:: \\Phi_j = E_\\perp A_w \\cos\\theta_i ,

``A_w cos(theta_i)`` being the triangle's area projected perpendicular to the
incident light (the numerator of eq. 4-18); absorption ``exp(-K d)`` (eq. 4-17)
is applied where the beam meets a plane. No Fresnel loss is applied, as in
eq. 4-18. A triangle seen from below by the light (a steep, folded wave) or
with zero area carries no flux; the water does not shadow itself.

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §4.3 (eq. 4-14), §4.5 (eqs. 4-16 to 4-18).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .water import incident_directions, refract_at_vertices

__all__ = ["IlluminationVolumes", "illumination_volumes"]


class IlluminationVolumes(NamedTuple):
    """The beams of one light under every water triangle.

    Attributes
    ----------
    origins : (F, 3, 3) float64
        Water-triangle vertices, world space.
    dirs : (F, 3, 3) float64
        Unit refracted directions at those vertices.
    flux : (F,) float64
        ``E_perp * A_w * cos(theta_i)``, >= 0; zero for beams that do not exist.
    mean_dir : (F, 3) float64
        Unit mean of the three directions, the beam axis.
    """

    origins: np.ndarray
    dirs: np.ndarray
    flux: np.ndarray
    mean_dir: np.ndarray


def illumination_volumes(light, mesh, eta):
    """Build the illumination volume of every water triangle (eq. 4-14).

    Parameters
    ----------
    light : dict
        Directional or point light.
    mesh : WaterMesh
    eta : float
        ``outside_ior / water.ior``.

    Returns
    -------
    IlluminationVolumes
    """
    _, t, ok = refract_at_vertices(light, mesh, eta)
    f = mesh.faces
    o = mesh.vertices[f]
    d = t[f]
    fn = np.cross(o[:, 1] - o[:, 0], o[:, 2] - o[:, 0])  # 2 A_w n
    centroid = o.mean(axis=1)
    inc, e_perp = incident_directions(light, centroid)
    proj = -np.einsum("ij,ij->i", fn, inc) * 0.5  # A_w cos(theta_i), signed
    flux = np.where(ok[f].all(axis=1) & (proj > 0.0), e_perp * np.maximum(proj, 0.0), 0.0)
    m = d.sum(axis=1)
    ln = np.linalg.norm(m, axis=1, keepdims=True)
    m = np.divide(m, ln, out=np.tile([0.0, -1.0, 0.0], (len(m), 1)), where=ln > 0)
    return IlluminationVolumes(o, d, flux, m)
