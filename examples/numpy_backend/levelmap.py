"""A clean-room NumPy backend of the level-map method (Tipprasert 2006, ch. 4).

Written from ``docs/oracle.md`` ("Porting rules: level map", "Level map",
"Stage buffers", "Conformance") and ``docs/backends.md`` alone, without reading
the package's source, the way an outside author ports the method to a GPU: one
function per pass (``water`` -> ``planes`` -> ``level_map`` -> ``caustics``
(-> ``plane_maps``) -> ``casting`` -> ``image``), each a handful of
whole-array NumPy operations (a vertex shader, a rasterizer, a blend, a ray
caster), no per-texel Python loop. The ``image`` pass (the camera's view
through the water, eq. 4-19) is in ``levelmap_image.py`` beside this file.

``run(golden_dir, out_dir)`` reads each level-map case's ``scene.json`` from a
golden suite, computes every pass and writes ``out_dir/<case>/result.npz`` with
the golden key names, shapes and dtypes, ready for ``refraction-ref check``.
``bugs=`` plants mistakes porters really make (see ``BUGS``), to show that
``check`` names the pass that holds them.

Only the default knobs of the contract (contract_version 6) and their
predecessors are ported (``variant = levelmap``, ``placement = component``
or ``thesis``, ``smart_slicing`` on or off, ``smart_spacing = respace`` or
``lattice``); any number of lights.

References
----------
N. Tipprasert, *An Interactive Rendering Method for Water-Side Scene with
Caustics Using Level Map Method*, M.Eng. thesis, Chulalongkorn University,
2006: §4.2.1 (eqs. 4-1 to 4-9, the reference box and planes), §4.2.2 (eqs.
4-10 to 4-13, the level map), §4.3 (eqs. 2-8, 4-14, the water and its
illumination volumes), §4.4-4.5 (eq. 4-15, intersection), eq. 4-18
(irradiance), §4.6 (eq. 4-19, the image), §4.7.1 (eq. 4-20, casting),
§4.7.2 (smart slicing).
"""

import json
import math
import os

import numpy as np

try:                                    # as a package module, or loaded by path (tests, the CLI)
    from .levelmap_image import BUGS as IMAGE_BUGS, image_pass
except ImportError:
    import importlib.util as _ilu
    _spec = _ilu.spec_from_file_location(
        "levelmap_image", os.path.join(os.path.dirname(os.path.abspath(__file__)), "levelmap_image.py"))
    _mod = _ilu.module_from_spec(_spec)
    _spec.loader.exec_module(_mod)
    IMAGE_BUGS, image_pass = _mod.BUGS, _mod.image_pass

#: Planted bugs, each a mistake a porter really makes (``run(..., bugs=...)``).
BUGS = {
    "half_slice": "plane offsets off by half a slice (tight placement's "
                  "slab centres with the thesis's spacing; in each sub-box when re-sliced)",
    "inverted_eta": "the relative index inverted at the water: water.ior / "
                    "outside_ior instead of outside_ior / water.ior",
    "other_diagonal": "the water quads split on the other diagonal",
    "no_snap": "the maps' rasterizer does not snap vertices to 1/256 texel (an analytic rasterizer: not "
               "a bug, check admits it by the depth keys' slope term)",
    "no_ad_floor": "A_d of eq. 4-18 not floored at one texel",
    "two_comparisons": "plane acceptance as two comparisons against "
                       "zeta_i -+ s/2 instead of one floor",
    "receiver_cos_axis": "the receiver's cosine of eq. 4-18 taken against the "
                         "box axis V instead of the receiver's normal",
    "radiance_twice": "casting: each light's map weighted by its radiance mean again (w^2 in all)",
    "casting_mean": "casting: the lights' maps averaged (divided by the light count) instead of summed",
    "cast_texelwise": "casting: the other lights' maps added texel by texel, not cast into light 0's frame",
    "cast_no_depth_test": "casting: light l's map cast without the depth test (its shadows lit)",
    **IMAGE_BUGS,
}

SNAP = 256          # sub-texel grid of the rasterizer (1/256 texel)
LIMIT = 2.0 ** 22   # vertices this far off the map drop their triangle

# ----------------------------------------------------------------------------
# scene: defaults of docs/oracle.md "Scene file", built-in meshes, placement
# ----------------------------------------------------------------------------


def _dot(p, a):
    """Dot products of 3-vectors ``p`` (..., 3) with the axis ``a``, summed
    ``x a0 + y a1 + z a2`` in that order (oracle, Porting rules: level map)."""
    return p[..., 0] * a[0] + p[..., 1] * a[1] + p[..., 2] * a[2]


def _normalize(v):
    n = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, v / np.where(n > 0, n, 1.0), 0.0)


def builtin_mesh(name, size=None):
    """Vertices and faces of a built-in receiver mesh before placement.

    ``plane``: the square ``[-sx/2, sx/2] x [-sz/2, sz/2]`` in the xz plane,
    two triangles, counter-clockwise seen from +y. ``sphere``: trimesh's
    icosphere, subdivision 5, unit diameter (oracle, "Built-in meshes").
    """
    if name == "plane":
        sx, sz = (size if size is not None else (4.0, 4.0))
        v = np.array([[-sx / 2, 0.0, -sz / 2], [sx / 2, 0.0, -sz / 2],
                      [sx / 2, 0.0, sz / 2], [-sx / 2, 0.0, sz / 2]])
        f = np.array([[0, 2, 1], [0, 3, 2]], dtype=np.int64)
        return v, f
    if name == "sphere":
        import trimesh
        m = trimesh.creation.icosphere(subdivisions=5, radius=0.5)
        return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)
    if os.path.exists(str(name)):
        import trimesh
        m = trimesh.load(name, force="mesh")
        return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)
    raise ValueError(f"numpy_backend.levelmap: receiver mesh {name!r} is not ported "
                     "(built-ins 'plane' and 'sphere', or a mesh file path)")


def _rotation(deg):
    """R = Rz Ry Rx of angles in degrees (oracle, Conventions: mesh placement)."""
    ax, ay, az = np.radians(np.asarray(deg, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def place_receiver(rec):
    """World vertices, faces, origin P0 and albedo of one receiver entry."""
    v, f = builtin_mesh(rec.get("mesh", "plane"), rec.get("size"))
    fit = rec.get("fit")
    if fit is not None:
        lo, hi = v.min(axis=0), v.max(axis=0)
        v = (v - (lo + hi) / 2) * (fit / np.max(hi - lo))
    t = rec.get("transform") or {}
    scale = float(t.get("scale", 1.0))
    R = _rotation(t.get("rotate", [0, 0, 0]))
    p0 = np.asarray(t.get("translate", [0, 0, 0]), dtype=np.float64)
    vs = v * scale
    w = np.stack([_dot(vs, R[0]), _dot(vs, R[1]), _dot(vs, R[2])], axis=-1) + p0
    albedo = np.asarray(rec.get("albedo", [0.8, 0.8, 0.8]), dtype=np.float64)
    return w, f, p0, albedo


def resolve(scene):
    """The parts of a scene the level map reads, every default filled in."""
    water = {"size": [4, 4], "height": 0.0, "resolution": 128, "ior": 1.33,
             "absorption": 0.0, "waves": []}
    water.update(scene.get("water") or {})
    water["waves"] = [dict({"amplitude": 0.02, "wavelength": 0.5, "direction": [1, 0],
                            "phase": 0.0}, **w) for w in water["waves"]]
    lm = {"planes": 50, "map_size": 512, "smart_slicing": True, "depth_levels": 32,
          "placement": "component", "smart_spacing": "respace", "variant": "levelmap",
          "shadows": True}
    lm.update(scene.get("levelmap") or {})
    # the caustic maps' knobs moved to the "caustics" block (levelmap.map_size etc. are its aliases)
    lm.update({k: v for k, v in (scene.get("caustics") or {}).items()
               if k in ("map_size", "placement", "shadows", "ambient")})
    lm.setdefault("ambient", 0.1)
    if (lm["placement"] not in ("component", "thesis") or lm["smart_spacing"] not in ("respace", "lattice")
            or lm["variant"] != "levelmap"):
        raise ValueError("numpy_backend.levelmap ports only caustics.placement='component' or 'thesis', "
                         "levelmap.smart_spacing='respace' or 'lattice', variant='levelmap'")
    lights = [dict({"type": "directional", "direction": [0, -1, 0], "position": None,
                    "radiance": [1, 1, 1]}, **l)
              for l in scene.get("lights", [{}])]
    receivers = scene.get("receivers") or []
    return water, lm, lights, receivers, float(scene.get("outside_ior", 1.0))


# ----------------------------------------------------------------------------
# the rasterizer (oracle, Porting rules: level map, level_map's "Rasterizer")
# ----------------------------------------------------------------------------


def snap(c, bugs=()):
    """Map coordinates to the rasterizer's fixed-point grid (1/256 texel)."""
    if "no_snap" in bugs:       # sample the unsnapped triangle (admitted: within 1/512 texel of the snap)
        return c * SNAP
    return np.rint(c * SNAP).astype(np.int64)


def rasterize(X, Y, H, W):
    """Fragments of triangles given in fixed-point map coordinates.

    Parameters
    ----------
    X, Y : (T, 3) int64 (float64 under the ``no_snap`` bug)
        Vertex columns and rows times 256.
    H, W : int
        Map size.

    Returns
    -------
    tri, i, j : (n,) int64
        Triangle and texel of each covered sample.
    w : (n, 3)
        Edge functions of the oriented triangle at the sample.
    A : (n,)
        Its (positive) doubled area.
    perm : (T, 3) int64
        Vertex order of each oriented triangle (``[0, 2, 1]`` where swapped).

    References
    ----------
    Top-left fill rule with exact integer edge functions, as fixed-point GPU
    rasterizers do (docs/oracle.md, Porting rules: level map).
    """
    A = (X[:, 1] - X[:, 0]) * (Y[:, 2] - Y[:, 0]) - (Y[:, 1] - Y[:, 0]) * (X[:, 2] - X[:, 0])
    perm = np.where((A < 0)[:, None], np.array([0, 2, 1]), np.array([0, 1, 2]))
    X = np.take_along_axis(X, perm, axis=1)
    Y = np.take_along_axis(Y, perm, axis=1)
    A = np.abs(A)
    half = SNAP // 2
    # texels whose sample (256 j + 128, 256 i + 128) lies in the triangle's box
    j0 = np.maximum(np.ceil((X.min(axis=1) - half) / SNAP), 0).astype(np.int64)
    j1 = np.minimum(np.floor((X.max(axis=1) - half) / SNAP), W - 1).astype(np.int64)
    i0 = np.maximum(np.ceil((Y.min(axis=1) - half) / SNAP), 0).astype(np.int64)
    i1 = np.minimum(np.floor((Y.max(axis=1) - half) / SNAP), H - 1).astype(np.int64)
    nj = np.maximum(j1 - j0 + 1, 0)
    ni = np.maximum(i1 - i0 + 1, 0)
    count = np.where(A > 0, nj * ni, 0)
    tri = np.repeat(np.arange(len(A)), count)
    local = np.arange(tri.size) - np.repeat(np.cumsum(count) - count, count)
    i = i0[tri] + local // nj[tri]
    j = j0[tri] + local % nj[tri]
    px = SNAP * j + half
    py = SNAP * i + half
    Xt, Yt = X[tri], Y[tri]
    w = np.empty((tri.size, 3), dtype=Xt.dtype)
    cover = np.ones(tri.size, dtype=bool)
    for k, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):   # w_k: the edge a -> b
        dx, dy = Xt[:, b] - Xt[:, a], Yt[:, b] - Yt[:, a]
        w[:, k] = dx * (py - Yt[:, a]) - dy * (px - Xt[:, a])
        top_left = (dy < 0) | ((dy == 0) & (dx > 0))
        cover &= w[:, k] + np.where(top_left, 0, -1) >= 0
    return tri[cover], i[cover], j[cover], w[cover], A[tri[cover]], perm


def nearest_fragment(tri, i, j, z, W):
    """Per texel, the fragment with the smallest z (ties: the lower triangle)."""
    texel = i * W + j
    order = np.lexsort((tri, z, texel))
    first = np.ones(order.size, dtype=bool)
    first[1:] = texel[order][1:] != texel[order][:-1]
    return order[first]


# ----------------------------------------------------------------------------
# pass `water` (§4.3, eqs. 2-8, 4-14)
# ----------------------------------------------------------------------------


def refract(I, N, eta):
    """Snell's law in vector form, the normal turned to face I (eq. 2-8).

    Returns the unit refracted direction (NaN under total reflection) and
    ``k = 1 - eta^2 (1 - c^2)``.
    """
    c = -(I[..., 0] * N[..., 0] + I[..., 1] * N[..., 1] + I[..., 2] * N[..., 2])
    flip = c < 0
    N = np.where(flip[..., None], -N, N)
    c = np.where(flip, -c, c)
    k = 1.0 - eta * eta * (1.0 - c * c)
    with np.errstate(invalid="ignore"):
        T = _normalize(eta * I + (eta * c - np.sqrt(k))[..., None] * N)
    return T, k


def water_mesh(water, bugs=()):
    """The water grid's vertices, analytic unit normals and faces.

    References
    ----------
    Tipprasert 2006 §4.3 (the height field of summed sines); the face split of
    docs/oracle.md, Porting rules: level map, `water`.
    """
    n = int(water["resolution"])
    sx, sz = water["size"]
    xs = np.linspace(-sx / 2, sx / 2, n + 1)
    zs = np.linspace(-sz / 2, sz / 2, n + 1)
    x, z = np.meshgrid(xs, zs)                     # [i, j] = (xs[j], zs[i])
    h = np.full_like(x, float(water["height"]))
    hx = np.zeros_like(x)
    hz = np.zeros_like(x)
    for wave in water["waves"]:
        d = np.asarray(wave["direction"], dtype=np.float64)
        d = d / np.linalg.norm(d)
        kk = 2 * np.pi / wave["wavelength"]
        arg = kk * (d[0] * x + d[1] * z) + wave["phase"]
        h += wave["amplitude"] * np.sin(arg)
        hx += wave["amplitude"] * kk * d[0] * np.cos(arg)
        hz += wave["amplitude"] * kk * d[1] * np.cos(arg)
    verts = np.stack([x, h, z], axis=-1).reshape(-1, 3)
    normals = _normalize(np.stack([-hx, np.ones_like(hx), -hz], axis=-1)).reshape(-1, 3)
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v00 = (ii * (n + 1) + jj).ravel()
    v01, v10 = v00 + 1, v00 + n + 1
    v11 = v10 + 1
    if "other_diagonal" in bugs:    # planted: the diagonal (x_j, z_i) - (x_j+1, z_i+1)
        faces = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
    else:
        faces = np.concatenate([np.stack([v00, v10, v01], 1), np.stack([v10, v11, v01], 1)])
    return verts, normals, faces


def incident(light, points):
    """Unit incident directions at ``points`` and the irradiance factor there."""
    w = float(np.mean(light["radiance"]))
    if light["type"] == "point":
        d = points - np.asarray(light["position"], dtype=np.float64)
        r2 = np.sum(d * d, axis=-1)
        return _normalize(d), w / r2
    L = np.asarray(light["direction"], dtype=np.float64)
    L = L / np.linalg.norm(L)
    return np.broadcast_to(L, points.shape), np.full(points.shape[:-1], w)


def water_pass(water, light, eta, bugs=()):
    """Pass `water`: refraction at every vertex and the illumination volumes.

    Returns a dict: ``vertices``, ``normals`` (the stage buffers), ``faces``,
    per vertex ``T`` (unit refracted direction), per face ``flux`` (A_w
    cos(theta_i) E, zero where a vertex lets no light in) and ``axis`` (T_f).

    References
    ----------
    Tipprasert 2006 eq. 2-8 (Snell at the vertices), eq. 4-14 (illumination
    volumes: edge rays from the vertices along T).
    """
    verts, normals, faces = water_mesh(water, bugs)
    I, _ = incident(light, verts)
    T, k = refract(I, normals, eta)
    ok = (np.sum(I * normals, axis=-1) < 0) & (k >= 0) & (T[:, 1] < 0)
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    m = np.cross(verts[b] - verts[a], verts[c] - verts[a])        # 2 A_w n_f
    centroid = (verts[a] + verts[b] + verts[c]) / 3
    Ic, E = incident(light, centroid)
    proj = -np.sum(m * Ic, axis=-1) * 0.5                          # A_w cos(theta_i)
    lit = ok[a] & ok[b] & ok[c] & (proj > 0)
    flux = np.where(lit, E * proj, 0.0)
    s = np.where(ok[:, None], T, 0.0)
    axis = s[a] + s[b] + s[c]
    zero = ~np.any(axis != 0, axis=1)
    axis = np.where(zero[:, None], np.array([0.0, -1.0, 0.0]), _normalize(axis))
    return {"vertices": verts, "normals": normals, "faces": faces, "T": T,
            "flux": flux, "axis": axis}


# ----------------------------------------------------------------------------
# pass `planes` (§4.2.1, eqs. 4-1 to 4-9)
# ----------------------------------------------------------------------------


def planes_pass(rverts, p0, light, eta, n_planes, bugs=(), placement="component"):
    """Pass `planes`: the reference box of one (receiver, light) and its planes.

    Returns ``box`` (5, 3) ``[centre, U, V, W, (w, h, d)]``, ``zeta``
    (n_planes,) the plane offsets along T0 from the centre, ``s`` the slice
    and ``zlo`` the acceptance origin.

    References
    ----------
    Tipprasert 2006 eq. 4-1 (axes from T0), eqs. 4-2/4-3 (box about P0:
    ``component`` twice the largest |coordinate| on each axis, ``thesis``
    twice the whole length of the vertex farthest along it), eqs. 4-6 to 4-9
    (n + 1 planes bounding n slices, ``D_i = h/2 - s (i-1)``).
    """
    if light["type"] == "point":
        L = _normalize(p0 - np.asarray(light["position"], dtype=np.float64))
    else:
        L = np.asarray(light["direction"], dtype=np.float64)
        L = L / np.linalg.norm(L)
    T0, _ = refract(L[None], np.array([[0.0, 1.0, 0.0]]), eta)
    V = -_normalize(T0[0])
    N = np.array([0.0, 0.0, 1.0]) if abs(V[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    U = _normalize(np.cross(V, N))
    W = _normalize(np.cross(U, V))
    q = rverts - p0
    loc = np.stack([_dot(q, U), _dot(q, V), _dot(q, W)], axis=-1)
    if placement == "component":
        ext = 2 * np.abs(loc).max(axis=0)
    else:
        far = np.argmax(np.abs(loc), axis=0)
        ext = 2 * np.linalg.norm(loc[far], axis=1)
    ext = np.maximum(ext, 1e-6 * ext.max())
    h = ext[1]
    if n_planes == 1:           # one plane at the centre accepts the whole box
        s, zeta = h, np.zeros(1)
        zlo = -h / 2.0
    else:
        s = h / (n_planes - 1)
        zeta = -h / 2 + s * np.arange(n_planes)
        zlo = -h / 2.0 - s / 2.0
    if "half_slice" in bugs:        # planted: slab centres of `tight` with the thesis's s
        zeta = zeta + s / 2
        zlo = zeta[0] - s / 2.0
    box = np.stack([p0, U, V, W, ext])
    return {"box": box, "zeta": zeta, "s": s, "zlo": zlo, "half": np.full(len(zeta), s / 2.0)}


# ----------------------------------------------------------------------------
# pass `level_map` (§4.2.2, eqs. 4-10 to 4-13)
# ----------------------------------------------------------------------------


def map_coords(p, box, Hc, Wc):
    """(col, row, zeta) of world points in a box's map (zeta from its centre, along T0)."""
    centre, U, V, W, (w, h, d) = box
    q = p - centre
    return ((_dot(q, U) / w + 0.5) * Wc, (_dot(q, W) / d + 0.5) * Hc, -_dot(q, V))


def level_map_pass(tris, owner, r, albedo, box, Hc, Wc, bugs=()):
    """Pass `level_map`: position, diffuse and normal maps of receiver r.

    ``tris`` (T, 3, 3) are the receivers' world triangles (with ``shadows``
    every receiver's: the first surface along the light wins; else receiver
    r's own), ``owner`` (T,) their receiver index.

    References
    ----------
    Tipprasert 2006 eqs. 4-10 to 4-13: an orthographic view along the box,
    depth test keeping the surface nearest the light.
    """
    col, row, zeta = map_coords(tris, box, Hc, Wc)
    far = np.any((np.abs(col) >= LIMIT) | (np.abs(row) >= LIMIT), axis=1)
    X, Y = snap(col, bugs), snap(row, bugs)
    X[far] = 0
    Y[far] = 0                                     # zero area: draws nothing
    tri, i, j, w, A, perm = rasterize(X, Y, Hc, Wc)
    z = np.take_along_axis(zeta, perm, axis=1)[tri]
    depth = (w[:, 0] * z[:, 0] + w[:, 1] * z[:, 1] + w[:, 2] * z[:, 2]) * (1.0 / A)
    win = nearest_fragment(tri, i, j, depth, Wc)
    position = np.full((Hc, Wc), np.inf)
    winner = np.full((Hc, Wc), -1, dtype=np.int64)
    position[i[win], j[win]] = depth[win]
    winner[i[win], j[win]] = tri[win]
    fn = _normalize(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]))
    has = winner >= 0
    normal = np.where(has[..., None], fn[np.maximum(winner, 0)], 0.0)
    own = has & (owner[np.maximum(winner, 0)] == r)
    diffuse = np.where(own[..., None], albedo.astype(np.float32), np.float32(0))
    return {"position": position, "diffuse": diffuse.astype(np.float32), "normal": normal,
            "own": own}


# ----------------------------------------------------------------------------
# pass `caustics` (§4.4-4.7, eqs. 4-15, 4-18, 4-21/4-22 smart slicing)
# ----------------------------------------------------------------------------


def acceptance(position, own, pl, n_planes):
    """Index of the plane accepting each texel (eq. 4-15), -1 where none.

    One floor, never two comparisons: a floor at zeta = 0 on a slab boundary
    lands in exactly one plane.
    """
    with np.errstate(invalid="ignore"):
        k = np.floor((position - pl["zlo"]) / pl["s"])
    ok = own & np.isfinite(k) & (k >= 0) & (k < n_planes)
    return np.where(ok, k, -1).astype(np.int64)


def sub_boxes(position, own, h, levels):
    """Depth profile's runs of non-empty levels ``[a, e)`` (§4.7.2, eq. 4-21), and each texel's level."""
    with np.errstate(invalid="ignore"):
        lev = np.floor((position + h / 2) / h * levels)
    ok = own & np.isfinite(lev) & (lev >= 0) & (lev < levels)
    lev = np.where(ok, lev, -1).astype(np.int64)
    busy = np.bincount(lev[ok], minlength=levels) > 0
    edges = np.diff(np.concatenate([[0], busy.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))), lev


def respace(position, own, pl, n_planes, levels, bugs=()):
    """Smart slicing's re-slicing (§4.7.2, ``smart_spacing = respace``): each sub-box's own planes.

    Returns ``pl`` with ``zeta`` (the planes of every sub-box, nearest the
    light first), ``half`` (each plane's half slice) and ``plane_index``
    (the nearest plane of the texel's own sub-box, -1 where none).

    References
    ----------
    Tipprasert 2006 eqs. 4-21, 4-22 (``n_i = hr_i / (2 eps)`` planes per
    sub-box), eqs. 4-6 to 4-9 on the sub-box.
    """
    h = pl["box"][4, 1]
    runs, lev = sub_boxes(position, own, h, levels)
    slices = max(n_planes - 1, 1)
    zeta, half = [], []
    index = np.full(position.shape, -1, dtype=np.int64)
    for a, e in runs:
        z0, z1 = -h / 2 + h * a / levels, -h / 2 + h * e / levels
        k = max(int(round((e - a) / levels * slices)), 1)
        sb = (z1 - z0) / (k - 1) if k > 1 else z1 - z0
        first = z0 + sb / 2 if "half_slice" in bugs else z0     # planted: off by half the sub-box's slice
        if k == 1 and "half_slice" not in bugs:
            first = (z0 + z1) / 2
        mine = (lev >= a) & (lev < e)
        with np.errstate(invalid="ignore"):
            q = np.floor((position - first) / sb + 0.5) if k > 1 else np.zeros(position.shape)
        q = np.clip(np.nan_to_num(q), 0, k - 1).astype(np.int64)
        index[mine] = len(zeta) + q[mine]
        zeta.extend(first + sb * np.arange(k))
        half.extend([sb / 2.0] * k)
    return dict(pl, zeta=np.asarray(zeta, dtype=np.float64), half=np.asarray(half), plane_index=index)


def smart_slicing(position, own, plane_index, pl, n_planes, levels):
    """Planes kept by smart slicing (§4.7.2, lattice spacing), increasing."""
    h = pl["box"][4, 1]
    zlo, s = pl["zlo"], pl["s"]
    runs, _ = sub_boxes(position, own, h, levels)
    keep = np.zeros(n_planes, dtype=bool)
    for a, e in runs:
        z0, z1 = -h / 2 + h * a / levels, -h / 2 + h * e / levels
        lo = max(int(math.floor((z0 - zlo) / s)), 0)
        hi = min(int(math.ceil((z1 - zlo) / s)), n_planes)
        keep[lo:hi] = True
    keep[plane_index[plane_index >= 0]] = True
    return np.flatnonzero(keep).astype(np.int64)


def caustics_pass(wat, pl, lm, used, absorption, Hc, Wc, bugs=()):
    """Pass `caustics`: every beam intersected with every used plane, eq. 4-18.

    Returns the pair's map (Hc, Wc) float64 and each used plane's own
    contribution (k, Hc, Wc) float64.

    References
    ----------
    Tipprasert 2006 eq. 4-15 (the intersection triangle of an illumination
    volume with a reference plane, drawn where the plane accepts the texel's
    depth), eq. 4-18 ``I_c = I_i A_w cos(theta_i) e^{-K d} / (A_d
    cos(theta_t))``; the A_d floor and the interpolated water distance are the
    oracle's (docs/oracle.md, Porting rules: level map, `caustics`).
    """
    box = pl["box"]
    _, U, V, W, (w, h, d) = box
    verts, T, faces = wat["vertices"], wat["T"], wat["faces"]
    oc, orow, oz = map_coords(verts, box, Hc, Wc)
    Dc, Dr, Dz = _dot(T, U) * Wc / w, _dot(T, W) * Hc / d, -_dot(T, V)
    live = wat["flux"] > 0
    fl, fa = faces[live], wat["axis"][live]
    flux = wat["flux"][live]
    tdz = -_dot(fa, V)
    inv_tv = np.where(tdz > 1e-12, 1.0 / np.where(tdz > 1e-12, tdz, 1.0), 0.0)
    texel_area = (w / Wc) * (d / Hc)
    position, normal = lm["position"], lm["normal"]
    plane_index = lm["plane_index"]
    zeta = pl["zeta"]
    F = len(fl)
    # every (used plane, beam) pair at once: one draw call per plane on a GPU
    P = np.repeat(used, F)
    f = np.tile(np.arange(F), len(used))
    zp = zeta[P]
    with np.errstate(invalid="ignore", divide="ignore"):
        lam = (zp[:, None] - oz[fl[f]]) / Dz[fl[f]]
        c = oc[fl[f]] + lam * Dc[fl[f]]
        rr = orow[fl[f]] + lam * Dr[fl[f]]
    good = (np.all(Dz[fl[f]] > 0, axis=1) & np.all(lam >= 0, axis=1)
            & np.all((np.abs(c) < LIMIT) & (np.abs(rr) < LIMIT), axis=1))
    P, f, lam, c, rr = P[good], f[good], lam[good], c[good], rr[good]
    af = (c[:, 1] - c[:, 0]) * (rr[:, 2] - rr[:, 0]) - (rr[:, 1] - rr[:, 0]) * (c[:, 2] - c[:, 0])
    floor = 0.0 if "no_ad_floor" in bugs else 1.0
    with np.errstate(divide="ignore"):
        B = flux[f] * inv_tv[f] / (np.maximum(0.5 * np.abs(af), floor) * texel_area)
    tri, i, j, wk, A, perm = rasterize(snap(c, bugs), snap(rr, bugs), Hc, Wc)
    pp = P[tri]
    if "two_comparisons" in bugs:   # planted: a texel on a slab boundary lands in two planes
        zt = position[i, j]
        hit = (lm["own"][i, j] & (zt >= zeta[pp] - pl["half"][pp]) & (zt < zeta[pp] + pl["half"][pp]))
    else:
        hit = plane_index[i, j] == pp              # the depth test: this plane owns the texel
    tri, i, j, wk, A, pp = tri[hit], i[hit], j[hit], wk[hit], A[hit], pp[hit]
    lk = np.take_along_axis(lam, perm, axis=1)[tri]
    lt = (wk[:, 0] * lk[:, 0] + wk[:, 1] * lk[:, 1] + wk[:, 2] * lk[:, 2]) * (1.0 / A)
    fb = f[tri]
    if "receiver_cos_axis" in bugs:     # planted: cos against the box axis, not the receiver
        g = np.abs(_dot(fa[fb], V))
    else:
        g = np.abs(np.sum(fa[fb] * normal[i, j], axis=-1))
    if absorption > 0:
        g = g * np.exp(-absorption * lt - (absorption / tdz[fb]) * (position[i, j] - zeta[pp]))
    val = B[tri] * g
    slot = np.searchsorted(used, pp)
    per_plane = np.bincount(slot * (Hc * Wc) + i * Wc + j, weights=val,
                            minlength=len(used) * Hc * Wc).reshape(len(used), Hc, Wc)
    return per_plane.sum(axis=0), per_plane


# ----------------------------------------------------------------------------
# pass `casting` (§4.7.1, eq. 4-20)
# ----------------------------------------------------------------------------


def frame(box):
    """caustic_frame: (origin, u, v, normal) of a box (oracle, "Map frame")."""
    centre, U, V, W, (w, h, d) = box
    u, v = w * U, d * W
    return np.stack([centre - u / 2 - v / 2 + (h / 2) * V, u, v, V])


def casting_pass(maps, boxes, lms, Hc, Wc, weights=None, bugs=()):
    """Pass `casting`: every light's map cast into light 0's (eq. 4-20).

    Light 0's map is taken whole; each further light's map is read at the
    texel (floor) of light 0's own surface points in its frame, where light
    l's level map sees the same surface (its depth within a slope-scaled
    tolerance). The maps are added as they are: each light's radiance
    entered once, in `water`'s flux. ``weights`` (the planted
    ``radiance_twice``) multiplies each light's map by its radiance mean
    again.

    References
    ----------
    Tipprasert 2006 §4.7.1, eq. 4-20 (projective texturing of the other
    lights' maps, summed); docs/oracle.md, Porting rules: level map, `casting`.
    """
    if weights is not None:
        maps = [m * w for m, w in zip(maps, weights)]
    out = maps[0].copy()
    if len(maps) > 1 and "cast_texelwise" in bugs:     # planted: texel (i, j) of every map added as is
        for m in maps[1:]:
            out += m
    elif len(maps) > 1:
        c0, U0, V0, W0, (w0, h0, d0) = boxes[0]
        ii, jj = np.nonzero(lms[0]["own"] & np.isfinite(lms[0]["position"]))
        zeta = lms[0]["position"][ii, jj]
        p = (c0 + (((jj + 0.5) / Wc - 0.5) * w0)[:, None] * U0
             + (((ii + 0.5) / Hc - 0.5) * d0)[:, None] * W0 - zeta[:, None] * V0)
        n = lms[0]["normal"][ii, jj]
        ts0 = max(w0 / Wc, d0 / Hc)
        for l in range(1, len(maps)):
            box = boxes[l]
            col, row, z = map_coords(p, box, Hc, Wc)
            a, b = np.floor(row).astype(np.int64), np.floor(col).astype(np.int64)
            inside = (a >= 0) & (a < Hc) & (b >= 0) & (b < Wc)
            a, b = np.where(inside, a, 0), np.where(inside, b, 0)
            tsl = max(box[4, 0] / Wc, box[4, 2] / Hc)
            tol = 2 * max(tsl, ts0) / np.maximum(np.abs(np.sum(n * box[2], axis=-1)), 0.05)
            agree = inside & lms[l]["own"][a, b]
            if "cast_no_depth_test" not in bugs:       # planted: light l's shadows not tested
                agree &= np.abs(lms[l]["position"][a, b] - z) <= tol
            np.add.at(out, (ii[agree], jj[agree]), maps[l][a[agree], b[agree]])
    if "casting_mean" in bugs:                         # planted: the lights averaged, not summed
        out = out / len(maps)
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)


# ----------------------------------------------------------------------------
# the whole method, and the golden-suite driver
# ----------------------------------------------------------------------------


def render(scene, bugs=(), passes=("image",)):
    """Every pass of the level map for one scene; returns the candidate's arrays.

    ``passes=()`` stops after `casting` (no `image`: the view is the costly pass).
    """
    unknown = set(bugs) - set(BUGS)
    if unknown:
        raise ValueError(f"unknown bugs {sorted(unknown)}; known: {sorted(BUGS)}")
    water, lmk, lights, receivers, outside_ior = resolve(scene)
    eta = outside_ior / float(water["ior"])
    if "inverted_eta" in bugs:       # planted: the index ratio the wrong way round
        eta = 1.0 / eta
    n_planes, Hc = int(lmk["planes"]), int(lmk["map_size"])
    Wc = Hc
    recs = [place_receiver(r) for r in receivers]
    tris = np.concatenate([v[f] for v, f, _, _ in recs])
    owner = np.concatenate([np.full(len(f), k) for k, (_, f, _, _) in enumerate(recs)])
    out = {}
    waters = [water_pass(water, light, eta, bugs) for light in lights]
    out["stage.water.water_vertices"] = waters[0]["vertices"]
    out["stage.water.water_normals"] = waters[0]["normals"]
    K = float(water["absorption"])
    casts, boxes0 = [], []
    for r, (rv, _, p0, albedo) in enumerate(recs):
        maps, boxes, lms = [], [], []
        for l, light in enumerate(lights):
            tag = f"{r}_{l}"
            pl = planes_pass(rv, p0, light, eta, n_planes, bugs, lmk["placement"])
            # shadows: every receiver occludes; otherwise receiver r's own triangles only
            mine = slice(None) if lmk["shadows"] else owner == r
            lm = level_map_pass(tris[mine], owner[mine], r, albedo, pl["box"], Hc, Wc, bugs)
            lm["plane_index"] = acceptance(lm["position"], lm["own"], pl, n_planes)
            if lmk["smart_slicing"] and lmk["smart_spacing"] == "respace":
                pl = respace(lm["position"], lm["own"], pl, n_planes, int(lmk["depth_levels"]), bugs)
                lm["plane_index"] = pl["plane_index"]
                used = np.arange(len(pl["zeta"]), dtype=np.int64)
            elif lmk["smart_slicing"]:
                used = smart_slicing(lm["position"], lm["own"], lm["plane_index"], pl,
                                     n_planes, int(lmk["depth_levels"]))
            else:
                used = np.arange(n_planes, dtype=np.int64)
            cmap, per_plane = caustics_pass(waters[l], pl, lm, used, K, Hc, Wc, bugs)
            out[f"stage.planes.box_{tag}"] = pl["box"]
            out[f"stage.caustics.planes_{tag}"] = pl["zeta"]
            out[f"stage.level_map.position_{tag}"] = lm["position"]
            out[f"stage.level_map.diffuse_{tag}"] = lm["diffuse"]
            out[f"stage.level_map.normal_{tag}"] = lm["normal"]
            out[f"stage.caustics.caustic_map_{tag}"] = cmap
            out[f"stage.caustics.planes_used_{tag}"] = used
            out[f"stage.plane_maps.plane_maps_{tag}"] = per_plane.astype(np.float32)
            out[f"stage.plane_maps.plane_index_{tag}"] = used.copy()
            maps.append(cmap)
            boxes.append(pl["box"])
            lms.append(lm)
        weights = ([float(np.mean(li["radiance"])) for li in lights]
                   if "radiance_twice" in bugs else None)   # planted: w^2 instead of w
        cast = casting_pass(maps, boxes, lms, Hc, Wc, weights, bugs)
        casts.append(cast)
        boxes0.append(boxes[0])
        fr = frame(boxes[0])
        for key in (f"stage.casting.caustic_map_{r}", f"caustic_map_{r}"):
            out[key] = cast
        for key in (f"stage.casting.caustic_frame_{r}", f"caustic_frame_{r}"):
            out[key] = fr
    if "image" in passes:
        view = image_pass(dict(scene, water=water), waters[0], recs, boxes0, casts, eta, K,
                          float(lmk["ambient"]), bugs)
        for key, a in view.items():
            out[f"stage.image.{key}"] = a
            if key in ("image", "object_mask", "image_direct", "object_mask_direct"):
                out[key] = a
    return out


def run(golden_dir, out_dir, cases=None, bugs=(), passes=("image",)):
    """Write ``out_dir/<case>/result.npz`` for the level-map cases of a golden suite.

    Parameters
    ----------
    golden_dir : str
        A suite built by ``refraction-ref golden build``.
    out_dir : str
        The candidate folder (created).
    cases : sequence of str, optional
        Cases to run (default: every case whose method is ``levelmap``).
    bugs : sequence of str
        Planted bugs (keys of ``BUGS``).
    passes : sequence of str
        ``("image",)`` (the default) also runs the view; ``()`` stops after `casting`.

    Returns
    -------
    list of str
        The cases written.
    """
    with open(os.path.join(golden_dir, "manifest.json")) as fh:
        manifest = json.load(fh)
    if cases is None:
        cases = sorted(c for c, m in manifest["cases"].items() if m.get("method") == "levelmap")
    for case in cases:
        with open(os.path.join(golden_dir, case, "scene.json")) as fh:
            scene = json.load(fh)
        arrays = render(scene, bugs, passes)
        os.makedirs(os.path.join(out_dir, case), exist_ok=True)
        np.savez(os.path.join(out_dir, case, "result.npz"), **arrays)
    return list(cases)


if __name__ == "__main__":
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("golden")
    ap.add_argument("out")
    ap.add_argument("--cases", default=None, help="NAME,... (default: every levelmap case)")
    ap.add_argument("--bug", action="append", default=[], choices=sorted(BUGS))
    a = ap.parse_args()
    done = run(a.golden, a.out, a.cases.split(",") if a.cases else None, a.bug)
    print(f"wrote {len(done)} cases to {a.out}; now: refraction-ref check {a.out} --golden {a.golden}")
