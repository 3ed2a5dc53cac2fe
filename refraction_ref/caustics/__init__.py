"""Caustics onto diffuse receivers: a service every method uses (Chaudhari 2008, §4.1).

``knobs`` (the ``caustics`` block: map size, gathering, the level map's
placement, shadows and ambient) -> ``light`` (the light's camera and photon
flux) -> ``receivers`` (the receivers' triangle soup, caustic-map frames and
hits: ``eyespace``, the eye-space march of Krüger et al. 2006, or
``exact_hits``, Embree) -> ``splat`` (bilinear splat, Gaussian gathering of
Wyman and Davis 2006) -> ``shade`` (direct light with a shadow test,
``shadow``, plus caustics), and ``pipeline``: the generic
stages (receivers, receiver hits, splat, gather) that the image-space
method (:mod:`refraction_ref.imagespace.caustics`), the volumetric method
and the exact photon reference (:mod:`refraction_ref.exact.caustics`) put
around their own photon traces. This package imports no method.
"""

__all__ = ["has_caustics", "merge_caustics", "skip_reason", "caustic_arrays"]


def __getattr__(name):  # lazy: scene loading imports .knobs without the kernels
    if name in __all__:
        from . import pipeline

        return getattr(pipeline, name)
    raise AttributeError(name)
