"""The ``exact`` knob block (the exact Embree reference): defaults and validation side by side.

``normals`` and ``max_bounces`` are read by the per-pixel trace; ``photons``
and ``photon_seed`` by the exact photon reference of the caustic stages.
Water scenes (the exact water reference) read the ``levelmap`` block's
``exact_samples`` and ``exact_seed`` instead.

Importing this module is cheap (no kernels): scene loading reads it.
"""

from __future__ import annotations

from .graph import KnobBlock, register_block

__all__ = ["EXACT_DEFAULTS", "validate_exact", "BLOCK"]

EXACT_DEFAULTS = {
    "normals": "smooth",      # 'smooth' interpolated (area-weighted) vertex normals | 'face'
    "max_bounces": 64,        # events per ray (refractions and total internal reflections)
    "photons": 1024,          # caustics reference: jittered photons per side of the light's window
    "photon_seed": 0,         # seed of the jitter (the reference is deterministic)
    "record": 0,              # interfaces per path kept as stage buffers (stage.trace.path_pos/path_dir)
}

NORMALS = ("smooth", "face")


def validate_exact(data, base_dir="."):
    """Check ``data['exact']``; raise :class:`~refraction_ref.scene.SceneError` naming the key."""
    from .scene import SceneError, _num

    p = data["exact"]
    if p["normals"] not in NORMALS:
        raise SceneError(f"scene: 'exact.normals' is {p['normals']!r}; choose one of {', '.join(NORMALS)}")
    _num(p["max_bounces"], "exact.max_bounces", 1, 100000, integer=True)
    _num(p["photons"], "exact.photons", 1, 16384, integer=True)
    _num(p["photon_seed"], "exact.photon_seed", 0, integer=True)
    _num(p["record"], "exact.record", 0, 64, integer=True)
    return data


BLOCK = register_block(KnobBlock("exact", EXACT_DEFAULTS, validate_exact, owner="exact"))
