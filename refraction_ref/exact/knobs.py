"""The ``exact`` knob block (the exact Embree reference), declared once, and :class:`ExactKnobs`.

One block holds every setting of the exact reference, for every kind of scene:

- mesh scenes: ``normals`` and ``crease_deg`` are read by the ``geometry``
  stage (it makes the shading normals every tracing stage uses),
  ``max_bounces`` by the per-pixel trace and the photon trace, ``record`` by
  the per-pixel trace; ``photons`` and ``photon_seed`` by the exact photon
  reference of the caustic stages (:mod:`refraction_ref.exact.caustics`);
- water scenes (the exact water reference, :mod:`refraction_ref.exact.water`):
  ``water_samples`` (samples per side of the analytic surface) and
  ``photon_seed`` (their jitter).

``levelmap.exact_samples`` and ``levelmap.exact_seed`` are aliases of
``exact.water_samples`` and ``exact.photon_seed`` (declared by the
``levelmap`` block). What the exact reference shares with the other methods
(the receivers' map size, gathering, placement, shadows, ambient) it reads
from the ``caustics`` block; it reads no other method's block.

Each knob is declared once (:class:`~refraction_ref.knobs.Knob`): the block's
defaults (:data:`EXACT_DEFAULTS`), its checks and its table in docs/oracle.md
derive from :data:`KNOBS`. The stages take the checked block as one typed
value, :class:`ExactKnobs` (:func:`exact_knobs`).

Importing this module is cheap (no kernels): scene loading reads it.

References
----------
.. [1] docs/oracle.md, "### ``exact`` block" (the table generated from :data:`KNOBS`).
"""

from __future__ import annotations

from typing import NamedTuple

from ..knobs import Knob, declare_block

__all__ = ["KNOBS", "EXACT_DEFAULTS", "NORMALS", "validate_exact", "BLOCK", "ExactKnobs", "exact_knobs"]

#: the shading-normal rules of ``exact.normals`` (docs/oracle.md, Conventions):
#: ``crease`` per-corner normals from the triangles alone (smooth where two faces' normals differ by less
#: than ``crease_deg``, face normals across sharper edges; :func:`refraction_ref.meshes.corner_normals`);
#: ``file`` the vertex normals the mesh file stores (PLY nx/ny/nz, OBJ vn), turned with the object, and
#: ``crease`` for an object whose mesh has none; ``smooth`` area-weighted vertex normals across every edge;
#: ``face`` flat facets. ``crease``, not ``file``, is the default: the truth must follow from the triangles
#: any backend is given, and exporters write smooth normals across hard edges (trimesh's OBJ export of a box
#: stores (+-1, +-1, +-1)/sqrt(3) corner normals, which round it into a lens); no built-in mesh stores normals.
NORMALS = ("crease", "file", "smooth", "face")

KNOBS = (
    Knob("normals", "crease",
         "the shading normals refracted with (Conventions, vertex and shading normals): `crease` per-corner "
         "normals from the triangles alone, smooth across edges below `crease_deg` and sharp across the others; "
         "`file` the mesh file's own vertex normals, `crease` for objects without them; `smooth` area-weighted "
         "vertex normals across every edge (it rounds a cube into a lens); `face` face "
         "normals. The `trace` stage's plan note states the rule applied to each object and how many edges are "
         "sharp",
         kind="choice", choices=NORMALS),
    # 60 from benchmarks/bench_normals.py (results/normals.md: 256x256 exact renders, IOR 1.5, fit 1):
    # - CAD edges stay sharp: 700 of fandisk's 722 edges above 30 deg lie above 60 (its features sit at
    #   80-120 deg); 30, 45 and 60 give nearly one render (19.5 / 20.7 / 20.8 % of its pixels differ from
    #   face normals by > 1 deg, i.e. its smooth patches), 90 rounds the features (37.5 %, 20.1 % from
    #   'smooth'); the cube is exact at any angle up to 90;
    # - smooth surfaces stay smooth: against 'smooth', 60 changes 0.1 % of the teapot's pixels (its
    #   tessellation reaches 45 deg, its lid-knob pole 45-60; 1.5 % at 45, 3.5 % at 30) and 3.0 % of the
    #   bunny's (scan noise: 1,355 edges above 30, 110 above 60; 8.0 % at 45, 18.8 % at 30).
    # three.js's toCreasedNormals defaults to 60 deg too. An edge at exactly this angle is sharp.
    Knob("crease_deg", 60.0,
         "crease angle in degrees between two faces' normals (0 coplanar, 90 on a cube's edge): smooth below it, "
         "sharp at and above it; 180 is `smooth`. 60 keeps CAD edges (fandisk's lie at 80-120 degrees) and "
         "smooths tessellation and scan noise (teapot, bunny); `benchmarks/results/normals.md`",
         kind="float", lo=0.0, hi=180.0, lo_open=True, allowed="0 < x <= 180"),
    # at most 32767: the interface and event counts are int16
    Knob("max_bounces", 64, "surface events (refractions + TIR reflections) per ray",
         kind="int", lo=1, hi=32767),
    Knob("photons", 1024,
         "caustics reference: jittered photons per side of the light's window (the reference for Chaudhari "
         "2008 §4.1)",
         kind="int", lo=1, hi=16384),
    Knob("photon_seed", 0, "seed of the jitter; the reference is deterministic", kind="int", lo=0),
    Knob("record", 0,
         "events per path recorded as the `trace` stage buffers `path_pos`, `path_dir` (H, W, K, 3) with K = "
         "`record` (Stage buffers; kept with `--keep trace`), to diff against `imagespace.record`; 0 records "
         "none. No other output changes",
         kind="int", lo=0, hi=64),
    Knob("water_samples", 2048,
         "water scenes: jittered samples per side of the analytic water surface, seeded by `photon_seed` (no "
         "paper)",
         kind="int", lo=2, hi=16384),
)

BLOCK = declare_block("exact", KNOBS, owner="exact")

#: the block's defaults, from :data:`KNOBS`
EXACT_DEFAULTS = BLOCK.defaults

#: the block's checks, from :data:`KNOBS`: ``validate_exact(data, base_dir=".")`` returns ``data``
#: or raises :class:`~refraction_ref.validation.SceneError` naming the first key out of range
validate_exact = BLOCK.validate


class ExactKnobs(NamedTuple):
    """The checked ``exact`` block as one typed value (:func:`exact_knobs`); fields as :data:`KNOBS`.

    A field a stage did not ask for is None (a stage reads only the knobs its ``Stage.reads`` declares).
    """

    normals: str | None = None
    crease_deg: float | None = None
    max_bounces: int | None = None
    photons: int | None = None
    photon_seed: int | None = None
    record: int | None = None
    water_samples: int | None = None


#: how each knob is typed for the kernels
_TYPES = {"normals": str, "crease_deg": float, "max_bounces": int, "photons": int, "photon_seed": int,
          "record": int, "water_samples": int}


def exact_knobs(data=None, *names):
    """The ``exact`` block of a merged, checked scene as :class:`ExactKnobs`.

    Parameters
    ----------
    data : dict, optional
        The merged scene (``Scene.data``); None gives the declared defaults.
    *names : str
        The knobs to read (a stage names those its ``Stage.reads`` declares); none: every knob.

    Returns
    -------
    ExactKnobs
        Numbers as the kernels take them (``crease_deg`` a float, the counts ints); the knobs not
        named are None.

    References
    ----------
    .. [1] docs/oracle.md, "### ``exact`` block".
    """
    blk = EXACT_DEFAULTS if data is None else data["exact"]
    return ExactKnobs(**{name: _TYPES[name](blk[name]) for name in (names or ExactKnobs._fields)})
