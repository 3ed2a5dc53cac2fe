"""Embree scenes, built in one place for every method that intersects real triangles.

The exact reference (:mod:`refraction_ref.exact`), the caustics' receiver
hits and shadow rays (:mod:`refraction_ref.caustics.receivers`) and the exact
water reference (:mod:`refraction_ref.exact.water`) all ask Embree
(through embreex, float32) for the nearest triangle and then recompute the
hit in float64 on that triangle. Embree's BVH build is the costly part, so
triangle soups are cached by identity for the few scenes a render uses.

Threads: embreex's ``EmbreeScene.run`` releases the GIL while it traces,
and Embree's ray queries on a committed scene are thread-safe (Embree API
manual: "performing ray queries in a scene is thread-safe"), so one scene
is queried from several threads at once (it is committed first, in one
thread: :func:`commit`). :func:`run_chunks` splits the work into fixed-size
chunks whose bounds do not depend on the thread count; each chunk writes
its results into its own rows of preallocated arrays, so results are
bit-identical whatever the number of threads (:func:`numba.get_num_threads`,
the project's one thread knob). The threads come from one
:class:`~concurrent.futures.ThreadPoolExecutor` per process, grown lazily to
the largest thread count asked for; the calling thread works on the chunks
too. The float64 work of a chunk runs in the same thread, in serial Numba
kernels compiled ``nogil`` (the exact tracer's bounce): mixing the pool with
``prange`` kernels would leave OpenMP's workers spinning after every kernel
on the cores the pool's threads need (measured on 2 cores: about 2.8x the
CPU time of one thread, against 1.1x for the pool alone).
"""

from __future__ import annotations

import hashlib
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

__all__ = ["embree_scene", "mesh_scene", "soup_scene", "commit", "nearest_hits", "run_chunks", "chunk_length",
           "thread_count"]

_SOUPS = {}
_SOUP_CONTENT = {}  # (shape, digest of the float32 triangles) -> committed scene, the last few soups
_MESHES = {}       # content digest -> committed scene, the last few meshes traced
_MESH_LOCK = threading.Lock()

#: rays per Embree call of the exact tracer and :func:`nearest_hits` (results never
#: depend on it; small enough to balance the threads on a bounce of a few rays)
HIT_CHUNK = 8192

_POOL = None       # (pid, workers, ThreadPoolExecutor)
_POOL_LOCK = threading.Lock()
_LOCAL = threading.local()  # .busy: this thread runs a chunk of run_chunks


def embree_scene(vertices, faces):
    """An ``embreex`` scene of an indexed triangle mesh (float32 vertices, int32 faces), committed.

    Parameters
    ----------
    vertices : (V, 3) array_like
        Vertex positions, converted to float32.
    faces : (F, 3) array_like
        Vertex indices of each triangle, converted to int32; primitive k is
        ``faces[k]``.

    Returns
    -------
    embreex.rtcore_scene.EmbreeScene
        The committed scene (its BVH is built).

    References
    ----------
    .. [1] I. Wald, S. Woop, C. Benthin, G. S. Johnson, M. Ernst, "Embree: A
       Kernel Framework for Efficient CPU Ray Tracing", ACM Trans. Graph.
       33(4), 143, 2014.
    """
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(vertices, dtype=np.float32), np.ascontiguousarray(faces, dtype=np.int32))
    return commit(scene)


def mesh_scene(vertices, faces):
    """:func:`embree_scene`, reused while a mesh with the same float32 vertices and faces comes again.

    Keyed by the mesh's content (a BLAKE2 digest of the float32 vertices and
    int32 faces Embree gets; the last four meshes are kept): renders of one
    geometry (a sweep, a session, the lights of one render) skip embreex's
    mesh copy (about 45 ms for the bunny's 69k triangles, with the GIL held)
    and the BVH build (about 40 ms). A cached scene answers every query as a
    new one would (Embree's build and traversal are deterministic).

    Parameters
    ----------
    vertices : (V, 3) array_like
        Vertex positions, converted to float32.
    faces : (F, 3) array_like
        Vertex indices of each triangle, converted to int32.

    Returns
    -------
    embreex.rtcore_scene.EmbreeScene
        A committed scene, possibly shared with earlier calls.

    References
    ----------
    .. [1] I. Wald et al., "Embree: A Kernel Framework for Efficient CPU Ray
       Tracing", ACM Trans. Graph. 33(4), 143, 2014.
    """
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.int32)
    h = hashlib.blake2b(digest_size=20)
    h.update(v.tobytes())
    h.update(f.tobytes())
    key = (v.shape, f.shape, h.digest())
    with _MESH_LOCK:
        scene = _MESHES.pop(key, None)
        if scene is None:
            scene = embree_scene(v, f)
        while len(_MESHES) >= 4:  # least recently used first
            _MESHES.pop(next(iter(_MESHES)))
        _MESHES[key] = scene
    return scene


def commit(scene):
    """Commit an ``embreex`` scene now (its first ``run`` would), before several threads query it.

    Parameters
    ----------
    scene : embreex.rtcore_scene.EmbreeScene
        A scene, committed or not (committed by tracing zero rays).

    Returns
    -------
    embreex.rtcore_scene.EmbreeScene
        ``scene`` itself.
    """
    if not getattr(scene, "is_committed", 1):
        empty = np.zeros((0, 3), dtype=np.float32)
        scene.run(empty, empty)
    return scene


def soup_scene(tris, cache=True):
    """An ``embreex`` scene of a triangle soup (T, 3, 3): primitive k is ``tris[k]``.

    With ``cache``, the scene is reused while the same array object is passed
    again (the receivers of one render, the objects' shadow test), and while
    triangles with the same float32 coordinates come again (a BLAKE2 digest,
    as :func:`mesh_scene`: the receivers of the next render, rebuilt from
    the scene every render, skip embreex's copy and the BVH build, which
    runs on Embree's own TBB threads beside Numba's). A cached scene answers
    every query as a new one would.

    Parameters
    ----------
    tris : (T, 3, 3) ndarray
        Triangle corners in world space (converted to float32 for Embree).
    cache : bool
        Reuse and remember scenes (by identity and by content).

    Returns
    -------
    embreex.rtcore_scene.EmbreeScene
        A committed scene.

    References
    ----------
    .. [1] I. Wald et al., "Embree: A Kernel Framework for Efficient CPU Ray
       Tracing", ACM Trans. Graph. 33(4), 143, 2014.
    """
    key = (id(tris), tris.shape)
    hit = _SOUPS.get(key) if cache else None
    if hit is not None and hit[0] is tris:
        return hit[1]
    v = np.ascontiguousarray(tris.reshape(-1, 3), dtype=np.float32)
    ckey = None
    if cache:
        h = hashlib.blake2b(digest_size=20)
        h.update(v.tobytes())
        ckey = (v.shape, h.digest())
        with _MESH_LOCK:
            scene = _SOUP_CONTENT.pop(ckey, None)
            if scene is not None:
                _SOUP_CONTENT[ckey] = scene  # most recently used last
        if scene is not None:
            _SOUPS[key] = (tris, scene)
            return scene
    scene = embree_scene(v, np.arange(len(v), dtype=np.int32).reshape(-1, 3))
    if cache:
        if len(_SOUPS) >= 4:  # a few scenes per render: receivers, objects
            _SOUPS.pop(next(iter(_SOUPS)))
        _SOUPS[key] = (tris, scene)
        with _MESH_LOCK:
            while len(_SOUP_CONTENT) >= 4:
                _SOUP_CONTENT.pop(next(iter(_SOUP_CONTENT)))
            _SOUP_CONTENT[ckey] = scene
    return scene


def thread_count():
    """Threads for Embree work: Numba's thread count in the calling thread (``numba.set_num_threads``)."""
    return max(1, int(numba.get_num_threads()))


def _executor(workers):
    """The process's pool, with at least ``workers`` threads (re-made after a fork)."""
    global _POOL
    with _POOL_LOCK:
        pool = _POOL
        if pool is None or pool[0] != os.getpid() or pool[1] < workers:
            if pool is not None and pool[0] == os.getpid():
                pool[2].shutdown(wait=False)  # its queued and running work still completes
            _POOL = pool = (os.getpid(), workers, ThreadPoolExecutor(max_workers=workers,
                                                                    thread_name_prefix="refraction_ref-embree"))
        return pool[2]


def chunk_length(n, max_chunk, min_chunk=1024, multiple=8):
    """Rows per chunk for ``n`` rows: equal chunks of at most ``max_chunk``, their number a multiple
    of ``multiple`` (balanced over 2, 4, 8 threads) unless that would make them shorter than
    ``min_chunk``. A function of ``n`` alone, never of the thread count.

    Parameters
    ----------
    n : int
        Number of rows (rays) to split.
    max_chunk : int
        Largest chunk length (clamped to >= 1).
    min_chunk : int
        Shortest chunk length the rounding to ``multiple`` chunks may make.
    multiple : int
        The number of chunks is rounded up to a multiple of this.

    Returns
    -------
    int
        Rows per chunk (``max_chunk`` when ``n <= 0``).
    """
    n, max_chunk = int(n), max(1, int(max_chunk))
    if n <= 0:
        return max_chunk
    min_chunk = max(1, min(int(min_chunk), max_chunk))
    k = -(-n // max_chunk)
    k = -(-k // multiple) * multiple
    k = max(1, min(k, -(-n // min_chunk)))
    return -(-n // k)


def run_chunks(fn, n, chunk, threads=None):
    """Call ``fn(start, stop)`` on the fixed chunks ``[k chunk, min(n, (k + 1) chunk))`` of ``range(n)``.

    Up to ``threads`` threads (default :func:`thread_count`) take the chunks
    in increasing order: the calling thread and ``threads - 1`` threads of the
    shared pool. The chunks do not depend on the thread count; ``fn`` must
    write only its chunk's rows (then the result is the same whatever the
    threads). ``fn`` runs with the GIL held except where it releases it
    (Embree's ``run``, NumPy's loops, ``nogil`` Numba kernels); it must not
    launch parallel Numba kernels (Numba's thread count is per thread, and
    some threading layers refuse concurrent launches). A ``run_chunks`` called
    from inside ``fn`` runs its chunks in its own thread. Exceptions are
    re-raised in the caller.

    Parameters
    ----------
    fn : callable
        ``fn(start, stop)``, called once per chunk; its return value is ignored.
    n : int
        Number of rows.
    chunk : int
        Rows per chunk, >= 1 (see :func:`chunk_length`).
    threads : int, optional
        Most threads to use; default :func:`thread_count`.

    Returns
    -------
    None

    Raises
    ------
    ValueError
        ``chunk < 1``.
    """
    n, chunk = int(n), int(chunk)
    if chunk < 1:
        raise ValueError("chunk must be >= 1")
    nchunks = -(-n // chunk) if n > 0 else 0
    if nchunks == 0:
        return
    threads = thread_count() if threads is None else max(1, int(threads))
    if getattr(_LOCAL, "busy", False):  # nested: the outer call already uses the threads
        threads = 1
    threads = min(threads, nchunks)
    if threads == 1:
        for k in range(nchunks):
            fn(k * chunk, min(n, (k + 1) * chunk))
        return
    lock = threading.Lock()
    state = {"next": 0, "stop": False}

    def work():
        before = getattr(_LOCAL, "busy", False)
        _LOCAL.busy = True
        try:
            while True:
                with lock:
                    k = state["next"]
                    if state["stop"] or k >= nchunks:
                        return
                    state["next"] = k + 1
                try:
                    fn(k * chunk, min(n, (k + 1) * chunk))
                except BaseException:
                    state["stop"] = True
                    raise
        finally:
            _LOCAL.busy = before

    pool = _executor(threads - 1)
    futures = [pool.submit(work) for _ in range(threads - 1)]
    err = None
    try:
        work()
    except BaseException as e:  # noqa: BLE001 - re-raised below, once the helpers are done
        err = e
    for fu in futures:
        if fu.cancel():  # still queued behind other work: every chunk is taken already
            continue
        try:
            fu.result()
        except BaseException as e:  # noqa: BLE001
            err = err or e
    if err is not None:
        raise err


def nearest_hits(scene, origins, dirs, chunk=HIT_CHUNK, threads=None):
    """Embree's nearest hits of float32 rays, traced in fixed chunks on several threads (:func:`run_chunks`).

    Parameters
    ----------
    scene : embreex EmbreeScene
    origins, dirs : (N, 3) array_like
        Rays, converted to float32.
    chunk : int
        Rays per Embree call (results do not depend on it).
    threads : int, optional
        Default :func:`thread_count`.

    Returns
    -------
    prim, tfar, u, v : (N,) arrays
        Embree's ``primID`` (int32, -1 on a miss), ``tfar`` and the
        barycentrics ``u``, ``v`` (float32), as one ``scene.run(..., output=1)``
        would give them.
    """
    o = np.ascontiguousarray(origins, dtype=np.float32)
    d = np.ascontiguousarray(dirs, dtype=np.float32)
    n = len(o)
    prim = np.empty(n, np.int32)
    tfar = np.empty(n, np.float32)
    u = np.empty(n, np.float32)
    v = np.empty(n, np.float32)
    commit(scene)

    def one(a, b):
        res = scene.run(o[a:b], d[a:b], output=1)
        prim[a:b] = res["primID"]
        tfar[a:b] = res["tfar"]
        u[a:b] = res["u"]
        v[a:b] = res["v"]

    run_chunks(one, n, chunk, threads)
    return prim, tfar, u, v


def _after_fork_in_child():
    """A forked child has none of the parent's pool threads, and a lock may have been held at the fork."""
    global _POOL, _POOL_LOCK, _MESH_LOCK, _LOCAL
    _POOL = None
    _POOL_LOCK = threading.Lock()
    _MESH_LOCK = threading.Lock()
    _LOCAL = threading.local()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)
