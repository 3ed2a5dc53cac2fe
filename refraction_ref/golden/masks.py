"""Where ``check`` allows a difference: the golden's ambiguity masks and the ties a port may decide either way.

A failing element inside the ambiguity mask is counted against the tolerance's
``inside`` share, one outside it against ``fraction`` (:mod:`.tolerances`). The
mask marks the golden's silhouettes, status boundaries and depth
discontinuities of the maps (:func:`ambiguity_context`, :func:`ambiguity`);
the ties add the receiver triangles' shared edges (:func:`face_ties`) and the
shadow test's texel-edge ties (:func:`margin_ties`). The stopped viewing rays
of the volumetric image are judged with no allowance at all
(:func:`stopped_strict`), and a ``weight_key`` floor leaves out the elements
of no weight (:func:`weight_mask`).

References
----------
docs/oracle.md, "Conformance" (ambiguity masks, ties).
"""

from __future__ import annotations

import os

import numpy as np

from ..camera import Camera
from ..scene import load_scene
from .tolerances import elementwise, finiteness, fold_mask

__all__ = ["neighbour_changes", "popcount", "ambiguity_context", "ambiguity", "face_ties", "margin_ties",
           "stopped_strict", "weight_mask", "FACE_TIE_PIXELS"]


def neighbour_changes(a):
    """True where a pixel's 3x3 neighbourhood holds another value than the pixel (edges replicate).

    Parameters
    ----------
    a : (H, W) array_like
        Codes (status, counts, booleans).

    Returns
    -------
    (H, W) bool ndarray
    """
    a = np.asarray(a)
    H, W = a.shape
    p = np.pad(a, 1, mode="edge")
    out = np.zeros((H, W), bool)
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            out |= p[di:di + H, dj:dj + W] != a
    return out


def _codes(a):
    """A float array as codes for :func:`neighbour_changes` (NaN, inf kept apart); other dtypes as they are."""
    a = np.asarray(a)
    return finiteness(a) if a.dtype.kind == "f" else a


def _jumps(z):
    """Texels beside a depth discontinuity of a position map: finiteness changes, or a step between
    neighbours above ten times the map's median step (a wall, a step, another receiver)."""
    z = np.asarray(z, np.float64)
    fin = np.isfinite(z)
    out = neighbour_changes(fin)
    zz = np.where(fin, z, 0.0)
    steps = []
    for ax in (0, 1):
        d = np.abs(np.diff(zz, axis=ax))
        ok = fin & np.roll(fin, -1, axis=ax)
        ok = ok.take(np.arange(z.shape[ax] - 1), axis=ax)
        steps.append((d, ok))
    allst = np.concatenate([d[ok] for d, ok in steps]) if any(ok.any() for _, ok in steps) else np.zeros(0)
    if allst.size:
        thr = 10.0 * max(float(np.median(allst)), 1e-12)
        big = np.zeros(z.shape, bool)
        for ax, (d, ok) in enumerate(steps):
            b = ok & (d > thr)
            sl0 = [slice(None)] * 2
            sl1 = [slice(None)] * 2
            sl0[ax], sl1[ax] = slice(0, -1), slice(1, None)
            big[tuple(sl0)] |= b
            big[tuple(sl1)] |= b
        out |= neighbour_changes(big.astype(np.int8)) | big
    return out


#: golden keys whose changes mark the camera picture's silhouettes and decision boundaries
_SILHOUETTE_KEYS = ("depth_complexity", "stage.peel.depth_complexity", "hit", "status", "view_status",
                    "object_mask", "object_mask_direct")


def ambiguity_context(gold):
    """Per picture shape (H, W): the golden's ambiguity mask over it (camera silhouettes, map discontinuities).

    Parameters
    ----------
    gold : dict of str to ndarray
        The golden's arrays of one case.

    Returns
    -------
    dict of tuple to (H, W) bool ndarray
        The pictures' masks, read by :func:`ambiguity`.
    """
    pics = {}
    for k in _SILHOUETTE_KEYS:
        a = gold.get(k)
        if a is not None and a.ndim == 2:
            pics[a.shape] = pics.get(a.shape, np.zeros(a.shape, bool)) | neighbour_changes(_codes(a))
    for k, a in gold.items():
        if k.startswith("stage.level_map.position_") and a.ndim == 2:
            pics[a.shape] = pics.get(a.shape, np.zeros(a.shape, bool)) | _jumps(a)
    return pics


def _edge_counts(cc, gc):
    """(H, W) set-bit counts -> True where the candidate's count differs from the golden's and equals the
    golden's count at one of the pixel's 8 neighbours (edges replicate): the coverage an edge moved
    across the pixel's centre hands it.

    A silhouette edge (a fold's, or the object's outline) separates pixels whose counts differ by the
    fragments of the triangles that end there; an edge moved by a sub-pixel amount (another rasterizer's
    snap, float32 set-up) flips the pixels whose centres it crosses to their neighbour's side. A bitmask
    word that lost a set bit inside a surface (a blend that replaced the word) leaves a count no
    neighbour has: 3 beside 2 and 4 where a fold's two sheets share a word.
    """
    H, W = gc.shape
    p = np.pad(gc, 1, mode="edge")
    out = np.zeros((H, W), bool)
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            if di == dj == 1:
                continue
            out |= p[di:di + H, dj:dj + W] == cc
    return out & (cc != gc)


def ambiguity(key, g, tol, pics, c=None):
    """The ambiguity mask of a key (broadcastable to its failing mask), or None where none applies.

    Bit words (``tol['silhouette'] == 'counts'``): a silhouette explains a fragment that appears or
    vanishes as an edge moves across the pixel's centre, which hands the pixel the coverage of its
    neighbour across that edge: the candidate's set-bit count differs from the golden's and equals the
    golden's count at one of the 8 neighbours (:func:`_edge_counts`). A bit that moved, or a fragment lost
    from inside a surface (a count no neighbour has), is counted against ``fraction`` wherever it is.

    Keys of a light's view (``stage.photon_trace.*``) are over the light's texels, not the camera's
    pixels, even when the two pictures have the same size: only their own layers' edges are ambiguous.

    Parameters
    ----------
    key : str
        The key judged.
    g : ndarray
        The golden's array.
    tol : dict
        The key's tolerance (``locate``, ``silhouette``, ``own_edges``, ``over``).
    pics : dict
        :func:`ambiguity_context` of the case.
    c : ndarray, optional
        The candidate's array (read for bit words' counts).

    Returns
    -------
    bool ndarray or None
    """
    if not tol.get("locate"):
        return None
    g = np.asarray(g)
    if key.startswith("stage.photon_trace."):
        pics = {shp: np.zeros(shp, bool) for shp in pics}
    for shp, mask in pics.items():
        if g.ndim >= 2 and g.shape[:2] == shp:  # per pixel (H, W, ...)
            m = mask.copy()
            if tol.get("silhouette") == "counts" and c is not None and g.dtype.kind == "u" and g.ndim == 3:
                m &= _edge_counts(popcount(np.asarray(c, g.dtype)), popcount(g))
            if tol.get("own_edges") and g.ndim == 2:
                m |= neighbour_changes(_codes(g))
            if tol.get("over") == "nonzero" and g.ndim == 2:  # the lit region's edge
                m |= neighbour_changes(g != 0)
            return m.reshape(shp + (1,) * (g.ndim - 2))
        if g.ndim >= 3 and g.shape[1:3] == shp:  # per layer or plane (L, H, W, ...)
            m = np.zeros(g.shape[:3], bool) | mask[None]
            for i in range(g.shape[0]):
                gi = g[i] if g.ndim == 3 else np.all(np.isfinite(g[i]), axis=-1) if g.dtype.kind == "f" else g[i, ..., 0]
                m[i] |= neighbour_changes(_codes(gi) if g.ndim == 3 else gi)
                if tol.get("over") == "nonzero" and g.ndim == 3:
                    m[i] |= neighbour_changes(g[i] != 0)
            return m.reshape(m.shape + (1,) * (g.ndim - 3))
    return None


def popcount(words):
    """Set bits per pixel of (H, W, K) unsigned words.

    Parameters
    ----------
    words : (H, W, K) unsigned ndarray

    Returns
    -------
    (H, W) int ndarray
    """
    w = np.ascontiguousarray(words)
    return np.unpackbits(w.view(np.uint8).reshape(w.shape[:-1] + (-1,)), axis=-1).sum(axis=-1)


#: a photon whose golden hit lies within this many camera pixels (the pixel's footprint at the hit's depth,
#: measured in the triangles' plane) of an edge two receiver triangles share may name either triangle: the
#: eye-space march names the triangle of the depth image's texel where it detects the crossing, not the one
#: holding the hit (on ``is_caustics_sphere`` 277 of 11608 golden hits lie in the other triangle, all within
#: 2 pixels of the diagonal: a port with an exact ray-triangle hit names those), and an exact hit on the edge
#: itself is a float tie
FACE_TIE_PIXELS = 2.0


def _point_segment_distance(p, a, b):
    """Distance of points p (N, 3) to segments a-b (N, 3 each)."""
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=-1)


def face_ties(golden, name, gold, key, cand_face):
    """Photons whose candidate ``hit_face_l`` differs from the golden's across a shared receiver edge.

    True where the golden and the candidate name two receiver triangles that share an edge (two vertices)
    and the golden's hit point lies within :data:`FACE_TIE_PIXELS` camera pixels of that edge (the pixel's
    footprint at the hit's view depth). None when the scene's receivers or camera cannot be read.

    Parameters
    ----------
    golden : str
        The golden suite's folder.
    name : str
        The case.
    gold : dict of str to ndarray
        The golden's arrays of the case.
    key : str
        ``stage.receiver_hit.hit_face_<l>``.
    cand_face : ndarray
        The candidate's array of ``key``.

    Returns
    -------
    bool ndarray or None

    References
    ----------
    docs/oracle.md, "Conformance" (hit_face ties).
    """
    # imported here: ``refraction_ref.check`` comes with the package, the receivers' kernels only with a
    # case that has receivers
    from ..caustics.receivers import receiver_soup

    l = key.rsplit("_", 1)[-1]
    hp = gold.get(f"stage.receiver_hit.hit_pos_{l}")
    gf = np.asarray(gold[key])
    cf = np.asarray(cand_face)
    if hp is None or hp.shape != gf.shape + (3,) or cf.shape != gf.shape:
        return None
    try:
        scene = load_scene(os.path.join(golden, name, "scene.json"))
        tris = receiver_soup(scene).tris
        cam = Camera.from_dict(scene.data["camera"])
    except Exception:  # noqa: BLE001 - no receivers or camera to read: no ties, every difference counts
        return None
    T = len(tris)
    out = np.zeros(gf.shape, bool)
    sel = np.flatnonzero((cf != gf) & (gf >= 0) & (gf < T) & (cf >= 0) & (cf < T) & np.all(np.isfinite(hp), -1))
    if not sel.size:
        return out
    A, B = tris[gf[sel]], tris[cf[sel]]  # (n, 3, 3)
    same = np.all(A[:, :, None, :] == B[:, None, :, :], axis=-1)  # vertex a of A equals vertex b of B
    shared = same.any(axis=2)  # (n, 3): which of A's vertices B has too
    two = shared.sum(axis=1) == 2
    ia = np.argsort(~shared, axis=1, kind="stable")[:, :2]  # the two shared vertices first
    a = np.take_along_axis(A, ia[:, :1, None], axis=1)[:, 0]
    b = np.take_along_axis(A, ia[:, 1:2, None], axis=1)[:, 0]
    p = hp[sel]
    n = np.cross(A[:, 1] - A[:, 0], A[:, 2] - A[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    # measured in the triangles' plane: the eye-space march's hits lie up to a few 1e-3 off it
    dist = _point_segment_distance(p - np.sum((p - A[:, 0]) * n, axis=-1)[:, None] * n, a, b)
    z = np.maximum(-cam.world_to_view(p)[:, 2], 0.0)
    pix = 2.0 * cam.sy * (1.0 if cam.ortho else z) / cam.height
    out[sel] = two & (dist <= FACE_TIE_PIXELS * pix)
    return out


def margin_ties(gold, key, tol):
    """Pixels where the golden's shadow test is a tie: its margin within ``atol + rtol far`` of 0.

    ``key`` is ``stage.caustic_final.shadow_<l>``; the margin is the golden's ``shadow_margin_<l>``
    (``dl - (zmin + bias)``, 0 at a texel-edge tie), ``far`` the light camera's far plane
    (``stage.photon_trace.camera_<l>``, row 5); None where the golden lacks them.

    Parameters
    ----------
    gold : dict of str to ndarray
        The golden's arrays of the case.
    key : str
        The shadow key.
    tol : dict
        Its tolerance (``margin_key``, ``margin_atol``, ``margin_rtol``).

    Returns
    -------
    bool ndarray or None
    """
    head, tail = key.rsplit(".", 1)
    light = tail.rsplit("_", 1)[-1]
    m = gold.get(f"{head}.{tol['margin_key']}{light}")
    if m is None or np.shape(m) != np.shape(gold[key]):
        return None
    cam = gold.get(f"stage.photon_trace.camera_{light}")
    far = float(np.asarray(cam)[5, 1]) if cam is not None and np.shape(cam) == (6, 3) else 1.0
    eps = float(tol.get("margin_atol", 0.0)) + float(tol.get("margin_rtol", 0.0)) * abs(far)
    with np.errstate(invalid="ignore"):
        return np.abs(np.asarray(m, np.float64)) <= eps


#: volumetric image keys judged with no allowance where the viewing ray stopped (status 2 limit, 4 lost)
#: and the candidate's status agrees: the colour gathered before the stop is kept (docs/oracle.md,
#: "smooth and view"), and a port that drops it differs on these pixels only, a share of the image
#: below any fraction (vol_ramp_lost: 1 lost pixel of 1089)
_STOPPED_STRICT = {"image": ("status", "stage.view.status"), "stage.view.image": ("stage.view.status", "status")}
_STOPPED = (2, 4)


def stopped_strict(key, method, c, g, tol, cand, gold):
    """Pixels judged with no allowance (not even the ambiguity mask): the golden's stopped viewing rays
    (status 2 or 4) where the candidate's status agrees (the golden's when the candidate supplies none).

    Parameters
    ----------
    key : str
        The key judged (``image`` or ``stage.view.image``).
    method : str
        The case's method (the rule is the volumetric method's).
    c, g : ndarray
        The candidate's and the golden's arrays.
    tol : dict
        The key's tolerance.
    cand, gold : dict of str to ndarray
        Every array of the case (the statuses).

    Returns
    -------
    tuple or None
        ``(failing mask, shaped as the key's elementwise mask, detail)``, or None where the rule does
        not apply.
    """
    names = _STOPPED_STRICT.get(key)
    if method != "volumetric" or names is None or tol.get("kind") != "close" or g.ndim != 3:
        return None
    gs = next((np.asarray(gold[n]) for n in names if n in gold and np.shape(gold[n]) == g.shape[:2]), None)
    if gs is None:
        return None
    cs = next((np.asarray(cand[n]) for n in names if n in cand and np.shape(cand[n]) == g.shape[:2]), gs)
    strict = np.isin(gs, _STOPPED) & (cs == gs)
    n = int(np.count_nonzero(strict))
    if n == 0:
        return None
    el = elementwise(np.asarray(c), np.asarray(g), tol, None)[0]  # the key's own tolerance, element by element
    bad = strict.reshape(strict.shape + (1,) * (el.ndim - 2)) & el
    nb = int(np.count_nonzero(fold_mask(bad, strict.shape) if bad.ndim > 2 else bad))
    detail = (f"; stopped viewing rays (status 2 or 4, statuses agreeing): {nb} of {n} pixels differ, "
              f"judged with no allowance{' FAIL' if nb else ''}")
    return bad, detail


def weight_mask(key, tol, gold):
    """Elements judged under a ``weight_key`` floor: the golden companion's (summed over channels) above
    ``floor`` times its maximum, shaped (..., 1) to broadcast over the key's channels; None without one.

    Parameters
    ----------
    key : str
        The key judged.
    tol : dict
        Its tolerance (``weight_key``, ``floor``).
    gold : dict of str to ndarray
        The golden's arrays of the case.

    Returns
    -------
    bool ndarray or None
    """
    wk = tol.get("weight_key")
    if not wk:
        return None
    head, _, last = key.rpartition(".")
    comp = (head + "." if head else "") + last.replace(last.split("_")[0], wk, 1) if last else None
    w = gold.get(comp)
    g = gold.get(key)
    if w is None or g is None:
        return None
    w = np.abs(np.asarray(w, np.float64))
    if w.ndim == g.ndim and w.shape[-1] == 3:
        w = w.sum(axis=-1)
    if w.shape != g.shape[:w.ndim]:
        return None
    mx = float(np.max(w)) if w.size else 0.0
    m = w > float(tol.get("floor", 0.0)) * mx
    return m.reshape(m.shape + (1,) * (g.ndim - m.ndim))
