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

__all__ = ["MISSED", "EXITED", "LIMIT", "TIR", "LOST", "MEANINGS"]
