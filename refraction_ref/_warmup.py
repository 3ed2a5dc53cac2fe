"""Load every kernel once per process on a tiny scene, so timings exclude JIT time.

Kernels are compiled with ``cache=True``: in a second process this only
loads them from the on-disk cache.
"""

from __future__ import annotations

_done = set()


def imagespace():
    if "imagespace" in _done:
        return
    _done.add("imagespace")
    from .imagespace.pipeline import render_imagespace
    from .scene import load_scene

    base = {"camera": {"width": 16, "height": 16}, "imagespace": {"photons": 8, "caustic_map": 8},
            "objects": [{"mesh": "sphere", "fit": 1.0, "material": {"ior": 1.3, "absorption": [0.1, 0, 0]}}]}
    for over in ({}, {"imagespace.peeling": "lut"}, {"imagespace.depth": "float"},
                 {"imagespace.blend": "add", "imagespace.tir": True}):
        render_imagespace(load_scene(base, over), warm=False)
