"""The exact reference on several threads: bit-identical whatever the thread count, and equal
to a vectorised NumPy tracer.

Each bounce of :func:`refraction_ref.exact.trace_exact` splits its rays into
fixed chunks that the threads of one pool take in turn (Embree query, then a
GIL-free Numba kernel for the float64 bounce); the exact water reference and
the exact shadow rays use the same pool. Small ``chunk_size`` / water chunks
make even these small scenes use several chunks per bounce. ``_trace_numpy``
and ``_water_numpy`` below are vectorised NumPy forms of the same computations,
the references the kernels are checked against (measured: bit-identical; the
tolerance is 1e-12).
"""

from __future__ import annotations

import json
import os
import threading

import numba
import numpy as np
import pytest

import refraction_ref as rr
from refraction_ref import embree, optics
from refraction_ref.analytic import icosphere_mesh
from refraction_ref.exact import ExactMesh, area_weighted_vertex_normals, trace_exact
from refraction_ref.exact import water as exact_water
from refraction_ref.meshes import corner_normals, load_mesh
from refraction_ref.status import EXITED, LIMIT, LOST, MISSED, TIR

DATA = os.path.join(os.path.dirname(rr.__file__), "data")
TOL = 1e-12


def _rays(n, seed, r=0.6, dist=3.0):
    rng = np.random.default_rng(seed)
    target = rng.uniform(-r, r, (n, 3))
    o = rng.normal(size=(n, 3))
    o = dist * o / np.linalg.norm(o, axis=1, keepdims=True)
    d = target - o
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


def _two_objects():
    """An icosphere (IOR 2.4, absorbing) beside the bunny (IOR 1.5): TIR, leaving one object for another."""
    v1, f1 = icosphere_mesh(3, 0.5)
    v2, f2 = load_mesh("bunny")
    v2 = (v2 - v2.mean(axis=0)) / np.abs(v2).max() * 0.5
    v = np.vstack([v1 + [0.55, 0.0, 0.0], v2 - [0.55, 0.0, 0.0]])
    f = np.vstack([f1, f2 + len(v1)])
    fo = np.r_[np.zeros(len(f1), np.int64), np.ones(len(f2), np.int64)]
    return dict(vertices=v, faces=f, face_object=fo, object_ior=[2.4, 1.5],
                object_absorption=[[0.5, 1.0, 2.0], [0.0, 0.3, 0.0]])


# ---------------------------------------------------------------------------
# the NumPy tracer (the reference of the kernels)
# ---------------------------------------------------------------------------

def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _unit(a):
    with np.errstate(invalid="ignore", divide="ignore"):
        return a / np.linalg.norm(a, axis=1, keepdims=True)


def _trace(mesh_kw, origins, dirs, **kw):
    """:func:`trace_exact` of :class:`ExactMesh`'s fields ``mesh_kw`` (and ``normals``, ``smooth``,
    ``outside_ior`` among ``kw``) and the tracer's own keywords."""
    kw = dict(kw)
    mesh = ExactMesh(**mesh_kw, **{k: kw.pop(k) for k in ("normals", "smooth", "outside_ior") if k in kw})
    return trace_exact(mesh, origins, dirs, **kw)


def _trace_numpy(vertices, faces, face_object, object_ior, object_absorption, origins, dirs, *,
                 normals=None, smooth=True, outside_ior=1.0, max_bounces=64, record=0):
    """``trace_exact`` as a vectorised NumPy loop (one Embree call per bounce): the reference of its kernels."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    fo = np.asarray(face_object, np.int64)
    ior = np.asarray(object_ior, float)
    ab = np.asarray(object_absorption, float)
    o = np.asarray(origins, float)
    d = np.asarray(dirs, float)
    vn = None if not smooth else (area_weighted_vertex_normals(v, f) if normals is None else np.asarray(normals))
    lo, hi = v.min(axis=0), v.max(axis=0)
    eps = 1e-5 * max(float(np.linalg.norm(hi - lo)), float(np.abs(v).max()), 1e-30)
    n = len(o)
    nan3 = np.full((n, 3), np.nan)
    pos, dirn, side = o.copy(), d.copy(), np.zeros((n, 3))
    medium = np.full(n, -1, np.int64)
    status = np.full(n, -1, np.int8)
    last_tir = np.zeros(n, bool)
    out = {"hit": None, "status": status, "exit_pos": nan3.copy(), "exit_dir": nan3.copy(), "last_dir": d.copy(),
           "hit_pos": nan3.copy(), "first_face": np.full(n, -1, np.int64), "first_normal": nan3.copy(),
           "first_dir": nan3.copy(), "interfaces": np.zeros(n, np.int16), "bounces": np.zeros(n, np.int16),
           "path_length": np.zeros(n), "transmittance": np.ones((n, 3)), "leaked": np.zeros(n, bool)}
    if record:
        out["path_pos"] = np.full((n, record, 3), np.nan)
        out["path_dir"] = np.full((n, record, 3), np.nan)
    med_ior = np.append(ior, float(outside_ior))
    tri = v[f]
    e1_all, e2_all = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    ng_all = _unit(np.cross(e1_all, e2_all))
    scene = embree.embree_scene(v, f)
    for bounce in range(max_bounces + 1):
        idx = np.flatnonzero(status == -1)
        if len(idx) == 0:
            break
        p, dd = pos[idx], dirn[idx]
        org = p if bounce == 0 else p + eps * (dd + side[idx])
        res = scene.run(np.ascontiguousarray(org, np.float32), np.ascontiguousarray(dd, np.float32), output=1)
        prim = np.asarray(res["primID"], np.int64)
        mi = idx[prim < 0]
        if bounce == 0:
            status[mi] = MISSED
            out["exit_dir"][mi] = d[mi]
        else:
            status[mi] = EXITED
            out["exit_pos"][mi] = pos[mi]
            out["exit_dir"][mi] = dirn[mi]
            out["leaked"][mi] = medium[mi] != -1
        out["last_dir"][mi] = dirn[mi]
        hm = prim >= 0
        hi_, fi, p, dd = idx[hm], prim[hm], p[hm], dd[hm]
        if len(hi_) == 0:
            continue
        e1, e2 = e1_all[fi], e2_all[fi]
        pvec = np.cross(dd, e2)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / _dot(e1, pvec)
            tvec = p - tri[fi, 0]
            u = _dot(tvec, pvec) * inv
            qvec = np.cross(tvec, e1)
            w2 = _dot(dd, qvec) * inv
            t = _dot(e2, qvec) * inv
        bad = ~np.isfinite(t) | (t <= 0.0)
        if np.any(bad):
            tf = np.asarray(res["tfar"], float)[hm]
            h = org[hm] + tf[:, None] * dd if bounce else p + tf[:, None] * dd
            t = np.where(bad, _dot(h - p, dd), t)
            u = np.where(bad, np.asarray(res["u"], float)[hm], u)
            w2 = np.where(bad, np.asarray(res["v"], float)[hm], w2)
        x = p + t[:, None] * dd
        if bounce == 0:
            out["hit_pos"][hi_] = x
            out["first_face"][hi_] = fi
        if bounce == max_bounces:
            status[hi_] = np.where(last_tir[hi_], TIR, LIMIT).astype(np.int8)
            out["last_dir"][hi_] = dirn[hi_]
            continue
        med = medium[hi_]
        inside = med != -1
        if np.any(inside):
            k = med[inside]
            out["path_length"][hi_[inside]] += t[inside]
            out["transmittance"][hi_[inside]] *= optics.beer_lambert(ab[k], t[inside], ior[k])
        ng = ng_all[fi]
        cos_g = _dot(dd, ng)
        entering = cos_g < 0.0
        if smooth:
            b1, b2, b0 = np.clip(u, 0.0, 1.0), np.clip(w2, 0.0, 1.0), np.clip(1.0 - u - w2, 0.0, 1.0)
            s = b0 + b1 + b2
            s = np.where(s > 0, s, 1.0)
            cn = vn[fi] if vn.ndim == 3 else vn[f[fi]]
            ns = _unit((b0[:, None] * cn[:, 0] + b1[:, None] * cn[:, 1] + b2[:, None] * cn[:, 2]) / s[:, None])
            ns = np.where(np.all(np.isfinite(ns), axis=1)[:, None], ns, ng)
            flip = _dot(ns, ng) < 0.0
            ns[flip] = -ns[flip]
        else:
            ns = ng
        obj = fo[fi]
        eta = med_ior[med] / np.where(entering, ior[obj], float(outside_ior))
        newd, tir = optics.refract(dd, ns, eta)
        if smooth:
            sn, sg = np.sign(_dot(newd, ng)), np.sign(cos_g)
            wrong = np.where(tir, sn == sg, sn != sg)
            if np.any(wrong):
                newd[wrong], tir[wrong] = optics.refract(dd[wrong], ng[wrong], eta[wrong])
                ns[wrong] = ng[wrong]
        lost = ~np.all(np.isfinite(newd), axis=1)
        newd = np.where(lost[:, None], dd, newd)
        if bounce < record:
            out["path_pos"][hi_, bounce] = x
            out["path_dir"][hi_, bounce] = np.where(lost[:, None], np.nan, newd)
        if bounce == 0:
            out["first_normal"][hi_] = ns
            out["first_dir"][hi_] = newd
        crossed = ~tir & ~lost
        medium[hi_] = np.where(crossed, np.where(entering, obj, -1), med)
        out["interfaces"][hi_] += crossed.astype(np.int16)
        out["bounces"][hi_] += 1
        last_tir[hi_] = tir
        pos[hi_] = x
        dirn[hi_] = newd
        out["last_dir"][hi_] = newd
        side[hi_] = ng * np.where(_dot(newd, ng) >= 0.0, 1.0, -1.0)[:, None]
        status[hi_[lost]] = LOST
    out["hit"] = status != MISSED
    return out


def _close(ref, new):
    """``new`` agrees with ``ref`` (integers equal, floats within TOL, NaN where NaN)."""
    assert ref.keys() == new.keys()
    for k in ref:
        x, y = np.asarray(ref[k]), np.asarray(new[k])
        assert x.shape == y.shape, k
        if x.dtype.kind != "f":
            assert np.array_equal(x, y), k
            continue
        assert np.array_equal(np.isnan(x), np.isnan(y)), k
        fin = ~np.isnan(x)
        assert np.max(np.abs(x[fin] - y[fin]), initial=0.0) <= TOL, k


# ---------------------------------------------------------------------------
# the tracer: thread counts and the NumPy reference
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("extra", [{}, {"smooth": False}, {"record": 4, "outside_ior": 1.1}, {"max_bounces": 3},
                                   {"corner": True}])
def test_trace_identical_on_one_and_two_threads_and_to_numpy(extra, on_one_and_two_threads, same_arrays):
    kw = _two_objects()
    o, d = _rays(6000, 1)
    extra = dict(extra)
    if extra.pop("corner", False):
        extra["normals"] = corner_normals(kw["vertices"], kw["faces"], 30.0)
    a, b = on_one_and_two_threads(lambda: _trace(kw, o, d, chunk_size=512, **extra))
    same_arrays(a, b)
    st = np.bincount(a["status"], minlength=5)
    assert st[MISSED] > 0 and st[EXITED] > 0
    assert np.any(a["transmittance"] < 1.0)
    _close(_trace_numpy(**kw, origins=o, dirs=d, **extra), a)
    # the chunk size does not matter either
    same_arrays(a, _trace(kw, o, d, chunk_size=100_000, **extra))


def test_tir_heavy_sphere_identical_on_one_and_two_threads(on_one_and_two_threads, same_arrays):
    """IOR 2.4 (a diamond): rays trapped by TIR bounce until the limit (status 3); few rays per late bounce."""
    v, f = icosphere_mesh(4, 0.5)
    kw = dict(vertices=v, faces=f, face_object=np.zeros(len(f), np.int64), object_ior=[2.4],
              object_absorption=[[0.2, 0.4, 0.8]])
    o, d = _rays(8000, 2, r=0.5)
    a, b = on_one_and_two_threads(lambda: _trace(kw, o, d, chunk_size=256, max_bounces=40, record=3))
    same_arrays(a, b)
    assert np.sum(a["status"] == TIR) > 0 and a["bounces"].max() == 40
    _close(_trace_numpy(**kw, origins=o, dirs=d, max_bounces=40, record=3), a)


def test_grazing_rays_take_embrees_distance_identically(on_one_and_two_threads, same_arrays):
    """Rays in the plane of a cube's faces and along its edges (Möller-Trumbore's degenerate cases)."""
    import trimesh

    m = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    kw = dict(vertices=np.asarray(m.vertices, float), faces=np.asarray(m.faces), face_object=np.zeros(12, np.int64),
              object_ior=[1.5], object_absorption=[[0.1, 0.2, 0.3]])
    rng = np.random.default_rng(0)
    n = 4000
    o = np.c_[np.full(n, -2.0), rng.uniform(-0.6, 0.6, n), np.full(n, 0.5)]
    o[n // 4:n // 2, 1] = 0.5
    o[n // 2:, 2] = rng.uniform(-0.5, 0.5, n - n // 2)
    d = np.c_[np.ones(n), rng.normal(0.0, 1e-9, n), np.zeros(n)]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    a, b = on_one_and_two_threads(lambda: _trace(kw, o, d, chunk_size=300, record=2))
    same_arrays(a, b)
    _close(_trace_numpy(**kw, origins=o, dirs=d, record=2), a)


def test_mesh_scene_render_identical_on_one_and_two_threads(on_one_and_two_threads, same_arrays):
    scene = rr.load_scene({"objects": [{"mesh": "bunny", "material": {"ior": 1.6, "absorption": [0.5, 0.1, 1.0]}}],
                           "camera": {"width": 96, "height": 96}, "exact": {"record": 3}})
    a, b = on_one_and_two_threads(lambda: rr.render(scene, method="exact").arrays)
    same_arrays(a, b)
    assert np.any(a["status"] == EXITED)


# ---------------------------------------------------------------------------
# caustics photons and the water reference
# ---------------------------------------------------------------------------

def test_caustics_exact_photons_identical_on_one_and_two_threads(on_one_and_two_threads, same_arrays):
    scene = rr.load_scene(os.path.join(DATA, "caustics_default.json"))

    def run():
        r = rr.render(scene, method="exact", keep="photon_trace",
                      overrides={"camera.width": 48, "camera.height": 48, "exact.photons": 96,
                                 "imagespace.caustic_map": 64})
        return r.arrays

    a, b = on_one_and_two_threads(run)
    same_arrays(a, b)
    assert len(a["stage.photon_trace.exit_pos_0"]) > 0


def _water_scene():
    with open(os.path.join(DATA, "levelmap_default.json")) as fh:
        sc = json.load(fh)
    sc["lights"].append({"type": "point", "position": [0.5, 2.0, -0.3], "radiance": [2.0, 2.0, 2.0]})
    return rr.load_scene(sc)


_WATER = {"camera.width": 32, "camera.height": 32, "caustics.map_size": 96, "exact.water_samples": 160}


def _water_maps(scene):
    r = rr.render(scene, method="exact", overrides=_WATER)
    return {k: v for k, v in r.arrays.items()}, r.meta["stats"]


def test_exact_water_identical_on_one_and_two_threads(on_one_and_two_threads, monkeypatch, same_arrays):
    monkeypatch.setattr(exact_water, "CHUNK", 160 * 12)  # 12 rows a chunk: 14 chunks per light
    scene = _water_scene()
    (a, sa), (b, sb) = on_one_and_two_threads(lambda: _water_maps(scene))
    same_arrays(a, b)
    assert sa == sb and sum(st["hit"] for st in sa) > 0  # photons per light: traced, landed, deposited
    assert a["caustic_map_0"].max() > 0


def _water_numpy(scene, ctx, light_index, samples, seed, out, chunk):
    """The water photons as a serial NumPy loop (one chunk of rows at a time): the reference of the kernels."""
    from refraction_ref.levelmap.planes import to_map
    from refraction_ref.levelmap.water import incident_directions, surface_normals, wave_gradient, wave_height

    water, light, rec = scene.data["water"], scene.data["lights"][light_index], ctx["receivers"]
    sx, sz = (float(s) for s in water["size"])
    M = int(samples)
    rng = np.random.default_rng([int(seed), int(light_index)])
    emb = embree.soup_scene(rec.tris)
    rows = max(1, chunk // M)
    for i0 in range(0, M, rows):
        ii, jj = np.meshgrid(np.arange(i0, min(M, i0 + rows)), np.arange(M), indexing="ij")
        u, v = rng.random(ii.shape), rng.random(ii.shape)
        x = (-sx / 2.0 + (jj + u) * (sx / M)).ravel()
        z = (-sz / 2.0 + (ii + v) * (sz / M)).ravel()
        hx, hz = wave_gradient(water, x, z)
        p = np.stack([x, wave_height(water, x, z), z], axis=1)
        inc, e_perp = incident_directions(light, p)
        flux = e_perp * np.maximum(-np.einsum("ij,ij->i", inc, np.stack([-hx, np.ones_like(hx), -hz], axis=1)),
                                   0.0) * ((sx / M) * (sz / M))
        t, tir = optics.refract(inc, surface_normals(water, x, z), ctx["eta"])
        ok = (flux > 0) & ~tir & (t[:, 1] < 0)
        p, t, flux = p[ok], t[ok], flux[ok]
        res = emb.run(np.ascontiguousarray(p, np.float32), np.ascontiguousarray(t, np.float32), output=1)
        prim = np.asarray(res["primID"], np.int64)
        dist = np.asarray(res["tfar"], float)
        for r in range(len(ctx["pairs"])):
            m = (prim >= 0) & (rec.owner[np.maximum(prim, 0)] == r)
            box, lm = ctx["pairs"][r][0].box, ctx["pairs"][r][0].lm
            Hc, Wc = box.size
            q = to_map(box, p[m] + dist[m, None] * t[m])
            jn = np.clip(np.floor(q[:, 0]).astype(np.int64), 0, Wc - 1)
            in_ = np.clip(np.floor(q[:, 1]).astype(np.int64), 0, Hc - 1)
            cosv = np.abs(rec.normals[prim[m]] @ box.V)
            seen = lm.own[in_, jn] & (np.abs(q[:, 2] - lm.depth[in_, jn])
                                      <= 2.0 * box.texel_size / np.maximum(cosv, 0.05))
            w = flux[m] * np.exp(-ctx["K"] * dist[m]) * cosv / box.texel_area
            c, rr_ = q[:, 0] - 0.5, q[:, 1] - 0.5
            j0, i0_ = np.floor(c).astype(np.int64), np.floor(rr_).astype(np.int64)
            fx, fy = c - j0, rr_ - i0_
            acc = np.zeros(Hc * Wc)
            for di, wy in ((0, 1.0 - fy), (1, fy)):
                for dj, wx in ((0, 1.0 - fx), (1, fx)):
                    a, b = i0_ + di, j0 + dj
                    good = seen & (a >= 0) & (a < Hc) & (b >= 0) & (b < Wc)
                    acc += np.bincount(a[good] * Wc + b[good], weights=(w * wy * wx)[good], minlength=Hc * Wc)
            out[r] += acc.reshape(Hc, Wc)


def test_exact_water_matches_the_serial_numpy_loop(monkeypatch):
    chunk = 160 * 12
    monkeypatch.setattr(exact_water, "CHUNK", chunk)
    scene = _water_scene()
    numba_before = numba.get_num_threads()
    try:
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        new, _ = _water_maps(scene)
        monkeypatch.setattr(exact_water, "trace_water_photons",
                            lambda sc, ctx, l, M, seed, out, progress=False: _water_numpy(sc, ctx, l, M, seed, out,
                                                                                          chunk))
        ref, _ = _water_maps(scene)
    finally:
        numba.set_num_threads(numba_before)
    _close(ref, new)


def test_refract_rows_is_optics_refract():
    rng = np.random.default_rng(5)
    d = rng.normal(size=(5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = rng.normal(size=(5000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t, tir = optics.refract(d, n, 1.33)  # water to air: some TIR
    t2, tir2 = np.empty_like(d), np.empty(5000, bool)
    exact_water.refract_rows(d, n, 1.33, t2, tir2)
    assert np.array_equal(t, t2) and np.array_equal(tir, tir2) and tir.any()


# ---------------------------------------------------------------------------
# the pool
# ---------------------------------------------------------------------------

def test_run_chunks_fixed_chunks_nesting_and_errors():
    seen = []
    lock = threading.Lock()

    def rec(a, b):
        with lock:
            seen.append((a, b))

    for threads in (1, 2, 3):
        seen.clear()
        embree.run_chunks(rec, 10, 3, threads=threads)
        assert sorted(seen) == [(0, 3), (3, 6), (6, 9), (9, 10)]
    embree.run_chunks(rec, 0, 3)

    # a run_chunks inside a chunk runs in its own thread (no deadlock on the shared pool)
    inner = np.zeros(64, int)

    def outer(a, b):
        def fill(c, d):
            inner[a * 8 + c:a * 8 + d] += 1
        embree.run_chunks(fill, 8, 2, threads=2)

    embree.run_chunks(lambda a, b: [outer(k, k + 1) for k in range(a, b)], 8, 1, threads=2)
    assert np.all(inner == 1)

    def boom(a, b):
        if a == 6:
            raise KeyError("chunk 6")

    with pytest.raises(KeyError, match="chunk 6"):
        embree.run_chunks(boom, 10, 3, threads=2)
    with pytest.raises(ValueError):
        embree.run_chunks(rec, 10, 0)


def test_nearest_hits_matches_one_embree_call():
    v, f = icosphere_mesh(3, 0.5)
    scene = embree.embree_scene(v, f)
    o, d = _rays(5000, 7)
    o32, d32 = o.astype(np.float32), d.astype(np.float32)
    ref = scene.run(o32, d32, output=1)
    for threads in (1, 2):
        prim, tfar, u, w = embree.nearest_hits(scene, o32, d32, chunk=333, threads=threads)
        assert np.array_equal(prim, ref["primID"]) and np.array_equal(tfar, ref["tfar"])
        assert np.array_equal(u, ref["u"]) and np.array_equal(w, ref["v"])
    assert np.any(prim < 0) and np.any(prim >= 0)


def test_exact_visibility_chunks_and_threads(on_one_and_two_threads):
    """Shadow rays past an icosphere in chunks on two threads: the same as in one go."""
    from refraction_ref.caustics.shadow import exact_visibility

    v, f = icosphere_mesh(3, 0.5)
    tris = v[f]
    rng = np.random.default_rng(9)
    pts = np.c_[rng.uniform(-1.5, 1.5, 20000), np.full(20000, -0.8), rng.uniform(-1.5, 1.5, 20000)]
    nrm = np.tile([0.0, 1.0, 0.0], (20000, 1))
    for light in ({"type": "directional", "direction": [0.2, -1.0, 0.1]},
                  {"type": "point", "position": [0.3, 2.0, 0.0]}):
        ref = exact_visibility(tris, light, pts, nrm, chunk=1 << 20)
        a, b = on_one_and_two_threads(lambda: exact_visibility(tris, light, pts, nrm, chunk=999))
        assert np.array_equal(ref, a) and np.array_equal(ref, b)
        assert 0 < ref.sum() < len(ref)  # some points in the shadow
