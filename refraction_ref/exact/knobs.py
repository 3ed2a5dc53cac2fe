"""The ``exact`` knob block (the exact Embree reference): defaults and validation side by side.

One block holds every setting of the exact reference, for every kind of scene:

- mesh scenes: ``normals`` and ``crease_deg`` are read by the ``geometry``
  stage (it makes the shading normals every tracing stage uses),
  ``max_bounces`` by the per-pixel trace and the photon trace, ``record`` by
  the per-pixel trace; ``photons`` and ``photon_seed`` by the exact photon
  reference of the caustic stages (:mod:`refraction_ref.exact.caustics`);
- water scenes (the exact water reference, :mod:`refraction_ref.exact.water`):
  ``water_samples`` (samples per side of the analytic surface) and
  ``photon_seed`` (their jitter).

The old names ``levelmap.exact_samples`` and ``levelmap.exact_seed`` keep
working as aliases of ``exact.water_samples`` and ``exact.photon_seed``
(declared by the ``levelmap`` block). What the exact reference shares with
the other methods (the receivers' map size, gathering, placement, shadows,
ambient) it reads from the ``caustics`` block; it reads no other method's block.

Importing this module is cheap (no kernels): scene loading reads it.
"""

from __future__ import annotations

from ..graph import KnobBlock, register_block
from ..validation import SceneError, check_number

__all__ = ["EXACT_DEFAULTS", "validate_exact", "BLOCK"]

EXACT_DEFAULTS = {
    # shading normals (docs/oracle.md, Conventions):
    #   'crease' per-corner normals from the triangles alone: smooth where two faces' normals differ by
    #            less than crease_deg, face normals across sharper edges (meshes.corner_normals)
    #   'file'   the vertex normals the mesh file stores (PLY nx/ny/nz, OBJ vn), turned with the object;
    #            'crease' for an object whose mesh has none (generated, arrays, deformed, or a file without)
    #   'smooth' area-weighted vertex normals across every edge (the old default:
    #            it rounds a cube's edges into a lens) | 'face' flat facets
    # 'crease' and not 'file' is the default: the truth must follow from the triangles any backend is
    # given, and exporters write smooth normals across hard edges (trimesh's own OBJ export of a box
    # stores (+-1, +-1, +-1)/sqrt(3) corner normals: the lens again); no built-in mesh stores normals
    "normals": "crease",
    # crease angle in degrees, (0, 180]; an edge at exactly this angle is sharp; 180 = 'smooth'.
    # 60 from benchmarks/bench_normals.py (results/normals.md: 256x256 exact renders, IOR 1.5, fit 1):
    # - CAD edges stay sharp: 700 of fandisk's 722 edges above 30 deg lie above 60 (its features sit at
    #   80-120 deg); 30, 45 and 60 give nearly one render (19.5 / 20.7 / 20.8 % of its pixels differ from
    #   face normals by > 1 deg, i.e. its smooth patches), 90 rounds the features (37.5 %, 20.1 % from
    #   'smooth'); the cube is exact at any angle up to 90;
    # - smooth surfaces stay smooth: against 'smooth', 60 changes 0.1 % of the teapot's pixels (its
    #   tessellation reaches 45 deg, its lid-knob pole 45-60; 1.5 % at 45, 3.5 % at 30) and 3.0 % of the
    #   bunny's (scan noise: 1,355 edges above 30, 110 above 60; 8.0 % at 45, 18.8 % at 30).
    # three.js's toCreasedNormals defaults to 60 deg too.
    "crease_deg": 60.0,
    "max_bounces": 64,        # events per ray (refractions and total internal reflections)
    "photons": 1024,          # caustics reference: jittered photons per side of the light's window
    "photon_seed": 0,         # seed of the jitter (the reference is deterministic)
    "record": 0,              # interfaces per path kept as stage buffers (stage.trace.path_pos/path_dir)
    "water_samples": 2048,    # water reference: jittered samples per side of the analytic surface (seed: photon_seed)
}

NORMALS = ("crease", "file", "smooth", "face")


def validate_exact(data, base_dir="."):
    """Check the ``exact`` block of a merged scene.

    Parameters
    ----------
    data : dict
        The merged scene; ``data['exact']`` holds every key of :data:`EXACT_DEFAULTS`.
    base_dir : str, default "."
        The scene file's folder (unused: the block names no file).

    Returns
    -------
    dict
        ``data``, unchanged.

    Raises
    ------
    SceneError
        Naming the first key out of range (``exact.<key>``).
    """
    p = data["exact"]
    if p["normals"] not in NORMALS:
        raise SceneError(f"scene: 'exact.normals' is {p['normals']!r}; choose one of {', '.join(NORMALS)}")
    check_number(p["crease_deg"], "exact.crease_deg", 0.0, 180.0, lo_open=True)
    check_number(p["max_bounces"], "exact.max_bounces", 1, 32767, integer=True)  # the interface counts are int16
    check_number(p["photons"], "exact.photons", 1, 16384, integer=True)
    check_number(p["photon_seed"], "exact.photon_seed", 0, integer=True)
    check_number(p["record"], "exact.record", 0, 64, integer=True)
    check_number(p["water_samples"], "exact.water_samples", 2, 16384, integer=True)
    return data


BLOCK = register_block(KnobBlock("exact", EXACT_DEFAULTS, validate_exact, owner="exact"))
