"""Exact water-caustics reference (``--method exact`` on a scene with water).

The analytic water surface (not its mesh) is sampled very densely: one
jittered sample per cell of an ``exact.water_samples`` squared grid over the
water rectangle. Each sample carries the flux the light pours through its
patch, ``E_perp |I . (-h_x, 1, -h_z)| dx dz`` (the patch's area projected
perpendicular to the light; zero where the light meets the surface from
below), is refracted with the analytic normal (Snell, eq. 2-8, through
:func:`refraction_ref.optics.refract`) and intersected exactly with every
receiver triangle (Embree; the first hit wins, so receivers shadow each
other). Its flux, attenuated by ``exp(-K t)`` over the distance ``t`` in
water, is splatted bilinearly into the receiver's caustics map in the same
frame as the level map (first light's box), converted to irradiance with the
receiver's geometric normal, ``|n . V| / texel_area``. Photons landing on a
surface that the map does not see (hidden along ``-V``, detected with the
position map) are dropped, as the map cannot hold them. No Fresnel loss,
as in eq. 4-18; the refracted light does not meet the water again. The
``image`` stage then renders the pool through the analytic surface (eye rays
met exactly and refracted with the analytic normal, :mod:`.view`).

References
----------
.. [1] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
   with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
   University, 2006, §2.6, §4.5 (the quantities reproduced).
.. [2] J. Arvo, "Backward Ray Tracing", SIGGRAPH '86 course notes (light
   tracing into illumination maps).
"""

from __future__ import annotations

import contextlib
import threading

import numba as nb
import numpy as np

from ..embree import nearest_hits, run_chunks, soup_scene
from ..optics import refract3
from ..caustics.boxes import to_map
from ..levelmap.water import incident_directions, surface_normals, wave_gradient, wave_height
from ..vec3 import dot

__all__ = ["trace_water_photons", "refract_rows", "CHUNK"]

#: samples per chunk: a chunk is ``max(1, CHUNK // M)`` rows of the ``M x M`` grid of samples
CHUNK = 1 << 18


@nb.njit(cache=True, nogil=True)
def refract_rows(d, n, eta, out, tir):
    """:func:`refraction_ref.optics.refract` with one ``eta``, serial and without the GIL
    (it runs inside the threads of :func:`refraction_ref.embree.run_chunks`).

    Parameters
    ----------
    d, n : (N, 3) float64
        Unit directions and unit normals (against ``d``).
    eta : float
        ``n1 / n2``.
    out : (N, 3) float64
        The refracted (or, under TIR, reflected) directions, written.
    tir : (N,) bool
        Total internal reflection, written.

    References
    ----------
    .. [1] Tipprasert (2006), eq. 2-8 (Snell's law at the water surface).
    """
    for i in range(d.shape[0]):
        tx, ty, tz, t = refract3(d[i, 0], d[i, 1], d[i, 2], n[i, 0], n[i, 1], n[i, 2], eta)
        out[i, 0] = tx
        out[i, 1] = ty
        out[i, 2] = tz
        tir[i] = t


class _Abandoned(Exception):
    """Raised in the threads waiting for their turn once another chunk failed."""


class _Turns:
    """Ordered sections across threads: ``with turns.of(name, k):`` runs after ``k - 1``'s.

    A failed chunk (``fail``) releases every waiter with :class:`_Abandoned`,
    so no thread waits forever; ``error`` keeps the first failure.
    """

    def __init__(self):
        self.cond = threading.Condition()
        self.next = {}
        self.failed = False
        self.error = None

    @contextlib.contextmanager
    def of(self, name, k):
        with self.cond:
            self.cond.wait_for(lambda: self.failed or self.next.get(name, 0) == k)
            if self.failed:
                raise _Abandoned()
        try:
            yield  # alone in this section: the others wait for their turn
        finally:
            with self.cond:
                self.next[name] = k + 1
                self.cond.notify_all()

    def fail(self, error):
        with self.cond:
            if not self.failed:
                self.failed, self.error = True, error
            self.cond.notify_all()


def _splats(ctx, p, t, flux, prim, hit, dist):
    """Each receiver's bilinear splat of the photons that landed on it and that its map sees.

    Photons from ``p`` along ``t`` with ``flux``, meeting receiver triangle ``prim`` (where
    ``hit``) at distance ``dist``: ``[(r, (Hc, Wc) map, photons seen), ...]`` for the
    receivers met.
    """
    rec, K = ctx["receivers"], ctx["K"]
    splats = []
    for r in range(len(ctx["pairs"])):
        m = hit & (rec.owner[np.maximum(prim, 0)] == r)
        if not m.any():
            continue
        pair = ctx["pairs"][r][0]
        box, lm = pair.box, pair.lm
        Hc, Wc = box.size
        pts = p[m] + dist[m, None] * t[m]
        q = to_map(box, pts)
        jn = np.clip(np.floor(q[:, 0]).astype(np.int64), 0, Wc - 1)
        in_ = np.clip(np.floor(q[:, 1]).astype(np.int64), 0, Hc - 1)
        nrm = rec.normals[prim[m]]
        cosv = np.abs(dot(nrm, box.V))
        tol = 2.0 * box.texel_size / np.maximum(cosv, 0.05)
        seen = lm.own[in_, jn] & (np.abs(q[:, 2] - lm.depth[in_, jn]) <= tol)
        w = flux[m] * np.exp(-K * dist[m]) * cosv / box.texel_area
        c = q[:, 0] - 0.5
        rr = q[:, 1] - 0.5
        j0 = np.floor(c).astype(np.int64)
        i0_ = np.floor(rr).astype(np.int64)
        fx = c - j0
        fy = rr - i0_
        acc = np.zeros(Hc * Wc)
        for di, wy in ((0, 1.0 - fy), (1, fy)):
            for dj, wx in ((0, 1.0 - fx), (1, fx)):
                a = i0_ + di
                b = j0 + dj
                good = seen & (a >= 0) & (a < Hc) & (b >= 0) & (b < Wc)
                acc += np.bincount(a[good] * Wc + b[good], weights=(w * wy * wx)[good], minlength=Hc * Wc)
        splats.append((r, acc.reshape(Hc, Wc), int(seen.sum())))
    return splats


def trace_water_photons(scene, ctx, light_index, samples, seed, out, progress=False):
    """Trace the photons of one light into ``out[r]`` (maps in each receiver's frame 0).

    The samples are traced in chunks of whole grid rows (about ``2**18``
    photons) on ``numba.get_num_threads()`` threads
    (:func:`refraction_ref.embree.run_chunks`); each chunk draws its jitter
    from the one generator in chunk order, and the splats are added to
    ``out`` in chunk order, so the maps are bit-identical whatever the
    thread count.

    Parameters
    ----------
    scene : Scene
        A scene with ``water`` and ``lights``.
    ctx : dict
        The light side shared with the level map: ``receivers``
        (:class:`~refraction_ref.caustics.receivers.Receivers`), ``pairs[r][l]`` (box and
        level map per receiver and light: the maps' frame and what they see),
        ``eta`` (outside over water index) and ``K`` (the water's absorption).
    light_index : int
        The light traced.
    samples : int
        ``exact.water_samples``: jittered samples per side of the water rectangle.
    seed : int
        ``exact.photon_seed``; the generator is seeded with ``[seed, light_index]``.
    out : list of (Hc, Wc) ndarray
        Each receiver's irradiance map, in the frame of the first light's box; added to.
    progress : bool, default False
        Unused (kept for the signature of the stage's call).

    Returns
    -------
    dict
        ``photons`` traced, ``hit`` (landed on a receiver), ``deposited``
        (seen by the map).

    References
    ----------
    .. [1] docs/oracle.md, "Level map" (``exact`` on water scenes) and the ``exact`` block.
    .. [2] N. Tipprasert, "An Interactive Rendering Method for Water-Side Scene
       with Caustics Using Level Map Method", M.Eng. thesis, Chulalongkorn
       University, 2006, eq. 2-8 (Snell at the water surface), §4.5 and eq. 4-18
       (the flux through a patch, ``exp(-K t)``, no Fresnel loss).
    """
    water = scene.data["water"]
    light = scene.data["lights"][light_index]
    rec = ctx["receivers"]
    eta = ctx["eta"]
    sx, sz = (float(s) for s in water["size"])
    M = int(samples)
    rng = np.random.default_rng([int(seed), int(light_index)])
    emb = soup_scene(rec.tris)
    dA = (sx / M) * (sz / M)
    counts = {"hit": 0, "deposited": 0, "next": 0}  # next: the first chunk not yet added to out
    ready = {}  # chunk -> its splats, waiting for the chunks before it
    held = {}  # thread -> the arrays of its last chunk
    summing = threading.Lock()
    rows_per = max(1, CHUNK // M)
    turns = _Turns()

    def chunk(k):
        i0 = k * rows_per
        i1 = min(M, i0 + rows_per)
        ii, jj = np.meshgrid(np.arange(i0, i1), np.arange(M), indexing="ij")
        with turns.of("rng", k):  # the generator's draws in chunk order
            u = rng.random(ii.shape)
            v = rng.random(ii.shape)
        x = (-sx / 2.0 + (jj + u) * (sx / M)).ravel()
        z = (-sz / 2.0 + (ii + v) * (sz / M)).ravel()
        y = wave_height(water, x, z)
        hx, hz = wave_gradient(water, x, z)
        p = np.stack([x, y, z], axis=1)
        nt = np.stack([-hx, np.ones_like(hx), -hz], axis=1)  # normal scaled by the patch area ratio
        inc, e_perp = incident_directions(light, p)
        flux = e_perp * np.maximum(-np.einsum("ij,ij->i", inc, nt), 0.0) * dA
        t = np.empty_like(inc)
        tir = np.empty(len(inc), dtype=np.bool_)
        refract_rows(np.ascontiguousarray(inc), np.ascontiguousarray(surface_normals(water, x, z)), float(eta), t,
                      tir)
        ok = (flux > 0) & ~tir & (t[:, 1] < 0)
        if not ok.any():
            deposit(k, 0, [])
            return
        p, t, flux = p[ok], t[ok], flux[ok]
        prim, tfar, _, _ = nearest_hits(emb, p, t)
        prim = prim.astype(np.int64)
        hit = prim >= 0
        n_hit = int(hit.sum())
        dist = tfar.astype(np.float64)
        deposit(k, n_hit, _splats(ctx, p, t, flux, prim, hit, dist))
        # Keep this chunk's arrays until the thread's next chunk has made its own: freed all at
        # once, its ~100 MB of temporaries let glibc give the heap back to the system, and the
        # next chunk page-faults it all in again (measured: 6x the page faults, +50 % time).
        held[threading.get_ident()] = dict(locals())

    def deposit(k, n_hit, splats):
        """Add chunk k's splats to the maps in chunk order (whoever completes the sequence adds)."""
        with summing:
            ready[k] = (n_hit, splats)
            while counts["next"] in ready:
                n_hit, splats = ready.pop(counts["next"])
                counts["hit"] += n_hit
                for r, acc, n_seen in splats:
                    out[r] += acc
                    counts["deposited"] += n_seen
                counts["next"] += 1

    def chunks(k0, k1):
        try:
            for k in range(k0, k1):
                chunk(k)
        except _Abandoned:
            raise
        except BaseException as e:
            turns.fail(e)
            raise

    try:
        run_chunks(chunks, -(-M // rows_per), 1)
    except _Abandoned:
        raise turns.error from None
    finally:
        held.clear()  # now (the arrays refer back to `held`: a cycle the collector would free later)
    return {"photons": M * M, "hit": counts["hit"], "deposited": counts["deposited"]}

