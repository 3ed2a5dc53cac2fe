"""Interoperability with other renderers: every scene of ours in their formats.

:mod:`refraction_ref.interop.mitsuba`
    A scene as a Mitsuba 3 scene dictionary (``mi.load_dict``) or XML file
    with its meshes and environment bitmap beside it (``mi.load_file``), and
    a Fresnel-free refractive BSDF matching the exact references.

Importing this package does not import Mitsuba (an optional extra:
``pip install -e ".[crosscheck]"``).
"""
