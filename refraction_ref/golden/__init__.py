"""The conformance kit: a golden suite of small scenes and a check that names the failing pass.

``refraction-ref golden build DIR`` renders the catalogue
(``refraction_ref/data/golden/*.json``: every method and the cases that
break implementations) with the oracle, keeping every stage's buffers;
``refraction-ref check CANDIDATE --golden DIR`` judges a backend's outputs
key by key with documented tolerances (:mod:`.tolerances`) and names the
earliest failing stage. See ``docs/backends.md``.
"""

from .build import build, catalogue
from .check import CheckError, check

__all__ = ["build", "catalogue", "check", "CheckError"]
