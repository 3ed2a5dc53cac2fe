"""Diffuse receivers, once for every method: their triangles, caustic-map frames and hits (Chaudhari 2008, §4.1).

Triangles
    A scene's ``receivers`` (a floor, a pool's walls) take light: caustics
    from the image-space, volumetric and exact methods (Chaudhari 2008,
    §4.1; Sun et al. 2008, §6.2.2) and water caustics (Tipprasert 2006,
    ch. 4). :func:`receiver_soup` places every receiver's mesh
    (``fit``/``size`` then ``transform``, as objects) and merges them into
    one triangle soup (:class:`Receivers`); :func:`receiver_set` adds each
    receiver's caustic-map box (:class:`ReceiverSet`). The level map's own
    reference boxes, planes and position maps
    (:mod:`refraction_ref.levelmap.planes`, :mod:`refraction_ref.levelmap.maps`)
    are not receivers: they are the level-map method's reference planes
    (Tipprasert 2006, eqs. 4-1 to 4-13) laid over this same soup, one box
    per (receiver, light), where the caustic map of the other methods is one
    box per receiver aligned with the first light.
Frames
    Receiver ``r``'s caustic map lies on the face (nearest the light) of the
    **tight** box of its vertices in axes aligned with the first light's
    direction at the receiver: the level map's axes (eq. 4-1,
    :func:`~refraction_ref.caustics.boxes.box_axes`), not the level map's
    box (:func:`~refraction_ref.caustics.boxes.reference_box` with its
    default ``placement="tight"``; ``caustics.placement`` places only the
    level map's boxes), framed by
    :func:`~refraction_ref.caustics.boxes.frame_of`: ``caustic_frame_r``
    is (origin, u, v, normal) and texel (a, b) holds the irradiance on the
    first surface of the receiver seen from the light through
    ``origin + (b + .5)/Wc u + (a + .5)/Hc v``. A floor lit from straight
    above gets the floor rectangle itself.
Eye-space intersection (``receiver_hit = 'eyespace'``)
    The thesis follows Krüger et al. (2006): the exiting photon becomes a
    line primitive in the camera's image, and the first fragment of the
    line that falls behind the receivers' depth image is its hit. Here the
    ray is clipped to the camera's frustum, sampled once per pixel along
    its screen-space projection (``ceil(L) + 1`` steps for ``L`` pixels
    along the major axis, uniform on screen, perspective-correct along the
    ray), compared at each sample with the depth image of the receivers
    (rasterized from the camera with the shared rasterizer, nearest depth
    and triangle) at the nearest texel, and the crossing is refined by
    linear interpolation of the depth gap between the last sample in front
    and the first behind (the first behind itself when the sample before
    it saw no receiver); the hit's triangle is that of the texel where the
    crossing was detected. The hit lies on the ray, near but not exactly
    on the receiver (docs/oracle.md, "Porting rules: image-space",
    ``receiver_hit``). A sample that lands
    behind by more than the ray's depth step plus 1 % of the depth is taken
    as passing behind an occluder, not a hit, and the march goes on.
    Photons that leave the frustum, or never cross, are lost (the method's
    known limitation: it only sees what the camera sees).
Exact intersection (``receiver_hit = 'exact'``)
    Embree on the receivers' triangles: the oracle's ground truth for this
    step.

References
----------
.. [1] J. Krüger, K. Bürger, R. Westermann, "Interactive Screen-Space
   Accurate Photon Tracing on GPUs", EGSR 2006.
.. [2] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
   Objects", M.S. thesis, UMBC, 2008, §4.1.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..camera import project_point
from ..embree import HIT_CHUNK, chunk_length, commit, run_chunks, soup_scene
from .boxes import frame_of, reference_box, to_map
from ..meshes import object_mesh
from ..raster import clip_near, rasterize
from ..validation import SceneError

__all__ = ["Receivers", "receiver_soup", "ReceiverSet", "receiver_set", "eye_buffers", "march_eyespace", "hit_exact", "map_position",
           "IndexedTriangles"]


class Receivers(NamedTuple):
    """Every receiver triangle of a scene in one soup.

    Attributes
    ----------
    tris : (T, 3, 3) float64 world vertices
    owner : (T,) int64 receiver index
    normals : (T, 3) float64 unit face normals (zero for zero-area faces)
    albedo : (R, 3) float64
    vertices : list of (V_r, 3) per receiver (for the bounding boxes)
    """

    tris: np.ndarray
    owner: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray
    vertices: list


def receiver_soup(scene, method="scene"):
    """All receiver triangles of a scene (:class:`Receivers`), for every method.

    Parameters
    ----------
    scene : Scene
        A loaded scene; its ``receivers`` are placed as objects are
        (``fit``/``size``, then ``transform``).
    method : str
        The method that needs receivers, named in the error.

    Returns
    -------
    Receivers
        The triangle soup, owners, unit face normals, albedo and each
        receiver's vertices.

    Raises
    ------
    SceneError
        When the scene has no receivers (naming ``method``, which needs them).

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    .. [2] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
       with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
       University, 2006, §4.2 (the receivers of the level map).
    """
    tris, owner, alb, verts = [], [], [], []
    for k, rc in enumerate(scene.data["receivers"] or []):
        try:
            v, f = object_mesh(rc, scene.base_dir)
        except SceneError as e:
            raise SceneError(f"receivers[{k}].mesh: {e}") from None
        tris.append(v[f])
        owner.append(np.full(len(f), k, np.int64))
        alb.append(np.asarray(rc["albedo"], dtype=np.float64))
        verts.append(v)
    if not tris:
        raise SceneError(f"{method}: the scene has no receivers; add at least one entry to 'receivers' "
                         "(e.g. a pool floor: {\"mesh\": \"plane\", \"size\": [4, 4]})")
    t = np.concatenate(tris)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)
    return Receivers(t, np.concatenate(owner), n, np.stack(alb), verts)


class ReceiverSet(NamedTuple):
    """Every receiver triangle, with each receiver's caustic-map box.

    Attributes
    ----------
    tris : (T, 3, 3) float64 world vertices
    owner : (T,) int64 receiver index
    normals : (T, 3) float64 unit face normals
    albedo : (R, 3) float64
    boxes : list of Box, one per receiver
    """

    tris: np.ndarray
    owner: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray
    boxes: list

    def frame(self, r):
        """``caustic_frame_r`` (4, 3): origin, u, v, normal (docs/oracle.md).

        Parameters
        ----------
        r : int
            The receiver.

        Returns
        -------
        (4, 3) float64
        """
        return frame_of(self.boxes[r])


def receiver_set(scene, light, size):
    """Receiver triangles of a scene and their map boxes, aligned with ``light``.

    Parameters
    ----------
    scene : Scene
    light : dict
        The first light: its direction at each receiver's centre orients the box.
    size : int
        Texels per side of each caustic map (``caustics.map_size``).

    Returns
    -------
    ReceiverSet
        The soup of :func:`receiver_soup` with one caustic-map box per receiver.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    soup = receiver_soup(scene, "caustics")
    boxes = []
    for v in soup.vertices:
        centre = (v.min(axis=0) + v.max(axis=0)) / 2.0
        if light["type"] == "directional":
            T0 = np.asarray(light["direction"], dtype=np.float64)
        else:
            T0 = centre - np.asarray(light["position"], dtype=np.float64)
            if not np.linalg.norm(T0) > 0:
                T0 = np.array([0.0, -1.0, 0.0])
        boxes.append(reference_box(v, T0 / np.linalg.norm(T0), int(size)))
    return ReceiverSet(soup.tris, soup.owner, soup.normals, soup.albedo, boxes)


def map_position(rs, r, points):
    """Continuous (col, row) of world points in receiver ``r``'s caustic map.

    :func:`~refraction_ref.levelmap.planes.to_map`'s col and row, operation for operation
    (``q = p - centre``, ``col = (q.U / w + 0.5) Wc``, ``row = (q.W / d + 0.5) Hc``, the dot
    products in :func:`~refraction_ref.vec3.dot`'s order), in a kernel parallel over the points.

    Parameters
    ----------
    rs : ReceiverSet
    r : int
        The receiver.
    points : (N, 3) array_like
        World points.

    Returns
    -------
    col, row : (N,) float64
        Map positions (texel centres at ``+0.5``).

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    box = rs.boxes[r]
    p = np.asarray(points, dtype=np.float64)
    if p.ndim < 1 or p.shape[-1] != 3:
        q = to_map(box, points)
        return q[..., 0], q[..., 1]
    flat = np.ascontiguousarray(p).reshape(-1, 3)
    Hc, Wc = box.size
    frame = np.array([box.center, box.U, box.W, [box.w, box.d, 0.0]], dtype=np.float64)
    col, row = np.empty(len(flat)), np.empty(len(flat))
    _map_position_kernel(flat, frame, float(Hc), float(Wc), col, row)
    return col.reshape(p.shape[:-1]), row.reshape(p.shape[:-1])


@nb.njit(cache=True, parallel=True)
def _map_position_kernel(p, frame, Hc, Wc, col, row):
    cx, cy, cz = frame[0, 0], frame[0, 1], frame[0, 2]
    ux, uy, uz = frame[1, 0], frame[1, 1], frame[1, 2]
    wx, wy, wz = frame[2, 0], frame[2, 1], frame[2, 2]
    bw, bd = frame[3, 0], frame[3, 1]
    for k0 in nb.prange(p.shape[0]):
        k = np.int64(k0)
        qx = p[k, 0] - cx
        qy = p[k, 1] - cy
        qz = p[k, 2] - cz
        col[k] = ((qx * ux + qy * uy + qz * uz) / bw + 0.5) * Wc
        row[k] = ((qx * wx + qy * wy + qz * wz) / bd + 0.5) * Hc


def eye_buffers(rs, cam):
    """The receivers' depth image from the camera and the triangle seen at each pixel.

    Parameters
    ----------
    rs : ReceiverSet
    cam : Camera
        The eye camera.

    Returns
    -------
    depth : (H, W) float64
        Nearest receiver depth, ``+inf`` where none.
    tri : (H, W) int64
        Index into ``rs.tris``, ``-1`` where none.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    .. [2] J. Krüger, K. Bürger, R. Westermann, "Interactive Screen-Space
       Accurate Photon Tracing on GPUs", EGSR 2006.
    """
    tv = cam.world_to_view(rs.tris)
    d = -tv[..., 2]
    cross = d.min(axis=1) < cam.near
    if not cross.any():
        return rasterize(tv, cam, "nearest", clip=False)
    # clip the triangles crossing the near plane, remembering where each piece came from
    parts, src = [], []
    for t in range(len(tv)):
        if not cross[t]:
            parts.append(tv[t:t + 1])
            src.append(np.array([t]))
        else:
            c = clip_near(tv[t:t + 1], cam.near)
            parts.append(c)
            src.append(np.full(len(c), t))
    tv2 = np.concatenate(parts)
    src = np.concatenate(src).astype(np.int64)
    if len(tv2) == 0:  # every receiver behind the camera
        return np.full(cam.shape, np.inf), np.full(cam.shape, -1, np.int64)
    depth, ids = rasterize(tv2, cam, "nearest", clip=False)
    return depth, np.where(ids >= 0, src[np.maximum(ids, 0)], -1)


@nb.njit(cache=True, inline="always")
def _clip_plane(a0, a1, t0, t1):
    """Clip [t0, t1] to where the linear function a0 + a1 t <= 0."""
    if a1 == 0.0:
        if a0 > 0.0:
            return 1.0, 0.0
        return t0, t1
    tc = -a0 / a1
    if a1 > 0.0:
        return t0, min(t1, tc)
    return max(t0, tc), t1


class _Rays(NamedTuple):
    """Rays in the camera's view space."""

    O: np.ndarray  # (N, 3) origins
    D: np.ndarray  # (N, 3) directions


class _View(NamedTuple):
    """The camera the depth image was rendered with: image grid, projection, depth range."""

    W: int
    H: int
    sx: float
    sy: float
    ortho: bool
    near: float
    far: float


class _Knobs(NamedTuple):
    """Settings of the march."""

    rel_thick: float  # surface thickness as a fraction of its depth
    max_samples: int  # samples per ray at most


class _Hits(NamedTuple):
    """What the march finds, per ray."""

    t: np.ndarray  # (N,) ray parameter of the hit, NaN where none
    pix: np.ndarray  # (N, 2) int64 pixel (row, column), -1 where none


#: sides (pixels) of the two levels of tiles whose nearest receiver depth lets the march
#: step over samples that cannot hit (see :func:`_march_kernel`); the coarse a multiple of the fine
TILE_COARSE = 32
TILE_FINE = 8


@nb.njit(cache=True, parallel=True)
def _tile_min_kernel(depth, T, out):
    # out[a, b]: the nearest finite depth of tile (a, b) of T x T pixels, +inf where none
    # (min is exact: the same whatever the order)
    H, W = depth.shape
    for a0 in nb.prange(out.shape[0]):
        a = np.int64(a0)
        for b in range(out.shape[1]):
            out[a, b] = np.inf
        for i in range(a * T, min(a * T + T, H)):
            for j in range(W):
                v = depth[i, j]
                if math.isfinite(v) and v < out[a, j // T]:
                    out[a, j // T] = v


def tile_min(depth, T):
    """The nearest finite depth of each ``T`` x ``T`` tile of a depth image (``+inf`` where none).

    Parameters
    ----------
    depth : (H, W) float64
    T : int
        Tile side in pixels (the last row and column of tiles may be partial).

    Returns
    -------
    (ceil(H / T), ceil(W / T)) float64

    References
    ----------
    .. [1] J. Krüger, K. Bürger, R. Westermann, "Interactive Screen-Space
       Accurate Photon Tracing on GPUs", EGSR 2006.
    """
    d = np.ascontiguousarray(depth, dtype=np.float64)
    out = np.empty((-(-d.shape[0] // T), -(-d.shape[1] // T)))
    _tile_min_kernel(d, np.int64(T), out)
    return out


@nb.njit(cache=True, parallel=True)
def _coarsen_min(fine, r, out):
    # out[a, b] = min of fine[r a : r a + r, r b : r b + r] (exact in any order)
    for a0 in nb.prange(out.shape[0]):
        a = np.int64(a0)
        for b in range(out.shape[1]):
            v = np.inf
            for i in range(a * r, min(a * r + r, fine.shape[0])):
                for j in range(b * r, min(b * r + r, fine.shape[1])):
                    v = min(v, fine[i, j])
            out[a, b] = v


@nb.njit(cache=True, inline="always")
def _march_sample(m, n, persp, t0, t1, dA, dB, ox, oy, oz, dx, dy, dz, W, H, sx, sy, ortho):
    """Sample ``m`` of ``n`` of a clipped ray: its parameter ``t`` and (col, row, depth) on screen."""
    u = m / n
    if persp:  # perspective-correct: 1/depth is linear in screen space
        s = (u / dB) / ((1.0 - u) / dA + u / dB)
    else:
        s = u
    t = t0 + s * (t1 - t0)
    col, row, rd = project_point(ox + t * dx, oy + t * dy, oz + t * dz, W, H, sx, sy, ortho)
    return t, col, row, rd


#: how far inside a tile (pixels) the samples of a run stepped over must lie on the line
#: through the end points: far above the rounding of their screen positions (~1e-10 px),
#: far below a pixel
_TILE_MARGIN = 1e-6


@nb.njit(cache=True, inline="always")
def _run_in_tile(T, m, n, c0, r0, stepc, stepr, inv_c, inv_r, W, H):
    """The tile (a, b) of ``T`` pixels (a literal: the divisions are shifts) holding sample
    ``m`` (on screen ``(c0, r0) + m (stepc, stepr)``, ``_TILE_MARGIN`` inside) and the last
    sample ``mb <= n`` of the run from ``m`` still in it (``inv_c``, ``inv_r``: 1 / steps,
    0 for none); ``mb = -1`` when sample ``m`` is not inside a tile."""
    col = c0 + m * stepc
    row = r0 + m * stepr
    if not (col >= 0.0 and col < W and row >= 0.0 and row < H):
        return 0, 0, np.int64(-1)
    a = np.int64(math.floor(row)) // T
    b = np.int64(math.floor(col)) // T
    x0 = b * T + _TILE_MARGIN
    x1 = min(b * T + T, W) - _TILE_MARGIN
    y0 = a * T + _TILE_MARGIN
    y1 = min(a * T + T, H) - _TILE_MARGIN
    if not (col >= x0 and col <= x1 and row >= y0 and row <= y1):
        return a, b, np.int64(-1)
    k = 1e18
    if stepc > 0.0:
        k = min(k, (x1 - col) * inv_c)
    elif stepc < 0.0:
        k = min(k, (x0 - col) * inv_c)
    if stepr > 0.0:
        k = min(k, (y1 - row) * inv_r)
    elif stepr < 0.0:
        k = min(k, (y0 - row) * inv_r)
    return a, b, min(m + np.int64(k), n)


@nb.njit(cache=True, inline="always")
def _nearer(m, me, persp, inv_n, ia, ib, dA, dB, slack, lim):
    """Whether the ray's depth at samples ``m .. me`` is below ``lim`` (less ``slack``): from its
    end depths, 1/depth linear in the sample for perspective-correct samples (``ia``, ``ib``
    the end points' 1/depth), the depth itself for orthographic ones; the extremes at the ends."""
    if persp:
        w = min(ia + (m * inv_n) * (ib - ia), ia + (me * inv_n) * (ib - ia))
        return w > 0.0 and w * (lim - slack) > 1.0
    return max(dA + (m * inv_n) * (dB - dA), dA + (me * inv_n) * (dB - dA)) + slack < lim


@nb.njit(cache=True, parallel=True)
def _march_kernel(rays, depth, view, knobs, tiles, hits):
    # the named tuples unpacked by name, outside the prange loop (inside it, Numba
    # drops stores into arrays taken from a tuple: numba#7135)
    O, D = rays.O, rays.D
    W, H, sx, sy, ortho, near, far = view.W, view.H, view.sx, view.sy, view.ortho, view.near, view.far
    rel_thick, max_samples = knobs.rel_thick, knobs.max_samples
    t_hit, pix = hits.t, hits.pix
    tc, tf = tiles.coarse, tiles.fine
    for k0 in nb.prange(O.shape[0]):
        k = np.int64(k0)
        t_hit[k] = np.nan
        pix[k, 0] = -1
        pix[k, 1] = -1
        ox, oy, oz = O[k, 0], O[k, 1], O[k, 2]
        dx, dy, dz = D[k, 0], D[k, 1], D[k, 2]
        if not (math.isfinite(ox) and math.isfinite(dx)):
            continue
        # clip the ray to the view frustum: each bound is linear in t
        t0 = 0.0
        t1 = 1e30
        t0, t1 = _clip_plane(near + oz, dz, t0, t1)      # depth >= near
        t0, t1 = _clip_plane(-oz - far, -dz, t0, t1)     # depth <= far
        if ortho:
            t0, t1 = _clip_plane(ox - sx, dx, t0, t1)
            t0, t1 = _clip_plane(-ox - sx, -dx, t0, t1)
            t0, t1 = _clip_plane(oy - sy, dy, t0, t1)
            t0, t1 = _clip_plane(-oy - sy, -dy, t0, t1)
        else:  # |x| <= sx d, |y| <= sy d with d = -z
            t0, t1 = _clip_plane(ox + sx * oz, dx + sx * dz, t0, t1)
            t0, t1 = _clip_plane(-ox + sx * oz, -dx + sx * dz, t0, t1)
            t0, t1 = _clip_plane(oy + sy * oz, dy + sy * dz, t0, t1)
            t0, t1 = _clip_plane(-oy + sy * oz, -dy + sy * dz, t0, t1)
        if not (t1 > t0) or t1 >= 1e29:
            continue
        # screen-space end points: one sample per pixel along the projected line
        c0, r0, dA = project_point(ox + t0 * dx, oy + t0 * dy, oz + t0 * dz, W, H, sx, sy, ortho)
        c1, r1, dB = project_point(ox + t1 * dx, oy + t1 * dy, oz + t1 * dz, W, H, sx, sy, ortho)
        n = np.int64(math.ceil(max(abs(c1 - c0), abs(r1 - r0)))) + 1
        n = min(max(n, 2), max_samples)
        persp = not (ortho or not (dA > 0.0 and dB > 0.0))
        # Tiles: whether sample m hits depends on it and on sample m - 1 alone, and it can hit
        # only where the ray is at or behind the receiver under it. With samples uniform on
        # screen (orthographic, or perspective-correct: then on screen sample m lies at
        # (c0, r0) + m (c1 - c0, r1 - r0) / n and 1/depth is linear in m), a run of samples
        # inside one tile whose ray depth at both ends is nearer than the tile's nearest
        # receiver holds no hit: it is stepped over, and the sample before the next one tested
        # is evaluated as the state that one compares with. The hits are those of testing
        # every sample.
        tiled = ortho or persp
        stepc = (c1 - c0) / n
        stepr = (r1 - r0) / n
        inv_c = 1.0 / stepc if stepc != 0.0 else 0.0
        inv_r = 1.0 / stepr if stepr != 0.0 else 0.0
        inv_n = 1.0 / n
        ia = 1.0 / dA if dA != 0.0 else 0.0
        ib = 1.0 / dB if dB != 0.0 else 0.0
        # the bounds' own rounding, and that of a sample's depth -(oz + t dz), are ~1e-15 of these
        slack = 1e-9 * (abs(oz) + abs(t0 * dz) + abs(t1 * dz) + abs(dA) + abs(dB))
        prev_gap = -np.inf
        prev_t = t0
        prev_rd = dA
        m = np.int64(0)
        stale = False  # prev_* are not sample m - 1's (a run was stepped over)
        hit = False
        while m <= n and not hit:
            mb = m  # test samples m .. mb one by one
            if tiled:
                a, b, me = _run_in_tile(TILE_COARSE, m, n, c0, r0, stepc, stepr, inv_c, inv_r, W, H)
                if me >= m and _nearer(m, me, persp, inv_n, ia, ib, dA, dB, slack, tc[a, b]):
                    m = me + 1
                    stale = True
                    continue
                a, b, me = _run_in_tile(TILE_FINE, m, n, c0, r0, stepc, stepr, inv_c, inv_r, W, H)
                if me >= m:
                    if _nearer(m, me, persp, inv_n, ia, ib, dA, dB, slack, tf[a, b]):
                        m = me + 1
                        stale = True
                        continue
                    mb = me  # the rest of this fine tile, tested sample by sample
            if stale:
                t, col, row, rd = _march_sample(m - 1, n, persp, t0, t1, dA, dB, ox, oy, oz, dx, dy, dz,
                                                W, H, sx, sy, ortho)
                i = min(max(np.int64(math.floor(row)), 0), H - 1)
                j = min(max(np.int64(math.floor(col)), 0), W - 1)
                sd = depth[i, j]
                prev_gap = rd - sd if math.isfinite(sd) else -np.inf
                prev_t = t
                prev_rd = rd
                stale = False
            for q in range(m, mb + 1):
                t, col, row, rd = _march_sample(q, n, persp, t0, t1, dA, dB, ox, oy, oz, dx, dy, dz,
                                                W, H, sx, sy, ortho)
                i = min(max(np.int64(math.floor(row)), 0), H - 1)
                j = min(max(np.int64(math.floor(col)), 0), W - 1)
                sd = depth[i, j]
                gap = rd - sd if math.isfinite(sd) else -np.inf
                if gap >= 0.0 and prev_gap < 0.0:
                    if gap <= abs(rd - prev_rd) + rel_thick * sd:
                        f = 1.0
                        if math.isfinite(prev_gap):
                            f = -prev_gap / (gap - prev_gap)
                        t_hit[k] = prev_t + f * (t - prev_t)
                        pix[k, 0] = i
                        pix[k, 1] = j
                        hit = True
                        break
                prev_gap = gap
                prev_t = t
                prev_rd = rd
            m = mb + 1


class _Tiles(NamedTuple):
    """The depth image's nearest depth per tile, two levels (:func:`tile_min`)."""

    coarse: np.ndarray  # TILE_COARSE pixels a side
    fine: np.ndarray  # TILE_FINE pixels a side


def march_eyespace(origins_view, dirs_view, depth, cam, rel_thick=0.01, max_samples=1 << 16):
    """Krüger-style screen-space march of rays against a depth image.

    Parameters
    ----------
    origins_view, dirs_view : (N, 3) array_like
        Rays in the camera's view space.
    depth : (H, W) float64
        The receivers' depth image (:func:`eye_buffers`).
    cam : Camera
    rel_thick : float
        Surface thickness as a fraction of its depth (beyond it a sample
        behind the surface is taken as passing behind it).
    max_samples : int
        Samples per ray at most.

    Returns
    -------
    t : (N,) float64
        Ray parameter of the hit, NaN where none.
    pix : (N, 2) int64
        Pixel (row, column) of the hit, ``-1`` where none.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    .. [2] J. Krüger, K. Bürger, R. Westermann, "Interactive Screen-Space
       Accurate Photon Tracing on GPUs", EGSR 2006.
    """
    O = np.ascontiguousarray(origins_view, dtype=np.float64).reshape(-1, 3)
    D = np.ascontiguousarray(dirs_view, dtype=np.float64).reshape(-1, 3)
    t = np.empty(len(O))
    pix = np.empty((len(O), 2), np.int64)
    if len(O):
        W, H, sx, sy = cam.kernel_args()
        # marches differ in length by orders of magnitude (a ray crossing the image against one
        # that leaves at once): rays go to the threads in small chunks as they free up
        dep = np.ascontiguousarray(depth, dtype=np.float64)
        fine = tile_min(dep, TILE_FINE)
        coarse = np.empty((-(-dep.shape[0] // TILE_COARSE), -(-dep.shape[1] // TILE_COARSE)))
        _coarsen_min(fine, TILE_COARSE // TILE_FINE, coarse)
        with nb.parallel_chunksize(64):
            _march_kernel(_Rays(O, D), dep, _View(W, H, sx, sy, bool(cam.ortho), float(cam.near), float(cam.far)),
                          _Knobs(float(rel_thick), int(max_samples)), _Tiles(coarse, fine), _Hits(t, pix))
    return t, pix


@nb.njit(cache=True, parallel=True)
def _abs_max_kernel(vertices, faces):
    # max |vertices[faces]| (max is exact: the same whatever the order)
    m = 0.0
    for f0 in nb.prange(faces.shape[0]):
        f = np.int64(f0)
        for k in range(3):
            for c in range(3):
                m = max(m, abs(vertices[faces[f, k], c]))
    return m


class IndexedTriangles:
    """The triangles ``vertices[faces]`` without building them: what :func:`hit_exact` and
    :func:`~refraction_ref.caustics.shade.exact_visibility` read of them.

    ``tris[f, k]`` (``f`` indices, ``k`` a corner) is ``vertices[faces[f, k]]``, the values
    ``vertices[faces][f, k]`` holds; ``len`` is the number of faces; ``np.asarray`` builds
    the (F, 3, 3) array.
    """

    def __init__(self, vertices, faces):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.shape = (len(self.faces), 3, 3)

    def __len__(self):
        return len(self.faces)

    def __getitem__(self, key):
        f, k = key
        return self.vertices[self.faces[f, k]]

    def __array__(self, dtype=None, copy=None):
        a = self.vertices[self.faces]
        return a if dtype is None else a.astype(dtype)

    def abs_max(self):
        """``np.abs(vertices[faces]).max()`` on every thread (0 without faces)."""
        return float(_abs_max_kernel(self.vertices, self.faces)) if len(self.faces) else 0.0


def hit_exact(tris, origins, dirs, scene=None):
    """Nearest hit of world rays with triangles (Embree), t recomputed in float64.

    The rays are traced in fixed chunks of :data:`~refraction_ref.embree.HIT_CHUNK`
    on ``numba.get_num_threads()`` threads (:func:`~refraction_ref.embree.run_chunks`):
    each ray's hit is computed on its own, so the result does not depend on the
    chunks or the threads.

    Parameters
    ----------
    tris : (T, 3, 3) float64 or IndexedTriangles
    origins, dirs : (N, 3) float64
    scene : embreex scene, optional
        An Embree scene whose primitive ``k`` is ``tris[k]`` (e.g. the indexed mesh
        ``embree.mesh_scene(vertices, faces)`` with ``tris = vertices[faces]``);
        default the cached soup of ``tris``.

    Returns
    -------
    t : (N,) float64
        Distance along the ray, NaN on a miss.
    face : (N,) int64
        Triangle index, ``-1`` on a miss.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    o = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = len(o)
    if n == 0 or len(tris) == 0:
        return np.full(n, np.nan), np.full(n, -1, np.int64)
    t = np.empty(n)  # rows set to NaN / -1 by their chunk (_finite_rows32), then the hits
    face = np.empty(n, np.int64)
    scene = commit(soup_scene(np.asarray(tris)) if scene is None else scene)  # built before the threads query it

    VF = _indexed(tris)

    def one(a, b):
        # rays [a, b): the finite ones are traced; their float32 copies for Embree are made
        # by a nogil kernel (no NumPy under the GIL), in the chunk's thread
        m = b - a
        ii = np.empty(m, np.int64)
        o32 = np.empty((m, 3), np.float32)
        d32 = np.empty((m, 3), np.float32)
        cnt = _finite_rows32(o, d, a, b, ii, o32, d32, t, face)
        if cnt == 0:
            return
        res = scene.run(o32[:cnt], d32[:cnt], output=1)
        _mt_kernel(VF[0], VF[1], o, d, ii[:cnt], np.asarray(res["primID"]), np.asarray(res["tfar"]), t, face)

    run_chunks(one, n, chunk_length(n, HIT_CHUNK))
    return t, face


@nb.njit(cache=True, nogil=True)
def _finite_rows32(o, d, a, b, ii, o32, d32, t, face):
    # rays [a, b): t NaN and face -1 (no hit yet); those whose origin and direction are finite,
    # in order: their indices and float32 copies (NumPy's casts: round to nearest); returns how many
    cnt = 0
    for i in range(a, b):
        t[i] = np.nan
        face[i] = -1
        ok = True
        for c in range(3):
            if not (math.isfinite(o[i, c]) and math.isfinite(d[i, c])):
                ok = False
        if ok:
            ii[cnt] = i
            for c in range(3):
                o32[cnt, c] = np.float32(o[i, c])
                d32[cnt, c] = np.float32(d[i, c])
            cnt += 1
    return cnt


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _mt_kernel(V, F, o, d, ii, prim, tfar, t, face):
    # the float64 Moller-Trumbore distance on the triangle Embree found, for rays ii: the
    # NumPy code it replaced (np.cross; einsum('ij,ij->i'), whose order _einsum_dot keeps),
    # operation for operation; compiled nogil, so the chunks' threads run it at once
    for m in range(ii.shape[0]):
        f = np.int64(prim[m])
        if f < 0:
            continue
        i = ii[m]
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        e1x, e1y, e1z = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
        e2x, e2y, e2z = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        px = dy * e2z - dz * e2y
        py = dz * e2x - dx * e2z
        pz = dx * e2y - dy * e2x
        det = _einsum_dot(e1x, e1y, e1z, px, py, pz)
        tx, ty, tz = o[i, 0] - V[a, 0], o[i, 1] - V[a, 1], o[i, 2] - V[a, 2]
        qx = ty * e1z - tz * e1y
        qy = tz * e1x - tx * e1z
        qz = tx * e1y - ty * e1x
        tt = _einsum_dot(e2x, e2y, e2z, qx, qy, qz) / det
        if not (math.isfinite(tt) and tt > 0):
            tt = np.float64(tfar[m])
        t[i] = tt
        face[i] = f


@nb.njit(cache=True, inline="always")
def _einsum_dot(ax, ay, az, bx, by, bz):
    """``np.einsum('ij,ij->i')``'s sum of one row, in its order (see ``exact._dot3``)."""
    return (ax * bx + az * bz) + ay * by


def _indexed(tris):
    """(V, F) with ``tris[f, k] == V[F[f, k]]``: an IndexedTriangles' arrays, or a soup's corners."""
    if isinstance(tris, IndexedTriangles):
        return tris.vertices, tris.faces
    V = np.ascontiguousarray(tris, dtype=np.float64).reshape(-1, 3)
    return V, np.arange(len(V), dtype=np.int64).reshape(-1, 3)


def occluded(tris, origins, dirs, tmax=None, scene=None):
    """Does a ray meet any of the triangles (before ``tmax``)? Embree any-hit test.

    Parameters
    ----------
    tris : (T, 3, 3) float64 or IndexedTriangles
    origins, dirs : (N, 3) float64
        World rays.
    tmax : (N,) float64, optional
        Farthest distance tested per ray; default unbounded.
    scene : embreex scene, optional
        As for :func:`hit_exact`.

    Returns
    -------
    (N,) bool
        True where the ray is blocked.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, §4.1.
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    if len(o) == 0 or len(tris) == 0:
        return np.zeros(len(o), bool)
    t, _ = hit_exact(tris, o, dirs, scene)
    hit = np.isfinite(t)
    if tmax is not None:
        hit &= t < np.asarray(tmax)
    return hit
