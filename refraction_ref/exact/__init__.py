"""The exact reference (Embree): one package for every scene kind.

==================  ==============================================================
module              what it holds
==================  ==============================================================
:mod:`.trace`       the multi-interface Snell tracer through the real triangles
                    (:func:`trace_exact`, :class:`ExactMesh`)
:mod:`.bounce`      its kernels: one bounce of the rays still travelling
:mod:`.normals`     the mesh normals it refracts with (:func:`mesh_normals`)
:mod:`.knobs`       the ``exact`` knob block (cheap: no kernels; scene loading reads it)
:mod:`.pipeline`    ``--method exact``: its stages, assembly and :func:`render_exact`
:mod:`.caustics`    the exact photon reference's caustic stages (mesh scenes)
:mod:`.water`       the exact water-caustics reference (water scenes)
:mod:`.grin`        the graded-index reference: the ray equation by DOP853 on
                    the volumetric method's field (pure functions)
:mod:`.volume`      its stage graph (``--method exact`` on volume scenes)
==================  ==============================================================

>>> from refraction_ref.exact import trace_exact        # doctest: +SKIP

The names below are loaded on first use, so that ``import refraction_ref.exact.knobs``
(scene validation) compiles no kernel.

References
----------
.. [1] docs/oracle.md, "The exact reference" and the ``exact`` block.
"""

from importlib import import_module

#: public name -> the module of this package that defines it
_WHERE = {
    **dict.fromkeys(("trace_exact", "ExactMesh"), "trace"),
    **dict.fromkeys(("area_weighted_vertex_normals", "MeshNormals", "mesh_normals"), "normals"),
    **dict.fromkeys(("STATUS_MISSED", "STATUS_EXITED", "STATUS_BOUNCE_LIMIT", "STATUS_BOUNCE_LIMIT_TIR",
                     "STATUS_LOST"), "trace"),
    **dict.fromkeys(("render_exact", "render_water_exact", "shading_normals"), "pipeline"),
    "trace_water_photons": "water",
    "exact_caustic_stages": "caustics",
    **dict.fromkeys(("EXACT_DEFAULTS", "ExactKnobs", "exact_knobs"), "knobs"),
}

__all__ = list(_WHERE)


def __getattr__(name):  # lazy (PEP 562): the kernels load on first use, not with the knob block
    if name in _WHERE:
        return getattr(import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
