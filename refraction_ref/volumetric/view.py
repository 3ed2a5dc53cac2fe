"""The viewing pass: curved viewing rays through the radiance volume (§4.5).

Every pixel's primary ray (the shared :class:`~refraction_ref.camera.Camera`)
is intersected with the volume box and, inside it, advanced with a fixed
step of one voxel by the same integrator as the photons (eqs. 4-5, or RK4).
At each step the in-scattered radiance of the voxel, ``sigma(x) p(theta)
L(x)``, is added, weighted by the transmittance so far and the step
length, and the transmittance is multiplied by ``exp(-kappa ds)``. ``p`` is
the Henyey-Greenstein phase function with asymmetry g, evaluated between
the voxel's mean photon direction and the direction towards the camera
(g = 0 is isotropic, ``1 / 4 pi``). When the ray leaves the box the
environment seen along its final direction is added, times the
transmittance.

Where the octree marks the index constant, the ray moves straight (the
field is not sampled), exactly as photons do; its direction is normalised
once per straight run and such a step's length is ds exactly, so that
``exp(-kappa ds)`` is computed once per run of equal kappa (grey
extinction: one exp for the three channels). The ray's entry into the
volume box is a slab test inside the kernel.

Per-pixel ORACLE keys: ``exit_pos``/``exit_dir`` are where and in which
direction the viewing ray leaves the *volume box*; ``hit`` means the ray
met refractive material (``|n - outside| > 1/2`` of the volume's largest
contrast); ``interfaces`` counts crossings of that half-contrast level set,
``path_length`` the length travelled beyond it; ``status`` (the codes of
:mod:`refraction_ref.status`) is ``MISSED`` (left the box without meeting
material, or missed the box), ``EXITED`` (met material and left the box),
``LIMIT`` (stopped at ``max_steps``) or ``LOST`` (|v| collapsed, or the
integrator produced a non-finite state).

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.5.
.. [2] L. G. Henyey, J. L. Greenstein, "Diffuse radiation in the Galaxy",
   Astrophysical Journal 93, 1941 (the phase function).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..status import EXITED, LIMIT, LOST, MISSED
from .extinction import transmit
from .grid import cell, sample_field, segment_exit, volume_box
from .integrate import advance, euler_step
from .knobs import view_knobs

__all__ = ["view_volume", "view_grid", "hg_phase", "source_volume", "box_entry_one", "ViewVolume", "ViewRays",
           "ViewControl", "ViewResults"]


@nb.njit(cache=True, inline="always")
def hg_phase(cos_t, g):
    """Henyey-Greenstein phase function, normalised over the sphere.

    Parameters
    ----------
    cos_t : float
        Cosine of the angle between the photon direction and the direction
        towards the camera.
    g : float
        Asymmetry, in (-1, 1); 0 is isotropic.

    Returns
    -------
    float
        Phase function value per steradian.

    References
    ----------
    Sun et al. (2008), §4.5 (in-scattering towards the viewer).
    """
    d = 1.0 + g * g - 2.0 * g * cos_t
    return (1.0 - g * g) / (4.0 * math.pi * d * math.sqrt(d))


def source_volume(radiance, direction, scattering, extinction):
    """Pack what a viewing ray reads per voxel: (sigma L, direction, kappa), (nx, ny, nz, 9) float32.

    The float32 product ``radiance * scattering`` as NumPy forms it, packed in parallel over x slabs
    (``scattering`` and ``extinction`` may be broadcast views).

    Parameters
    ----------
    radiance : (nx, ny, nz, 3) float32
        Smoothed radiance (:func:`~refraction_ref.volumetric.smooth.smooth_radiance`).
    direction : (nx, ny, nz, 3) float32
        Unit mean photon direction per voxel.
    scattering : array_like, broadcastable to (nx, ny, nz, 3)
        Scattering coefficient sigma (per scene unit).
    extinction : array_like, broadcastable to (nx, ny, nz, 3)
        Extinction coefficient kappa (per scene unit).

    Returns
    -------
    (nx, ny, nz, 9) float32
        ``sigma L``, direction and ``kappa`` per voxel.

    References
    ----------
    Sun et al. (2008), §4.5 and §5.1 (radiance storage read by the viewing pass).
    """
    shape = radiance.shape[:3] + (3,)
    out = np.empty(radiance.shape[:3] + (9,), np.float32)
    _pack_source(np.ascontiguousarray(radiance, dtype=np.float32), np.ascontiguousarray(direction, dtype=np.float32),
                 np.broadcast_to(np.asarray(scattering, dtype=np.float32), shape),
                 np.broadcast_to(np.asarray(extinction, dtype=np.float32), shape), out)
    return out


@nb.njit(cache=True, parallel=True)
def _pack_source(rad, dirn, sig, kap, out):
    nx, ny, nz = rad.shape[0], rad.shape[1], rad.shape[2]
    for i in nb.prange(nx):
        for j in range(ny):
            for k in range(nz):
                for c in range(3):
                    out[i, j, k, c] = rad[i, j, k, c] * sig[i, j, k, c]
                    out[i, j, k, 3 + c] = dirn[i, j, k, c]
                    out[i, j, k, 6 + c] = kap[i, j, k, c]


@nb.njit(cache=True, inline="always")
def _slab(o, d, lo, hi):
    """One axis of the slab test, as :func:`~refraction_ref.volumetric.photons.box_entry` (NaN: a miss)."""
    inv = 1.0 / d if d != 0.0 else math.copysign(np.inf, d)
    t0 = (lo - o) * inv
    t1 = (hi - o) * inv
    if math.isnan(t0):
        return -np.inf, np.inf
    if math.isnan(t1):
        return np.nan, np.nan
    return min(t0, t1), max(t0, t1)


@nb.njit(cache=True, inline="always")
def box_entry_one(lo, hi, ox, oy, oz, dx, dy, dz):
    """Entry parameter of one ray into the box (clamped at 0), ``inf`` when it misses.

    Parameters
    ----------
    lo, hi : (3,) float64
        Corners of the box.
    ox, oy, oz : float
        Ray origin.
    dx, dy, dz : float
        Ray direction.

    Returns
    -------
    float
        Ray parameter of the entry point.

    References
    ----------
    Sun et al. (2008), §4.5 (viewing rays entering the volume).
    """
    a0, b0 = _slab(ox, dx, lo[0], hi[0])
    a1, b1 = _slab(oy, dy, lo[1], hi[1])
    a2, b2 = _slab(oz, dz, lo[2], hi[2])
    t_in = max(max(a0, max(a1, a2)), 0.0)
    t_out = min(b0, min(b1, b2))
    if math.isnan(a0) or math.isnan(a1) or math.isnan(a2) or not (t_out > t_in):
        return np.inf
    return t_in


class ViewVolume(NamedTuple):
    """What a viewing ray reads: the index field, the source volume, the octree steps, the box (:func:`view_grid`)."""

    field: np.ndarray  # (nx, ny, nz, 4) float32: n and grad n
    src: np.ndarray  # (nx, ny, nz, 9) float32: :func:`source_volume`
    step_max: np.ndarray  # (nx, ny, nz) float32: maximum step in voxels (inf: constant node)
    lo: np.ndarray  # (3,) the box (grid.VolumeBox)
    hi: np.ndarray  # (3,)
    ih: np.ndarray  # (3,) 1 / voxel size
    hmin: float  # smallest voxel side: the step


class ViewRays(NamedTuple):
    """Primary rays, (R, 3) float64 each."""

    org: np.ndarray
    dirs: np.ndarray


class ViewControl(NamedTuple):
    """Integration, phase function and the material level set of one viewing pass."""

    integrator: int  # knobs.EULER or knobs.RK4
    g: float  # Henyey-Greenstein asymmetry
    n_half: float  # the half-contrast index level that counts as material (module docstring)
    side: float  # +1: material has n above n_half, -1: below
    max_steps: int


class ViewResults(NamedTuple):
    """Per-ray arrays the kernel fills (see :func:`view_volume`, Returns)."""

    color: np.ndarray  # (R, 3) in-scattered radiance
    trans: np.ndarray  # (R, 3) transmittance
    exit_pos: np.ndarray  # (R, 3)
    exit_dir: np.ndarray  # (R, 3)
    hit: np.ndarray  # (R,) bool
    interfaces: np.ndarray  # (R,) int16
    path_length: np.ndarray  # (R,)
    status: np.ndarray  # (R,) int8


@nb.njit(cache=True, inline="always")
def _in_scatter(src, i, j, k, u, g, seg, t, c):
    """Colour ``c`` plus the in-scattering of voxel (i, j, k) towards the camera over ``seg``, attenuated by ``t``.

    ``u`` is the ray's unit direction (the camera sees along ``-u``), ``g``
    the Henyey-Greenstein asymmetry (0: isotropic); ``t`` and ``c`` are RGB
    3-tuples. Returns the new colour.

    References
    ----------
    Sun et al. (2008), §4.5 (in-scattering along the viewing ray).
    """
    cr, cg, cb = c
    tr, tg, tb = t
    ux, uy, uz = u
    sr, sg, sb = src[i, j, k, 0], src[i, j, k, 1], src[i, j, k, 2]
    if sr != 0.0 or sg != 0.0 or sb != 0.0:
        if g != 0.0:
            ph = hg_phase(-(src[i, j, k, 3] * ux + src[i, j, k, 4] * uy + src[i, j, k, 5] * uz), g)
        else:
            ph = 1.0 / (4.0 * math.pi)
        cr += tr * sr * ph * seg
        cg += tg * sg * ph * seg
        cb += tb * sb * ph * seg
    return cr, cg, cb


@nb.njit(cache=True, parallel=True)
def _view_kernel(vol, rays, control, out):
    # the named tuples unpacked by name (a reordered field cannot swap two arguments), one field per
    # statement: numba's alias analysis follows ``a = out.a`` to the argument, but not
    # ``a, b, c, d = out.a, out.b, out.c, out.d`` (a tuple built and unpacked), and its dead-code
    # elimination would then drop the writes to such arrays inside the parallel loop; plain
    # names also keep the parallel loop's arguments as they were with positional arguments
    field = vol.field
    src = vol.src
    step_max = vol.step_max
    lo = vol.lo
    hi = vol.hi
    ih = vol.ih
    hmin = vol.hmin
    org = rays.org
    dirs = rays.dirs
    integrator = control.integrator
    g = control.g
    n_half = control.n_half
    side = control.side
    max_steps = control.max_steps
    color = out.color
    trans = out.trans
    exit_pos = out.exit_pos
    exit_dir = out.exit_dir
    hit = out.hit
    interfaces = out.interfaces
    path_length = out.path_length
    status = out.status
    nx, ny, nz = field.shape[0], field.shape[1], field.shape[2]
    lo0, lo1, lo2 = lo[0], lo[1], lo[2]
    ih0, ih1, ih2 = ih[0], ih[1], ih[2]
    for r in nb.prange(org.shape[0]):
        t_in = box_entry_one(lo, hi, org[r, 0], org[r, 1], org[r, 2], dirs[r, 0], dirs[r, 1], dirs[r, 2])
        if not (t_in < np.inf):
            continue
        x = org[r, 0] + t_in * dirs[r, 0]
        y = org[r, 1] + t_in * dirs[r, 1]
        z = org[r, 2] + t_in * dirs[r, 2]
        n = sample_field(field, lo, ih, x, y, z)[0]
        vx, vy, vz = n * dirs[r, 0], n * dirs[r, 1], n * dirs[r, 2]
        cr = 0.0
        cg = 0.0
        cb = 0.0
        tr = 1.0
        tg = 1.0
        tb = 1.0
        inside = side * (n - n_half) > 0.0
        crossings = 0
        travelled = 0.0
        met = inside
        st = LIMIT  # unless the ray exits or is lost within max_steps
        ds = hmin
        # the unit direction v / |v| is reused while v does not change (straight steps in constant nodes)
        ux, uy, uz = 0.0, 0.0, 0.0
        u_ok = False
        # exp(-kappa seg) is reused while kappa and seg do not change (grey, uniform media)
        ek, eseg, ea = -1.0, -1.0, 1.0
        for _ in range(max_steps):
            i = cell((x - lo0) * ih0, nx)
            j = cell((y - lo1) * ih1, ny)
            k = cell((z - lo2) * ih2, nz)
            const = step_max[i, j, k] == np.inf
            if const:
                n = np.float64(field[i, j, k, 0])
                gx, gy, gz = 0.0, 0.0, 0.0
            else:
                n, gx, gy, gz = sample_field(field, lo, ih, x, y, z)
            now = side * (n - n_half) > 0.0
            if now != inside:
                crossings += 1
                inside = now
                met = True
            if not u_ok:
                vn = math.sqrt(vx * vx + vy * vy + vz * vz)
                if not (vn > 1e-12):
                    st = LOST
                    break
                ux, uy, uz = vx / vn, vy / vn, vz / vn
                u_ok = True
            if const:
                x1, y1, z1, vx1, vy1, vz1 = x + ds * ux, y + ds * uy, z + ds * uz, vx, vy, vz
            elif integrator == 0:  # eqs. 4-5 inlined (a call passing arrays costs reference counting)
                x1, y1, z1, vx1, vy1, vz1 = euler_step((x, y, z), (vx, vy, vz), (n, gx, gy, gz), ds)
                u_ok = False
            else:
                x1, y1, z1, vx1, vy1, vz1 = advance(field, lo, ih, integrator, (x, y, z), (vx, vy, vz),
                                                    (n, gx, gy, gz), ds)
                u_ok = False
                if not (math.isfinite(x1) and math.isfinite(y1) and math.isfinite(z1)
                        and math.isfinite(vx1) and math.isfinite(vy1) and math.isfinite(vz1)):
                    st = LOST
                    break
            s = segment_exit(lo, hi, x, y, z, x1, y1, z1)
            if const:  # a straight step: its length is ds (the chord would only add rounding noise)
                seg = s * ds
            else:
                seg = s * math.sqrt((x1 - x) ** 2 + (y1 - y) ** 2 + (z1 - z) ** 2)
            # in-scattering of the voxel towards the camera (-u), attenuated so far
            cr, cg, cb = _in_scatter(src, i, j, k, (ux, uy, uz), g, seg, (tr, tg, tb), (cr, cg, cb))
            tr, tg, tb, ek, eseg, ea = transmit(src, i, j, k, seg, (tr, tg, tb), ek, eseg, ea)
            if inside:
                travelled += seg
            if s < 1.0:
                st = EXITED
                if not const and s > 0.0:  # the direction at the exit: redo the step over the part inside
                    vx1, vy1, vz1 = advance(field, lo, ih, integrator, (x, y, z), (vx, vy, vz), (n, gx, gy, gz),
                                            s * ds)[3:]
                v1 = math.sqrt(vx1 * vx1 + vy1 * vy1 + vz1 * vz1)
                exit_pos[r, 0] = x + s * (x1 - x)
                exit_pos[r, 1] = y + s * (y1 - y)
                exit_pos[r, 2] = z + s * (z1 - z)
                exit_dir[r, 0] = vx1 / v1
                exit_dir[r, 1] = vy1 / v1
                exit_dir[r, 2] = vz1 / v1
                break
            x, y, z, vx, vy, vz = x1, y1, z1, vx1, vy1, vz1
        color[r, 0] = cr
        color[r, 1] = cg
        color[r, 2] = cb
        trans[r, 0] = tr
        trans[r, 1] = tg
        trans[r, 2] = tb
        hit[r] = met
        interfaces[r] = crossings
        path_length[r] = travelled
        status[r] = st if met or st != EXITED else MISSED


def view_grid(field, source, step_max, bounds):
    """The :class:`ViewVolume` the viewing kernel reads, from the passes' volumes.

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and grad n (:func:`~refraction_ref.volumetric.gradient.gradient_field`).
    source : (nx, ny, nz, 9) float32
        :func:`source_volume`.
    step_max : (nx, ny, nz) float32
        Octree maximum steps of the dilated octree (``inf`` marks constant
        nodes; :func:`~refraction_ref.volumetric.knobs.octree_dilations`).
    bounds : (2, 3) array_like
        World-space corners of the volume.

    Returns
    -------
    ViewVolume

    References
    ----------
    Sun et al. (2008), §4.5 (the viewing pass reads the radiance volume).
    """
    box = volume_box(bounds, field.shape)
    return ViewVolume(np.ascontiguousarray(field), np.ascontiguousarray(source), np.ascontiguousarray(step_max),
                      box.lo, box.hi, box.ih, box.hmin)


def view_volume(volume, origins, dirs, knobs=None, *, outside_ior=1.0, n_range=None, max_steps=0):
    """Trace viewing rays through the volume (§4.5).

    Parameters
    ----------
    volume : ViewVolume
        The index field, source volume and octree steps (:func:`view_grid`).
    origins, dirs : (R, 3) float64
        Primary rays.
    knobs : ViewKnobs, optional
        Integrator and phase asymmetry
        (:func:`~refraction_ref.volumetric.knobs.view_knobs`; default: the
        declared defaults).
    outside_ior : float
        Index outside the objects (the material level set).
    n_range : (float, float), optional
        Minimum and maximum of the index (e.g. the octree's ``n_min``,
        ``n_max``), to save a pass over the volume.
    max_steps : int
        Step limit per ray; 0 = ``4 * (nx + ny + nz)``.

    Returns
    -------
    dict
        ``inscatter`` (R, 3) and ``transmittance`` (R, 3), ``exit_pos``,
        ``exit_dir`` (R, 3; exit_dir = ray direction and exit_pos NaN where
        the ray missed the box), ``hit``, ``interfaces``, ``path_length``,
        ``status``.

    References
    ----------
    Sun et al. (2008), §4.5, eqs. 4-6.
    """
    knobs = view_knobs() if knobs is None else knobs
    field = volume.field
    org = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
    R = len(org)
    if n_range is None:
        nmin, nmax = float(field[..., 0].min()), float(field[..., 0].max())
    else:  # as float32, like the field
        nmin, nmax = float(np.float32(n_range[0])), float(np.float32(n_range[1]))
    far = nmax if abs(nmax - outside_ior) >= abs(nmin - outside_ior) else nmin
    side = 1.0 if far >= outside_ior else -1.0
    n_half = 0.5 * (outside_ior + far) if far != outside_ior else np.inf * side
    if max_steps <= 0:
        max_steps = 4 * int(sum(field.shape[:3]))
    color = np.zeros((R, 3))
    trans = np.ones((R, 3))
    exit_pos = np.full((R, 3), np.nan)
    exit_dir = d.copy()
    hit = np.zeros(R, np.bool_)
    interfaces = np.zeros(R, np.int16)
    path_length = np.zeros(R)
    status = np.full(R, MISSED, np.int8)  # rays that miss the box keep it
    control = ViewControl(int(knobs.integrator), float(knobs.phase_g), float(n_half), side, int(max_steps))
    _view_kernel(volume, ViewRays(org, d), control,
                 ViewResults(color, trans, exit_pos, exit_dir, hit, interfaces, path_length, status))
    # the direction the environment is seen along (NaN, i.e. black, where the ray did not get out)
    last_dir = exit_dir.copy()
    stuck = (status == LIMIT) | (status == LOST)
    last_dir[stuck] = np.nan
    exit_pos[stuck] = np.nan
    exit_dir[stuck] = np.nan
    miss = status == MISSED
    exit_pos[miss] = np.nan
    exit_dir[miss] = d[miss]
    return {"inscatter": color, "transmittance": trans, "exit_pos": exit_pos, "exit_dir": exit_dir,
            "last_dir": last_dir, "hit": hit, "interfaces": interfaces, "path_length": path_length,
            "status": status}
