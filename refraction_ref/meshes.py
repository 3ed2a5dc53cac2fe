"""Meshes: the built-in ones, file loading, fitting, transforms, deformation.

Built-in meshes:

``bunny``
    The Stanford bunny, 69,451 triangles (open: holes in its base), shipped
    in ``refraction_ref/data``.
``teapot``
    Newell's teapot, 6,320 triangles (open seams), shipped likewise.
``sphere``
    An icosphere of unit diameter, subdivision 5 (20,480 triangles), fine
    enough to stand in for an analytic sphere.
``plane``
    A square in the xz plane with normal +y, sized by the object's
    ``size: [sx, sz]``.

A mesh with ``fit: s`` is centred on its bounding-box centre and scaled so
that its largest extent is ``s``; then its ``transform`` is applied (scale,
rotate in degrees about x, y, z in that order, translate), as docs/oracle.md says.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numba as nb
import numpy as np

from .validation import SceneError
from .vec3 import affine, dot, readonly

__all__ = ["BUILTIN_MESHES", "Geometry", "corner_normals", "crease_edge_angles", "eye_inside", "file_vertex_normals",
           "load_mesh", "object_mesh", "scene_geometry", "rotation_matrix", "sine_displacement"]

_DATA = os.path.join(os.path.dirname(__file__), "data")
#: Built-in names. ``bunny``, ``teapot``, ``igea`` and ``fandisk`` are PLY files shipped in
#: ``refraction_ref/data`` (the meshes of the papers' tables, and a CAD mesh with sharp edges);
#: ``sphere`` and ``plane`` are generated.
BUILTIN_MESHES = ("bunny", "teapot", "sphere", "plane", "igea", "fandisk")


@functools.lru_cache(maxsize=16)
def _read_mesh_file(path, mtime):
    import trimesh

    try:
        # the file's own data first: processing drops NaN vertices and their faces in silence
        m = trimesh.load(path, force="mesh", process=False)
        _check_raw_mesh(path, np.asarray(m.vertices), np.asarray(m.faces))
        m.process()  # what load(process=True) runs, on the arrays already read
    except SceneError:
        raise
    except IndexError as e:  # trimesh's OBJ reader indexes its vertices with the faces while parsing
        raise SceneError(f"mesh file '{path}' has a face that names a vertex the file does not have ({e}); "
                         "fix the face indices or add the missing vertices") from None
    except Exception as e:  # trimesh raises many types
        raise SceneError(f"mesh file '{path}' could not be read ({type(e).__name__}: {e}); "
                         "give a mesh format trimesh reads (PLY, OBJ, STL, OFF, GLB)") from None
    v = np.asarray(m.vertices, dtype=np.float64)
    f = np.asarray(m.faces, dtype=np.int64)
    v.setflags(write=False)
    f.setflags(write=False)
    return v, f


def _count(n, one, many):
    return f"{n} {one if n == 1 else many}"


def _check_raw_mesh(path, v, f):
    """Refuse non-finite vertices and out-of-range face indices as the file holds them (before trimesh's
    processing, which drops the first without a word and indexes with the second)."""
    if v.size:
        bad = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
        if len(bad):
            raise SceneError(f"mesh file '{path}' has {_count(len(bad), 'vertex', 'vertices')} with NaN or "
                             f"infinite coordinates (the first: vertex {bad[0]} counting from 0, "
                             f"{v[bad[0]].tolist()}); repair the mesh: give every vertex finite coordinates or "
                             "remove it and its faces")
    if f.size:
        out = np.flatnonzero(np.any((f < 0) | (f >= len(v)), axis=1))
        if len(out):
            raise SceneError(f"mesh file '{path}' has {_count(len(out), 'face', 'faces')} with vertex indices "
                             f"outside 0..{len(v) - 1} (the first: face {out[0]} counting from 0, indices "
                             f"{f[out[0]].tolist()}); fix the face indices or add the missing vertices")


@functools.lru_cache(maxsize=32)
def _topology_of_file(path, mtime):
    v, f = _read_mesh_file(path, mtime)
    return _boundary_edge_count(f), _degenerate_count(v, f)


@functools.lru_cache(maxsize=8)
def _icosphere(subdivisions):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.5)
    v = np.asarray(m.vertices, dtype=np.float64)
    f = np.asarray(m.faces, dtype=np.int64)
    v.setflags(write=False)
    f.setflags(write=False)
    return v, f


def load_mesh(name, size=None, base_dir="."):
    """Vertices (V, 3) and faces (F, 3) of a built-in mesh or a mesh file.

    Parameters
    ----------
    name : str or (vertices, faces) pair
        A built-in name (:data:`BUILTIN_MESHES`), a mesh file path any format
        trimesh reads (PLY, OBJ, STL, OFF, GLB), or the two arrays themselves.
    size : (2,) sequence of float, optional
        ``[sx, sz]`` extent of the ``plane`` mesh (default 4 x 4); ignored otherwise.
    base_dir : str
        Folder for a relative file path.

    Returns
    -------
    v : (V, 3) float64 ndarray
        Vertex positions in the mesh's own frame (read-only for cached meshes).
    f : (F, 3) int64 ndarray
        Vertex indices of each triangle.

    Raises
    ------
    SceneError
        For a missing, unreadable or empty mesh, or non-finite vertices.
    """
    if isinstance(name, (tuple, list)) and len(name) == 2:
        v, f = (np.asarray(name[0], dtype=np.float64), np.asarray(name[1], dtype=np.int64))
        where = "<arrays>"
    elif name == "sphere":
        v, f = _icosphere(5)
        where = name
    elif name == "plane":
        sx, sz = (4.0, 4.0) if size is None else (float(size[0]), float(size[1]))
        v = np.array([[-sx / 2, 0, -sz / 2], [sx / 2, 0, -sz / 2], [sx / 2, 0, sz / 2], [-sx / 2, 0, sz / 2]])
        f = np.array([[0, 2, 1], [0, 3, 2]])  # counter-clockwise seen from +y
        where = name
    else:
        path = os.path.join(_DATA, f"{name}.ply") if name in BUILTIN_MESHES else (
            name if os.path.isabs(name) else os.path.join(base_dir, name))
        if not os.path.isfile(path):
            raise SceneError(f"mesh '{name}' not found (looked for {path}); "
                             f"use a built-in mesh ({', '.join(BUILTIN_MESHES)}) or an existing file")
        v, f = _read_mesh_file(os.path.abspath(path), os.path.getmtime(path))
        where = path
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise SceneError(f"mesh '{where}' is empty or not a triangle mesh (vertices {v.shape}, "
                         f"faces {f.shape}); give a mesh with at least one triangle")
    if not np.all(np.isfinite(v)):
        bad = int(np.count_nonzero(~np.all(np.isfinite(v), axis=1)))
        raise SceneError(f"mesh '{where}' has {bad} vertices with NaN or infinite coordinates; "
                         "repair the mesh (e.g. trimesh: mesh.update_faces / remove the vertices)")
    if f.min() < 0 or f.max() >= len(v):
        raise SceneError(f"mesh '{where}' has face indices outside 0..{len(v) - 1}")
    return v, f


def rotation_matrix(degrees):
    """Rotation about x, then y, then z (degrees), as a (3, 3) matrix acting on column vectors.

    Parameters
    ----------
    degrees : (3,) array_like
        Angles about x, y and z in degrees.

    Returns
    -------
    (3, 3) float64 ndarray
        ``Rz @ Ry @ Rx``.
    """
    ax, ay, az = np.radians(np.asarray(degrees, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def vertex_normals(v, f):
    """Area-weighted unit vertex normals (zero-area faces contribute nothing).

    Parameters
    ----------
    v : (V, 3) float64 ndarray
        Vertex positions.
    f : (F, 3) int ndarray
        Counter-clockwise (outward) triangles.

    Returns
    -------
    (V, 3) float64 ndarray
        Unit normals; zero rows for vertices without an area-carrying face.

    References
    ----------
    .. [1] N. Max, "Weights for Computing Vertex Normals from Facet Normals",
       *Journal of Graphics Tools* 4(2), 1-6, 1999 (area weighting of face
       normals).
    """
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


CREASE_MARGIN = 1e-12  # in cosine: an edge at the crease angle is sharp, whatever the rounding


@nb.njit(cache=True, inline="always")
def face_corner_normals(fi, f, fn, un, start, incident, cos_t, out):
    """The three corner normals of face ``fi`` (:func:`corner_normals`' rule) into ``out[fi]``.

    ``start``/``incident``: the faces around each vertex in face order (a
    face that uses a vertex twice listed twice, counted once). Shared by the
    serial kernel here and the exact reference's parallel one.

    Parameters
    ----------
    fi : int
        Face index.
    f : (F, 3) int64 ndarray
        Triangles (vertex indices).
    fn : (F, 3) float64 ndarray
        Unnormalised face normals ``(v1 - v0) x (v2 - v0)``.
    un : (F, 3) float64 ndarray
        Unit face normals (zero rows for zero-area faces).
    start : (V + 1,) int64 ndarray
        ``incident[start[v]:start[v + 1]]`` are the faces around vertex ``v``.
    incident : (3 F,) int64 ndarray
        Face indices grouped by vertex, in increasing face order.
    cos_t : float
        Cosine of the crease angle plus the margin (``-inf`` for 180 degrees):
        faces with ``un[fi] . un[g] > cos_t`` join the corner's group.
    out : (F, 3, 3) float64 ndarray
        Output corner normals; row ``fi`` is written (left as is for a
        zero-area face).

    Returns
    -------
    None
    """
    if un[fi, 0] == 0.0 and un[fi, 1] == 0.0 and un[fi, 2] == 0.0:
        return  # a zero-area face has no normal: zero corners (the tracer uses the face normal)
    for k in range(3):
        vtx = f[fi, k]
        sx = 0.0
        sy = 0.0
        sz = 0.0
        last = -1
        for p in range(start[vtx], start[vtx + 1]):
            g = incident[p]
            if g == last:  # a face that uses this vertex twice counts once
                continue
            last = g
            if g == fi or un[fi, 0] * un[g, 0] + un[fi, 1] * un[g, 1] + un[fi, 2] * un[g, 2] > cos_t:
                sx += fn[g, 0]
                sy += fn[g, 1]
                sz += fn[g, 2]
        ln = np.sqrt(sx * sx + sy * sy + sz * sz)
        if ln > 0.0:
            out[fi, k, 0] = sx / ln
            out[fi, k, 1] = sy / ln
            out[fi, k, 2] = sz / ln


@nb.njit(cache=True)
def _corner_normals_kernel(f, fn, un, start, incident, cos_t, out):
    for fi in range(f.shape[0]):
        face_corner_normals(fi, f, fn, un, start, incident, cos_t, out)


def corner_normals(vertices, faces, crease_deg):
    """Per-corner shading normals that stay smooth below a crease angle and keep sharper edges sharp.

    The "auto-smooth" rule: the normal at corner ``k`` of face ``f`` (its
    vertex ``v = faces[f, k]``) is the normalised sum of the **unnormalised**
    face normals ``(v1 - v0) x (v2 - v0)`` (unit normals weighted by twice
    the area, as in :func:`vertex_normals`) of those faces around ``v`` whose
    unit normal makes an angle **below** ``crease_deg`` with face ``f``'s
    own: ``n_f . n_g > cos(crease_deg) + 1e-12``. The margin makes an edge
    at exactly the crease angle sharp whatever the rounding (a cube's 90
    degree edges stay sharp at ``crease_deg = 90``, also when the cube is
    turned). Face ``f`` always belongs to its own group, so a corner on an
    edge at or above ``crease_deg`` (the angle between the two faces'
    normals: 0 for coplanar faces, 90 degrees on a cube's edge) gets only
    its own smooth group, and a corner inside a flat facet gets that
    facet's normal. ``crease_deg = 180`` includes every face around the
    vertex, i.e. the area-weighted vertex normal of :func:`vertex_normals`
    (up to rounding: the sums run in another order).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions (world space for the exact tracer).
    faces : (F, 3) array_like of int
        Counter-clockwise (outward) triangles.
    crease_deg : float
        Crease angle in degrees, in ``(0, 180]``.

    Returns
    -------
    (F, 3, 3) ndarray of float64
        Unit normal of every corner (``[f, k]`` belongs to vertex
        ``faces[f, k]``), for barycentric interpolation over the face. All
        corners of a zero-area face are zero (the exact tracer then uses the
        face normal, as for a zero vertex normal).

    Notes
    -----
    The groups are decided per vertex against the corner's own face, not by
    walking edges: two faces around a vertex that do not share an edge are
    compared directly, so a smooth group never creeps around a vertex
    through a chain of small angles. Work is the sum over vertices of the
    squared number of faces around each (about 36 V for a typical mesh);
    the result is deterministic (faces are summed in index order).

    References
    ----------
    .. [1] H. Hoppe, T. DeRose, T. Duchamp, M. Halstead, H. Jin, J. McDonald,
       J. Schweitzer, W. Stuetzle, "Piecewise Smooth Surface Reconstruction",
       *Proc. SIGGRAPH 94*, 295-302, 1994 (sharp edges of scanned and CAD
       surfaces; the fandisk mesh).
    .. [2] N. Max, "Weights for Computing Vertex Normals from Facet Normals",
       *Journal of Graphics Tools* 4(2), 1-6, 1999 (area weighting of face
       normals).
    .. [3] three.js, ``BufferGeometryUtils.toCreasedNormals(geometry,
       creaseAngle)``: the same per-vertex angle test against each face's
       normal; Blender's "Auto Smooth" angle splits smooth groups at sharper
       edges likewise.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    crease_deg = float(crease_deg)
    if not (0.0 < crease_deg <= 180.0):
        raise ValueError(f"crease_deg must lie in (0, 180], got {crease_deg}")
    out = np.zeros((len(f), 3, 3))
    if len(f) == 0:
        return out
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    ln = np.linalg.norm(fn, axis=1, keepdims=True)
    un = np.divide(fn, ln, out=np.zeros_like(fn), where=ln > 0)
    corner_v = f.ravel()
    order = np.argsort(corner_v, kind="stable")  # corners by vertex, faces in index order
    incident = np.ascontiguousarray(order // 3)
    start = np.zeros(len(v) + 1, dtype=np.int64)
    np.cumsum(np.bincount(corner_v, minlength=len(v)), out=start[1:])
    cos_t = -np.inf if crease_deg >= 180.0 else float(np.cos(np.radians(crease_deg))) + CREASE_MARGIN
    _corner_normals_kernel(np.ascontiguousarray(f), fn, un, start, incident, cos_t, out)
    return out


def crease_edge_angles(vertices, faces):
    """Angle in degrees between the normals of the two faces of every interior edge.

    0 for coplanar faces, 90 on a cube's edge; an edge used by one face
    (boundary) or by more than two (non-manifold) is left out, as are pairs
    with a zero-area face. This is the angle :func:`corner_normals` compares
    with its crease angle.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles (vertex indices).

    Returns
    -------
    (E,) ndarray of float64
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return np.zeros(0)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    ln = np.linalg.norm(fn, axis=1, keepdims=True)
    un = np.divide(fn, ln, out=np.zeros_like(fn), where=ln > 0)
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(f)), 3)
    key = e[:, 0] * (int(f.max()) + 1) + e[:, 1]
    o = np.argsort(key, kind="stable")
    key, owner = key[o], owner[o]
    change = np.flatnonzero(np.diff(key)) + 1
    starts = np.concatenate([[0], change])
    runs = np.diff(np.concatenate([starts, [len(key)]]))
    s2 = starts[runs == 2]
    a, b = owner[s2], owner[s2 + 1]
    ok = (ln[a, 0] > 0) & (ln[b, 0] > 0)
    c = np.clip(np.einsum("ij,ij->i", un[a[ok]], un[b[ok]]), -1.0, 1.0)
    return np.degrees(np.arccos(c))


@functools.lru_cache(maxsize=16)
def _file_normals(path, mtime):
    import trimesh

    v, _ = _read_mesh_file(path, mtime)
    try:
        sc = trimesh.load_scene(path, process=True)
    except Exception:  # the mesh itself loaded (or failed) in _read_mesh_file
        return None
    parts, pos = [], []
    for node in sc.graph.nodes_geometry:
        T, name = sc.graph[node]
        g = sc.geometry[name]
        if not isinstance(g, trimesh.Trimesh):
            continue
        # trimesh keeps normals read from the file in its cache and computes them only on
        # request: membership of the cache is how trimesh's own PLY export tells them apart
        if "vertex_normals" not in g._cache:
            return None
        T = np.asarray(T, dtype=np.float64)
        M = T[:3, :3]
        n = affine(g._cache["vertex_normals"], np.linalg.inv(M))  # inverse transpose
        parts.append(n)
        pos.append(affine(g.vertices, M.T, T[:3, 3]))
    if not parts:
        return None
    n = np.concatenate(parts)
    p = np.concatenate(pos)
    # Scene.to_mesh (what _read_mesh_file loads) concatenates the same nodes in the same
    # order; anything else (a trimesh that orders them otherwise) is refused, not guessed
    if n.shape != v.shape or not np.allclose(p, v, rtol=1e-6, atol=1e-9 * max(1.0, float(np.abs(v).max()))):
        return None
    n[~np.all(np.isfinite(n), axis=1)] = 0.0
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)
    n.setflags(write=False)
    return n


def file_vertex_normals(name, base_dir="."):
    """The vertex normals a mesh file stores, in the order of :func:`load_mesh`'s vertices, or None.

    PLY ``nx ny nz`` vertex properties and OBJ ``vn`` records, as trimesh
    reads them (``trimesh.load_scene``; trimesh keeps normals it read from
    a file in the mesh's cache and only computes them on request). Returns
    None for a file without vertex normals (every built-in PLY), a
    generated mesh (``sphere``, ``plane``), a mesh given as arrays, or a
    multi-part file whose parts cannot be matched to the merged vertices.
    Normals are unit length (zero rows where the file's were zero or not
    finite) and in the mesh file's frame: apply the object's rotation for
    world space (``fit`` and the uniform ``scale`` do not turn them).

    Parameters
    ----------
    name : str or (vertices, faces) pair
        The object's ``mesh`` entry, as for :func:`load_mesh`.
    base_dir : str
        Folder for a relative file path.

    Returns
    -------
    (V, 3) float64 ndarray or None
        Read-only unit normals.
    """
    if not isinstance(name, str) or name in ("sphere", "plane"):
        return None
    path = os.path.join(_DATA, f"{name}.ply") if name in BUILTIN_MESHES else (
        name if os.path.isabs(name) else os.path.join(base_dir, name))
    if not os.path.isfile(path):
        return None
    return _file_normals(os.path.abspath(path), os.path.getmtime(path))


def sine_displacement(v, normals, amplitude, wavelength, direction, phase):
    """Vertex displacement along the normal, ``a sin(2 pi / lambda (p . u) + phase)``.

    The deforming-mesh demonstration of Chaudhari (2008), Fig. 4.2, where a
    vertex shader displaces the vertices before every pass that rasterizes
    the model.

    Parameters
    ----------
    v : (V, 3) float64 ndarray
        World-space vertices.
    normals : (V, 3) float64 ndarray
        Unit vertex normals (:func:`vertex_normals`).
    amplitude : float
        ``a``, in world units.
    wavelength : float
        ``lambda``, in world units.
    direction : (3,) array_like
        Wave direction ``u`` (normalised here).
    phase : float
        Phase in radians.

    Returns
    -------
    (V, 3) float64 ndarray
        Displaced vertices.

    References
    ----------
    .. [1] P. Chaudhari, "Real-Time Multiple Refractions Through Deformable
       Objects", M.S. thesis, UMBC, 2008, Fig. 4.2 (deforming models).
    """
    u = np.asarray(direction, dtype=np.float64)
    u = u / np.linalg.norm(u)
    s = amplitude * np.sin(2.0 * np.pi / wavelength * dot(v, u) + phase)
    return v + s[:, None] * normals


@nb.njit(cache=True)
def _bounds_kernel(v, lo, hi):
    for k in range(v.shape[0]):
        for c in range(3):
            x = v[k, c]
            if x < lo[c]:
                lo[c] = x
            if x > hi[c]:
                hi[c] = x


def bounds(v):
    """Axis-aligned bounds (lo, hi) of points (N, 3), N >= 1 (NaN coordinates are skipped).

    Parameters
    ----------
    v : (..., 3) array_like
        Points (reshaped to (N, 3)).

    Returns
    -------
    lo, hi : (3,) float64 ndarray
        Per-axis minimum and maximum (``inf`` / ``-inf`` where no finite value).
    """
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    _bounds_kernel(readonly(np.ascontiguousarray(v, dtype=np.float64).reshape(-1, 3)), lo, hi)  # one signature
    return lo, hi


def object_mesh(obj, base_dir=".", deform_fn=None):
    """World-space vertices and faces of one scene object (or receiver) dict.

    Fits the mesh (``fit``), applies ``transform`` (scale, rotate about x, y, z,
    translate) and then the deformation: ``deform_fn`` if given, else a
    ``deform`` dict's sine displacement.

    Parameters
    ----------
    obj : dict
        A merged ``objects[k]`` (or receiver) entry: ``mesh``, optional
        ``size``, ``fit``, ``deform``, and ``transform`` (``scale``,
        ``rotate`` in degrees, ``translate``).
    base_dir : str
        Folder for a relative mesh path.
    deform_fn : callable, optional
        ``deform_fn(vertices, normals) -> vertices`` on (V, 3) world-space arrays.

    Returns
    -------
    v : (V, 3) float64 ndarray
        World-space vertices.
    f : (F, 3) ndarray
        Triangles (vertex indices).

    Raises
    ------
    SceneError
        A mesh that cannot be loaded or fitted, or a deform callable returning
        non-finite or misshaped vertices.
    """
    v, f = load_mesh(obj["mesh"], obj.get("size"), base_dir)
    v = np.asarray(v, dtype=np.float64)  # not modified in place: every step below makes a new array
    if obj.get("fit") is not None:
        lo, hi = bounds(v)
        ext = float(np.max(hi - lo))
        if ext <= 0:
            raise SceneError(f"mesh '{obj['mesh']}' has zero extent and cannot be fitted")
        v = (v - (lo + hi) / 2.0) * (float(obj["fit"]) / ext)
    t = obj["transform"]
    # p' = R (s p) + t, in a Numba kernel: a BLAS matmul here would start OpenBLAS's
    # worker threads, which then spin against Numba's threads on a small machine
    R = rotation_matrix(t["rotate"]) * float(t["scale"])
    v = affine(v, R.T, np.asarray(t["translate"], dtype=np.float64))
    d = obj.get("deform")
    if deform_fn is not None:
        v = np.asarray(deform_fn(v.copy(), vertex_normals(v, f)), dtype=np.float64)
        if v.shape != (len(v), 3) or not np.all(np.isfinite(v)):
            raise SceneError("deform callable must return finite (V, 3) vertices")
    elif isinstance(d, dict):
        v = sine_displacement(v, vertex_normals(v, f), d["amplitude"], d["wavelength"], d["direction"], d["phase"])
    return v, np.asarray(f)


@dataclass
class Geometry:
    """All refractive objects of a scene merged into one triangle soup.

    Attributes
    ----------
    vertices : (V, 3) float64, world space
    faces : (F, 3) int64
    face_object : (F,) int32, the object index of every face
    ior : (K,) float64 and absorption : (K, 3) float64, per object
    boundary_edges : (K,) int, edges used by one face only (0 = closed)
    degenerate : (K,) int, zero-area faces
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_object: np.ndarray
    ior: np.ndarray
    absorption: np.ndarray
    boundary_edges: np.ndarray
    degenerate: np.ndarray

    @property
    def tri(self):
        return self.vertices[self.faces]


def _degenerate_count(v, f):
    """Zero-area faces."""
    area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    return int(np.count_nonzero(area <= 0))


def mesh_topology(obj, base_dir, v, f):
    """(boundary edges, zero-area faces) of an object's mesh, cached for mesh files.

    Parameters
    ----------
    obj : dict
        The scene object (its ``mesh`` and ``deform`` decide whether the
        file's cached counts apply).
    base_dir : str
        Folder for a relative mesh path.
    v : (V, 3) float64 ndarray
        The object's world-space vertices (used when not cached).
    f : (F, 3) int ndarray
        The object's triangles.

    Returns
    -------
    boundary_edges : int
        Edges used by exactly one face (0 = closed).
    degenerate : int
        Zero-area faces.
    """
    name = obj["mesh"]
    if isinstance(name, str) and name not in ("sphere", "plane") and obj.get("deform") is None:
        path = os.path.join(_DATA, f"{name}.ply") if name in BUILTIN_MESHES else (
            name if os.path.isabs(name) else os.path.join(base_dir, name))
        if os.path.isfile(path):
            return _topology_of_file(os.path.abspath(path), os.path.getmtime(path))
    return _boundary_edge_count(f), _degenerate_count(v, f)


def _boundary_edge_count(f):
    """Edges used by exactly one face (0 for a closed, i.e. watertight, mesh)."""
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    e = e[e[:, 0] != e[:, 1]]  # a repeated-vertex face's self-loop (a, a) is no edge
    key = e[:, 0].astype(np.int64) * (int(f.max()) + 1) + e[:, 1]
    key.sort()
    change = np.flatnonzero(np.diff(key)) + 1
    runs = np.diff(np.concatenate([[0], change, [len(key)]]))
    return int(np.count_nonzero(runs == 1))


def scene_geometry(scene):
    """Merge the scene's refractive objects into one :class:`Geometry`.

    Parameters
    ----------
    scene : Scene
        A loaded scene (``data["objects"]``, ``base_dir`` and the ``deform``
        callables in ``callables``).

    Returns
    -------
    Geometry
        Empty arrays when the scene has no object.

    Raises
    ------
    SceneError
        Naming ``objects[k].mesh`` for a mesh that cannot be built.
    """
    vs, fs, fo, iors, absn, bnd, deg = [], [], [], [], [], [], []
    off = 0
    for k, o in enumerate(scene.data["objects"]):
        try:
            v, f = object_mesh(o, scene.base_dir, scene.callables.get(("deform", k)))
        except SceneError as e:
            raise SceneError(f"objects[{k}].mesh: {e}") from None
        nbnd, ndeg = mesh_topology(o, scene.base_dir, v, f)
        vs.append(v)
        fs.append(f + off)
        fo.append(np.full(len(f), k, np.int32))
        off += len(v)
        iors.append(float(o["material"]["ior"]))
        absn.append(np.asarray(o["material"]["absorption"], dtype=np.float64))
        bnd.append(nbnd)
        deg.append(ndeg)
    if not vs:
        return Geometry(np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int32),
                        np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    def cat(a):
        return a[0] if len(a) == 1 else np.concatenate(a)

    return Geometry(cat(vs), cat(fs), cat(fo), np.asarray(iors),
                    np.stack(absn), np.asarray(bnd), np.asarray(deg))


def eye_inside(geom, eye):
    """True when the camera sits inside a refractive object (the methods cannot start there).

    Counts the crossings of a ray from the eye in a fixed, irrational
    direction (so that it does not graze the vertices of regular meshes)
    with each object's triangles: odd means inside.

    Parameters
    ----------
    geom : Geometry
        The merged refractive objects (:func:`scene_geometry`).
    eye : (3,) array_like
        Camera position in world space.

    Returns
    -------
    bool

    References
    ----------
    .. [1] E. Haines, "Point in Polygon Strategies", *Graphics Gems IV*,
       24-46, 1994 (crossings test, extended here to a ray through a closed
       triangle mesh).
    """
    v = geom.vertices
    if len(v) == 0:
        return False
    eye = np.asarray(eye, dtype=np.float64)
    u = np.array([1.0, 0.3713, 0.1927])
    u /= np.linalg.norm(u)
    p = np.cross(u, [0.0, 0.0, 1.0])
    p /= np.linalg.norm(p)
    q = np.cross(u, p)
    lo_all, hi_all = bounds(v)
    if np.any(eye <= lo_all) or np.any(eye >= hi_all):
        return False  # outside every object's bounding box
    for k in range(len(geom.ior)):
        fv = v[geom.faces[geom.face_object == k]] - eye
        lo, hi = fv.reshape(-1, 3).min(0), fv.reshape(-1, 3).max(0)
        if not (np.all(lo < 0) and np.all(hi > 0)):
            continue
        a, b, c = (affine(fv[:, m], np.stack([p, q, u], axis=1)) for m in range(3))

        def cr(s, t):
            return s[:, 0] * t[:, 1] - s[:, 1] * t[:, 0]

        s1, s2, s3 = cr(a, b), cr(b, c), cr(c, a)
        inside_tri = ((s1 > 0) & (s2 > 0) & (s3 > 0)) | ((s1 < 0) & (s2 < 0) & (s3 < 0))
        den = s1 + s2 + s3
        with np.errstate(invalid="ignore", divide="ignore"):
            t = (s2 * a[:, 2] + s3 * b[:, 2] + s1 * c[:, 2]) / den
        if np.count_nonzero(inside_tri & (t > 0)) % 2 == 1:
            return True
    return False
