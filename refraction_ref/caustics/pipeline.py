"""Caustics from multiply-refracted photons onto diffuse receivers (Chaudhari 2008, §4.1), pass by pass.

==========================  =====================================================  ===========
stage (``timings_ms``)      pass                                                   section
==========================  =====================================================  ===========
``receivers``               receiver triangles and their caustic-map frames         §4.1
``receiver_depth``          the receivers' depth image from the camera              §4.1
``photon_trace``            per light: its camera, then min/max, voxelization,      §3.3-3.8
                            peeling, reduction (``photon_trace.minmax`` ...) and
                            one photon per texel through every layer
``receiver_hit``            eye-space march (Krüger 2006) or Embree                 §4.1
``splat``                   bilinear splat of irradiance into each receiver's map   §2.3.2
``gather``                  Gaussian gathering in a window (Wyman & Davis 2006)     §2.3.2
``caustic_final``           receivers lit directly (shadow test) and by caustics;   §4.1
                            the object with single-surface and multi-layer passes
==========================  =====================================================  ===========

These are stages of the image-space and exact methods' graphs
(:func:`imagespace_caustic_stages`,
:func:`refraction_ref.exact.caustics.exact_caustic_stages`), added
when the scene has lights and receivers.

Outputs (docs/oracle.md, per receiver ``r``): ``caustic_map_r`` (Hc, Wc) float32,
the irradiance carried by photons that passed through a refractive object,
for lights of unit strength (unit irradiance perpendicular to a directional
light, unit intensity of a point light), averaged over the three colour
channels of the absorption and summed over lights; ``caustic_frame_r``
(4, 3). Added: ``caustic_rgb_r`` (Hc, Wc, 3) float32, the same per channel
with each light's radiance (what the final image uses);
``image_caustics`` (H, W, 3) float32, the final image with the full
multi-layer pass through the object; ``image_caustics_single``, the
thesis's final pass (single-surface refraction, image-space method only).
``image`` keeps its meaning (the object's refraction of the environment).

The exact reference (``--method exact``) emits ``exact.photons`` squared
jittered photons through the same window, traces them through the real
triangles (:func:`~refraction_ref.exact.trace_exact`), meets the receivers
with Embree and splats them into the same maps without gathering; the
relative L1 difference of its two interleaved halves (blurred one texel),
halved, is its own noise, reported per receiver in ``meta['caustics']``.

Threads: every stage runs on ``numba.get_num_threads()`` threads and gives
the same bits whatever their number. Per-photon and per-pixel kernels write
only their own rows (the march, the map look-ups, the shadow-map test, the
shading sums); the splat gives each band of map rows to one thread, which
adds its photons in index order; both passes of the gathering own rows of
their output; Embree's receiver hits and shadow rays run in fixed chunks on
the shared thread pool (:func:`refraction_ref.embree.run_chunks`). The final
pass shades the receivers seen directly and both passes' rays in one call
(both methods). The exact reference's jittered photons come from one random
stream, drawn in fixed chunks that each jump to their own draws
(:func:`~.light.window_samples`); its splat makes the whole map and the two
halves' maps from one footprint and binning, the halves' blur for the noise
estimate is a kernel (:func:`~refraction_ref.metrics.relative_l1`),
and the rows that NumPy's boolean masks and fancy indexing gathered or
scattered (exited photons, receiver pixels, the energy book-keeping's
subsets) are gathered by kernels in the same order. Sums that cross threads
stay NumPy's, over the same arrays.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..embree import mesh_scene
from ..environment import environment_lookup
from ..graph import Stage
from ..lights import light_camera
from ..optics import beer_lambert, refract
from ..status import EXITED
from .light import texel_flux, window_samples
from .receivers import IndexedTriangles, eye_buffers, hit_exact, march_eyespace, receiver_set
from .shade import take_rows, exact_visibility, shade_points, shadow_map_visibility
from .splat import (accumulate_light, channel_mean, finite_maps, gather_gaussian, receiver_photons,
                    splat_bilinear, splat_bilinear_groups)

__all__ = ["has_caustics", "imagespace_caustic_stages", "caustic_arrays", "receiver_hits",
           "splat_maps", "merge_caustics", "skip_reason", "camera_array", "receiver_stages", "photon_buffer_names",
           "per_light_names", "gather_names", "receiver_hit_stage", "splat_stage", "gather_stage", "shade_rays",
           "put_rows"]


@nb.njit(cache=True, parallel=True)
def _put_rows_kernel(a, idx, vals, scale):
    # a[idx] = vals (scale False) or a[idx] *= vals[idx] (scale True)
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        i = idx[k]
        for c in range(a.shape[1]):
            if scale:
                a[i, c] *= vals[i, c]
            else:
                a[i, c] = vals[k, c]


def put_rows(a, idx, vals):
    """``a[idx] = vals`` (rows of an (N, C) float64 array), on every thread."""
    if len(idx):
        _put_rows_kernel(a, np.ascontiguousarray(idx, np.int64), np.ascontiguousarray(vals, dtype=np.float64), False)


@nb.njit(cache=True, parallel=True)
def _mul_rows_kernel(a, idx, vals):
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        for c in range(a.shape[1]):
            a[idx[k], c] *= vals[k, c]


def _mul_rows(a, idx, vals):
    """``a[idx] *= vals`` (rows of an (N, C) float64 array), on every thread."""
    if len(idx):
        _mul_rows_kernel(a, np.ascontiguousarray(idx, np.int64), np.ascontiguousarray(vals, dtype=np.float64))


@nb.njit(cache=True, parallel=True)
def _depth_points_kernel(origin, rdir, rdepth, idx, fwd, out):
    # origin[i] + d (depth[i] / (d . fwd)), vec3.dot's order
    for k0 in nb.prange(idx.shape[0]):
        k = np.int64(k0)
        i = idx[k]
        s = rdepth[i] / (rdir[i, 0] * fwd[0] + rdir[i, 1] * fwd[1] + rdir[i, 2] * fwd[2])
        for c in range(3):
            out[k, c] = origin[i, c] + rdir[i, c] * s


def _depth_points(origin, rdir, rdepth, idx, fwd):
    out = np.empty((len(idx), 3))
    if len(idx):
        _depth_points_kernel(origin, rdir, rdepth, np.ascontiguousarray(idx, np.int64),
                             np.ascontiguousarray(fwd, dtype=np.float64), out)
    return out


@nb.njit(cache=True, parallel=True)
def _front_points_kernel(t, dv, oi, zfront, W, H, sx, sy, ortho, pv):
    # t = where(all(isfinite(t)), t, dv) in place; pv: _final_imagespace's NumPy expressions
    for k0 in nb.prange(oi.shape[0]):
        k = np.int64(k0)
        if not (math.isfinite(t[k, 0]) and math.isfinite(t[k, 1]) and math.isfinite(t[k, 2])):
            for c in range(3):
                t[k, c] = dv[k, c]
        p = oi[k]
        ii = p // W
        jj = p - ii * W
        xs = jj + 0.5
        ys = ii + 0.5
        x = (xs / W * 2.0 - 1.0) * sx
        y = (1.0 - ys / H * 2.0) * sy
        dfront = zfront[p]
        if ortho:
            pv[k, 0] = x
            pv[k, 1] = y
        else:
            pv[k, 0] = x * dfront
            pv[k, 1] = y * dfront
        pv[k, 2] = -dfront


@nb.njit(cache=True, parallel=True)
def _row_means_kernel(a, out):
    # a.mean(axis=1) of an (N, C) array: NumPy adds the C values in order, then divides by C
    C = a.shape[1]
    for k0 in nb.prange(a.shape[0]):
        k = np.int64(k0)
        s = 0.0
        for c in range(C):
            s += a[k, c]
        out[k] = s / C


@nb.njit(cache=True, parallel=True)
def _exit_flux_kernel(flux0, ex, trans, out):
    for k0 in nb.prange(ex.shape[0]):
        k = np.int64(k0)
        f = flux0[ex[k]]
        for c in range(trans.shape[1]):
            out[k, c] = f * trans[k, c]


def _exit_flux(flux0, ex, trans):
    """``flux0[ex, None] * trans``, on every thread when both are float64 ((N,) and (len(ex), C))."""
    if not (isinstance(flux0, np.ndarray) and flux0.dtype == np.float64 and flux0.ndim == 1
            and _f64_rows(trans) and len(trans) == len(ex)):
        return flux0[ex, None] * trans
    out = np.empty(trans.shape)
    if len(ex):
        _exit_flux_kernel(flux0, np.ascontiguousarray(ex, dtype=np.int64), np.ascontiguousarray(trans), out)
    return out


def _f64_rows(a):
    """An (N, C >= 1) float64 array: its row means are :func:`_row_means`'s."""
    return isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 2 and a.shape[1] > 0


def _row_means(a):
    """``a.mean(axis=1)`` of an (N, C) float64 array (C >= 1), bit for bit, on every thread."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    out = np.empty(len(a))
    if len(a):
        _row_means_kernel(a, out)
    return out


def has_caustics(scene):
    """A scene casts caustics when it has at least one light and one receiver."""
    return bool(scene.data["lights"]) and bool(scene.data["receivers"])


def merge_caustics(arrays, c_arrays):
    """Add the caustic outputs to a run's arrays; ``image`` becomes the full scene.

    With receivers, the rendered colour is the final pass of §4.1 (receivers
    lit directly and by the caustics, seen through the object); the
    refraction-only view of the environment is kept as ``image_refraction``.
    Both the image-space method and the exact reference call this.
    """
    arrays.update(c_arrays)
    arrays["image_refraction"] = arrays["image"]
    arrays["image"] = arrays["image_caustics"]
    return arrays


def skip_reason(scene):
    missing = [k for k in ("lights", "receivers") if not scene.data[k]]
    return f"the scene has no {' and no '.join(missing)}: no caustics to map"


def receiver_hits(rs, origins, dirs, mode, cam=None, eyebuf=None):
    """Where world rays meet the receivers: eye-space march or Embree.

    Returns
    -------
    points : (N, 3) float64
        Hit points (NaN where none).
    face : (N,) int64
        Receiver triangle hit, ``-1`` where none.
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    if mode == "exact":
        t, face = hit_exact(rs.tris, o, d)
    else:
        t, pix = march_eyespace(cam.world_to_view(o), cam.dir_world_to_view(d), eyebuf[0], cam)
        ok = pix[:, 0] >= 0
        face = np.full(len(o), -1, np.int64)
        face[ok] = eyebuf[1][pix[ok, 0], pix[ok, 1]]
    P = np.empty(o.shape)
    face_out = np.empty(len(o), np.int64)
    if len(o):  # P = o + t[:, None] * d; face where t is finite, else -1: on every thread
        _hit_points_kernel(np.ascontiguousarray(o), np.ascontiguousarray(t, dtype=np.float64),
                           np.ascontiguousarray(d), np.ascontiguousarray(face, dtype=np.int64), P, face_out)
    return P, face_out


@nb.njit(cache=True, parallel=True)
def _hit_points_kernel(o, t, d, face, P, face_out):
    for k0 in nb.prange(o.shape[0]):
        k = np.int64(k0)
        for c in range(3):
            P[k, c] = o[k, c] + t[k] * d[k, c]
        face_out[k] = face[k] if (math.isfinite(t[k]) and face[k] >= 0) else -1


def splat_maps(rs, P, face, flux, size, groups=None):
    """Irradiance maps (Hc, Wc, C) per receiver from photon hits (see :mod:`.splat`).

    ``groups`` (N,) int, optional: also the maps of the photons of each group
    ``0 .. groups.max()`` alone (the exact reference's two interleaved halves),
    from the same map positions and values (every photon's are its own, so
    they are those of ``splat_maps`` on the group's photons alone); then
    returns ``(maps, [maps of group 0, maps of group 1, ...])``.
    """
    maps = []
    ng = 0 if groups is None else int(np.max(groups, initial=-1)) + 1
    per_group = [[] for _ in range(ng)]
    flux = np.asarray(flux, dtype=np.float64)
    if flux.ndim == 1:
        flux = flux[:, None]
    flux = np.ascontiguousarray(flux)
    P = np.ascontiguousarray(P, dtype=np.float64)
    face = np.ascontiguousarray(face, dtype=np.int64)
    normals = np.ascontiguousarray(rs.normals, dtype=np.float64)
    on = np.full(len(face), -1, np.int64)  # the receiver each photon meets, -1 none
    hit = face >= 0
    on[hit] = rs.owner[face[hit]]
    for r, box in enumerate(rs.boxes):
        idx = np.flatnonzero(on == r)
        # map positions and values in one kernel; the whole map and each group's from one
        # footprint and binning (splat.splat_bilinear_groups: the bits of separate splats)
        col, row, val = receiver_photons(P, face, idx, normals, box, flux)
        if ng == 0:
            maps.append(splat_bilinear(col, row, val, box.size))
            continue
        allm = splat_bilinear_groups(col, row, val, box.size, np.asarray(groups)[idx], ng)
        maps.append(allm[0])
        for h in range(ng):
            per_group[h].append(allm[1 + h])
    return maps if groups is None else (maps, per_group)


def _photon_stats(flux0, status, trans_exit, landed):
    """Energy book-keeping of one light's photons (unit light, mean over channels).

    ``flux_silhouette`` entered the objects; of it, ``flux_absorbed`` was
    absorbed, ``flux_lost_in_object`` stopped inside (status 2-4),
    ``flux_exited`` left, and of that ``flux_missed_receivers`` met no
    receiver; the caller adds ``flux_on_receivers`` (what was splatted).
    """
    f = flux0
    t = _row_means(trans_exit) if _f64_rows(trans_exit) else trans_exit.mean(axis=1)
    if (isinstance(f, np.ndarray) and f.dtype == np.float64 and f.ndim == 1 and isinstance(status, np.ndarray)
            and status.ndim == 1 and status.dtype.kind in "iu" and len(status) == len(f)):
        # f[status != 0], f[status == EXITED], f[status >= 2] gathered on every thread (fixed
        # chunks, order kept); their sums NumPy's
        f_sil, f_ex, f_lost = _split_flux(f, status)
    else:
        f_sil, f_ex, f_lost = f[status != 0], f[status == EXITED], f[status >= 2]
    fe_t = f_ex * t
    return {
        "flux_silhouette": float(f_sil.sum()),
        "flux_absorbed": float((f_ex * (1.0 - t)).sum()),
        "flux_lost_in_object": float(f_lost.sum()),
        "flux_exited": float(fe_t.sum()),
        "flux_missed_receivers": float(fe_t[~landed].sum()),
        "photons_in_silhouette": len(f_sil),
        "photons_lost_in_object": len(f_lost),
        "photons_missed_receivers": int(np.count_nonzero(~landed)),
    }


_SPLIT_CHUNK = 1 << 16


@nb.njit(cache=True, parallel=True)
def _split_count_kernel(status, exited, chunk, cnt):
    n = status.shape[0]
    for q0 in nb.prange(cnt.shape[0]):
        q = np.int64(q0)
        for i in range(q * chunk, min(n, (q + 1) * chunk)):
            s = status[i]
            if s != 0:
                cnt[q, 0] += 1
            if s == exited:
                cnt[q, 1] += 1
            if s >= 2:
                cnt[q, 2] += 1


@nb.njit(cache=True, parallel=True)
def _split_fill_kernel(status, f, exited, chunk, off, f_sil, f_ex, f_lost):
    n = status.shape[0]
    for q0 in nb.prange(off.shape[0]):
        q = np.int64(q0)
        a, b, c = off[q, 0], off[q, 1], off[q, 2]
        for i in range(q * chunk, min(n, (q + 1) * chunk)):
            s = status[i]
            if s != 0:
                f_sil[a] = f[i]
                a += 1
            if s == exited:
                f_ex[b] = f[i]
                b += 1
            if s >= 2:
                f_lost[c] = f[i]
                c += 1


def _split_flux(f, status):
    """``f[status != 0], f[status == EXITED], f[status >= 2]``, on every thread."""
    nch = max(1, -(-len(f) // _SPLIT_CHUNK))
    cnt = np.zeros((nch, 3), np.int64)
    _split_count_kernel(status, EXITED, _SPLIT_CHUNK, cnt)
    off = np.zeros((nch, 3), np.int64)
    np.cumsum(cnt[:-1], axis=0, out=off[1:])
    tot = cnt.sum(axis=0)
    f_sil, f_ex, f_lost = np.empty(tot[0]), np.empty(tot[1]), np.empty(tot[2])
    _split_fill_kernel(status, f, EXITED, _SPLIT_CHUNK, off, f_sil, f_ex, f_lost)
    return f_sil, f_ex, f_lost


def _collect(lights, rs, per_light, arrays, gather):
    """Sum per-light unit maps into ``caustic_map_r`` / ``caustic_rgb_r``; returns the RGB maps."""
    rgb_maps = []
    for r, box in enumerate(rs.boxes):
        unit = np.zeros(box.size)
        rgb = np.zeros(box.size + (3,))
        for l, maps in enumerate(per_light):
            m = maps[r]
            if gather > 1:
                m = gather_gaussian(m, gather)
            accumulate_light(m, lights[l]["radiance"], unit, rgb)  # unit += mean over channels, rgb += m L
        unit, unit32 = finite_maps(unit)  # NaN and infinities to 0 (np.nan_to_num), on every thread
        rgb, rgb32 = finite_maps(rgb)
        arrays[f"caustic_map_{r}"] = unit32
        arrays[f"caustic_frame_{r}"] = rs.frame(r).astype(np.float64)
        arrays[f"caustic_rgb_{r}"] = rgb32
        rgb_maps.append(rgb)
    return rgb_maps


# ---------------------------------------------------------------------------
# stages shared by both methods
# ---------------------------------------------------------------------------

def camera_array(cam):
    """A camera as a (6, 3) float64 buffer: eye; right, up, back axes; (sx, sy, ortho); (near, far, width)."""
    return np.array([np.asarray(cam.eye, dtype=np.float64), *cam.basis, [cam.sx, cam.sy, float(cam.ortho)],
                     [cam.near, cam.far, float(cam.width)]], dtype=np.float64)


def _st_receivers(ctx):
    d = ctx.scene.data
    rs = receiver_set(ctx.scene, d["lights"][0], int(d["imagespace"]["caustic_map"]))
    ctx.note(f"{len(rs.boxes)} receiver(s), {len(rs.tris)} triangles, {d['imagespace']['caustic_map']}^2 maps")
    return {"rs": rs, **{f"frame_{r}": rs.frame(r).astype(np.float64) for r in range(len(rs.boxes))}}


def _st_receiver_depth(ctx):
    from ..camera import Camera

    cam = Camera.from_dict(ctx.scene.data["camera"])
    depth, tri = eye_buffers(ctx.buf["receivers"]["rs"], cam)
    return {"eyebuf": (depth, tri), "depth": depth, "triangle": tri, "cam": cam}


def receiver_stages(n_receivers):
    return (
        Stage("receivers", _st_receivers, reads=("receivers", "lights", "imagespace.caustic_map"),
              makes=tuple(f"frame_{r}" for r in range(n_receivers)),
              doc="receiver triangles and caustic-map frames (§4.1)"),
        Stage("receiver_depth", _st_receiver_depth, reads=("camera",), after=("receivers",),
              makes=("depth", "triangle"), doc="the receivers' depth image from the camera (§4.1)"),
    )


def per_light_names(prefix, n):
    return tuple(f"{prefix}_{l}" for l in range(n))


def gather_names(nr):
    """The gather stage's outputs per receiver: the map, its frame and the per-channel map."""
    return tuple(nm for k in ("caustic_map", "caustic_frame", "caustic_rgb") for nm in per_light_names(k, nr))


def photon_buffer_names(n, with_ldi):
    """Per-light buffers of ``photon_trace`` (None for a light whose photons meet no object)."""
    names = ("camera", "ldi", "exit_pos", "exit_dir") if with_ldi else ("camera", "exit_pos", "exit_dir")
    return tuple(nm for k in names for nm in per_light_names(k, n))


def gather_stage(ctx, gather_key):
    d = ctx.scene.data
    rs = ctx.buf["receivers"]["rs"]
    per_light = ctx.buf["splat"]["maps"]
    g = int(d["imagespace"]["gather"]) if gather_key else 1
    arrays = {}
    rgb_maps = _collect(d["lights"], rs, per_light, arrays, g)
    ctx.note(f"Gaussian gathering, window {g} texels (Wyman & Davis 2006)" if g > 1 else "no gathering")
    return {"arrays": arrays, "rgb_maps": rgb_maps, **arrays}


# ---------------------------------------------------------------------------
# image-space method (§4.1)
# ---------------------------------------------------------------------------

def _st_photon_trace_is(ctx):
    from ..imagespace.pipeline import layered_trace

    d = ctx.scene.data
    p = d["imagespace"]
    g = ctx.buf["geometry"]
    geom, ior, outside, absorption = g["geom"], g["ior"], g["outside_ior"], g["absorption"]
    out = {"lights": [], **dict.fromkeys(photon_buffer_names(len(d["lights"]), True))}
    for l, light in enumerate(d["lights"]):
        lcam = light_camera(light, geom.vertices, int(p["photons"])) if len(geom.faces) else None
        if lcam is None:
            out["lights"].append(None)
            continue
        lt = {}
        tv = layered_trace(geom, lcam, p, ior, outside, lt, [])
        for k, v in lt.items():
            ctx.timings[k] = ctx.timings.get(k, 0.0) + v
        tr = tv["trace"]
        st = tr["status"].ravel()
        N = lcam.width
        cols = np.tile(np.arange(N) + 0.5, N)
        rows = np.repeat(np.arange(N) + 0.5, N)
        flux0 = texel_flux(lcam, cols, rows)
        ex = np.flatnonzero(st == EXITED)
        trans = beer_lambert(absorption, tr["path_length"].ravel()[ex], ior)
        o = tr["exit_pos"].reshape(-1, 3)[ex]  # world space (layered_trace)
        dd = tr["exit_dir"].reshape(-1, 3)[ex]
        bias = 1e-3 * (lcam.far - lcam.near) + 2.0 * 2.0 * lcam.sy / N
        out["lights"].append({"cam": lcam, "status": st, "flux0": flux0, "ex": ex, "trans": trans, "o": o, "d": dd,
                              "shadow": (lcam, tv["zmin"], bias)})
        out[f"camera_{l}"] = camera_array(lcam)
        out[f"ldi_{l}"] = tv["ldi"] if 0 not in tv["ldi"].strides else None
        out[f"exit_pos_{l}"] = o
        out[f"exit_dir_{l}"] = dd
    ctx.note(f"{p['photons']}x{p['photons']} photons per light through all layers (§4.1)")
    return out


def receiver_hit_stage(ctx, eyespace):
    rs = ctx.buf["receivers"]["rs"]
    rd = ctx.buf.get("receiver_depth") if eyespace else None
    nl = len(ctx.buf["photon_trace"]["lights"])
    out = {"hits": [], **dict.fromkeys(per_light_names("hit_pos", nl) + per_light_names("hit_face", nl))}
    for l, L in enumerate(ctx.buf["photon_trace"]["lights"]):
        if L is None:
            out["hits"].append(None)
            continue
        P, face = receiver_hits(rs, L["o"], L["d"], "eyespace" if eyespace else "exact",
                                rd["cam"] if rd else None, rd["eyebuf"] if rd else None)
        out["hits"].append((P, face))
        out[f"hit_pos_{l}"] = P
        out[f"hit_face_{l}"] = face
    ctx.note("eye-space march in the receivers' depth image (Krüger et al. 2006)" if eyespace
             else "Embree on the receivers' triangles")
    return out


def splat_stage(ctx, reference):
    """Splat each light's photons into the receivers' maps; the reference also splats its two halves."""
    d = ctx.scene.data
    size = int(d["imagespace"]["caustic_map"])
    rs = ctx.buf["receivers"]["rs"]
    maps, stats, halves = [], [], []
    for L, hit in zip(ctx.buf["photon_trace"]["lights"], ctx.buf["receiver_hit"]["hits"]):
        if L is None:
            maps.append([np.zeros(b.size + (3,)) for b in rs.boxes])
            stats.append({"photons": 0})
            continue
        P, face = hit
        flux = _exit_flux(L["flux0"], L["ex"], L["trans"])
        if reference:  # the maps and those of the two interleaved halves, from one set of map positions
            m, hm = splat_maps(rs, P, face, flux, size, groups=L["half"])
            maps.append(m)
            halves.append((hm[0] if len(hm) > 0 else [np.zeros(b.size + (3,)) for b in rs.boxes],
                           hm[1] if len(hm) > 1 else [np.zeros(b.size + (3,)) for b in rs.boxes]))
        else:
            maps.append(splat_maps(rs, P, face, flux, size))
        s = _photon_stats(L["flux0"], L["status"], L["trans"], face >= 0)
        s["flux_on_receivers"] = float((_row_means(flux)[face >= 0] if _f64_rows(flux)
                                        else flux[face >= 0].mean(axis=1)).sum())
        if reference:
            s["photons"] = [int(d["exact"]["photons"])] * 2
        else:
            s["photon_texture"] = [L["cam"].width, L["cam"].width]
            s["projection"] = L["cam"].projection
        stats.append(s)
    ctx.stats["caustic_lights"] = stats
    if reference:
        noise = _reference_noise(rs, halves)
        ctx.stats["reference_noise_rel_l1"] = noise
        ctx.note("own noise (relative L1 of two interleaved halves, one-texel blur): "
                 + ", ".join(f"{v:.3g}" for v in noise))
    return {"maps": maps, **_splat_buffers(maps, len(rs.boxes))}


def _reference_noise(rs, halves):
    """Half the relative L1 difference of the two interleaved halves' maps, per receiver."""
    from ..metrics import relative_l1

    noise = []
    for r in range(len(rs.boxes)):
        a = sum(channel_mean(h[0][r]) for h in halves) if halves else np.zeros(rs.boxes[r].size)
        b = sum(channel_mean(h[1][r]) for h in halves) if halves else np.zeros(rs.boxes[r].size)
        noise.append(0.5 * relative_l1(a, b, blur=1.0) if np.abs(b).sum() > 0 else 0.0)
    return noise


def _splat_buffers(maps, R):
    """The splatted maps before gathering, summed over lights and channels' mean: ``splat_r`` (Hc, Wc)."""
    return {f"splat_{r}": np.sum([channel_mean(m[r]) for m in maps], axis=0).astype(np.float32) for r in range(R)}


def _st_final_is(ctx):
    d = ctx.scene.data
    p = d["imagespace"]
    b = ctx.buf
    g = b["geometry"]
    rs = b["receivers"]["rs"]
    rd = b["receiver_depth"]
    shadow = [None if L is None else L["shadow"] for L in b["photon_trace"]["lights"]]

    def vis(l, pts, nrm):
        if shadow[l] is None:
            return np.ones(len(pts))
        lcam, zmin, bias = shadow[l]
        return shadow_map_visibility(lcam, zmin, pts, bias)

    eye = {"trace": b["trace"], "zmin": b["minmax"]["zmin"]}
    img, img1 = _final_imagespace(ctx.scene, rs, rd["cam"], eye, rd["eyebuf"], b["gather"]["rgb_maps"], vis,
                                  p["receiver_hit"], g["ior"], g["outside_ior"], g["absorption"], p)
    ctx.note("receivers lit directly (shadow map) and by the caustics; the object's multi-layer and "
             "single-surface (the thesis's) final passes")
    return {"image_caustics": img, "image_caustics_single": img1}


def imagespace_caustic_stages(scene):
    """The caustic stages the image-space method adds for a scene with lights and receivers (§4.1)."""
    from ..imagespace.pipeline import MINMAX_KNOBS, PEEL_KNOBS, REDUCE_KNOBS, TRACE_KNOBS, VOXELIZE_KNOBS

    nl, nr = len(scene.data["lights"]), len(scene.data["receivers"])
    eyespace = scene.data["imagespace"]["receiver_hit"] == "eyespace"
    knobs = tuple(dict.fromkeys(("photons",) + MINMAX_KNOBS + VOXELIZE_KNOBS + PEEL_KNOBS + REDUCE_KNOBS
                                + TRACE_KNOBS))
    return receiver_stages(nr) + (
        Stage("photon_trace", _st_photon_trace_is, reads=("lights",) + tuple(f"imagespace.{k}" for k in knobs),
              after=("geometry",),
              makes=photon_buffer_names(nl, True),
              doc="per light: its camera, the passes of ch. 3 in its view, one photon per texel (§4.1)"),
        Stage("receiver_hit", lambda ctx: receiver_hit_stage(ctx, eyespace),
              reads=("imagespace.receiver_hit",),
              after=("receivers", "photon_trace") + (("receiver_depth",) if eyespace else ()),
              makes=per_light_names("hit_pos", nl) + per_light_names("hit_face", nl),
              doc="where exiting photons meet the receivers (§4.1)"),
        Stage("splat", lambda ctx: splat_stage(ctx, False), reads=("imagespace.caustic_map",),
              after=("receivers", "photon_trace", "receiver_hit"), makes=per_light_names("splat", nr),
              doc="bilinear splat of each photon's irradiance (§2.3.2)"),
        Stage("gather", lambda ctx: gather_stage(ctx, True), reads=("imagespace.gather", "lights"),
              after=("receivers", "splat"), makes=gather_names(nr),
              doc="Gaussian gathering (Wyman & Davis 2006)"),
        Stage("caustic_final", _st_final_is,
              reads=("environment", "lights", "imagespace.normals", "imagespace.delta",
                     "imagespace.receiver_hit"),
              after=("geometry", "minmax", "trace", "receivers", "receiver_depth", "photon_trace", "gather"),
              makes=("image_caustics", "image_caustics_single"),
              doc="receivers lit directly and by caustics, seen through the object (§4.1)"),
    )


def caustic_arrays(scene, method, bufs, stats):
    """The caustic output keys and ``meta['caustics']`` from the caustic stages' buffers."""
    arrays = dict(bufs["gather"]["arrays"])
    arrays.update({k: v for k, v in bufs["caustic_final"].items() if k.startswith("image_caustics")})
    d = scene.data
    info = {"lights": stats.get("caustic_lights", []), "receivers": len(bufs["receivers"]["rs"].boxes),
            "caustic_map": int(d["imagespace"]["caustic_map"])}
    if method == "exact":
        info.update({"receiver_hit": "exact", "gather": 1, "photons": int(d["exact"]["photons"]),
                     "reference_noise_rel_l1": stats.get("reference_noise_rel_l1", [])})
    else:
        info.update({"receiver_hit": d["imagespace"]["receiver_hit"], "gather": int(d["imagespace"]["gather"]),
                     "photons": int(d["imagespace"]["photons"])})
    return arrays, info


def shade_rays(scene, rs, cam, o, d, mode, eyebuf, rgb_maps, vis, direct=None):
    """Colour seen along world rays: the receiver they meet (shaded), else the environment.

    ``direct``: (points, faces, ray directions) of receiver points seen directly, shaded in
    the same call (every point's colour is its own); then returns ``(rays' colours, theirs)``.
    """
    out = np.zeros((len(o), 3))
    if len(o):
        P, face = receiver_hits(rs, o, d, mode, cam, eyebuf)
        hit = face >= 0
    else:
        P, face, hit = np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, bool)
    pts, fcs, drs = P[hit], face[hit], d[hit]
    if direct is not None:
        pts, fcs, drs = (np.concatenate([a, b]) for a, b in zip((pts, fcs, drs), direct))
    c = shade_points(rs, scene.data["lights"], rgb_maps, pts, fcs, drs, vis)
    nh = int(hit.sum())
    out[hit] = c[:nh]
    if (~hit).any():
        out[~hit] = environment_lookup(scene.data["environment"], d[~hit], scene.base_dir)
    return out if direct is None else (out, c[nh:])


def _final_imagespace(scene, rs, cam, eye, eyebuf, rgb_maps, vis, mode, ior, outside, absorption, p):
    from ..imagespace.normals import layer_normals

    H, W = cam.shape
    tr = eye["trace"]
    zfront = eye["zmin"]
    rdepth, rtri = eyebuf
    origin, rdir = cam.primary_rays()
    env = scene.data["environment"]
    obj = np.isfinite(zfront)
    rec = np.isfinite(rdepth) & (rdepth < np.where(obj, zfront, np.inf))
    obj &= ~rec
    base = np.zeros((H, W, 3))
    # receivers seen directly: shaded with the object's rays below (one call); the rows of
    # the boolean masks (row-major) gathered by kernels on every thread
    ri = np.flatnonzero(rec)
    rdir_f = np.ascontiguousarray(rdir.reshape(-1, 3))
    dirs = take_rows(rdir_f, ri)
    fwd = -cam.basis[2]
    # origin[rec] + dirs * (rdepth[rec] / dot(dirs, fwd))[:, None]
    direct = (_depth_points(np.ascontiguousarray(origin.reshape(-1, 3)), rdir_f,
                            np.ascontiguousarray(rdepth, dtype=np.float64).reshape(-1), ri, fwd),
              rtri.reshape(-1)[ri], dirs)
    bg = ~rec & ~obj
    if bg.any():
        base[bg] = environment_lookup(env, rdir[bg], scene.base_dir)
    if not obj.any():
        _, base[rec] = shade_rays(scene, rs, cam, np.zeros((0, 3)), np.zeros((0, 3)), mode, eyebuf, rgb_maps, vis,
                                   direct)
        return base.astype(np.float32), base.astype(np.float32)
    # the multi-layer pass: exit rays on to the receivers, else the environment (§3.6-3.8)
    st = tr["status"]
    ex = obj & (st == 1)
    oi = np.flatnonzero(obj)
    xi = np.flatnonzero(ex)
    trans = beer_lambert(absorption, tr["path_length"].reshape(-1)[oi], ior)  # per pixel: only the object's
    o_full = take_rows(tr["exit_pos"].reshape(-1, 3), xi)  # world space (layered_trace)
    d_full = take_rows(tr["exit_dir"].reshape(-1, 3), xi)
    # the thesis's final pass: refraction at the front surface only
    nrm = layer_normals(np.where(np.isfinite(zfront), zfront, np.inf), cam, p["normals"], int(p["delta"]))
    dv = take_rows(cam.primary_rays_view().reshape(-1, 3), oi)
    t, _ = refract(dv, take_rows(nrm.reshape(-1, 3), oi), outside / ior)
    # np.where(all(isfinite(t), axis=1), t, dv), and the front points in view space (pixel
    # centres (jj + .5, ii + .5) at depth zfront), on every thread
    pv = np.empty((len(oi), 3))
    _front_points_kernel(t, dv, oi, np.ascontiguousarray(zfront, dtype=np.float64).reshape(-1), W, H,
                         float(cam.sx), float(cam.sy), bool(cam.ortho), pv)
    # both passes' rays in one march and one shading: each ray's colour is its own, and one call
    # instead of two halves the serial work around the kernels
    n_full = len(o_full)
    c, cd = shade_rays(scene, rs, cam, np.concatenate([o_full, cam.view_to_world(pv)]),
                        np.concatenate([d_full, cam.dir_view_to_world(t)]), mode, eyebuf, rgb_maps, vis, direct)
    base = base.reshape(-1, 3)
    put_rows(base, ri, cd)
    full = base.copy()
    single = base.copy()
    if n_full:
        put_rows(full, xi, c[:n_full])
    stuck = obj & (st != 1)
    if stuck.any():
        full[stuck.reshape(-1)] = environment_lookup(env, tr["last_dir"][stuck], scene.base_dir)
    _mul_rows(full, oi, trans)  # full[obj] *= trans
    put_rows(single, oi, c[n_full:])
    full, single = full.reshape(H, W, 3), single.reshape(H, W, 3)
    return full.astype(np.float32), single.astype(np.float32)
