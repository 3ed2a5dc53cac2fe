"""Per-pixel and per-photon status codes of the oracle contract (``docs/oracle.md``).

One set of names for every method: kernels compare against these module
constants (Numba freezes module-level integers into the compiled code), and
the pipelines, ``compare`` and the tests read the same names.

==  =========================  ==================================================================
 0  ``MISSED``                 no object at this pixel (the primary ray met no refractive surface)
 1  ``EXITED``                 the ray left the object(s); ``exit_pos`` / ``exit_dir`` are valid
 2  ``LIMIT``                  stopped at the layer limit (``imagespace.layers``) or the
                               event/bounce limit (``imagespace.max_interfaces``,
                               ``exact.max_bounces``)
 3  ``TIR``                    total internal reflection the method could not follow
                               (``imagespace.tir=false``, the thesis's behaviour), or a
                               bounce limit reached while trapped by TIR
 4  ``LOST``                   the image-space search could not resolve an intersection (ray
                               parallel to the screen, turned towards the viewer, off screen,
                               converged where the layer is absent); for the exact
                               reference, a hit it could not resolve in float64
==  =========================  ==================================================================

The level map's view through the water (Tipprasert 2006; the ``image`` stage
buffer ``view_status`` of :mod:`refraction_ref.levelmap.view`) has codes of its
own, the ``VIEW_*`` family: the same small integers with other meanings (its
2 is a ray lost after the water, its 4 total internal reflection), so they
have their own names and never mix with the per-pixel ``status`` above.

==  =========================  ==================================================================
 0  ``VIEW_MISSED``            no water and no receiver along the eye ray: black
 1  ``VIEW_THROUGH``           refracted by the water onto a receiver (the thesis's view)
 2  ``VIEW_LOST``              refracted by the water, then met no receiver: black
 3  ``VIEW_DIRECT``            missed the water rectangle, met a receiver directly
 4  ``VIEW_TIR``               total internal reflection at the water (only when
                               ``outside_ior > water.ior``): black, not followed
==  =========================  ==================================================================

(The volumetric march's ``photon_status`` codes are the ``PHOTON_*`` names and
``STATUS`` of :mod:`refraction_ref.volumetric.march`.)
"""

MISSED = 0
EXITED = 1
LIMIT = 2
TIR = 3
LOST = 4

#: code -> (name, meaning) for reports, plots and ``docs/oracle.md``
MEANINGS = {
    MISSED: ("missed", "no object at this pixel"),
    EXITED: ("exited", "the ray left the object(s)"),
    LIMIT: ("limit", "stopped at the layer limit or the event/bounce limit"),
    TIR: ("tir", "total internal reflection the method could not follow"),
    LOST: ("lost", "the search could not resolve an intersection"),
}

#: code -> its label in reports and plot legends (``"3 TIR"``)
LABELS = {MISSED: "0 missed", EXITED: "1 exited", LIMIT: "2 limit", TIR: "3 TIR", LOST: "4 lost"}

VIEW_MISSED = 0
VIEW_THROUGH = 1
VIEW_LOST = 2
VIEW_DIRECT = 3
VIEW_TIR = 4

#: view code -> name (``stage.image.view_status`` of the level map and the exact water reference)
VIEW_STATUS = {VIEW_MISSED: "missed", VIEW_THROUGH: "through", VIEW_LOST: "lost", VIEW_DIRECT: "direct",
               VIEW_TIR: "tir"}

__all__ = ["MISSED", "EXITED", "LIMIT", "TIR", "LOST", "MEANINGS", "LABELS", "VIEW_MISSED", "VIEW_THROUGH",
           "VIEW_LOST", "VIEW_DIRECT", "VIEW_TIR", "VIEW_STATUS"]
