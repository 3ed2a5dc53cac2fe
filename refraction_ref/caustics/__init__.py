"""Caustics from multiply-refracted photons onto diffuse receivers (Chaudhari 2008, §4.1).

``light`` (the light's camera and photon flux) -> the image-space passes of
chapter 3 in the light's view (:func:`~refraction_ref.imagespace.pipeline.layered_trace`)
-> ``receivers`` (caustic-map frames; eye-space march of Krüger et al. 2006
or Embree) -> ``splat`` (bilinear splat, Gaussian gathering of Wyman and
Davis 2006) -> ``shade`` (direct light with a shadow test plus caustics),
put together by ``pipeline`` for the image-space method and for the exact
photon reference.
"""

from .pipeline import exact_caustic_stages, has_caustics, imagespace_caustic_stages

__all__ = ["imagespace_caustic_stages", "exact_caustic_stages", "has_caustics"]
