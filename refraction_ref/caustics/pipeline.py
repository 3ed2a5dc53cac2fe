"""Caustics onto diffuse receivers (Chaudhari 2008, §4.1): the generic stages every method shares.

==========================  =====================================================  ===========
stage (``timings_ms``)      pass                                                   section
==========================  =====================================================  ===========
``receivers``               receiver triangles and their caustic-map frames         §4.1
                            (``caustics.map_size``)
``receiver_depth``          the receivers' depth image from the camera              §4.1
``receiver_hit``            eye-space march (Krüger 2006) or Embree                 §4.1
``splat``                   bilinear splat of irradiance into each receiver's map   §2.3.2
``gather``                  Gaussian gathering in a window (Wyman & Davis 2006,     §2.3.2
                            ``caustics.gather``), or a plain sum over lights
==========================  =====================================================  ===========

A method puts its own ``photon_trace`` (the photons that leave its objects)
and ``caustic_final`` (the final image, colouring its rays by
:func:`~refraction_ref.caustics.shade.shade_rays`) around these:
:func:`refraction_ref.imagespace.caustics.imagespace_caustic_stages` (the
passes of chapter 3 in each light's view),
:func:`refraction_ref.exact.caustics.exact_caustic_stages` (the exact photon
reference); the volumetric method uses :func:`~.receivers.receiver_set`'s maps,
:func:`splat_maps` and :func:`collect_maps` in its own ``caustics`` stage.
This module imports no method.

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

import numba as nb
import numpy as np

from ..graph import Stage
from ..status import EXITED
from .receivers import eye_buffers, receiver_hits, receiver_set
from .splat import (accumulate_light, channel_mean, finite_maps, gather_gaussian, receiver_photons,
                    splat_bilinear, splat_bilinear_groups)

__all__ = ["has_caustics", "caustic_arrays", "collect_maps", "splat_maps", "merge_caustics", "skip_reason",
           "camera_array", "receiver_stages", "photon_buffer_names", "per_light_names", "gather_names",
           "receiver_hit_stage", "splat_stage", "gather_stage"]


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
    """A scene casts caustics when it has at least one light and one receiver.

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    bool
    """
    return bool(scene.data["lights"]) and bool(scene.data["receivers"])


def merge_caustics(arrays, c_arrays):
    """Add the caustic outputs to a run's arrays; ``image`` becomes the full scene.

    With receivers, the rendered colour is the final pass of §4.1 (receivers
    lit directly and by the caustics, seen through the object); the
    refraction-only view of the environment is kept as ``image_refraction``.
    Both the image-space method and the exact reference call this.

    Parameters
    ----------
    arrays : dict
        The method's output arrays (``image`` among them); updated in place.
    c_arrays : dict
        The caustic outputs (:func:`caustic_arrays`), ``image_caustics`` among them.

    Returns
    -------
    dict
        ``arrays``.
    """
    arrays.update(c_arrays)
    arrays["image_refraction"] = arrays["image"]
    arrays["image"] = arrays["image_caustics"]
    return arrays


def skip_reason(scene):
    """Why a scene has no caustic stages (for ``meta.plan``).

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    str
    """
    missing = [k for k in ("lights", "receivers") if not scene.data[k]]
    return f"the scene has no {' and no '.join(missing)}: no caustics to map"


def splat_maps(rs, P, face, flux, size, groups=None):
    """Irradiance maps (Hc, Wc, C) per receiver from photon hits (see :mod:`.splat`).

    Parameters
    ----------
    rs : ReceiverSet
    P : (N, 3) array_like
        Photon hit points.
    face : (N,) array_like of int
        Receiver triangle of each photon, ``-1`` none.
    flux : (N,) or (N, C) array_like
        Each photon's flux.
    size : int
        Texels per side (``caustics.map_size``; the boxes carry it).
    groups : (N,) array_like of int, optional
        Also the maps of the photons of each group ``0 .. groups.max()`` alone
        (the exact reference's two interleaved halves), from the same map
        positions and values (every photon's are its own, so they are those of
        ``splat_maps`` on the group's photons alone).

    Returns
    -------
    list of (Hc, Wc, C) float64
        One map per receiver; with ``groups``, ``(maps, [maps of group 0,
        maps of group 1, ...])``.
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


def collect_maps(lights, rs, per_light, arrays, gather):
    """Sum per-light unit maps into ``caustic_map_r`` / ``caustic_rgb_r``; returns the RGB maps.

    Parameters
    ----------
    lights : list of dict
        The scene's lights (their ``radiance``).
    rs : ReceiverSet
    per_light : list of list of (Hc, Wc, 3) float64
        ``per_light[l][r]``: light ``l``'s map of receiver ``r`` for a unit light.
    arrays : dict
        Gets ``caustic_map_r``, ``caustic_frame_r`` and ``caustic_rgb_r``.
    gather : int
        Gaussian gathering window (Wyman & Davis 2006); 1 for none.

    Returns
    -------
    list of (Hc, Wc, 3) float64
        Per receiver, the caustic irradiance with each light's radiance.
    """
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
    """A camera as a (6, 3) float64 buffer: eye; right, up, back axes; (sx, sy, ortho); (near, far, width).

    Parameters
    ----------
    cam : Camera

    Returns
    -------
    (6, 3) float64
    """
    return np.array([np.asarray(cam.eye, dtype=np.float64), *cam.basis, [cam.sx, cam.sy, float(cam.ortho)],
                     [cam.near, cam.far, float(cam.width)]], dtype=np.float64)


def _st_receivers(ctx):
    d = ctx.scene.data
    rs = receiver_set(ctx.scene, d["lights"][0], int(d["caustics"]["map_size"]))
    ctx.note(f"{len(rs.boxes)} receiver(s), {len(rs.tris)} triangles, {d['caustics']['map_size']}^2 maps")
    return {"rs": rs, **{f"frame_{r}": rs.frame(r).astype(np.float64) for r in range(len(rs.boxes))}}


def _st_receiver_depth(ctx):
    from ..camera import Camera

    cam = Camera.from_dict(ctx.scene.data["camera"])
    depth, tri = eye_buffers(ctx.buf["receivers"]["rs"], cam)
    return {"eyebuf": (depth, tri), "depth": depth, "triangle": tri, "cam": cam}


def receiver_stages(n_receivers):
    """The ``receivers`` and ``receiver_depth`` stages (§4.1), shared by the methods.

    Parameters
    ----------
    n_receivers : int
        The scene's receivers (one frame buffer each).

    Returns
    -------
    tuple of Stage
        ``receivers`` (reads ``caustics.map_size``) and ``receiver_depth``.
    """
    return (
        Stage("receivers", _st_receivers, reads=("receivers", "lights", "caustics.map_size"),
              makes=tuple(f"frame_{r}" for r in range(n_receivers)),
              doc="receiver triangles and caustic-map frames (§4.1)"),
        Stage("receiver_depth", _st_receiver_depth, reads=("camera",), after=("receivers",),
              makes=("depth", "triangle"), doc="the receivers' depth image from the camera (§4.1)"),
    )


def per_light_names(prefix, n):
    """``prefix_0 .. prefix_{n-1}``: one buffer name per light (or receiver).

    Parameters
    ----------
    prefix : str
    n : int

    Returns
    -------
    tuple of str
    """
    return tuple(f"{prefix}_{l}" for l in range(n))


def gather_names(nr):
    """The gather stage's outputs per receiver: the map, its frame and the per-channel map.

    Parameters
    ----------
    nr : int
        Number of receivers.

    Returns
    -------
    tuple of str
    """
    return tuple(nm for k in ("caustic_map", "caustic_frame", "caustic_rgb") for nm in per_light_names(k, nr))


def photon_buffer_names(n, with_ldi):
    """Per-light buffers of ``photon_trace`` (None for a light whose photons meet no object).

    Parameters
    ----------
    n : int
        Number of lights.
    with_ldi : bool
        The image-space trace also keeps each light's layered depth image.

    Returns
    -------
    tuple of str
    """
    names = ("camera", "ldi", "exit_pos", "exit_dir") if with_ldi else ("camera", "exit_pos", "exit_dir")
    return tuple(nm for k in names for nm in per_light_names(k, n))


def gather_stage(ctx, gather_key):
    """The ``gather`` stage: per-light maps summed into the output maps, gathered or not.

    Parameters
    ----------
    ctx : Context
        The stage's context (``receivers`` and ``splat`` buffers).
    gather_key : bool
        Read the window from ``caustics.gather`` (image-space method); False:
        no gathering (the exact reference).

    Returns
    -------
    dict
        ``arrays``, ``rgb_maps`` and the output maps by name.
    """
    d = ctx.scene.data
    rs = ctx.buf["receivers"]["rs"]
    per_light = ctx.buf["splat"]["maps"]
    g = int(d["caustics"]["gather"]) if gather_key else 1
    arrays = {}
    rgb_maps = collect_maps(d["lights"], rs, per_light, arrays, g)
    ctx.note(f"Gaussian gathering, window {g} texels (Wyman & Davis 2006)" if g > 1 else "no gathering")
    return {"arrays": arrays, "rgb_maps": rgb_maps, **arrays}



def receiver_hit_stage(ctx, eyespace):
    """The ``receiver_hit`` stage: where each light's exiting photons meet the receivers.

    Parameters
    ----------
    ctx : Context
        The stage's context (``receivers``, ``photon_trace`` and, eye-space,
        ``receiver_depth`` buffers).
    eyespace : bool
        March in the camera's depth image (Krüger et al. 2006); else Embree.

    Returns
    -------
    dict
        ``hits`` per light and ``hit_pos_l`` / ``hit_face_l``.
    """
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
    """Splat each light's photons into the receivers' maps; the reference also splats its two halves.

    Parameters
    ----------
    ctx : Context
        The stage's context (``receivers``, ``photon_trace``, ``receiver_hit``).
    reference : bool
        The exact reference: also the two interleaved halves' maps, whose
        difference is its own noise (``ctx.stats["reference_noise_rel_l1"]``).

    Returns
    -------
    dict
        ``maps`` (per light, per receiver) and ``splat_r``.
    """
    d = ctx.scene.data
    size = int(d["caustics"]["map_size"])
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
    if len(maps) == 1:  # one light: its channel means as they are (the sum of one map is that map)
        return {f"splat_{r}": _float32(channel_mean(maps[0][r])) for r in range(R)}
    return {f"splat_{r}": np.sum([channel_mean(m[r]) for m in maps], axis=0).astype(np.float32) for r in range(R)}


@nb.njit(cache=True, parallel=True)
def _float32_kernel(a, out):
    for k0 in nb.prange(a.shape[0]):
        k = np.int64(k0)
        out[k] = np.float32(a[k])


def _float32(a):
    """``a.astype(np.float32)`` of a float64 array, on every thread."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    out = np.empty(a.shape, np.float32)
    _float32_kernel(a.reshape(-1), out.reshape(-1))
    return out


def caustic_arrays(scene, method, bufs, stats):
    """The caustic output keys and ``meta['caustics']`` from the caustic stages' buffers.

    Parameters
    ----------
    scene : Scene
    method : str
        ``"imagespace"`` or ``"exact"`` (what ``meta['caustics']`` reports).
    bufs : dict
        The stages' buffers (``gather``, ``caustic_final``, ``receivers``).
    stats : dict
        The run's stats (``caustic_lights``, ``reference_noise_rel_l1``).

    Returns
    -------
    arrays : dict
        ``caustic_map_r``, ``caustic_frame_r``, ``caustic_rgb_r``, ``image_caustics*``.
    info : dict
        ``meta['caustics']``.
    """
    arrays = dict(bufs["gather"]["arrays"])
    arrays.update({k: v for k, v in bufs["caustic_final"].items() if k.startswith("image_caustics")})
    d = scene.data
    info = {"lights": stats.get("caustic_lights", []), "receivers": len(bufs["receivers"]["rs"].boxes),
            "caustic_map": int(d["caustics"]["map_size"])}
    if method == "exact":
        info.update({"receiver_hit": "exact", "gather": 1, "photons": int(d["exact"]["photons"]),
                     "reference_noise_rel_l1": stats.get("reference_noise_rel_l1", [])})
    else:
        info.update({"receiver_hit": d["imagespace"]["receiver_hit"], "gather": int(d["caustics"]["gather"]),
                     "photons": int(d["imagespace"]["photons"])})
    return arrays, info
