"""The volumetric porting rules of docs/oracle.md ("Porting rules: volumetric"), written down as plain
Python/NumPy from the docs alone: `photons`, `march` (deposits, extinction, receivers), `smooth`, `view`.

Used by tests/volumetric/test_volumetric_porting.py, which runs it on small scenes and asserts that it
reproduces the oracle's stage buffers, so the documented rules are tested. Every function is plain
Python on float64 scalars and NumPy arrays (a port's shader code, one photon or pixel at a time).
"""
import math

import numpy as np


# ----------------------------------------------------------------------------- shared helpers
def cell(u, n):
    """The voxel of a voxel coordinate u = (x - lo) * (1 / h): floor, clamped to 0 .. n - 1 (NaN -> 0)."""
    if not u > 0.0:
        return 0
    c = int(u)
    return c if c < n - 1 else n - 1


def sample(field, lo, ih, x):
    """Trilinear (n, gx, gy, gz) at world point x: float32 values, float64 weights and sums."""
    idx, frac = [], []
    for a in range(3):
        na = field.shape[a]
        u = (x[a] - lo[a]) * ih[a] - 0.5
        if not u >= 0.0:
            c, f = 0, 0.0
        elif u >= na - 1:
            c, f = na - 2, 1.0
        else:
            c = int(u)
            f = u - c
        idx.append(c)
        frac.append(f)
    out = [0.0, 0.0, 0.0, 0.0]
    for di in range(2):
        wx = frac[0] if di else 1.0 - frac[0]
        for dj in range(2):
            wy = frac[1] if dj else 1.0 - frac[1]
            for dk in range(2):
                w = wx * wy * (frac[2] if dk else 1.0 - frac[2])
                for c in range(4):
                    out[c] += w * float(field[idx[0] + di, idx[1] + dj, idx[2] + dk, c])
    return out


def euler(x, v, g, ds):
    """Eqs. 4-5: x1 = x + (ds / n) v, v1 = v + ds grad n."""
    s = ds / g[0]
    return ([x[a] + s * v[a] for a in range(3)], [v[a] + ds * g[1 + a] for a in range(3)])


def segment_exit(lo, hi, x, x1):
    """Fraction s in [0, 1] of x -> x1 inside the box."""
    s = 1.0
    for a in range(3):
        d = x1[a] - x[a]
        if x1[a] > hi[a] and d > 0.0:
            s = min(s, (hi[a] - x[a]) / d)
        elif x1[a] < lo[a] and d < 0.0:
            s = min(s, (lo[a] - x[a]) / d)
    return max(s, 0.0)


def half_contrast(field, outside_ior):
    """(n_half, side) from the float32 extremes of n."""
    lo, hi = float(field[..., 0].min()), float(field[..., 0].max())
    far = hi if abs(hi - outside_ior) >= abs(lo - outside_ior) else lo
    if far == outside_ior:
        return math.inf, 1.0
    return outside_ior + 0.5 * (far - outside_ior), (1.0 if far > outside_ior else -1.0)


# ----------------------------------------------------------------------------- photons
def slab(o, d, lo, hi):
    """(t_in, t_out) of one ray and a box; t_in = inf for a miss. 1/0 = +-inf; a NaN t0 (0 * inf: the
    ray lies in the lower face's plane) makes that axis (-inf, inf), a NaN t1 (the upper face's) a miss:
    the box is half-open, [lo, hi)."""
    tin, tout = -math.inf, math.inf
    for a in range(3):
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.float64(1.0) / np.float64(d[a])
            t0 = float((lo[a] - o[a]) * inv)
            t1 = float((hi[a] - o[a]) * inv)
        if t0 != t0:
            l, h = -math.inf, math.inf
        elif t1 != t1:                                # NaN propagates (np.minimum): no entry
            return math.inf, math.nan
        else:
            l, h = min(t0, t1), max(t0, t1)
        tin, tout = max(tin, l), min(tout, h)
    tin = max(tin, 0.0)
    return (tin if tout > tin else math.inf), tout


def directional_texels(d, lo, hi, M):
    """Texel ray origins (M*M, 3) and the texel side of a directional light's window on the box."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    a = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    pa, pc = corners @ e1, corners @ e2
    side = max(np.ptp(pa), np.ptp(pc)) * (1 + 1e-9)
    ca, cc = 0.5 * (pa.min() + pa.max()), 0.5 * (pc.min() + pc.max())
    dmin = float((corners @ d).min()) - 1.0
    s = (np.arange(M) + 0.5) / M - 0.5
    org = np.empty((M * M, 3))
    for r in range(M):
        for q in range(M):
            A, C = ca + s[q] * side, cc - s[r] * side
            org[r * M + q] = [A * e1[c] + C * e2[c] + dmin * d[c] for c in range(3)]
    return org, d, side / M


def occupied_box(ior, lo, hi, h, outside_ior, grow):
    """The volume input's proxy: voxels with |n - outside_ior| >= 1e-6, grown, clipped to the box."""
    occ = np.abs(ior - outside_ior) >= 1e-6
    blo, bhi = np.empty(3), np.empty(3)
    for a in range(3):
        ax = np.flatnonzero(occ.any(axis=tuple(c for c in range(3) if c != a)))
        blo[a] = max(lo[a] + (ax[0] - grow) * h[a], lo[a])
        bhi[a] = min(lo[a] + (ax[-1] + 1 + grow) * h[a], hi[a])
    return blo, bhi


def photons(ior, lo, hi, light_dir, radiance, M, outside_ior=1.0, grow=6.0):
    """`photons` for one directional light on a `volume` input (proxy: the occupied box)."""
    N = np.array(ior.shape)
    h = (hi - lo) / N
    h2 = float(np.prod(h)) ** (2.0 / 3.0)
    plo, phi = occupied_box(ior, lo, hi, h, outside_ior, grow)
    org, d, texel = directional_texels(light_dir, lo, hi, M)
    L = np.asarray(radiance, float) * texel ** 2 / h2
    pos, dirs, rad = [], [], []
    for o in org:
        t = slab(o, d, plo, phi)[0]
        if t < math.inf:
            pos.append(np.minimum(np.maximum(o + t * d, lo), hi))
            dirs.append(d)
            rad.append(L)
    return np.array(pos).reshape(-1, 3), np.array(dirs).reshape(-1, 3), np.array(rad).reshape(-1, 3)


# ----------------------------------------------------------------------------- march
def kappa_of(ior_shape, scattering, absorption):
    """kappa (nx, ny, nz, 3) float32 from the knobs: float32(float64(float32(sigma)) + absorption)."""
    sig = np.broadcast_to(np.asarray(scattering, float), (3,)).astype(np.float32)
    k = (sig.astype(np.float64) + np.broadcast_to(np.asarray(absorption, float), (3,))).astype(np.float32)
    return np.broadcast_to(k, tuple(ior_shape) + (3,))


def entry_point(pos, d, lo, hi):
    """Where the texel ray entered the box: pos - t d, t the exit parameter of (pos, -d) (0 if not finite)."""
    t = math.inf
    for a in range(3):
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.float64(1.0) / np.float64(-d[a])
            t0 = float((lo[a] - pos[a]) * inv)
            t1 = float((hi[a] - pos[a]) * inv)
        t = min(t, math.inf if t0 != t0 else max(t0, t1))
    t = max(t, 0.0) if math.isfinite(t) else 0.0
    return [pos[a] - t * d[a] for a in range(3)]


def walk(a, b, lo, ih, N, clamp):
    """Amanatides-Woo from a to b in voxel coordinates u = (p - lo) * ih: [(i, j, k, t0, t1)], lv."""
    u0 = [(a[c] - lo[c]) * ih[c] for c in range(3)]
    du = [(b[c] - lo[c]) * ih[c] - u0[c] for c in range(3)]
    lv = math.sqrt(du[0] ** 2 + du[1] ** 2 + du[2] ** 2)
    out = []
    if not lv > 0.0:
        return out, lv
    v = [cell(u0[c], N[c]) for c in range(3)]
    st = [1 if du[c] > 0 else -1 for c in range(3)]
    tm = [((v[c] + (1 if du[c] > 0 else 0)) - u0[c]) / du[c] if du[c] != 0.0 else math.inf for c in range(3)]
    dt = [abs(1.0 / du[c]) if du[c] != 0.0 else math.inf for c in range(3)]
    t = 0.0
    for _ in range(sum(N) + 3):
        tn = min(tm[0], min(tm[1], min(tm[2], 1.0)))
        if tn - t > 0.0:
            out.append((v[0], v[1], v[2], t, tn))
        if tn >= 1.0:
            break
        c = 0 if (tm[0] <= tm[1] and tm[0] <= tm[2]) else (1 if tm[1] <= tm[2] else 2)
        v[c] += st[c]
        tm[c] += dt[c]
        if clamp:
            v[c] = min(max(v[c], 0), N[c] - 1)
        elif v[c] < 0 or v[c] >= N[c]:
            break
        t = tn
    return out, lv


def skipped_transmittance(entry, pos, kappa, lo, ih, N):
    """exp(-sum kappa * world length) per channel along entry -> pos (walk clamped to the grid)."""
    L = math.sqrt(sum((pos[c] - entry[c]) ** 2 for c in range(3)))
    tau = [0.0, 0.0, 0.0]
    if L > 0.0:
        for i, j, k, t0, t1 in walk(entry, pos, lo, ih, N, True)[0]:
            for c in range(3):
                tau[c] += float(kappa[i, j, k, c]) * ((t1 - t0) * L)
    return [math.exp(-tau[c]) for c in range(3)]


def deposit(dep, a, e, L0, L1, lo, ih, N, no_length=False):
    """Add (L0 + (L1 - L0) tm)(t1 - t0) lv per voxel of a -> e (RGB) and dir * sum(RGB) to dep[..., 3:]."""
    seg = math.sqrt(sum((e[c] - a[c]) ** 2 for c in range(3)))
    d = [(e[c] - a[c]) / seg for c in range(3)]
    cells, lv = walk(a, e, lo, ih, N, False)
    if no_length:
        lv = 1.0
    for i, j, k, t0, t1 in cells:
        tm = 0.5 * (t0 + t1)
        rgb = [(L0[c] * lv + (L1[c] - L0[c]) * lv * tm) * (t1 - t0) for c in range(3)]
        s = rgb[0] + rgb[1] + rgb[2]
        for c in range(3):
            dep[i, j, k, c] += rgb[c]
            dep[i, j, k, 3 + c] += d[c] * s
    return dep


def axis_distance(x, u, lo, h, ih, n, L):
    if u == 0.0:
        return math.inf
    U = (x - lo) * ih
    c = int(U) if U > 0.0 else 0
    b0 = (c >> L) << L
    if u > 0.0:
        return (min(b0 + (1 << L), n) - U) * h / u
    return (b0 - U) * h / u


def moller_trumbore(tri, x, d, tmax):
    """Smallest t in (0, tmax] where x + t d meets the triangle (two-sided), inf if none."""
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    p = np.cross(d, e2)
    det = float(e1 @ p)
    if det == 0.0 or det != det:
        return math.inf
    inv = 1.0 / det
    tv = np.asarray(x) - tri[0]
    u = float(tv @ p) * inv
    if u < 0.0 or u > 1.0:
        return math.inf
    q = np.cross(tv, e1)
    w = float(np.asarray(d) @ q) * inv
    if w < 0.0 or u + w > 1.0:
        return math.inf
    t = float(e2 @ q) * inv
    return t if 0.0 < t <= tmax else math.inf


def first_receiver(tris, x, d, tmax):
    """(t, triangle) of the nearest receiver triangle on x + t d, t in (0, tmax]; (inf, -1) if none."""
    best, bq = math.inf, -1
    for q, tri in enumerate(tris):
        t = moller_trumbore(tri, x, d, tmax)
        if t < best:
            best, bq = t, q
    return best, bq


def march(field, kappa, level, step_max, lo, hi, pos, dirs, rad, *, ds_min=1.0, min_radiance=1e-3,
          stop_fraction=1e-3, outside_ior=1.0, entry=True, receivers=None, record=0, bugs=()):
    """`march` (stepping paper, euler): (deposit (N..., 6) float64, exit_pos, exit_dir, status, hit_pos,
    hit_tri, hit_trans, touched, steps, paths). ``receivers``: (T, 3, 3) triangles, receiver order.
    ``bugs``: porters' errors the docs warn about, for the tests: "full_step_exit" (exit_dir from the
    whole step's v1), "no_length" (deposits not weighted by the length in voxels), "no_extinction"."""
    N = field.shape[:3]
    h = (hi - lo) / np.array(N)
    ih = 1.0 / h
    hmin = float(h.min())
    P = len(pos)
    max_steps = int(math.ceil(8 * max(N) / ds_min)) + 16
    n_half, side = half_contrast(field, outside_ior)
    tris = np.zeros((0, 3, 3)) if receivers is None else np.asarray(receivers, float)
    dep = np.zeros(tuple(N) + (6,))
    exit_pos = np.full((P, 3), np.nan)
    exit_dir = np.full((P, 3), np.nan)
    hit_pos = np.full((P, 3), np.nan)
    hit_tri = np.full(P, -1)
    hit_trans = np.full((P, 3), np.nan)
    status = np.zeros(P, np.int8)
    touched = np.zeros(P, bool)
    steps_of = np.zeros(P, np.int64)
    segments = []                                     # per photon: the deposit calls, for the stopping rule
    paths = np.full((P, record + 1, 3), np.nan)
    for p in range(P):
        x = list(pos[p])
        pre = skipped_transmittance(entry_point(pos[p], dirs[p], lo, hi), pos[p], kappa, lo, ih, N) \
            if entry else [1.0, 1.0, 1.0]
        Lc = [rad[p, c] * pre[c] for c in range(3)]
        thr = min_radiance * max(Lc)
        tr = list(pre)
        n0 = sample(field, lo, ih, x)[0]
        v = [n0 * dirs[p, c] for c in range(3)]
        steps, st, segs = 0, 0, []
        paths[p, 0] = x
        while True:
            if steps >= max_steps:
                st = 2
                break
            i, j, k = (cell((x[c] - lo[c]) * ih[c], N[c]) for c in range(3))
            g = sample(field, lo, ih, x)
            n = g[0]
            if side * (n - n_half) > 0.0:
                touched[p] = True
            vn = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
            if not (vn > 1e-12 * n) or not (n > 0.0):
                st = 4
                break
            ivn = 1.0 / vn                            # times the reciprocal (the viewing pass divides)
            u = [v[c] * ivn for c in range(3)]
            Lv = int(level[i, j, k])
            ds = max(min(axis_distance(x[c], u[c], lo[c], h[c], ih[c], N[c], Lv) for c in range(3)), 0.0)
            ds = max(ds + 1e-4 * hmin, ds_min * hmin)
            ds = min(ds, float(step_max[i, j, k]) * hmin)
            x1, v1 = euler(x, v, g, ds)
            if not all(math.isfinite(q) for q in x1 + v1):
                st = 4
                break
            s = segment_exit(lo, hi, x, x1)
            hq = -1
            if len(tris):
                th, hq = first_receiver(tris, x, np.subtract(x1, x), s)
                if hq >= 0:
                    s = th
            e = [x[c] + s * (x1[c] - x[c]) for c in range(3)]
            seg = math.sqrt(sum((e[c] - x[c]) ** 2 for c in range(3)))
            a = [math.exp(-float(kappa[i, j, k, c]) * seg) for c in range(3)]
            if "no_extinction" in bugs:
                a = [1.0, 1.0, 1.0]
            L1 = [Lc[c] * a[c] for c in range(3)]
            tr = [tr[c] * a[c] for c in range(3)]
            if seg > 0.0:
                segs.append((steps, list(x), e, list(Lc), L1))
            steps += 1
            if steps <= record:
                paths[p, steps] = e
            if hq >= 0:
                st = 5
                hit_pos[p], hit_tri[p], hit_trans[p] = e, hq, tr
                break
            if s < 1.0:
                st = 1
                if s > 0.0 and "full_step_exit" not in bugs:
                    v1 = euler(x, v, g, s * ds)[1]
                nv = math.sqrt(sum(q * q for q in v1))
                exit_pos[p] = e
                exit_dir[p] = [q / nv for q in v1]
                hit_trans[p] = tr
                break
            x, v, Lc = x1, v1, L1
            if max(Lc) < thr:
                st = 3
                break
        status[p], steps_of[p] = st, steps
        segments.append(segs)
    cut = None
    if stop_fraction and P:
        kk = int(math.ceil(stop_fraction * P)) - 1
        cut = int(np.sort(steps_of)[::-1][max(kk, 0)])
        late = steps_of > cut
        status[late] = 2
        exit_pos[late] = exit_dir[late] = hit_pos[late] = np.nan
        hit_tri[late] = -1
    for p in range(P):
        for q, x, e, L0, L1 in segments[p]:
            if cut is None or q < cut:
                deposit(dep, x, e, L0, L1, lo, ih, N, "no_length" in bugs)
    if cut is not None:
        steps_of = np.minimum(steps_of, cut)
    if len(tris):                                     # exited photons go on straight to a receiver outside
        reach = 1e6 * (1.0 + max(np.abs(lo).max(), 0) + np.abs(hi).max())
        for p in np.flatnonzero(status == 1):
            t, q = first_receiver(tris, exit_pos[p], exit_dir[p], reach)
            if q >= 0:
                hit_pos[p], hit_tri[p] = exit_pos[p] + t * exit_dir[p], q
    return dict(deposit=dep, exit_pos=exit_pos, exit_dir=exit_dir, status=status, hit_pos=hit_pos,
                hit_tri=hit_tri, hit_trans=hit_trans, touched=touched, steps=steps_of, paths=paths)


# ----------------------------------------------------------------------------- smooth
def smooth(dep):
    """[1/4, 1/2, 1/4] along x, y, z (edges clamped); radiance float32, unit direction float32."""
    a = dep.astype(np.float64)
    for ax in range(3):
        lo = np.concatenate([a.take([0], ax), a.take(range(a.shape[ax] - 1), ax)], ax)
        hi = np.concatenate([a.take(range(1, a.shape[ax]), ax), a.take([-1], ax)], ax)
        a = a * 0.5 + (lo + hi) * 0.25             # scipy's symmetric order: centre, then the pair
    nrm = np.sqrt(a[..., 3] ** 2 + a[..., 4] ** 2 + a[..., 5] ** 2)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        dirn = np.where(nrm > 0, a[..., 3:] / nrm, 0.0)
    return a[..., :3].astype(np.float32), dirn.astype(np.float32)


# ----------------------------------------------------------------------------- view
def hg(cos_t, g):
    """Henyey-Greenstein; cos_t = photon direction . (towards the camera); g > 0 scatters forward."""
    d = 1.0 + g * g - 2.0 * g * cos_t
    return (1.0 - g * g) / (4.0 * math.pi * d * math.sqrt(d))


def view(field, view_step_max, radiance, direction, sigma, kappa, lo, hi, origins, dirs, env,
         phase_g=0.0, outside_ior=1.0, bugs=()):
    """`view` (euler): per ray (exit_pos, exit_dir, status, hit, interfaces, path_length, image float32).
    ``env(dirs)`` -> float32 RGB (black for NaN). ``bugs``: "shade_ray_dir" (status 0 shaded along the
    written exit_dir = ray_dir), "hg_sign" (cos taken with +u, towards the light's continuation)."""
    N = field.shape[:3]
    h = (hi - lo) / np.array(N)
    ih = 1.0 / h
    ds = float(h.min())
    n_half, side = half_contrast(field, outside_ior)
    sL = (radiance * np.broadcast_to(sigma, radiance.shape).astype(np.float32)).astype(np.float32)
    R = len(origins)
    out = dict(exit_pos=np.full((R, 3), np.nan), exit_dir=np.array(dirs, float), status=np.zeros(R, np.int8),
               hit=np.zeros(R, bool), interfaces=np.zeros(R, np.int16), path_length=np.zeros(R))
    shade_dir = np.array(dirs, float)
    color, T = np.zeros((R, 3)), np.ones((R, 3))
    for r in range(R):
        t_in = slab(origins[r], dirs[r], lo, hi)[0]
        if not t_in < math.inf:
            continue                                  # status 0, exit_dir = ray_dir, environment(ray_dir)
        x = [origins[r][c] + t_in * dirs[r][c] for c in range(3)]
        n = sample(field, lo, ih, x)[0]
        v = [n * dirs[r][c] for c in range(3)]
        inside = side * (n - n_half) > 0.0            # the sampled n at the entry point
        met, cross, plen, st = inside, 0, 0.0, 2
        for _ in range(4 * sum(N)):
            i, j, k = (cell((x[c] - lo[c]) * ih[c], N[c]) for c in range(3))
            straight = view_step_max[i, j, k] == np.inf
            g = [float(field[i, j, k, 0]), 0.0, 0.0, 0.0] if straight else sample(field, lo, ih, x)
            now = side * (g[0] - n_half) > 0.0
            if now != inside:
                cross, inside, met = cross + 1, now, True
            vn = math.sqrt(sum(q * q for q in v))
            if not vn > 1e-12:
                st = 4
                break
            u = [q / vn for q in v]
            if straight:
                x1, v1 = [x[c] + ds * u[c] for c in range(3)], list(v)
            else:
                x1, v1 = euler(x, v, g, ds)
            s = segment_exit(lo, hi, x, x1)
            seg = s * ds if straight else s * math.sqrt(sum((x1[c] - x[c]) ** 2 for c in range(3)))
            if np.any(sL[i, j, k] != 0):
                cos_t = -float(sum(float(direction[i, j, k, c]) * u[c] for c in range(3)))
                if "hg_sign" in bugs:
                    cos_t = -cos_t
                ph = hg(cos_t, phase_g) if phase_g != 0.0 else 1.0 / (4.0 * math.pi)
                color[r] += T[r] * sL[i, j, k].astype(np.float64) * ph * seg
            for c in range(3):
                kc = float(kappa[i, j, k, c])
                if kc != 0.0:
                    T[r, c] *= math.exp(-kc * seg)
            if inside:
                plen += seg
            if s < 1.0:
                st = 1
                if not straight and s > 0.0:
                    v1 = euler(x, v, g, s * ds)[1]
                nv = math.sqrt(sum(q * q for q in v1))
                out["exit_pos"][r] = [x[c] + s * (x1[c] - x[c]) for c in range(3)]
                shade_dir[r] = [q / nv for q in v1]   # status 0 and 1: the bent direction at the box exit
                break
            x, v = x1, v1
        st = st if (met or st != 1) else 0
        out["status"][r], out["hit"][r], out["interfaces"][r], out["path_length"][r] = st, met, cross, plen
        if st == 1:
            out["exit_dir"][r] = shade_dir[r]
        elif st == 0:
            out["exit_pos"][r] = np.nan               # written as a miss: NaN, exit_dir = ray_dir
            if "shade_ray_dir" in bugs:
                shade_dir[r] = dirs[r]
        else:
            out["exit_pos"][r] = out["exit_dir"][r] = shade_dir[r] = np.nan   # black environment
    env_rgb = env(shade_dir).astype(np.float64)
    out["image"] = (color + T * env_rgb).astype(np.float32)
    return out
