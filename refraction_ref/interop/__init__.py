"""Interoperability with other renderers: every scene of ours in their formats, and the cross-check against one.

:mod:`refraction_ref.interop.mitsuba`
    A scene as a Mitsuba 3 scene dictionary (``mi.load_dict``) or XML file
    with its meshes and environment bitmap beside it (``mi.load_file``), and
    a Fresnel-free refractive BSDF matching the exact references.
:mod:`refraction_ref.interop.crosscheck`
    ``refraction-ref crosscheck``: the exact references against Mitsuba 3
    per golden case, by what it checks: :mod:`~refraction_ref.interop.paths`
    (every pixel's exit), :mod:`~refraction_ref.interop.images` (the image
    through the pixel centres), :mod:`~refraction_ref.interop.caustics` (the
    caustic maps), :mod:`~refraction_ref.interop.water` (the water scenes),
    on the shared rays of :mod:`~refraction_ref.interop.rays`; the targets,
    verdicts and Markdown report in :mod:`~refraction_ref.interop.report`,
    its figures in :mod:`~refraction_ref.interop.figures`.

Importing this package does not import Mitsuba (an optional extra:
``pip install -e ".[crosscheck]"``), nor its modules.
"""
