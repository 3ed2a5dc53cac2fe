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
field is not sampled), exactly as photons do.

Per-pixel ORACLE keys: ``exit_pos``/``exit_dir`` are where and in which
direction the viewing ray leaves the *volume box*; ``hit`` means the ray
met refractive material (``|n - outside| > 1/2`` of the volume's largest
contrast); ``interfaces`` counts crossings of that half-contrast level set,
``path_length`` the length travelled beyond it; ``status`` is 0 (did not
meet material), 1 (exited), 2 (stopped at the step limit) or 4 (lost: |v|
collapsed).

References
----------
.. [1] X. Sun et al., "Interactive Relighting of Dynamic Refractive
   Objects", ACM TOG 27(3), 2008, §4.5.
.. [2] L. G. Henyey, J. L. Greenstein, "Diffuse radiation in the Galaxy",
   Astrophysical Journal 93, 1941 (the phase function).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .march import _geometry, _integ_code, advance, sample_field, segment_exit, voxel_of

__all__ = ["view_volume", "hg_phase", "source_volume"]


@nb.njit(cache=True, inline="always")
def hg_phase(cos_t, g):
    """Henyey-Greenstein phase function, normalised over the sphere."""
    d = 1.0 + g * g - 2.0 * g * cos_t
    return (1.0 - g * g) / (4.0 * math.pi * d * math.sqrt(d))


def source_volume(radiance, direction, scattering, extinction):
    """Pack what a viewing ray reads per voxel: (sigma L, direction, kappa), (nx, ny, nz, 9) float32."""
    out = np.empty(radiance.shape[:3] + (9,), np.float32)
    out[..., 0:3] = radiance * scattering
    out[..., 3:6] = direction
    out[..., 6:9] = extinction
    return out


@nb.njit(cache=True, parallel=True)
def _view_kernel(field, src, smax, lo, hi, h, ih, hmin, org, dirs, t_in, integ, g, n_out, n_half, side,
                 max_steps, color, trans, exit_pos, exit_dir, hit, interfaces, path_len, status):
    nx, ny, nz = field.shape[0], field.shape[1], field.shape[2]
    for r in nb.prange(org.shape[0]):
        if not (t_in[r] < np.inf):
            continue
        x = org[r, 0] + t_in[r] * dirs[r, 0]
        y = org[r, 1] + t_in[r] * dirs[r, 1]
        z = org[r, 2] + t_in[r] * dirs[r, 2]
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
        plen = 0.0
        met = inside
        st = 2
        ds = hmin
        for _ in range(max_steps):
            i, j, k = voxel_of(lo, ih, nx, ny, nz, x, y, z)
            if smax[i, j, k] == np.inf:
                n = np.float64(field[i, j, k, 0])
                gx, gy, gz = 0.0, 0.0, 0.0
                const = True
            else:
                n, gx, gy, gz = sample_field(field, lo, ih, x, y, z)
                const = False
            now = side * (n - n_half) > 0.0
            if now != inside:
                crossings += 1
                inside = now
                met = True
            vn = math.sqrt(vx * vx + vy * vy + vz * vz)
            if not (vn > 1e-12):
                st = 4
                break
            ux, uy, uz = vx / vn, vy / vn, vz / vn
            if const:
                x1, y1, z1, vx1, vy1, vz1 = x + ds * ux, y + ds * uy, z + ds * uz, vx, vy, vz
            else:
                x1, y1, z1, vx1, vy1, vz1 = advance(field, lo, ih, integ, x, y, z, vx, vy, vz, n, gx, gy, gz, ds)
            if not (math.isfinite(x1) and math.isfinite(y1) and math.isfinite(z1)
                    and math.isfinite(vx1) and math.isfinite(vy1) and math.isfinite(vz1)):
                st = 4
                break
            s = segment_exit(lo, hi, x, y, z, x1, y1, z1)
            seg = s * math.sqrt((x1 - x) ** 2 + (y1 - y) ** 2 + (z1 - z) ** 2)
            # in-scattering of the voxel towards the camera (-u), attenuated so far
            sr, sg, sb = src[i, j, k, 0], src[i, j, k, 1], src[i, j, k, 2]
            if sr != 0.0 or sg != 0.0 or sb != 0.0:
                if g != 0.0:
                    ph = hg_phase(-(src[i, j, k, 3] * ux + src[i, j, k, 4] * uy + src[i, j, k, 5] * uz), g)
                else:
                    ph = 1.0 / (4.0 * math.pi)
                cr += tr * sr * ph * seg
                cg += tg * sg * ph * seg
                cb += tb * sb * ph * seg
            kr, kg, kb = src[i, j, k, 6], src[i, j, k, 7], src[i, j, k, 8]
            if kr != 0.0:
                tr *= math.exp(-kr * seg)
            if kg != 0.0:
                tg *= math.exp(-kg * seg)
            if kb != 0.0:
                tb *= math.exp(-kb * seg)
            if inside:
                plen += seg
            if s < 1.0:
                st = 1
                if not const and s > 0.0:  # the direction at the exit: redo the step over the part inside
                    vx1, vy1, vz1 = advance(field, lo, ih, integ, x, y, z, vx, vy, vz, n, gx, gy, gz, s * ds)[3:]
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
        path_len[r] = plen
        status[r] = st if met or st != 1 else 0


def view_volume(field, src, smax, bounds, origins, dirs, *, integrator="euler", phase_g=0.0,
                outside_ior=1.0, max_steps=0):
    """Trace viewing rays through the volume (§4.5).

    Parameters
    ----------
    field : (nx, ny, nz, 4) float32
        n and grad n.
    src : (nx, ny, nz, 9) float32
        :func:`source_volume`.
    smax : (nx, ny, nz) float32
        Octree maximum steps (``inf`` marks constant nodes).
    bounds : (2, 3)
    origins, dirs : (R, 3) float64
        Primary rays.
    integrator : {'euler', 'rk4'}
    phase_g : float
        Henyey-Greenstein asymmetry.
    outside_ior : float
    max_steps : int
        0 = ``4 * (nx + ny + nz)``.

    Returns
    -------
    dict
        ``inscatter`` (R, 3) and ``transmittance`` (R, 3), ``exit_pos``,
        ``exit_dir`` (R, 3; exit_dir = ray direction and exit_pos NaN where
        the ray missed the box), ``hit``, ``interfaces``, ``path_length``,
        ``status``.
    """
    from .photons import box_entry

    lo, hi, h, ih, shape_n, hmin = _geometry(bounds, field.shape)
    org = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
    R = len(org)
    t_in, _ = box_entry(org, d, np.stack([lo, hi]))
    nvals = field[..., 0]
    far = float(nvals.max()) if abs(float(nvals.max()) - outside_ior) >= abs(float(nvals.min()) - outside_ior) \
        else float(nvals.min())
    side = 1.0 if far >= outside_ior else -1.0
    n_half = 0.5 * (outside_ior + far) if far != outside_ior else np.inf * side
    if max_steps <= 0:
        max_steps = 4 * int(sum(field.shape[:3]))
    color = np.zeros((R, 3))
    trans = np.ones((R, 3))
    exit_pos = np.full((R, 3), np.nan)
    exit_dir = d.copy()
    hit = np.zeros(R, np.bool_)
    inter = np.zeros(R, np.int16)
    plen = np.zeros(R)
    status = np.zeros(R, np.int8)
    _view_kernel(np.ascontiguousarray(field), np.ascontiguousarray(src), np.ascontiguousarray(smax),
                 lo, hi, h, ih, hmin, org, d, t_in, _integ_code(integrator), float(phase_g), float(outside_ior),
                 float(n_half), side, int(max_steps), color, trans, exit_pos, exit_dir, hit, inter, plen, status)
    # the direction the environment is seen along (NaN, i.e. black, where the ray did not get out)
    last_dir = exit_dir.copy()
    stuck = (status == 2) | (status == 4)
    last_dir[stuck] = np.nan
    exit_pos[stuck] = np.nan
    exit_dir[stuck] = np.nan
    miss = status == 0
    exit_pos[miss] = np.nan
    exit_dir[miss] = d[miss]
    return {"inscatter": color, "transmittance": trans, "exit_pos": exit_pos, "exit_dir": exit_dir,
            "last_dir": last_dir, "hit": hit, "interfaces": inter, "path_length": plen, "status": status}
