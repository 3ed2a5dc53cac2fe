"""How a candidate's array is judged against the oracle's: the tolerance kinds and their defaults.

Kinds (``docs/oracle.md``, "Conformance"):

``exact``
    Equal values (status, interfaces, hit, bitmask words, layer counts,
    triangle ids). ``fraction`` of the elements may differ: silhouette
    pixels and fragments exactly on a slice boundary are legitimate ties.
``close``
    ``|c - g| <= atol + rtol |g|`` (positions, depths, path lengths, maps
    of deterministic photons, images); NaN must meet NaN. ``scale='max'``
    makes ``atol`` relative to the largest ``|g|`` (photon maps).
    ``slope=s`` (rasterized depths) adds ``s * step(g)``, ``step(g)`` the
    largest ``|g(p) - g(q)|`` over the finite 8 neighbours ``q`` of the
    element in its picture (:func:`neighbour_step`): the depth sampled
    ``s`` pixels away along x and y. :data:`SNAP_SLOPE` = 1/512 admits a
    rasterizer that does not snap vertices to the oracle's 1/256 pixel
    grid, or casts rays analytically (``docs/oracle.md``, "Conformance").
    ``snap_slope`` (the light's LDI) admits, on at most ``snap_fraction`` of
    the informative elements outside the ambiguity mask, ``snap_slope *
    step(g)`` (:data:`FLOAT32_SNAP_SLOPE` = 1/256: a float32 projection that
    snaps a vertex to the neighbouring 1/256 step).
``angle``
    Unit vectors (directions, normals): the angle between them at most
    ``deg`` degrees, and ``|c|`` within ``norm`` of 1 (a normal that is not
    renormalised fails even when it points the right way); NaN meets NaN.
``ztest``
    Maps of jittered photons (the exact references): per texel
    ``z = (c - mean) / sqrt(var (1 + 1/K) + p q^2)`` over the oracle's K
    independent batches, two-sided, Bonferroni-corrected for the number of
    texels tested at significance ``alpha`` (Mitsuba 3's render tests in
    spirit). ``q`` is the irradiance one photon deposits in one texel (its
    flux over the texel's area) and ``p = (hits + 1) / (K + 2)`` the
    texel's estimated chance of a hit (``hits``: batches in which it was
    hit): a texel that photons seldom reach has a sample variance of zero
    in K batches although one photon may land there, and the floor
    ``p q^2`` keeps the Gaussian test honest there.

Every kind first says which elements fail; the verdict then *locates* them
(``docs/oracle.md``, "Conformance"):

``over``
    The elements a fraction is counted over, the ones that carry
    information: ``all``; ``nonzero`` (either array non-zero: non-empty
    bitmask words, covered pixels, lit texels); ``finite`` (either array
    finite: present layers, recorded interfaces).
``locate``
    Differences are allowed only inside an **ambiguity mask** computed from
    the golden (by :mod:`.check`, per case): for arrays over the camera's
    pixels the silhouettes (within one pixel of a change of the depth
    complexity, of ``hit`` or of the status), for arrays over a map's
    texels the texels beside a depth discontinuity of the position map or
    the edge of the lit region, and for ``own_edges`` keys (codes) also
    where the golden key itself changes. A failing element outside the
    mask is *located*; ``fraction`` is the share of the informative
    elements that may be located failures (0 for codes: a wrong value in
    the interior fails however few pixels carry it). Arrays with no pixel
    or texel axes (photons, volumes, frames) count every failure.
``inside``
    The share of the informative elements that may differ inside the mask
    (:data:`INSIDE`, 2 % for codes): the mask explains ties along edges, not
    a region decided wrongly (TIR pixels marked exited are thin slivers,
    all beside a status change, and 7 % of the diamond's covered pixels).
``why``
    The tolerance's rationale, printed beside each verdict.

"""

from __future__ import annotations

import fnmatch

import numpy as np

from .report import fmt_share

__all__ = ["TOLERANCES", "tolerance_for", "judge", "informative", "nonfinite_mismatch", "finiteness",
           "FINITENESS", "SNAP_SLOPE", "FLOAT32_SNAP_SLOPE", "FLOAT32_SNAP_FRACTION", "neighbour_step",
           "flux_error", "FLUX", "VOLUME_FLUX", "RADIANCE_FLOOR",
           "DEFAULT", "DEFAULT_INT", "elementwise", "fold_mask"]

_TIE = ("a fragment exactly on a slice boundary rounds either way: one bit moves by one slice, anywhere "
        "(counted over the non-empty words); fragments appear or vanish at silhouettes (edge ties)")
_CODE = ("a code is a decision: it may differ only where the golden's own decision changes nearby "
         "(silhouettes, status boundaries); a wrong value in the interior fails")
_DIR = ("unit vectors: float64 arithmetic in another order moves them by ~1e-12 rad; differences follow "
        "slice ties and silhouettes (1 % of the covered pixels elsewhere: a tie moves an interface by a slice)")
_POS = ("positions and lengths: another order of float64 arithmetic; differences follow slice ties and "
        "silhouettes (0.5 % of the informative elements elsewhere)")
#: the allowed relative error of a map's (or volume's) total, per channel: |sum c - sum g| <= FLUX
#: sum |g|. Another summation order of float32 deposits moves a total by a few float32 ulps (about 1e-7
#: relative per deposit, 1e-5 even for thousands of deposits per texel), and a photon that ties at the
#: lit region's or a receiver's edge (counted by the per-texel fraction) carries 1/P of the flux (P photons,
#: 1e-4 to 1e-3 of it on the catalogue's maps); a scale error of 1 % (a splat without its cosine, a
#: deposit without its segment length) is five times the allowance
FLUX = 2e-3
_FLUX_WHY = ("; the total (per channel) within 0.2 %: a 1 % scale error fails here, where the texels' "
             "allowance is relative to the map's maximum")
_MAP = ("maps of deterministic photons: another summation order; photons landing on the lit region's edge or "
        "beside a depth discontinuity of the receivers (1 % of the lit texels elsewhere)" + _FLUX_WHY)
_EXACT_F = "set-up arithmetic (frames, cameras, boxes): float64 rounding only"
_PHOTON_POS = ("photon positions, one row per photon: float64 arithmetic of the photon's path; photons grazing "
               "an edge of the object, the box or a receiver (0.5 % of them)")


def _pos(why):
    """The positions' spec (1e-6 + 1e-5 |g|, 0.5 % of the finite elements, located) with its own rationale."""
    return {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.005, "over": "finite", "locate": True,
            "why": why}

#: the sample shift, in pixels per axis, that a rasterizer without the oracle's 1/256 snap (or a ray caster)
#: may have: rounding a vertex to 1/256 moves it by at most 1/512 per axis, and an attribute interpolated
#: at a pixel centre of the snapped triangle is the unsnapped triangle's at a point moved by a convex
#: combination of the vertices' moves, so by at most 1/512 per axis as well
SNAP_SLOPE = 1.0 / 512.0
_SLOPE = ("a rasterizer without the 1/256 vertex snap, or a ray caster, samples each depth up to 1/512 pixel "
          "per axis from the snapped triangle's point: |c - g| may add (1/512) x the largest step to the 8 "
          "neighbours; coverage differs only at silhouettes")
_DEPTH = "rasterized depths: another order of float64 arithmetic; " + _SLOPE + " (0.5 % elsewhere)"
#: a vertex projected in float32 lands within eps of the float64 position (1.2e-5 pixel measured on the
#: catalogue's 128-texel light views: a few ulps of the pixel coordinate); where the float64 position lies
#: within eps of a midpoint between two 1/256 steps the snap picks the neighbouring step, moving the vertex
#: by a whole step, 1/256 pixel, and the depths interpolated at the texel centres of its triangles by up to
#: their weight times step(g)/256 (docs/oracle.md, "Float32 rasterizers")
FLOAT32_SNAP_SLOPE = 1.0 / 256.0
#: the share of a light LDI's texels that may lie beyond the slope term but within FLOAT32_SNAP_SLOPE: per
#: vertex the chance of the other step is 2 x 256 eps per axis (1.2 % for both axes at eps = 1.2e-5); a
#: texel leaves the 1/512 term only where such a vertex weighs more than 1/2 (a quarter of each triangle of
#: its fan, the fans covering the surface three times: 3/4 of the vertex share) and moves along the depth's
#: gradient (about half of them): 0.46 %, taken as zmin's and zlo's 0.5 %, the buffers the light's LDI
#: stands for (its bitmask and depth bounds are not contract keys)
FLOAT32_SNAP_FRACTION = 0.005
_LIGHT_LDI = ("the light's layer depths: slice centres of its bitmask (not a contract key, so no replay); "
              + _SLOPE + "; a float32 projection may snap a vertex to the neighbouring 1/256 step: up to "
              "step(g)/256 on 0.5 % of the texels outside the light's silhouettes, beyond that on none")

#: the radiance floor of the volumetric ``direction``: voxels whose golden radiance (summed over channels) is
#: below this fraction of its maximum are not judged. Directions are normalised sums of float32 deposits: a
#: voxel the Gaussian's tail barely reaches (radiance 1e-16 of the maximum) holds a sum of rounding residues
#: whose direction may point anywhere, while above 1e-4 its float32 sum (relative error ~1e-7 of the largest
#: deposit) is good to ~1e-3, the key's rtol
RADIANCE_FLOOR = 1e-4
#: the allowed relative error of a radiance (or deposit) volume's total per channel: photons grazing the box
#: may change status (0.5 % of them, ``photon_status``), each carrying its own share of the flux
VOLUME_FLUX = 5e-3
#: the spec of a key no pattern names (a buffer added to the contract before its rule): float arrays as
#: positions, integer and bool arrays (indices, codes) exact; the report says it is the default
DEFAULT = {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.005, "over": "finite", "locate": True,
           "default": True,
           "why": "no rule names this key: the default for float arrays (float64 rounding: 1e-6 + 1e-5 |g|, 0.5 % "
                  "of the finite elements); add its rule to refraction_ref/golden/tolerances.py"}
DEFAULT_INT = {"kind": "exact", "fraction": 0.0, "over": "all", "locate": True, "default": True,
               "why": "no rule names this key: the default for integer and bool arrays (indices, codes, counts): "
                      "equal outside the ambiguity mask; add its rule to refraction_ref/golden/tolerances.py"}

#: (pattern on the key, spec): the first match wins. Stage buffers are ``stage.<stage>.<buffer>``.
TOLERANCES = [
    ("*start_radiance", _pos("photon radiance as emitted: the light's radiance, float64; photons starting on a "
                             "proxy's edge (0.5 %)")),
    ("stage.voxelize.bits", {"kind": "exact", "fraction": 0.002, "over": "nonzero", "locate": True,
                             "silhouette": "counts", "why": _TIE}),
    ("stage.peel.depth_complexity", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True,
                                     "why": "layer counts change only where fragments appear or vanish "
                                            "(silhouettes); judged against the candidate's own bitmask"}),
    ("depth_complexity", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True,
                          "why": "as stage.peel.depth_complexity"}),
    ("stage.receiver_depth.triangle", {"kind": "exact", "fraction": 0.0, "over": "all", "locate": True,
                                       "own_edges": True, "why": "triangle ids tie on shared edges"}),
    ("stage.caustic_final.shadow_margin_*", {
        "kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.005, "over": "finite", "locate": True,
        "why": "how far a receiver point lies behind the shadow map's depth plus the bias: float64 arithmetic "
               "of the point and the light's view (1e-6 + 1e-5 |g|, 0.5 % of the compared pixels); 0 at a "
               "texel-edge tie, -inf where no depth was compared"}),
    ("stage.caustic_final.shadow_*", {
        "kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True,
        "margin_key": "shadow_margin_", "margin_atol": 1e-6, "margin_rtol": 1e-5,
        "why": "the shadow test's verdict at every receiver pixel seen directly (1 lit, 2 in shadow): equal, "
               "but where the golden's shadow_margin_l is within 1e-6 + 1e-5 far of 0 (the depths compared "
               "agree to the positions' tolerance at the light's far plane, or the point lies within 5e-3 of "
               "a light texel's edge across which the verdict changes) and at object silhouettes and the "
               "receivers' outline; a shadow map read one texel off fails"}),
    ("stage.receiver_hit.hit_face_*", {"kind": "exact", "fraction": 0.005, "over": "all", "locate": True,
                                       "face_ties": True, "inside": 1.0,
                                       "why": "a photon whose hit lies within two camera pixels of an edge two "
                                              "receiver triangles share may name either (inside the ambiguity "
                                              "mask); elsewhere 0.5 % of the photons (hit or missed at a "
                                              "receiver's outer edge, a depth discontinuity or the image's border)"}),
    ("*hit_receiver", {"kind": "exact", "fraction": 0.005, "over": "all",
                       "why": "the receiver a photon met is an index: equal, but for photons grazing a receiver's "
                              "edge or the volume's box (0.5 %, as photon_status)"}),
    ("*path_index", {"kind": "exact", "fraction": 0.0, "over": "all",
                     "why": "photon indices of the sample (evenly spaced over P): integers, no rounding"}),
    ("photon_steps", {"kind": "close", "atol": 0.0, "rtol": 1e-5, "over": "all",
                      "why": "the total marching steps of all photons, a count: within 1e-5 of it (a photon grazing "
                             "the box may take a step more or less)"}),
    ("*photon_status", {"kind": "exact", "fraction": 0.005, "over": "all",
                        "why": "photons grazing the volume's box or a receiver's edge"}),
    ("*status", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True, "own_edges": True,
                 "inside": 0.02, "why": _CODE}),
    ("*interfaces", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True, "own_edges": True,
                     "inside": 0.02, "why": _CODE}),
    ("*hit", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True, "own_edges": True,
              "inside": 0.02, "why": _CODE}),
    ("*object_mask*", {"kind": "exact", "fraction": 0.0, "over": "nonzero", "locate": True, "own_edges": True,
                       "inside": 0.02, "why": _CODE}),
    ("*.octree.level", {"kind": "exact", "fraction": 0.0, "over": "all",
                        "why": "the leaf test on the golden's own index volume: no ambiguity"}),
    ("*plane_index*", {"kind": "exact", "over": "all", "why": "the planes drawn: a decision of smart slicing"}),
    ("*planes_used*", {"kind": "exact", "over": "all", "why": "the planes drawn: a decision of smart slicing"}),
    ("*path_dir", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite",
                   "locate": True, "split_first": True, "why": _DIR + "; interface 0 judged apart from the rest"}),
    ("*path_pos", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.005, "over": "finite",
                   "locate": True, "split_first": True, "why": _POS + "; interface 0 judged apart from the rest"}),
    ("*_dir", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite", "locate": True,
               "why": _DIR}),
    ("*_dir_*", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite", "why": _DIR}),
    ("*normals", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite", "locate": True,
                  "why": "unit normals: differences follow slice ties and silhouettes (1 % elsewhere)"}),
    ("*normal_*", {"kind": "angle", "deg": 0.05, "norm": 1e-6, "fraction": 0.01, "over": "finite", "locate": True,
                   "why": "unit normals of the receivers: faces tie on shared edges"}),
    ("*direction", {"kind": "close", "atol": 1e-4, "rtol": 1e-3, "fraction": 0.01, "over": "all",
                    "weight_key": "radiance", "floor": RADIANCE_FLOOR,
                    "why": "smoothed photon directions: deposition order; judged only in voxels whose golden "
                           "radiance (summed over channels) is above 1e-4 of its maximum (an almost empty "
                           "voxel's normalised direction is rounding noise); 1 % of those voxels"}),
    ("*caustic_frame_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all", "why": _EXACT_F}),
    ("*frame_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all", "why": _EXACT_F}),
    ("*camera_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all", "why": _EXACT_F}),
    ("*box_*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all", "why": _EXACT_F}),
    ("stage.caustics.planes_[0-9]*", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all",
                                      "why": "plane offsets from the box (eqs. 4-1..4-9): float64 rounding only"}),
    ("*caustic_map*", {"kind": "close", "flux": FLUX, "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01,
                       "over": "nonzero", "locate": True, "why": _MAP}),
    ("*caustic_rgb*", {"kind": "close", "flux": FLUX, "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01,
                       "over": "nonzero", "locate": True, "why": _MAP}),
    ("*splat_*", {"kind": "close", "flux": FLUX, "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01,
                  "over": "nonzero",
                  "locate": True, "why": _MAP}),
    ("*plane_maps*", {"kind": "close", "flux": FLUX, "atol": 2e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01,
                      "over": "nonzero", "locate": True,
                      "why": _MAP + "; counted over each plane's lit texels, not diluted over the planes"}),
    ("*radiance", {"kind": "close", "atol": 1e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01, "over": "nonzero",
                   "flux": VOLUME_FLUX,
                   "why": "photon radiance in the volume: deposition order (1 % of the lit voxels); the total per "
                          "channel within 0.5 % (photons grazing the box change status, 0.5 %)"}),
    ("stage.march.deposit*", {"kind": "close", "atol": 1e-3, "rtol": 1e-3, "scale": "max", "fraction": 0.01,
                              "over": "nonzero", "flux": VOLUME_FLUX,
                              "why": "deposits before smoothing: as the radiance volume (deposition order, 1 % of "
                                     "the lit voxels; the total per channel within 0.5 %): a deposit without its "
                                     "segment length or without the extinction fails here"}),
    ("stage.image.water_pos", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.01, "over": "finite",
                               "locate": True,
                               "why": "where the eye ray meets the water mesh: float64 ray-triangle arithmetic "
                                      "(1e-5 relative); a ray through a shared edge of two water triangles, "
                                      "silhouettes and status changes free, 1 % of the pixels elsewhere"}),
    ("stage.image.receiver_pos", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.01, "over": "finite",
                                  "locate": True,
                                  "why": "the receiver point a pixel shows: float64 arithmetic of the refracted (or "
                                         "direct) ray; the receiver's silhouette and status changes free, 1 % "
                                         "of the pixels elsewhere (rays through a water mesh edge)"}),
    ("stage.image.water_length", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "fraction": 0.01, "over": "finite",
                                  "locate": True,
                                  "why": "distance travelled in water: |receiver_pos - water_pos| in float64, "
                                         "judged as those two positions"}),
    ("*image*", {"kind": "close", "atol": 2e-3, "rtol": 1e-3, "fraction": 0.01, "over": "all", "locate": True,
                 "why": "colours: 8-bit-level differences; silhouettes free, 1 % of the pixels elsewhere "
                        "(slice ties move a path)"}),
    ("*diffuse_*", {"kind": "close", "atol": 1e-6, "rtol": 1e-6, "fraction": 0.0, "over": "nonzero",
                    "locate": True, "why": "albedo per texel: differs only beside a depth discontinuity"}),
    ("stage.photon_trace.ldi_*", {"kind": "close", "atol": 1e-5, "rtol": 1e-5, "slope": SNAP_SLOPE,
                                  "snap_slope": FLOAT32_SNAP_SLOPE, "snap_fraction": FLOAT32_SNAP_FRACTION,
                                  "fraction": 0.0, "over": "finite", "locate": True, "why": _LIGHT_LDI}),
    ("*ldi*", {"kind": "close", "atol": 1e-5, "rtol": 1e-5, "slope": SNAP_SLOPE, "fraction": 0.0, "over": "finite",
               "locate": True,
               "why": "layer depths are slice centres: they differ only where the bitmask does (judged against "
                      "the candidate's own bitmask) or at silhouettes; " + _SLOPE}),
    ("stage.minmax.z*", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "slope": SNAP_SLOPE, "fraction": 0.005,
                         "over": "finite", "locate": True, "why": _DEPTH}),
    ("stage.voxelize.z*", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "slope": SNAP_SLOPE, "fraction": 0.005,
                           "over": "finite", "locate": True, "why": _DEPTH}),
    ("stage.receiver_depth.depth", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "slope": SNAP_SLOPE,
                                    "fraction": 0.005, "over": "finite", "locate": True, "why": _DEPTH}),
    ("stage.level_map.position_*", {"kind": "close", "atol": 1e-6, "rtol": 1e-5, "slope": SNAP_SLOPE,
                                    "fraction": 0.005, "over": "finite", "locate": True, "why": _DEPTH}),
    ("photon_exit_pos", _pos(_PHOTON_POS)),
    ("stage.march.exit_pos", _pos(_PHOTON_POS)),
    ("*exit_pos", _pos(_POS)),
    ("*path_length", _pos("optical path lengths per pixel: sums of float64 segment lengths times the index; "
                          "differences follow slice ties and silhouettes (0.5 % of the finite pixels elsewhere)")),
    ("*ray_origin", _pos("primary ray origins: the eye (or the orthographic window's points), float64 set-up "
                         "arithmetic")),
    ("*exit_pos_[0-9]*", _pos(_PHOTON_POS)),
    ("*hit_pos*", _pos(_PHOTON_POS)),
    ("*start_pos", _pos(_PHOTON_POS)),
    ("*photon_paths.paths", _pos("the sampled photons' positions after each step, marched alone: float64 "
                                 "arithmetic of the march; a photon grazing the box stops a step earlier or later "
                                 "(0.5 % of the recorded points)")),
    ("*water_vertices", _pos("the water grid's vertices (eq. 2-8's waves): float64 arithmetic")),
    ("ior", _pos("the index volume: generated or voxelized and blurred, float64 set-up arithmetic")),
    ("*ior_volume", _pos("the index volume: generated or voxelized and blurred, float64 set-up arithmetic")),
    ("volume_bounds", {"kind": "close", "atol": 1e-7, "rtol": 1e-7, "over": "all", "why": _EXACT_F}),
    ("*gradient.field", _pos("(n, dn/dx, dn/dy, dn/dz) in float32: central and one-sided differences, float32 "
                             "rounding")),
    ("*step_max", _pos("octree step sizes (float32, inf in constant nodes): the leaf's size from the octree's "
                       "own index ranges")),
    ("*reduce.bounds_*", _pos("each layer's search bound: the extremum of its MIP level plus the margin, float64")),
    ("*geometry.absorption", _pos("the objects' absorption, copied from the scene")),
    ("*", DEFAULT),
]

#: the share of the informative elements that may differ inside the ambiguity mask, unless a spec says
INSIDE = 0.05

#: keys of maps from jittered photons, judged by the Z-test when the oracle stored batches
NOISY = ("caustic_map_*",)
ZTEST = {"kind": "ztest", "alpha": 1e-3, "atol": 1e-3, "over": "all",
         "why": "jittered photons: a Z-test against the oracle's K independent batches, Bonferroni-corrected"}


def tolerance_for(key, noisy=False, dtype=None):
    """The tolerance spec of an array key (a copy of the first matching :data:`TOLERANCES` entry).

    Parameters
    ----------
    key : str
        An array key.
    noisy : bool
        The case is judged statistically: keys matching :data:`NOISY` get the
        :data:`ZTEST` spec.
    dtype : numpy dtype, optional
        The array's dtype: a key no pattern names gets :data:`DEFAULT_INT` when
        it is an integer or bool array, else :data:`DEFAULT`.

    Returns
    -------
    dict
        The spec (``kind``, tolerances, ``over``, ...), a copy.

    Raises
    ------
    KeyError
        No pattern matches ``key``.
    """
    if noisy and any(fnmatch.fnmatchcase(key, p) for p in NOISY):
        return dict(ZTEST)
    for pat, spec in TOLERANCES:
        if fnmatch.fnmatchcase(key, pat):
            if spec is DEFAULT and dtype is not None and np.dtype(dtype).kind in "biu":
                return dict(DEFAULT_INT)
            return dict(spec)
    raise KeyError(key)


#: the categories of :func:`finiteness`, by code
FINITENESS = ("NaN", "+inf", "-inf", "finite")


def finiteness(a):
    """Per element of a float array its :data:`FINITENESS` code: 0 NaN, 1 +inf, 2 -inf, 3 finite.

    Parameters
    ----------
    a : ndarray
        A float array.

    Returns
    -------
    int ndarray
        Codes with the shape of ``a``.
    """
    return np.where(np.isnan(a), 0, np.where(a == np.inf, 1, np.where(a == -np.inf, 2, 3)))


def nonfinite_mismatch(c, g):
    """Counts of NaN / inf / finite mismatches by category (``{"NaN where the golden has +inf": n, ...}``).

    Parameters
    ----------
    c : ndarray
        Candidate array.
    g : ndarray
        Golden array, same shape.

    Returns
    -------
    dict of str to int
        Only the categories that occur; empty for non-float arrays.
    """
    if c.dtype.kind not in "fc" or g.dtype.kind not in "fc":
        return {}
    names = FINITENESS
    cc, gc = finiteness(c), finiteness(g)
    out = {}
    for i in range(4):
        for j in range(4):
            if i != j:
                n = int(np.count_nonzero((cc == i) & (gc == j)))
                if n:
                    out[f"{names[i]} where the golden has {names[j]}"] = n
    return out


def informative(c, g, over):
    """The elements a fraction counts over (``over``: all, nonzero, finite), per element of the judged array.

    Parameters
    ----------
    c, g
        As :func:`nonfinite_mismatch`.
    over : {'all', 'nonzero', 'finite'}
        ``nonzero``: where either is nonzero (NaN counts); ``finite``: where
        either is finite (for float arrays); otherwise every element.

    Returns
    -------
    bool ndarray
        Mask with the shape of ``g``.
    """
    if over == "nonzero":
        with np.errstate(invalid="ignore"):
            m = (np.nan_to_num(c, nan=1.0) != 0) | (np.nan_to_num(g, nan=1.0) != 0)
    elif over == "finite" and g.dtype.kind in "fc":
        m = np.isfinite(c) | np.isfinite(g) if c.dtype.kind in "fc" else np.isfinite(g)
    else:
        m = np.ones(g.shape, bool)
    return m


def elementwise(c, g, spec, batches):
    """Per element: failing mask (over the array's elements, or its vectors for ``angle``), error, detail.

    Parameters
    ----------
    c, g : ndarray
        The candidate's and the golden's arrays (one shape).
    spec : dict
        The tolerance (its ``kind`` and that kind's entries).
    batches : ndarray, optional
        The golden's batches (``ztest``).

    Returns
    -------
    bad : bool ndarray
        The failing elements, before any allowance.
    error : dict
        The measured error.
    detail : str
    """
    kind = spec["kind"]
    if kind == "exact":
        bad = (c != g) if g.dtype.kind not in "fc" else ~((c == g) | (np.isnan(c) & np.isnan(g)))
        err = {"differing": int(np.count_nonzero(bad))}
        detail = f"{err['differing']} of {bad.size} elements differ"
    elif kind == "close":
        c64, g64 = c.astype(np.float64), g.astype(np.float64)
        fin = np.isfinite(g64)
        scale = float(np.max(np.abs(g64[fin]))) if spec.get("scale") == "max" and fin.any() else 1.0
        tol = spec["atol"] * scale + spec["rtol"] * np.abs(np.where(fin, g64, 0.0))
        slope = float(spec.get("slope", 0.0))
        if slope:
            tol = tol + slope * neighbour_step(g64)
        with np.errstate(invalid="ignore"):
            diff = np.abs(c64 - g64)
            bad = (np.isnan(c64) != np.isnan(g64)) | (fin & ~(diff <= tol)) | (np.isinf(g64) & (c64 != g64))
        d = diff[fin & np.isfinite(c64)]
        err = {"max_abs": float(d.max()) if d.size else 0.0, "scale": scale}
        detail = (f"max |c - g| {err['max_abs']:.3g} over the finite pairs (tolerance {spec['atol']:g} x "
                  f"{scale:.3g} + {spec['rtol']:g} |g|" + (f" + {slope:.3g} step(g)" if slope else "") + ")")
    elif kind == "angle":
        c64, g64 = c.astype(np.float64), g.astype(np.float64)
        if c64.shape[-1] != 3:
            raise ValueError("angle tolerance on an array whose last axis is not 3")
        fin = np.all(np.isfinite(g64), axis=-1)
        cfin = np.all(np.isfinite(c64), axis=-1)
        both = fin & cfin
        ang = np.zeros(fin.shape)
        nrm = np.linalg.norm(np.where(np.isfinite(c64), c64, 0.0), axis=-1)
        gn = np.linalg.norm(np.where(np.isfinite(g64), g64, 0.0), axis=-1)
        dots = np.sum(np.where(both[..., None], c64 * g64, 0.0), axis=-1)
        crs = np.linalg.norm(np.cross(np.where(both[..., None], c64, 0.0), np.where(both[..., None], g64, 0.0)),
                             axis=-1)
        ang[both] = np.degrees(np.arctan2(crs[both], dots[both]))
        unit = both & (gn > 0.5)  # zero vectors (no photon passed, no surface) must stay zero
        bad = (fin != cfin) | (unit & ((ang > spec["deg"]) | (np.abs(nrm - 1.0) > spec["norm"]))) \
            | (both & (gn <= 0.5) & (nrm > 1e-9))
        a = ang[unit]
        err = {"max_deg": float(a.max()) if a.size else 0.0,
               "max_norm_error": float(np.abs(nrm[unit] - 1.0).max()) if unit.any() else 0.0}
        detail = (f"max angle {err['max_deg']:.3g} deg (tolerance {spec['deg']:g}), max | |c| - 1 | "
                  f"{err['max_norm_error']:.2g} (tolerance {spec['norm']:g})")
    elif kind == "ztest":
        if batches is None:
            raise ValueError("a ztest tolerance needs the oracle's batches")
        b = np.asarray(batches, np.float64)
        K = b.shape[0]
        mean = b.mean(axis=0)
        var = b.var(axis=0, ddof=1) if K > 1 else np.zeros_like(mean)
        c64 = c.astype(np.float64)
        scale = float(np.abs(mean).max()) or 1.0
        q = float(spec.get("quantum", 0.0))
        p = (np.count_nonzero(b != 0, axis=0) + 1.0) / (K + 2.0)
        var_t = var * (1.0 + 1.0 / K) + p * q * q
        has = var_t > 0
        n = max(int(np.count_nonzero(has)), 1)
        t = _z_threshold(spec["alpha"] / n)  # two-sided Bonferroni threshold: P(|Z| > t) = alpha / n
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(has, (c64 - mean) / np.sqrt(np.where(has, var_t, 1.0)), 0.0)
        bad = (has & ~(np.abs(z) <= t)) | (~has & ~(np.abs(c64 - mean) <= spec["atol"] * scale))
        err = {"max_abs_z": float(np.abs(z[has]).max()) if has.any() else 0.0, "threshold": t, "batches": K}
        detail = f"max |z| {err['max_abs_z']:.3g} (threshold {t:.3g}: alpha {spec['alpha']:g} over {n} texels, K = {K})"
    else:
        raise ValueError(f"unknown tolerance kind {kind!r}")
    return bad, err, detail


def neighbour_step(g):
    """Per element, the largest ``|g(p) - g(q)|`` over its finite 8 neighbours ``q`` in the picture.

    The picture is the last two axes (rows and columns: (H, W), or (L, H, W) per layer); 0 where the
    element or all its neighbours are not finite. Diagonal neighbours count, so ``step >= |g_x| + |g_y|``
    on a plane: a sample moved by ``s`` pixels along both axes moves the value by at most ``s * step``.

    References
    ----------
    docs/oracle.md, "Conformance" (the ``slope`` term of ``close``).
    """
    g = np.asarray(g, np.float64)
    if g.ndim < 2:
        raise ValueError("a slope tolerance needs an array with picture axes (..., H, W)")
    H, W = g.shape[-2:]
    fin = np.isfinite(g)
    p = np.pad(np.where(fin, g, 0.0), [(0, 0)] * (g.ndim - 2) + [(1, 1), (1, 1)])
    pf = np.pad(fin, [(0, 0)] * (g.ndim - 2) + [(1, 1), (1, 1)])
    out = np.zeros(g.shape)
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            if di == dj == 1:
                continue
            ok = fin & pf[..., di:di + H, dj:dj + W]
            d = np.abs(p[..., di:di + H, dj:dj + W] - np.where(fin, g, 0.0))
            out = np.where(ok, np.maximum(out, d), out)
    return out


def fold_mask(a, shape):
    """Reduce a per-element mask to ``shape`` (the failing mask's: vectors fold their last axis) with any().

    Parameters
    ----------
    a : bool ndarray
    shape : tuple of int

    Returns
    -------
    bool ndarray
        Broadcast to ``shape``.
    """
    while a.ndim > len(shape):
        a = a.any(axis=-1)
    return np.broadcast_to(a, shape)


def _flux_axes(g):
    """The axes a total sums over: per channel for (..., 3) arrays of 3 or more axes, else all.

    The level map's ``plane_maps_r_l`` (k, H, W) is summed over its planes too: a fragment on the boundary
    between two planes' acceptance ranges moves its flux from one plane to the next (an unsnapped
    rasterizer moves 0.3-0.6 % of a plane's flux so) while the sum keeps it.
    """
    if g.ndim >= 3 and g.shape[-1] == 3:
        return tuple(range(g.ndim - 1))
    return tuple(range(g.ndim))


def flux_error(cand, gold):
    """Relative error of the totals, per channel (``(..., 3)`` arrays of 3 or more axes), else of the whole array.

    ``|sum c - sum g| / sum |g|`` over the finite elements; 0 where both totals are 0, inf where only the
    golden's is.

    Parameters
    ----------
    cand, gold : ndarray
        Same shape.

    Returns
    -------
    err, ratio : 1-D float ndarrays
        Per group: the relative error and ``sum c / sum g`` (NaN where ``sum g`` is 0).

    References
    ----------
    docs/oracle.md, "Conformance" (the ``flux`` term of ``close``).
    """
    g = np.asarray(gold, np.float64)
    c = np.asarray(cand, np.float64)
    ax = _flux_axes(g)
    sg = np.where(np.isfinite(g), g, 0.0).sum(axis=ax)
    ag = np.abs(np.where(np.isfinite(g), g, 0.0)).sum(axis=ax)
    sc = np.where(np.isfinite(c), c, 0.0).sum(axis=ax)
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.where(ag > 0, np.abs(sc - sg) / np.where(ag > 0, ag, 1.0), np.where(sc == 0, 0.0, np.inf))
        ratio = np.where(sg != 0, sc / np.where(sg != 0, sg, 1.0), np.nan)
    return np.atleast_1d(err), np.atleast_1d(ratio)


def _total_ratio(ratio, err):
    """One group's total against the golden's, for the report: never NaN where a total is zero.

    ``"1.0012 x the golden's"``; ``"both empty"`` where both totals are 0 (a receiver no photon reaches);
    ``"the golden's total is 0, the candidate's is not"`` where only the candidate has flux.
    """
    if np.isfinite(ratio):
        return f"{ratio:.5g} x the golden's"
    return "both empty" if err == 0 else "the golden's total is 0, the candidate's is not"


def moments_test(cand, batches, alpha):
    """The second test of ``ztest`` maps: the map's total and centroid against the K batches' (Student's t).

    Per statistic ``s`` (the total, the flux-weighted centroid's column and row, in texels)
    ``t = (s(c) - mean_k s(b_k)) / (sd_k s(b_k) sqrt(1 + 1/K))``: a candidate drawn independently from the
    oracle's distribution gives a Student's t with K - 1 degrees of freedom (the statistics are sums over
    many photons, so close to normal). Two-sided, Bonferroni over the three at ``alpha``. A map shifted by
    one texel moves its centroid by about one texel, where the batches' centroids scatter by hundredths,
    while the per-texel test sees each texel's change within its own noise.

    Parameters
    ----------
    cand : (H, W) ndarray
        The candidate map.
    batches : (K, H, W) ndarray
        The oracle's independent maps.
    alpha : float
        Significance of the three tests together.

    Returns
    -------
    dict
        ``ok``, ``t`` (per statistic), ``threshold``, ``shift`` (the candidate's centroid minus the
        batches' mean, (col, row) texels) and ``sd`` (the batches' centroid spread, texels).
    """
    from scipy.stats import t as student

    b = np.asarray(batches, np.float64)
    c = np.asarray(cand, np.float64)
    K = b.shape[0]
    H, W = c.shape[-2:]
    cols = np.arange(W) + 0.5
    rows = np.arange(H) + 0.5

    def stats(m):
        tot = m.sum(axis=(-2, -1))
        with np.errstate(invalid="ignore", divide="ignore"):
            cx = (m.sum(axis=-2) * cols).sum(axis=-1) / tot
            cy = (m.sum(axis=-1) * rows).sum(axis=-1) / tot
        return np.stack([tot, cx, cy], axis=-1)

    sb, sc = stats(b), stats(c)
    # an empty batch or candidate has no centroid: the total judges emptiness, the centroid is left out
    n = np.count_nonzero(np.isfinite(sb), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, np.nansum(sb, axis=0) / np.maximum(n, 1), np.nan)
        sd = np.sqrt(np.nansum((sb - mean) ** 2, axis=0) / np.maximum(n - 1, 1))
    sd = np.where(n > 1, sd, 0.0)
    thr = float(student.isf(alpha / 3.0 / 2.0, max(K - 1, 1)))
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(sd > 0, (sc - mean) / (np.where(sd > 0, sd, 1.0) * np.sqrt(1.0 + 1.0 / K)),
                     np.where(np.isclose(sc, mean, rtol=1e-9, atol=0.0), 0.0, np.inf))
    t[1:] = np.where(np.isnan(sc[1:]) | np.isnan(mean[1:]), 0.0, t[1:])
    t = np.nan_to_num(t, nan=np.inf)
    return {"ok": bool(np.all(np.abs(t) <= thr)), "t": [float(x) for x in t], "threshold": thr,
            "shift": [float(sc[1] - mean[1]), float(sc[2] - mean[2])], "sd": [float(sd[1]), float(sd[2])]}


def judge(cand, gold, spec, batches=None, ambiguous=None, judged=None):
    """Judge one array against the golden.

    Parameters
    ----------
    cand, gold : ndarray
        Same shape (checked by the caller).
    spec : dict
        A :data:`TOLERANCES` spec (or :data:`ZTEST`).
    batches : (K, ...) ndarray, optional
        The oracle's independent batches, for ``ztest``.
    ambiguous : bool ndarray, optional
        The ambiguity mask (broadcastable to the failing mask), for ``locate`` specs.
    judged : bool ndarray, optional
        The elements judged at all (broadcastable to the failing mask; the ``weight_key`` floor of the
        volumetric ``direction``): the others neither fail nor count as informative.

    Returns
    -------
    dict
        ``ok``, ``failing`` (located failures over informative elements), ``allowed``, ``counts``
        (failing, inside the ambiguity mask, located, informative), ``nonfinite`` (mismatch counts by
        category), ``error`` (measured), ``detail``, ``why``, ``parts`` (``split_first``: interface 0 and
        the rest judged apart) and ``bad`` (the located failing elements, for the mask file).
    """
    allowed = float(spec.get("fraction", 0.0))
    c = np.asarray(cand)
    g = np.asarray(gold)
    bad, err, detail = elementwise(c, g, spec, batches)
    info = fold_mask(informative(c, g, spec.get("over", "all")), bad.shape) | bad
    if judged is not None:
        jm = fold_mask(np.asarray(judged, bool), bad.shape)
        bad, info = bad & jm, info & jm
        detail += f"; judged where the golden's {spec.get('weight_key', 'weight')} is above " \
                  f"{spec.get('floor', 0):g} of its maximum: {int(np.count_nonzero(jm))} of {jm.size} elements"
    amb = np.zeros(bad.shape, bool) if ambiguous is None else fold_mask(np.asarray(ambiguous, bool), bad.shape)
    located = bad & ~amb
    nonfinite = nonfinite_mismatch(c, g)
    snap = None
    if spec.get("snap_slope") and spec["kind"] == "close":
        # the located failures within the wider term count against snap_fraction, the rest against fraction
        hard = elementwise(c, g, dict(spec, slope=spec["snap_slope"]), batches)[0]
        if judged is not None:
            hard = hard & jm
        snap = located & ~hard

    inside = float(spec.get("inside", INSIDE)) if ambiguous is not None else 1.0

    def verdict(loc, inf, b, a):
        n_info = int(np.count_nonzero(inf))
        n_loc = int(np.count_nonzero(loc))
        frac = n_loc / max(n_info, 1)
        n_in = int(np.count_nonzero(b & a))
        return {"ok": frac <= allowed and n_in <= inside * max(n_info, 1), "failing": frac, "counts": {
            "failing": int(np.count_nonzero(b)), "inside_ambiguity": int(np.count_nonzero(b & a)),
            "located": n_loc, "informative": n_info}}

    parts = None
    if spec.get("split_first") and bad.ndim >= 3 and bad.shape[2] > 1:  # (H, W, K): interface k on axis 2
        parts = {name: verdict(located[:, :, sl], info[:, :, sl], bad[:, :, sl], amb[:, :, sl])
                 for name, sl in (("interface 0", slice(0, 1)), ("interfaces 1+", slice(1, None)))}
        v = verdict(located, info, bad, amb)
        v["ok"] = all(p["ok"] for p in parts.values())
        v["failing"] = max(p["failing"] for p in parts.values())
    else:
        v = verdict(located if snap is None else located & ~snap, info, bad, amb)
    cn = v["counts"]
    detail += (f"; {fmt_share(cn['located'], cn['informative'])} of the informative elements failing outside "
               f"the ambiguity mask ({cn['inside_ambiguity']} more inside it, {100 * inside:.3g} % allowed there)")
    if snap is not None:
        n_snap, n_info = int(np.count_nonzero(snap)), max(cn["informative"], 1)
        ok_snap = n_snap <= float(spec.get("snap_fraction", 0.0)) * n_info
        v["ok"] = v["ok"] and ok_snap
        cn["snap"] = n_snap
        detail += (f"; {fmt_share(n_snap, cn['informative'])} more beyond it but within {spec['snap_slope']:.3g} "
                   f"step(g) (a vertex on the neighbouring snap step; "
                   f"{100 * float(spec.get('snap_fraction', 0.0)):.3g} % allowed){'' if ok_snap else ' FAIL'}")
    if spec.get("flux") and spec["kind"] == "close" and c.shape == g.shape:
        fe, ratio = flux_error(c, g)
        ok_flux = bool(np.all(fe <= spec["flux"]))
        err["flux_error"] = float(np.max(fe)) if fe.size else 0.0
        v["ok"] = v["ok"] and ok_flux
        per = ", ".join(_total_ratio(r, e) for r, e in zip(ratio[:8], fe[:8]))
        detail += (f"; total {per} (largest error {100 * err['flux_error']:.3g} %, tolerance "
                   f"{100 * spec['flux']:.3g} %{'' if ok_flux else ' FAIL'})")
        v["flux_ok"] = ok_flux
    if spec["kind"] == "ztest" and batches is not None and spec.get("moments", True) and g.ndim == 2:
        mt = moments_test(c, batches, spec["alpha"])
        err["moments"] = mt
        v["ok"] = v["ok"] and mt["ok"]
        v["moments_ok"] = mt["ok"]
        detail += (f"; total and centroid: t = {', '.join(f'{x:.3g}' for x in mt['t'])} (threshold "
                   f"{mt['threshold']:.3g}, Student's t over {np.shape(batches)[0]} batches; centroid shift "
                   f"({mt['shift'][0]:.3g}, {mt['shift'][1]:.3g}) texels, batches' spread "
                   f"({mt['sd'][0]:.2g}, {mt['sd'][1]:.2g})){'' if mt['ok'] else ' FAIL'}")
    if parts:
        detail += "; " + ", ".join(f"{n}: {p['counts']['located']} of {p['counts']['informative']}"
                                   f"{'' if p['ok'] else ' FAIL'}" for n, p in parts.items())
    if nonfinite:
        detail += "; " + ", ".join(f"{n} {k}" for k, n in nonfinite.items())
    return dict(v, allowed=allowed, inside_allowed=inside, error=err, detail=detail, why=spec.get("why", ""), nonfinite=nonfinite,
                parts=parts, bad=located)


def _z_threshold(p):
    """``t`` with ``P(|Z| > t) = p`` for a standard normal Z."""
    from scipy.stats import norm

    return float(norm.isf(p / 2.0))
