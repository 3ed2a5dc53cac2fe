"""Photon generation from directional and point lights (§4.3).

As in the paper, the volume's bounding box is "rendered from the light"
into an M x M texture (M = ``photons``) and every covered texel becomes one
photon, placed where the texel's ray enters the box (the 3D position the
paper's shader writes for front faces), travelling along that ray, with the
light's RGB emission. The rasterization of the six box faces is replaced by
its exact equivalent for a box, a slab test per texel ray.

* Directional light: an orthographic texture perpendicular to the light
  direction, just covering the box's projection (square texels).
* Point light: a perspective texture from the light position looking at the
  box centre (the shared :class:`~refraction_ref.camera.Camera`, so texel
  rays are its primary rays), just covering the box.

Proxy geometry (§4.3, last paragraph): "we can render a proxy geometry
into the shadow map, rather than the bounding cube of the volume". The
light's texture keeps its window (it still just covers the volume's box,
so texels are the box's texels), but a texel makes a photon only where its
ray meets the proxy, and the photon starts where it does:

* ``("mesh", tris)``: an inflated copy of the objects' meshes
  (:func:`inflate_mesh`), rendered as the nearest front face per texel
  (Embree's nearest hit on the texel's ray, then the hit recomputed in
  float64 on that triangle: the exact equivalent of rasterizing the proxy
  at texel centres). A texel whose nearest proxy face is a back face (its
  ray starts inside the proxy, or slips through a crack) starts on the
  volume's box instead, as without a proxy.
* ``("box", (2, 3) bounds)``: a box inside the volume (for ``volume``
  input: the voxels whose index differs from the outside, grown by the
  inflation; :func:`occupied_box`).

Photon weights make the stored radiance independent of the photon count and
of the voxel size: a photon carries ``L * dA / h^2`` (directional: dA the
texel area) or ``I * domega / h^2`` (point: domega the texel's solid
angle), where h^2 is the voxel's cross-section. Marching deposits weight x
length-in-voxels, so a uniform beam of radiance L fills every voxel it
crosses with L.

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.3.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..camera import Camera
from ..kernels import copy_rows
from ..validation import SceneError

__all__ = ["generate_photons", "box_entry", "slab_entry", "slab_both", "entry_points", "inflate_mesh",
           "occupied_box"]


def box_entry(origins, dirs, bounds):
    """Parameter where rays enter a box (slab test), ``inf`` when they miss.

    Parameters
    ----------
    origins, dirs : (P, 3) float64
    bounds : (2, 3) float64

    Returns
    -------
    t_in, t_out : (P,) float64
        Entry and exit parameters (t_in clamped at 0 for origins inside).

    References
    ----------
    Sun et al. (2008), §4.3 (where each texel's ray enters the volume's box).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / dirs
        t0 = (bounds[0] - origins) * inv
        t1 = (bounds[1] - origins) * inv
    lo = np.where(np.isnan(t0), -np.inf, np.minimum(t0, t1))
    hi = np.where(np.isnan(t0), np.inf, np.maximum(t0, t1))
    t_in = np.maximum(lo.max(axis=1), 0.0)
    t_out = hi.min(axis=1)
    miss = ~(t_out > t_in)
    t_in[miss] = np.inf
    return t_in, t_out


@nb.njit(cache=True, inline="always")
def _np_min(a, b):
    """``np.minimum``: NaN-propagating, and ``b`` on a tie (so the same signed zero)."""
    return a if (a < b or a != a) else b


@nb.njit(cache=True, inline="always")
def _np_max(a, b):
    """``np.maximum``: NaN-propagating, and ``b`` on a tie (so the same signed zero)."""
    return a if (a > b or a != a) else b


def slab_entry(org, dirs, b, t_in):
    """:func:`box_entry`'s ``t_in`` per ray, the same operations in the same order; parallel over rays.

    Parameters
    ----------
    org, dirs : (P, 3) float64
        Ray origins and directions.
    b : (2, 3) float64
        The box.
    t_in : (P,) float64
        Written: the entry parameter (``inf`` where the ray misses).

    Returns
    -------
    None

    References
    ----------
    Sun et al. (2008), §4.3 (where each texel's ray enters the volume's box).
    """
    slab_both(org, dirs, b, t_in, t_in, False)


@nb.njit(cache=True, parallel=True)
def slab_both(org, dirs, b, t_in, t_out, want_out):
    """:func:`box_entry`'s ``t_in`` and (``want_out``) ``t_out`` per ray; parallel over rays.

    The same operations in the same order as :func:`box_entry` (``np.min``
    over the axes is a left fold of ``np.minimum``).

    Parameters
    ----------
    org, dirs : (P, 3) float64
        Ray origins and directions.
    b : (2, 3) float64
        The box.
    t_in, t_out : (P,) float64
        Written: entry (``inf`` where the ray misses) and, with
        ``want_out``, exit parameters.
    want_out : bool
        Write ``t_out``.

    Returns
    -------
    None

    References
    ----------
    Sun et al. (2008), §4.3 (where each texel's ray enters the volume's box).
    """
    for p in nb.prange(org.shape[0]):
        lo = 0.0
        hi = 0.0
        for c in range(3):
            inv = 1.0 / dirs[p, c]
            t0 = (b[0, c] - org[p, c]) * inv
            t1 = (b[1, c] - org[p, c]) * inv
            if t0 != t0:
                lc = -np.inf
                hc = np.inf
            else:
                lc = _np_min(t0, t1)
                hc = _np_max(t0, t1)
            if c == 0:
                lo = lc
                hi = hc
            else:
                lo = _np_max(lo, lc)
                hi = _np_min(hi, hc)
        t = _np_max(lo, 0.0)
        t_in[p] = t if hi > t else np.inf
        if want_out:
            t_out[p] = hi


@nb.njit(cache=True, parallel=True)
def entry_points(pos, dirs, b, entry):
    """Where each photon's texel ray entered the box: ``pos - max(t, 0) dirs`` with ``t`` the exit
    parameter of the reversed ray (:func:`box_entry` of ``(pos, -dirs)``; 0 where not finite), the same
    operations in the same order as that NumPy expression; parallel over photons.

    Parameters
    ----------
    pos, dirs : (P, 3) float64
        Photon start points and directions.
    b : (2, 3) float64
        World-space corners of the volume.
    entry : (P, 3) float64
        Output, written in place.

    Returns
    -------
    None
        ``entry`` holds the points.

    References
    ----------
    Sun et al. (2008), §4.3 (photons that start on a proxy, last paragraph).
    """
    for p in nb.prange(pos.shape[0]):
        hi = 0.0
        for c in range(3):
            inv = 1.0 / (-dirs[p, c])
            t0 = (b[0, c] - pos[p, c]) * inv
            t1 = (b[1, c] - pos[p, c]) * inv
            hc = np.inf if t0 != t0 else _np_max(t0, t1)
            hi = hc if c == 0 else _np_min(hi, hc)
        s = _np_max(hi, 0.0) if (hi == hi and abs(hi) < np.inf) else 0.0
        for c in range(3):
            entry[p, c] = pos[p, c] - s * dirs[p, c]


@nb.njit(cache=True, parallel=True)
def _ortho_origins(ca, cc, s, side, e1, e2, dmin, d, org):
    """Texel ray origins of a directional light's texture (row r, column q); parallel over rows."""
    M = s.shape[0]
    for r in nb.prange(M):
        C = cc - s[r] * side
        for q in range(M):
            A = ca + s[q] * side
            for c in range(3):
                org[r * M + q, c] = A * e1[c] + C * e2[c] + dmin * d[c]


@nb.njit(cache=True, parallel=True)
def _gather_hits(org, dirs, t_in, idx, b, pos, dout):
    """Entry points (clipped to the box) and directions of the covered texels; parallel over photons."""
    for m in nb.prange(idx.shape[0]):
        p = idx[m]
        t = t_in[p]
        for c in range(3):
            x = org[p, c] + t * dirs[p, c]
            x = _np_max(x, b[0, c])
            pos[m, c] = _np_min(x, b[1, c])
            dout[m, c] = dirs[p, c]


@nb.njit(cache=True, parallel=True)
def _face_cross(v, f, out):
    """``np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])``, the same operations; parallel over faces."""
    for i in nb.prange(f.shape[0]):
        a = f[i, 0]
        b = f[i, 1]
        c = f[i, 2]
        e1x = v[b, 0] - v[a, 0]
        e1y = v[b, 1] - v[a, 1]
        e1z = v[b, 2] - v[a, 2]
        e2x = v[c, 0] - v[a, 0]
        e2y = v[c, 1] - v[a, 1]
        e2z = v[c, 2] - v[a, 2]
        out[i, 0] = e1y * e2z - e1z * e2y
        out[i, 1] = e1z * e2x - e1x * e2z
        out[i, 2] = e1x * e2y - e1y * e2x


@nb.njit(cache=True, parallel=True)
def _gather_corners(v, f, out):
    """``v[f]`` for (F, 3) faces: (F, 3, 3); parallel over faces."""
    for i in nb.prange(f.shape[0]):
        for k in range(3):
            q = f[i, k]
            for c in range(3):
                out[i, k, c] = v[q, c]


@nb.njit(cache=True)
def _scatter_add_rows(n, f, fn):
    """``for k in range(3): np.add.at(n, f[:, k], fn)``: the same additions in the same order (serial)."""
    for k in range(3):
        for i in range(f.shape[0]):
            r = f[i, k]
            for c in range(n.shape[1]):
                n[r, c] += fn[i, c]


@nb.njit(cache=True)
def _scatter_min(a, idx, x):
    """``np.minimum.at(a, idx, x)`` (NaN-propagating, ``x`` on a tie), serial."""
    for i in range(idx.shape[0]):
        a[idx[i]] = _np_min(a[idx[i]], x[i])


def _weld(v):
    """``np.unique(v, axis=0, return_inverse=True)`` (rows sorted lexicographically, inverse flattened).

    By a stable ``np.lexsort`` of the columns, in half its time: the same order, the same groups (rows
    equal as floats). Where a group holds rows that differ in their bits (0.0 and -0.0), which of them
    np.unique keeps is up to its unstable sort, so that case is left to np.unique itself.
    """
    if len(v) == 0:
        uv, inv = np.unique(v, axis=0, return_inverse=True)
        return uv, inv.reshape(-1)
    perm = np.lexsort((v[:, 2], v[:, 1], v[:, 0]))
    s = v[perm]
    new = np.empty(len(v), bool)
    new[0] = True
    np.any(s[1:] != s[:-1], axis=1, out=new[1:])
    bits = s.view(np.uint64)
    if np.any(bits[1:][~new[1:]] != bits[:-1][~new[1:]]):
        uv, inv = np.unique(v, axis=0, return_inverse=True)
        return uv, inv.reshape(-1)
    inv = np.empty(len(v), np.int64)
    inv[perm] = np.cumsum(new) - 1
    return s[new], inv


def inflate_mesh(vertices, faces, distance, indexed=False):
    """An inflated copy of a closed triangle mesh: every face plane moved out by at least ``distance``.

    Vertices are welded by position (so seams do not open), each is moved
    along its area-weighted normal by ``distance / c`` where c is the
    smallest cosine between that normal and the normals of its faces,
    bounded below by 1/2 (a "mitred" offset: each face's plane moves by at
    least ``distance`` wherever c >= 1/2). Faces are wound outwards (the
    winding is flipped if the signed volume is negative).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int
    distance : float
        World units (>= 0).
    indexed : bool
        Also return the welded mesh the triangles index.

    Returns
    -------
    tris : (F, 3, 3) float64
        The inflated triangles, wound outwards.
    points, welded : (W, 3) float64, (F, 3) int64
        Only with ``indexed``: ``tris == points[welded]``.

    References
    ----------
    Sun et al. (2008), §4.3: "for a complex object, we typically use a
    mesh that has been inflated to encompass the entire object".
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return (np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 3), np.int64)) if indexed else np.zeros((0, 3, 3))
    uv, inv = _weld(v)
    fw = inv[f]
    vol = float(np.einsum("ij,ij->i", uv[fw[:, 0]], np.cross(uv[fw[:, 1]], uv[fw[:, 2]])).sum())
    if vol < 0:
        fw = fw[:, ::-1]
    fw = np.ascontiguousarray(fw)
    # meshes.vertex_normals(uv, fw), its np.add.at as a Numba loop (the same additions in the same order)
    fn = np.empty((len(fw), 3))
    _face_cross(uv, fw, fn)  # = np.cross(uv[fw[:, 1]] - uv[fw[:, 0]], uv[fw[:, 2]] - uv[fw[:, 0]]), in parallel
    vn = np.zeros_like(uv)
    _scatter_add_rows(vn, fw, fn)
    ln = np.linalg.norm(vn, axis=1, keepdims=True)
    vn = np.divide(vn, ln, out=np.zeros_like(vn), where=ln > 0)
    ln = np.linalg.norm(fn, axis=1, keepdims=True)
    fn = np.divide(fn, ln, out=np.zeros_like(fn), where=ln > 0)
    cmin = np.ones(len(uv))
    for k in range(3):  # np.minimum.at, as a Numba loop
        _scatter_min(cmin, fw[:, k].copy(), np.where(ln[:, 0] > 0, np.einsum("ij,ij->i", vn[fw[:, k]], fn), 1.0))
    scale = float(distance) / np.maximum(cmin, 0.5)
    out = uv + vn * scale[:, None]
    tris = np.empty((len(fw), 3, 3))
    _gather_corners(out, fw, tris)  # = out[fw], in parallel
    return (tris, out, fw) if indexed else tris


def occupied_box(ior, bounds, outside_ior, eps, grow):
    """The proxy of a ``volume`` input: the box of the voxels whose index differs from the outside.

    Parameters
    ----------
    ior : (nx, ny, nz) float64
    bounds : (2, 3) float64
    outside_ior : float
    eps : float
        A voxel differs when ``|n - outside_ior| >= eps`` (the octree's
        primary tolerance).
    grow : float
        Voxels added on every side (``volumetric.proxy_inflate``).

    Returns
    -------
    (2, 3) float64 or None
        World bounds, clipped to the volume; None when no voxel differs.

    References
    ----------
    Sun et al. (2008), §4.3 (proxy geometry, last paragraph).
    """
    n = np.asarray(ior)
    b = np.asarray(bounds, dtype=np.float64)
    h = (b[1] - b[0]) / np.asarray(n.shape, dtype=np.float64)
    occ = np.abs(n - float(outside_ior)) >= float(eps)
    if not occ.any():
        return None
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):
        ax = np.flatnonzero(occ.any(axis=tuple(c for c in range(3) if c != a)))
        lo[a] = b[0, a] + (ax[0] - float(grow)) * h[a]
        hi[a] = b[0, a] + (ax[-1] + 1 + float(grow)) * h[a]
    return np.stack([np.maximum(lo, b[0]), np.minimum(hi, b[1])])


@nb.njit(cache=True, parallel=True)
def _proxy_entry(org, dirs, tris, prim, t_box, t_out):
    """Start parameter per texel ray from the proxy's nearest face (float64 on Embree's triangle).

    ``t_box`` (in, out): the box entry (inf: misses the box). Out: the
    proxy's front-face hit clamped to the box entry, the box entry where
    the nearest face is a back face, inf where the ray misses the proxy or
    meets it beyond the box; parallel over rays.
    """
    for p in nb.prange(org.shape[0]):
        q = prim[p]
        tb = t_box[p]
        if q < 0 or not (tb < np.inf):
            t_box[p] = np.inf
            continue
        e1x = tris[q, 1, 0] - tris[q, 0, 0]
        e1y = tris[q, 1, 1] - tris[q, 0, 1]
        e1z = tris[q, 1, 2] - tris[q, 0, 2]
        e2x = tris[q, 2, 0] - tris[q, 0, 0]
        e2y = tris[q, 2, 1] - tris[q, 0, 1]
        e2z = tris[q, 2, 2] - tris[q, 0, 2]
        nx_ = e1y * e2z - e1z * e2y
        ny_ = e1z * e2x - e1x * e2z
        nz_ = e1x * e2y - e1y * e2x
        dn = dirs[p, 0] * nx_ + dirs[p, 1] * ny_ + dirs[p, 2] * nz_
        if not dn < 0.0:  # a back face (or edge-on): start on the box, as without a proxy
            continue
        t = ((tris[q, 0, 0] - org[p, 0]) * nx_ + (tris[q, 0, 1] - org[p, 1]) * ny_
             + (tris[q, 0, 2] - org[p, 2]) * nz_) / dn
        if not t < t_out[p]:  # the proxy lies beyond the volume on this ray
            t_box[p] = np.inf
        elif t > tb:
            t_box[p] = t


def _contiguous(a, dtype):
    """``np.ascontiguousarray(a, dtype)`` of a (P, 3) float64 array, copied (or rounded) in parallel."""
    if a.dtype == dtype and a.flags.c_contiguous:
        return a
    out = np.empty(a.shape, dtype)
    copy_rows(a, out)
    return out


def _proxy_t(org, dirs, b, proxy_geometry):
    """Start parameters of the texel rays with the proxy (inf: no photon)."""
    t_in = np.empty(len(org))
    if proxy_geometry is None:
        slab_entry(org, dirs, b, t_in)  # = box_entry's t_in, in parallel
        return t_in
    kind, data = proxy_geometry
    if kind == "box":
        slab_entry(org, dirs, np.asarray(data, dtype=np.float64), t_in)
        return t_in
    from ..embree import mesh_scene, nearest_hits, soup_scene

    t_out = np.empty(len(org))
    slab_both(org, dirs, b, t_in, t_out, True)  # = box_entry's (t_in, t_out), in parallel
    if isinstance(data, tuple):  # (tris, points, welded): the same triangles, indexed
        tris, pts, welded = data
    else:
        tris, pts, welded = data, None, None
    tris = np.ascontiguousarray(tris, dtype=np.float64)
    if len(tris) == 0:
        t_in[:] = np.inf
        return t_in
    # Embree's nearest face: the indexed mesh (primitive k = tris[k], the same float32 corners, so the same
    # BVH and hits as the soup) is copied into Embree in a third of the soup's time, and mesh_scene keeps it
    # while the proxy comes again (a light change re-runs this stage on the same geometry)
    scene = soup_scene(tris, cache=False) if pts is None else mesh_scene(pts, welded)
    # Embree's float32 rays, rounded in parallel (nearest_hits would round them in one thread)
    prim = nearest_hits(scene, _contiguous(org, np.float32), _contiguous(dirs, np.float32))[0]
    _proxy_entry(org, dirs, tris, prim, t_in, t_out)
    return t_in


def _basis(d):
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(d, e1)


def _inside(p, bounds):
    return bool(np.all(p > bounds[0]) and np.all(p < bounds[1]))


def generate_photons(lights, bounds, shape, photons, proxy_geometry=None):
    """One photon per covered texel of each light's view of the volume box, or of a proxy (§4.3).

    Parameters
    ----------
    lights : list of dict
        Scene lights: ``type`` 'directional' (``direction``) or 'point'
        (``position``), and ``radiance`` [r, g, b].
    bounds : (2, 3) float64
        Volume bounds.
    shape : (3,) int
        Volume grid shape (for the voxel cross-section).
    photons : int
        Texture side M per light.
    proxy_geometry : None or (kind, data), optional
        None: photons start on the volume's box. ``("mesh", tris)`` with
        ``tris`` (T, 3, 3) the proxy's triangles wound outwards
        (:func:`inflate_mesh`; or ``("mesh", (tris, points, welded))``, its
        ``indexed`` output, traced as the same triangles), or ``("box", bounds)`` a box inside the
        volume (:func:`occupied_box`): only texels whose ray meets the proxy
        make photons, starting where they meet it (module docstring).

    Returns
    -------
    pos, dirs : (P, 3) float64
        Entry points on the box and unit directions.
    rad : (P, 3) float64
        Photon weights (see the module docstring).
    light : (P,) int32
        Index of the emitting light.
    notes : list of str

    Raises
    ------
    SceneError
        A point light without a position or inside the volume, a zero
        direction, an unknown type, a negative radiance.

    References
    ----------
    Sun et al. (2008), §4.3.
    """
    b = np.asarray(bounds, dtype=np.float64)
    h = (b[1] - b[0]) / np.asarray(shape[:3], dtype=np.float64)
    h2 = float(np.prod(h)) ** (2.0 / 3.0)
    corners = np.array([[b[i][0], b[j][1], b[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    M = int(photons)
    out_p, out_d, out_r, out_l, notes = [], [], [], [], []
    for li, L in enumerate(lights):
        rad = np.asarray(L.get("radiance", [1, 1, 1]), dtype=np.float64)
        if rad.shape != (3,) or not np.all(np.isfinite(rad)) or np.any(rad < 0):
            raise SceneError(f"lights[{li}].radiance is {L.get('radiance')!r}; give three finite values >= 0")
        if L["type"] == "directional":
            d = np.asarray(L["direction"], dtype=np.float64)
            if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
                raise SceneError(f"lights[{li}].direction is {L['direction']!r}; give a non-zero [x, y, z]")
            d = d / np.linalg.norm(d)
            e1, e2 = _basis(d)
            a, c = corners @ e1, corners @ e2
            side = max(np.ptp(a), np.ptp(c)) * (1.0 + 1e-9)
            ca, cc = 0.5 * (a.min() + a.max()), 0.5 * (c.min() + c.max())
            s = (np.arange(M) + 0.5) / M - 0.5
            # texel (row r, column q): row 0 at the top (+e2), as the camera convention
            dmin = float(np.min(corners @ d)) - 1.0  # the texture plane, in front of the box
            org = np.empty((M * M, 3))
            _ortho_origins(float(ca), float(cc), s, float(side), e1, e2, dmin, d, org)
            dirs = np.broadcast_to(d, org.shape)
            w = rad * (side / M) ** 2 / h2
            weights = np.broadcast_to(w, org.shape)
            what = f"directional light {li}: {M}x{M} orthographic texture"
        elif L["type"] == "point":
            if L.get("position") is None:
                raise SceneError(f"lights[{li}] is a point light without 'position'; give [x, y, z]")
            p = np.asarray(L["position"], dtype=np.float64)
            if p.shape != (3,) or not np.all(np.isfinite(p)):
                raise SceneError(f"lights[{li}].position is {L['position']!r}; give finite [x, y, z]")
            if _inside(p, b):
                raise SceneError(f"lights[{li}].position {p.tolist()} is inside the volume bounds "
                                 f"{b.tolist()}; photons are generated from the light's view of the box, "
                                 "so move the light outside it (or enlarge volumetric.bounds)")
            centre = 0.5 * (b[0] + b[1])
            f = centre - p
            f /= np.linalg.norm(f)
            up = np.array([0.0, 1.0, 0.0]) if abs(f[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
            cam0 = Camera(tuple(p), tuple(centre), tuple(up), 60.0, M, M, 1e-6, 1e9)
            cv = cam0.world_to_view(corners)
            dz = -cv[:, 2]
            t = float(np.max(np.abs(cv[:, :2]) / dz[:, None])) * (1.0 + 1e-9)
            fov = float(np.degrees(2.0 * np.arctan(t)))
            if fov >= 179.0:
                raise SceneError(f"lights[{li}].position {p.tolist()} is too close to the volume to see all of it "
                                 "in one texture; move the light farther away")
            cam = Camera(tuple(p), tuple(centre), tuple(up), fov, M, M, 1e-6, 1e9)
            org, dirs = cam.primary_rays()
            org, dirs = org.reshape(-1, 3), dirs.reshape(-1, 3)
            cos = -(cam.dir_world_to_view(dirs)[:, 2])
            domega = (2.0 * cam.sx / M) * (2.0 * cam.sy / M) * cos ** 3
            weights = rad[None, :] * domega[:, None] / h2
            what = f"point light {li}: {M}x{M} perspective texture, fov {fov:.1f} deg"
        else:
            raise SceneError(f"lights[{li}].type is {L['type']!r}; the volumetric method knows 'directional' "
                             "and 'point'")
        org = _contiguous(org, np.float64)  # (the directional light's broadcast direction, copied in parallel)
        dirs = _contiguous(dirs, np.float64)
        t_in = _proxy_t(org, dirs, b, proxy_geometry)
        idx = np.flatnonzero(np.isfinite(t_in)) if np.any(rad > 0) else np.zeros(0, np.int64)
        pos = np.empty((len(idx), 3))
        dsel = np.empty((len(idx), 3))
        _gather_hits(org, dirs, t_in, idx, b, pos, dsel)
        out_p.append(pos)
        out_d.append(dsel)
        if weights.strides[0] == 0:  # one weight for every texel (directional)
            out_r.append(np.repeat(weights[:1], len(idx), axis=0))
        else:
            out_r.append(np.array(weights[idx]))
        out_l.append(np.full(len(idx), li, np.int32))
        hit_count = len(idx)
        on = ("box" if proxy_geometry is None
              else "inflated mesh proxy" if proxy_geometry[0] == "mesh" else "occupied-box proxy")
        notes.append(f"{what}, {hit_count} texels covered by the {on} -> photons")
    if not out_p:
        z = np.zeros((0, 3))
        return z, z.copy(), z.copy(), np.zeros(0, np.int32), notes
    if len(out_p) == 1:  # one light: its arrays as they are (contiguous, fresh), not a copy
        return out_p[0], out_d[0], np.ascontiguousarray(out_r[0]), out_l[0], notes
    return (np.ascontiguousarray(np.concatenate(out_p)), np.ascontiguousarray(np.concatenate(out_d)),
            np.ascontiguousarray(np.concatenate(out_r)), np.concatenate(out_l), notes)
