"""WebGPU caustic stages of the image-space method (Chaudhari 2008 §4.1): caustics mapping, in WGSL.

Written from ``docs/oracle.md`` ("Caustic stages (§4.1)") without reading the
package's source. The light's view reruns the eye passes of ``imagespace.py``
on the light's camera (``photon_trace``); then, one pipeline each:

``receiver_depth``  render pipeline: the receivers drawn from the eye, nearest fragment per pixel
                    (an ``atomicMin`` of the depth's bits, then of the triangle index among the
                    fragments at that depth: ties go to the lower triangle)
``receiver_hit``    compute, one invocation per exiting photon: Krüger's eye-space march, the photon's
                    line rasterized against the receivers' depth image, the secant at the first crossing
``splat``           compute, one invocation per photon: the bilinear splat into the receiver's caustic
                    map with float atomics (a compare-and-swap loop on the float's bits)
``gather``          compute: the separable Gaussian (rows, then columns) with mirrored borders, then the
                    lights summed
``caustic_final``   compute, one invocation per eye pixel: receivers lit directly (a shadow map: the
                    light's ``minmax`` pass) and by the caustic map, seen directly, through the
                    multi-layer trace's exit rays, or through one refraction at the front surface

The light cameras, the receivers' triangles and their map frames are set-up
arithmetic done on the host in float64, as a renderer builds its matrices.
"""
from __future__ import annotations

import struct
from types import SimpleNamespace

import numpy as np

#: planted bugs of the caustic stages: name -> (the pass that holds it, what a porter got wrong)
BUGS = {
    "splat_no_atomics": ("splat", "the splat's read-add-write of a map texel without atomics: deposits of "
                                  "photons landing in one texel at once are lost"),
    "caustic_half_texel": ("splat", "the caustic map half a texel off: the bilinear splat at (col, row) instead "
                                    "of (col - 0.5, row - 0.5) (texel corners taken for centres)"),
}

# ----------------------------------------------------------------------------- host set-up (float64)


def light_camera(V, light, N):
    """A light's camera fitted to the objects' bounding sphere ("The light's camera")."""
    c = (V.min(axis=0) + V.max(axis=0)) / 2.0
    r = max(float(np.sqrt(((V - c) ** 2).sum(axis=1).max())), 1e-9)
    if light["type"] == "directional":
        d = np.asarray(light["direction"], np.float64)
        d = d / np.linalg.norm(d)
        eye = c - d * (1.1 * r)
        sy = 2.0 * r * 1.02 / 2.0
        sx = sy * N / N
        near, far, ortho = 0.05 * r, 2.2 * r, True
    else:
        eye = np.asarray(light["position"], np.float64)
        dist = float(np.linalg.norm(c - eye))
        d = (c - eye) / dist
        fov = float(np.degrees(2.0 * np.arcsin(min(r * 1.02 / dist, 0.999))))
        sy = float(np.tan(np.radians(fov) / 2.0))
        sx = float(sy * N / N)
        near, far, ortho = max(dist - 1.05 * r, 1e-4 * dist), dist + 1.05 * r, False
    up = np.array([0.0, 0.0, 1.0]) if abs(d[1]) > 0.9 else np.array([0.0, 1.0, 0.0])
    f = c - eye
    f = f / np.linalg.norm(f)
    rt = np.cross(f, up)
    rt = rt / np.linalg.norm(rt)
    B = np.stack([rt, np.cross(rt, f), -f])
    return SimpleNamespace(W=N, H=N, sx=sx, sy=sy, eye=eye, B=B, near=near, far=far, ortho=ortho)


def plane_triangles(rc):
    """A built-in ``plane`` receiver's world triangles (2, 3, 3)."""
    if rc.get("mesh", "plane") != "plane" or rc.get("fit") is not None:
        raise NotImplementedError("the WebGPU backend's receivers are built-in planes without fit")
    a, b = rc.get("size") or [4.0, 4.0]
    v = np.array([[-a / 2, 0, -b / 2], [a / 2, 0, -b / 2], [a / 2, 0, b / 2], [-a / 2, 0, b / 2]], np.float64)
    t = rc["transform"]
    ax, ay, az = np.radians(np.asarray(t["rotate"], np.float64))
    Rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    Ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    Rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx * float(t["scale"])
    v = v[:, 0:1] * R[:, 0] + v[:, 1:2] * R[:, 1] + v[:, 2:3] * R[:, 2] + np.asarray(t["translate"], np.float64)
    return v[np.array([[0, 2, 1], [0, 3, 2]])]


def face_normals(tris):
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def map_box(Vr, light):
    """Receiver r's caustic-map box in the first light's axes: (centre, U, V, Wa, w, h, d)."""
    c = (Vr.min(axis=0) + Vr.max(axis=0)) / 2.0
    T0 = (np.asarray(light["direction"], np.float64) if light["type"] == "directional"
          else c - np.asarray(light["position"], np.float64))
    T0 = T0 / np.linalg.norm(T0)
    V = -T0
    V = V / np.linalg.norm(V)
    N_ = np.array([0.0, 0.0, 1.0]) if abs(V[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    U = np.cross(V, N_)
    U /= np.linalg.norm(U)
    Wa = np.cross(U, V)
    Wa /= np.linalg.norm(Wa)
    R = np.stack([U, V, Wa])
    loc = Vr[:, 0:1] * R[:, 0] + Vr[:, 1:2] * R[:, 1] + Vr[:, 2:3] * R[:, 2]
    lo, hi = loc.min(axis=0), loc.max(axis=0)
    centre = ((lo + hi) / 2.0) @ R
    ext = np.maximum(hi - lo, 1e-6 * max(float((hi - lo).max()), 1e-12))
    return centre, U, V, Wa, ext[0], ext[1], ext[2]


def map_frame(box):
    centre, U, V, Wa, w, h, d = box
    return np.stack([centre - w / 2.0 * U - d / 2.0 * Wa + h / 2.0 * V, w * U, d * Wa, V])


# ----------------------------------------------------------------------------- WGSL
_C_VEC = ("absorption",)
_C_F32 = ("Hcf", "Wcf", "ior", "a0", "lsx", "lsy", "Nf", "pinf", "nan", "tie")
_C_U32 = ("Hc", "Wc", "nl", "nr", "light", "recv", "np", "lortho", "gr", "nt", "single_eta_dummy")


def c_decl():
    lines = [f"  {n}: vec4f," for n in _C_VEC] + [f"  {n}: f32," for n in _C_F32] + [f"  {n}: u32," for n in _C_U32]
    return "struct C {\n" + "\n".join(lines) + "\n}\n"


def c_bytes(vals):
    out = b""
    for n in _C_VEC:
        v = np.zeros(4, np.float32)
        x = np.asarray(vals.get(n, 0.0), np.float64).ravel()
        v[:len(x)] = x
        out += v.tobytes()
    for n in _C_F32:
        out += struct.pack("<f", float(vals.get(n, 0.0)))
    for n in _C_U32:
        out += struct.pack("<I", int(vals.get(n, 0)))
    return out


# the receivers drawn from the eye: a triangle's index rides along as a flat attribute
RECV_RASTER = """
@group(0) @binding(1) var<storage, read_write> dmin: array<atomic<u32>>;
@group(0) @binding(2) var<storage, read_write> tmin: array<atomic<u32>>;
struct VO { @builtin(position) pos: vec4f, @location(0) @interpolate(linear) q: f32,
            @location(1) @interpolate(flat) tri: u32 }
@vertex
fn vs(@location(0) x: vec3f, @location(1) tri: u32) -> VO {
  let v = x.x * p.c0.xyz + x.y * p.c1.xyz + x.z * p.c2.xyz + p.t.xyz;
  let d = -v.z;
  var o: VO;
  let col = (v.x / (d * p.sx) * 0.5 + 0.5) * p.Wf;
  let row = (0.5 - v.y / (d * p.sy) * 0.5) * p.Hf;
  o.pos = vec4f(round(col * 256.0) / (128.0 * p.Wf) - 1.0, 1.0 - round(row * 256.0) / (128.0 * p.Hf), 0.5, 1.0);
  o.q = 1.0 / d;
  o.tri = tri;
  return o;
}
fn pixel(pos: vec4f) -> u32 { return u32(pos.y) * p.W + u32(pos.x); }
@fragment
fn fs_depth(i: VO) -> @location(0) vec4f {
  atomicMin(&dmin[pixel(i.pos)], bitcast<u32>(1.0 / i.q));
  return vec4f(0.0);
}
@fragment
fn fs_tri(i: VO) -> @location(0) vec4f {
  if (atomicLoad(&dmin[pixel(i.pos)]) == bitcast<u32>(1.0 / i.q)) { atomicMin(&tmin[pixel(i.pos)], i.tri); }
  return vec4f(0.0);
}
"""

# Krüger's eye-space march of one ray (world origin o, direction dir) against the receivers' depth image
MARCH = """
@group(0) @binding(2) var<storage, read> rdepth: array<f32>;
@group(0) @binding(3) var<storage, read> rtri: array<i32>;
fn clip_plane(a0: f32, a1: f32, t: vec2f) -> vec2f {
  if (a1 == 0.0) {
    if (a0 > 0.0) { return vec2f(1.0, 0.0); }
    return t;
  }
  let tc = -a0 / a1;
  if (a1 > 0.0) { return vec2f(t.x, min(t.y, tc)); }
  return vec2f(max(t.x, tc), t.y);
}
fn eproject(P: vec3f) -> vec2f {            // the eye's project: (row, col)
  let inv = 1.0 / -P.z;
  return vec2f(0.5 * p.Hf - P.y * inv * (0.5 * p.Hf / p.sy), P.x * inv * (0.5 * p.Wf / p.sx) + 0.5 * p.Wf);
}
struct Hit { t: f32, i: i32, j: i32, ok: bool }
fn march(ow: vec3f, dw: vec3f) -> Hit {
  let o = ow.x * p.c0.xyz + ow.y * p.c1.xyz + ow.z * p.c2.xyz + p.t.xyz;
  let v = dw.x * p.c0.xyz + dw.y * p.c1.xyz + dw.z * p.c2.xyz;
  var h: Hit;
  h.ok = false; h.t = c.nan; h.i = -1; h.j = -1;
  var tt = vec2f(0.0, 1e30);
  tt = clip_plane(p.near + o.z, v.z, tt);
  tt = clip_plane(-o.z - p.far, -v.z, tt);
  tt = clip_plane(o.x + p.sx * o.z, v.x + p.sx * v.z, tt);
  tt = clip_plane(-o.x + p.sx * o.z, -v.x + p.sx * v.z, tt);
  tt = clip_plane(o.y + p.sy * o.z, v.y + p.sy * v.z, tt);
  tt = clip_plane(-o.y + p.sy * o.z, -v.y + p.sy * v.z, tt);
  let t0 = tt.x;
  let t1 = tt.y;
  if (!(t1 > t0) || t1 >= 1e29) { return h; }
  let PA = o + t0 * v;
  let PB = o + t1 * v;
  let a = eproject(PA);
  let b = eproject(PB);
  let dA = -PA.z;
  let dB = -PB.z;
  let n = min(max(u32(ceil(max(abs(b.y - a.y), abs(b.x - a.x)))) + 1u, 2u), 65536u);
  var gap_prev = -c.pinf;
  var t_prev = t0;
  var rd_prev = dA;
  for (var m = 0u; m <= n; m++) {
    let u = f32(m) / f32(n);
    let s = (u / dB) / ((1.0 - u) / dA + u / dB);
    let t = t0 + s * (t1 - t0);
    let P = o + t * v;
    let rc = eproject(P);
    let rd = -P.z;
    let i = min(max(i32(floor(rc.x)), 0), i32(p.H) - 1);
    let j = min(max(i32(floor(rc.y)), 0), i32(p.W) - 1);
    let sd = rdepth[u32(i) * p.W + u32(j)];
    var gap = -c.pinf;
    if (isfin(sd)) { gap = rd - sd; }
    if (gap >= 0.0 && gap_prev < 0.0 && gap <= abs(rd - rd_prev) + 0.01 * sd) {
      var f = 1.0;
      if (isfin(gap_prev)) { f = -gap_prev / (gap - gap_prev); }
      h.t = t_prev + f * (t - t_prev);
      h.i = i; h.j = j; h.ok = true;
      return h;
    }
    gap_prev = gap;
    t_prev = t;
    rd_prev = rd;
  }
  return h;
}
"""

RECEIVER_HIT = """
@group(0) @binding(1) var<uniform> c: C;
@group(0) @binding(4) var<storage, read> ph_pos: array<vec4f>;
@group(0) @binding(5) var<storage, read> ph_dir: array<vec4f>;
@group(0) @binding(6) var<storage, read_write> hit_pos: array<vec4f>;
@group(0) @binding(7) var<storage, read_write> hit_face: array<i32>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) g: vec3u) {
  let k = g.x + g.y * 65535u * 64u;
  if (k >= c.np) { return; }
  let o = ph_pos[k].xyz;
  let d = ph_dir[k].xyz;
  let h = march(o, d);
  if (h.ok) {
    hit_pos[k] = vec4f(o + h.t * d, 0.0);
    hit_face[k] = rtri[u32(h.i) * p.W + u32(h.j)];
  } else {
    hit_pos[k] = vec4f(c.nan, c.nan, c.nan, 0.0);
    hit_face[k] = -1;
  }
}
"""

SPLAT = """
@group(0) @binding(1) var<uniform> c: C;
struct Rcv { centre: vec4f, U: vec4f, Wa: vec4f, V: vec4f, ext: vec4f, albedo: vec4f }
@group(0) @binding(2) var<storage, read> rcv: array<Rcv>;
@group(0) @binding(3) var<storage, read> tnorm: array<vec4f>;      // .w: the owner receiver
@group(0) @binding(4) var<storage, read> hit_pos: array<vec4f>;
@group(0) @binding(5) var<storage, read> hit_face: array<i32>;
@group(0) @binding(6) var<storage, read> ph_tex: array<vec4f>;     // (texel i, texel j, path length, -)
@group(0) @binding(7) var<storage, read_write> mapb: array<atomic<u32>>;
fn add_f32(idx: u32, x: f32) {
  if (BUG_NO_ATOMICS) {
    let old = atomicLoad(&mapb[idx]);
    atomicStore(&mapb[idx], bitcast<u32>(bitcast<f32>(old) + x));
    return;
  }
  var old = atomicLoad(&mapb[idx]);
  loop {
    let r = atomicCompareExchangeWeak(&mapb[idx], old, bitcast<u32>(bitcast<f32>(old) + x));
    if (r.exchanged) { break; }
    old = r.old_value;
  }
}
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) g: vec3u) {
  let k = g.x + g.y * 65535u * 64u;
  if (k >= c.np) { return; }
  let face = hit_face[k];
  if (face < 0) { return; }
  let tn = tnorm[u32(face)];
  if (u32(tn.w) != c.recv) { return; }
  let R = rcv[c.recv];
  // the photon's flux: its texel's area on the light's window (a point light: its solid angle), times
  // the Beer-Lambert transmittance of its path inside
  let pt = ph_tex[k];
  var f0 = c.a0;
  if (c.lortho == 0u) {
    let x = ((pt.y + 0.5) / c.Nf * 2.0 - 1.0) * c.lsx;
    let y = (1.0 - (pt.x + 0.5) / c.Nf * 2.0) * c.lsy;
    f0 = c.a0 / pow(1.0 + x * x + y * y, 1.5);
  }
  let flux = f0 * exp(-c.absorption.xyz * (pt.z * c.ior));
  let cosv = abs(tn.x * R.V.x + tn.y * R.V.y + tn.z * R.V.z);
  let val = flux * (cosv / ((R.ext.x / c.Wcf) * (R.ext.z / c.Hcf)));
  let q = hit_pos[k].xyz - R.centre.xyz;
  let col = ((q.x * R.U.x + q.y * R.U.y + q.z * R.U.z) / R.ext.x + 0.5) * c.Wcf;
  let row = ((q.x * R.Wa.x + q.y * R.Wa.y + q.z * R.Wa.z) / R.ext.z + 0.5) * c.Hcf;
  let off = select(0.5, 0.0, BUG_HALF_TEXEL);
  let x = clamp(col - off, -1.0, c.Wcf);
  let y = clamp(row - off, -1.0, c.Hcf);
  if (!isfin(x) || !isfin(y)) { return; }
  let j0 = i32(floor(x));
  let i0 = i32(floor(y));
  let fx = x - floor(x);
  let fy = y - floor(y);
  for (var di = 0; di < 2; di++) {
    for (var dj = 0; dj < 2; dj++) {
      let wy = select(1.0 - fy, fy, di == 1);
      let wx = select(1.0 - fx, fx, dj == 1);
      let w = wy * wx;
      if (w == 0.0) { continue; }
      let ii = clamp(i0 + di, 0, i32(c.Hc) - 1);
      let jj = clamp(j0 + dj, 0, i32(c.Wc) - 1);
      let base = (u32(ii) * c.Wc + u32(jj)) * 3u;
      add_f32(base, w * val.x);
      add_f32(base + 1u, w * val.y);
      add_f32(base + 2u, w * val.z);
    }
  }
}
"""

# the Gaussian along one axis with mirrored borders: axis 0 runs along u (columns), 1 along v (rows)
GATHER = """
@group(0) @binding(1) var<uniform> c: C;
@group(0) @binding(2) var<storage, read> src: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;
@group(0) @binding(4) var<storage, read> wts: array<f32>;
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) g: vec3u) {
  if (g.x >= c.Wc || g.y >= c.Hc) { return; }
  let along_u = c.light == 0u;                // reused as the axis switch
  var Nn: i32;
  var i: i32;
  if (along_u) { Nn = i32(c.Wc); i = i32(g.x); } else { Nn = i32(c.Hc); i = i32(g.y); }
  let r = i32(c.gr);
  var s = vec3f(0.0);
  for (var t = -r; t <= r; t++) {
    let w = wts[u32(t + r)];
    for (var k = 0; k < 3; k++) {
      var sidx: i32;
      if (k == 0) { sidx = i - t; } else if (k == 1) { sidx = -1 - i - t; } else { sidx = 2 * Nn - 1 - i - t; }
      if (sidx >= 0 && sidx < Nn) {
        var pix: u32;
        if (along_u) { pix = g.y * c.Wc + u32(sidx); } else { pix = u32(sidx) * c.Wc + g.x; }
        s = s + w * vec3f(src[pix * 3u], src[pix * 3u + 1u], src[pix * 3u + 2u]);
      }
    }
  }
  let o = (g.y * c.Wc + g.x) * 3u;
  dst[o] = s.x;
  dst[o + 1u] = s.y;
  dst[o + 2u] = s.z;
}
"""

# the lights summed: caustic_map (mean of the channels, unit lights), caustic_rgb (times radiance), splat
ACCUM = """
@group(0) @binding(1) var<uniform> c: C;
@group(0) @binding(2) var<storage, read> gathered: array<f32>;
@group(0) @binding(3) var<storage, read> splatted: array<f32>;
@group(0) @binding(4) var<storage, read_write> cmap: array<f32>;
@group(0) @binding(5) var<storage, read_write> crgb: array<f32>;
@group(0) @binding(6) var<storage, read_write> smap: array<f32>;
@group(0) @binding(7) var<storage, read> rad: array<vec4f>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) g: vec3u) {
  let k = g.x;
  if (k >= c.Hc * c.Wc) { return; }
  let m = vec3f(gathered[3u * k], gathered[3u * k + 1u], gathered[3u * k + 2u]);
  let sp = vec3f(splatted[3u * k], splatted[3u * k + 1u], splatted[3u * k + 2u]);
  cmap[k] = cmap[k] + (m.x + m.y + m.z) / 3.0;
  smap[k] = smap[k] + (sp.x + sp.y + sp.z) / 3.0;
  let rl = rad[c.light].xyz;
  crgb[3u * k] = crgb[3u * k] + m.x * rl.x;
  crgb[3u * k + 1u] = crgb[3u * k + 1u] + m.y * rl.y;
  crgb[3u * k + 2u] = crgb[3u * k + 2u] + m.z * rl.z;
  if (c.light + 1u == c.nl) {                 // the last light: NaN and inf written as 0
    if (!isfin(cmap[k])) { cmap[k] = 0.0; }
    for (var ch = 0u; ch < 3u; ch++) { if (!isfin(crgb[3u * k + ch])) { crgb[3u * k + ch] = 0.0; } }
  }
}
"""

FINAL = """
@group(0) @binding(1) var<uniform> c: C;
struct Rcv { centre: vec4f, U: vec4f, Wa: vec4f, V: vec4f, ext: vec4f, albedo: vec4f }
struct Lt { dir: vec4f, pos: vec4f, rad: vec4f, lc0: vec4f, lc1: vec4f, lc2: vec4f, lt: vec4f, cam: vec4f }
struct TraceOut { exit_pos: vec4f, exit_dir: vec4f, last_dir: vec4f, plen: f32, nint: i32, status: i32, pad: i32 }
@group(0) @binding(4) var<storage, read> rcv: array<Rcv>;
@group(0) @binding(5) var<storage, read> tnorm: array<vec4f>;
@group(0) @binding(6) var<storage, read> lts: array<Lt>;
@group(0) @binding(7) var<storage, read> lzmin: array<f32>;          // every light's N x N min depth
@group(0) @binding(8) var<storage, read> crgb: array<f32>;           // every receiver's Hc x Wc x 3 map
@group(0) @binding(9) var<storage, read> zfront: array<f32>;
@group(0) @binding(10) var<storage, read> rdir: array<vec4f>;
@group(0) @binding(11) var<storage, read> vdir: array<vec4f>;
@group(0) @binding(12) var<storage, read> tr: array<TraceOut>;
@group(0) @binding(13) var<storage, read> nfront: array<vec4f>;
@group(0) @binding(14) var<storage, read_write> img_full: array<vec4f>;
@group(0) @binding(15) var<storage, read_write> img_single: array<vec4f>;
@group(0) @binding(16) var<storage, read_write> shadow: array<u32>;   // per light, H x W
@group(0) @binding(17) var<storage, read_write> smargin: array<f32>;
const PI: f32 = 3.14159265358979;

fn environment(L: vec3f) -> vec3f {
  if (!(isfin(L.x) && isfin(L.y) && isfin(L.z))) { return vec3f(0.0); }
  if (p.env_const != 0u) { return p.col0.xyz; }
  let u = atan2(L.x, -L.z) / (2.0 * PI) + 0.5;
  let v = acos(clamp(L.y, -1.0, 1.0)) / PI;
  let k = (i32(floor(u * p.tiles)) + i32(floor(v * (p.tiles / 2.0)))) % 2;
  return select(p.col0.xyz, p.col1.xyz, k == 1);
}

// the shadow map's margin dl - (zmin + bias) at light-screen (col, row); -inf where no depth is compared
fn margin_at(l: u32, col: f32, row: f32, dl: f32) -> f32 {
  let N = lts[l].cam.w;
  if (!(isfin(col) && isfin(row) && col >= 0.0 && col < N && row >= 0.0 && row < N && dl > 0.0)) {
    return -c.pinf;
  }
  let n = u32(N);
  let z = lzmin[l * n * n + u32(floor(row)) * n + u32(floor(col))];
  if (!isfin(z)) { return -c.pinf; }
  return dl - (z + lts[l].lt.w);
}
struct LS { col: f32, row: f32, dl: f32 }
fn light_screen(l: u32, P: vec3f) -> LS {
  let L = lts[l];
  let pv = P.x * L.lc0.xyz + P.y * L.lc1.xyz + P.z * L.lc2.xyz + L.lt.xyz;
  var o: LS;
  o.dl = -pv.z;
  var s = 1.0;
  if (L.cam.z == 0.0) { s = o.dl; }
  o.col = (pv.x / (s * L.cam.x) * 0.5 + 0.5) * L.cam.w;
  o.row = (0.5 - pv.y / (s * L.cam.y) * 0.5) * L.cam.w;
  return o;
}

fn shade_receiver(P: vec3f, face: i32, dir: vec3f) -> vec3f {
  let tn = tnorm[u32(face)];
  var n = tn.xyz;
  if ((n.x * dir.x + n.z * dir.z) + n.y * dir.y > 0.0) { n = -n; }
  var acc = vec3f(0.0);
  for (var l = 0u; l < c.nl; l++) {
    let lt = lts[l];
    var L: vec3f;
    var fall = 1.0;
    if (lt.dir.w == 0.0) {
      L = lt.dir.xyz;
    } else {
      let q = P - lt.pos.xyz;
      let r2 = max(dot(q, q), 1e-30);
      L = q / sqrt(r2);
      fall = 1.0 / r2;
    }
    var cs = -((n.x * L.x + n.z * L.z) + n.y * L.y);
    if (!(cs > 0.0)) { cs = 0.0; }
    var vis = 0.0;
    if (cs > 0.0) {
      let ls = light_screen(l, P);
      vis = select(1.0, 0.0, margin_at(l, ls.col, ls.row, ls.dl) > 0.0);
    }
    acc = acc + lt.rad.xyz * (cs * fall * vis);
  }
  let r = u32(tn.w);
  let R = rcv[r];
  let q = P - R.centre.xyz;
  let col = ((q.x * R.U.x + q.y * R.U.y + q.z * R.U.z) / R.ext.x + 0.5) * c.Wcf;
  let row = ((q.x * R.Wa.x + q.y * R.Wa.y + q.z * R.Wa.z) / R.ext.z + 0.5) * c.Hcf;
  var x = clamp(col - 0.5, 0.0, c.Wcf - 1.0);
  var y = clamp(row - 0.5, 0.0, c.Hcf - 1.0);
  if (!isfin(x)) { x = 0.0; }
  if (!isfin(y)) { y = 0.0; }
  let j0 = min(u32(floor(x)), c.Wc - 1u);
  let i0 = min(u32(floor(y)), c.Hc - 1u);
  let j1 = min(j0 + 1u, c.Wc - 1u);
  let i1 = min(i0 + 1u, c.Hc - 1u);
  let fx = x - f32(j0);
  let fy = y - f32(i0);
  let base = r * c.Hc * c.Wc;
  let e00 = vec3f(crgb[(base + i0 * c.Wc + j0) * 3u], crgb[(base + i0 * c.Wc + j0) * 3u + 1u], crgb[(base + i0 * c.Wc + j0) * 3u + 2u]);
  let e01 = vec3f(crgb[(base + i0 * c.Wc + j1) * 3u], crgb[(base + i0 * c.Wc + j1) * 3u + 1u], crgb[(base + i0 * c.Wc + j1) * 3u + 2u]);
  let e10 = vec3f(crgb[(base + i1 * c.Wc + j0) * 3u], crgb[(base + i1 * c.Wc + j0) * 3u + 1u], crgb[(base + i1 * c.Wc + j0) * 3u + 2u]);
  let e11 = vec3f(crgb[(base + i1 * c.Wc + j1) * 3u], crgb[(base + i1 * c.Wc + j1) * 3u + 1u], crgb[(base + i1 * c.Wc + j1) * 3u + 2u]);
  acc = acc + (1.0 - fy) * ((1.0 - fx) * e00 + fx * e01) + fy * ((1.0 - fx) * e10 + fx * e11);
  return R.albedo.xyz * acc;
}

fn colour(o: vec3f, d: vec3f) -> vec3f {
  let h = march(o, d);
  if (h.ok) {
    let face = rtri[u32(h.i) * p.W + u32(h.j)];
    if (face >= 0) { return shade_receiver(o + h.t * d, face, d); }
  }
  return environment(d);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) g: vec3u) {
  let idx = g.x;
  if (idx >= p.W * p.H) { return; }
  let i = idx / p.W;
  let j = idx % p.W;
  let zf = zfront[idx];
  let dep = rdepth[idx];
  var obj = isfin(zf);
  var rec = isfin(dep) && (!obj || dep < zf);
  obj = obj && !rec;
  let rd = rdir[idx].xyz;
  for (var l = 0u; l < c.nl; l++) {
    shadow[l * p.W * p.H + idx] = 0u;
    smargin[l * p.W * p.H + idx] = c.nan;
  }
  var full = vec3f(0.0);
  var single = vec3f(0.0);
  if (rec) {
    let f = -p.b.xyz;
    let P = p.eye.xyz + rd * (dep / (rd.x * f.x + rd.y * f.y + rd.z * f.z));
    let face = rtri[idx];
    full = shade_receiver(P, face, rd);
    single = full;
    // the shadow buffers: every light's test at every receiver pixel, with texel-edge ties set to 0
    for (var l = 0u; l < c.nl; l++) {
      let ls = light_screen(l, P);
      var m = margin_at(l, ls.col, ls.row, ls.dl);
      let sh = m > 0.0;
      for (var k = 0; k < 4; k++) {
        var dc = 0.0;
        var dr = 0.0;
        if (k == 0) { dc = c.tie; } else if (k == 1) { dc = -c.tie; } else if (k == 2) { dr = c.tie; } else { dr = -c.tie; }
        if ((margin_at(l, ls.col + dc, ls.row + dr, ls.dl) > 0.0) != sh) { m = 0.0; }
      }
      shadow[l * p.W * p.H + idx] = select(1u, 2u, sh);
      smargin[l * p.W * p.H + idx] = m;
    }
  } else if (obj) {
    let t = tr[idx];
    if (t.status == 1) {
      full = colour(t.exit_pos.xyz, t.exit_dir.xyz);
    } else {
      full = environment(t.last_dir.xyz);
    }
    full = full * exp(-p.absorption.xyz * (t.plen * p.ior));
    // the thesis's final pass: one refraction at the front surface (normal of zfront by the normals rule)
    let n0 = nfront[idx].xyz;
    let v = vdir[idx].xyz;
    let eta = p.oior / p.ior;
    var n = n0;
    var cc = -(v.x * n.x + v.y * n.y + v.z * n.z);
    if (cc < 0.0) { n = -n; cc = -cc; }
    let k = 1.0 - eta * eta * (1.0 - cc * cc);
    var w: vec3f;
    if (k < 0.0) { w = v + 2.0 * cc * n; } else { w = eta * v + (eta * cc - sqrt(max(k, 0.0))) * n; }
    w = w * (1.0 / sqrt(w.x * w.x + w.y * w.y + w.z * w.z));
    if (!(isfin(w.x) && isfin(w.y) && isfin(w.z))) { w = v; }
    let x = ((f32(j) + 0.5) / p.Wf * 2.0 - 1.0) * p.sx;
    let y = (1.0 - (f32(i) + 0.5) / p.Hf * 2.0) * p.sy;
    single = colour(to_world_pt(vec3f(x * zf, y * zf, -zf)), to_world_dir(w));
  } else {
    full = environment(rd);
    single = full;
  }
  img_full[idx] = vec4f(full, 0.0);
  img_single[idx] = vec4f(single, 0.0);
}
"""


def cshader(isp, body, bugs=()):
    bugs = set(bugs)
    consts = (f"const BUG_NO_ATOMICS: bool = {str('splat_no_atomics' in bugs).lower()};\n"
              f"const BUG_HALF_TEXEL: bool = {str('caustic_half_texel' in bugs).lower()};\n")
    return isp.shader("", ()) + c_decl() + consts + body


# ----------------------------------------------------------------------------- driver
def run_caustics(isp, data, view, k, mat, V, F, eye_out, st, bugs=(), timer=None):
    """The caustic stages after the eye passes; returns the result keys (stage buffers and finals)."""
    gpu = isp.gpu
    timer = timer or gpu.Timer(enabled=False)
    H, W = view.H, view.W
    n = H * W
    lights, receivers = data["lights"], data["receivers"]
    Hc = Wc = int(data["caustics"]["map_size"])
    g = int(data["caustics"]["gather"])
    N = int(k.photons)
    res = {}
    stage = lambda s, b, a: res.__setitem__(f"stage.{s}.{b}", a)

    # receivers: the soup and each receiver's map box in the first light's axes (host, float64)
    with timer("receivers"):
        tris, owner, boxes = [], [], []
        for r, rc in enumerate(receivers):
            t = plane_triangles(rc)
            tris.append(t)
            owner += [r] * len(t)
            boxes.append(map_box(t.reshape(-1, 3), lights[0]))
        tris = np.concatenate(tris)
        owner = np.asarray(owner)
        tn = face_normals(tris)
        for r, box in enumerate(boxes):
            fr = map_frame(box)
            stage("receivers", f"frame_{r}", fr)
            stage("gather", f"caustic_frame_{r}", fr)
            res[f"caustic_frame_{r}"] = fr
        rcv = np.zeros((len(boxes), 6, 4), np.float32)
        for r, (centre, U, Vv, Wa, w, h, d) in enumerate(boxes):
            rcv[r, 0, :3], rcv[r, 1, :3], rcv[r, 2, :3], rcv[r, 3, :3] = centre, U, Wa, Vv
            rcv[r, 4, :3] = (w, h, d)
            rcv[r, 5, :3] = receivers[r].get("albedo", [0.8, 0.8, 0.8])
        rcv_b = gpu.storage(rcv)
        tnb = np.zeros((len(tris), 4), np.float32)
        tnb[:, :3] = tn
        tnb[:, 3] = owner
        tn_b = gpu.storage(tnb)

    with timer("receiver_depth"):
        verts = tris.reshape(-1, 3).astype(np.float32)
        ids = np.repeat(np.arange(len(tris), dtype=np.uint32), 3)
        dmin = gpu.storage(np.full(n, 0x7F800000, np.uint32))
        tmin = gpu.storage(np.full(n, 0xFFFFFFFF, np.uint32))
        src = isp.shader(RECV_RASTER, bugs)
        layout = [(12, [("float32x3", 0, 0)]), (4, [("uint32", 0, 1)])]
        vbs = [gpu.vertex(verts), gpu.vertex(ids)]
        gpu.draw(gpu.render(src, layout, "vs", "fs_depth"), [eye_out.P, dmin, None], vbs, len(verts), (W, H))
        gpu.draw(gpu.render(src, layout, "vs", "fs_tri"), [eye_out.P, dmin, tmin], vbs, len(verts), (W, H))
        rdepth = gpu.read(dmin, np.float32, (H, W))
        rtri = gpu.read(tmin, np.uint32, (H, W)).astype(np.int64)
        rtri[rtri == 0xFFFFFFFF] = -1
        stage("receiver_depth", "depth", rdepth.astype(np.float64))
        stage("receiver_depth", "triangle", rtri)
        rtri_b = gpu.storage(rtri.astype(np.int32))

    # per light: the light's passes (photon_trace), the march (receiver_hit), the splat
    Vf, Ff = V.astype(np.float32), F.astype(np.uint32)
    lk = SimpleNamespace(**vars(k))
    lk.record = 0
    maps = [[None] * len(receivers) for _ in lights]
    splats = [[None] * len(receivers) for _ in lights]
    lzmins, lts = [], []
    for li, light in enumerate(lights):
        lc = light_camera(V, light, N)
        cam = np.stack([lc.eye, lc.B[0], lc.B[1], lc.B[2], [lc.sx, lc.sy, 1.0 if lc.ortho else 0.0],
                        [lc.near, lc.far, N]])
        stage("photon_trace", f"camera_{li}", cam)
        with timer("photon_trace"):
            lo = isp.run_view(lc, lk, mat, Vf, Ff, bugs, None, env=None, record=0, tag=f"light{li}")
            lst = isp.read_view(lo, lk, bool(k.peel_all))
            stage("photon_trace", f"ldi_{li}", lst["peel"]["ldi"])
            lzmins.append(lst["minmax"]["zmin"].astype(np.float32))
            tr = lst["trace"]
            sel = np.flatnonzero(tr["status"].ravel() == 1)          # texel order (row-major)
            ex_pos = tr["exit_pos"].reshape(-1, 3)[sel]
            ex_dir = tr["exit_dir"].reshape(-1, 3)[sel]
            stage("photon_trace", f"exit_pos_{li}", ex_pos)
            stage("photon_trace", f"exit_dir_{li}", ex_dir)
            P_ = len(sel)
            pos4 = np.zeros((max(P_, 1), 4), np.float32)
            dir4 = np.zeros((max(P_, 1), 4), np.float32)
            tex4 = np.zeros((max(P_, 1), 4), np.float32)
            pos4[:P_, :3], dir4[:P_, :3] = ex_pos, ex_dir
            tex4[:P_, 0], tex4[:P_, 1] = np.divmod(sel, N)
            tex4[:P_, 2] = tr["path_length"].ravel()[sel]
            pos_b, dir_b, tex_b = gpu.storage(pos4), gpu.storage(dir4), gpu.storage(tex4)
        cvals = dict(Hcf=Hc, Wcf=Wc, Hc=Hc, Wc=Wc, ior=mat["ior"], absorption=mat["absorption"],
                     a0=(2.0 * lc.sx / N) * (2.0 * lc.sy / N), lsx=lc.sx, lsy=lc.sy, Nf=N, pinf=np.inf, nan=np.nan,
                     tie=5e-3, nl=len(lights), nr=len(receivers), light=li, np=P_, lortho=int(lc.ortho),
                     gr=0, nt=len(tris))
        with timer("receiver_hit"):
            hp = gpu.storage(nbytes=16 * max(P_, 1))
            hf = gpu.storage(nbytes=4 * max(P_, 1))
            Cb = gpu.uniform(c_bytes(cvals))
            gpu.dispatch(gpu.compute(cshader(isp, MARCH + RECEIVER_HIT, bugs)),
                         [eye_out.P, Cb, dmin, rtri_b, pos_b, dir_b, hp, hf], gpu.groups_for(P_))
            hit_pos = gpu.read(hp, np.float32, (max(P_, 1), 4))[:P_, :3].astype(np.float64)
            hit_face = gpu.read(hf, np.int32, (max(P_, 1),))[:P_].astype(np.int64)
            stage("receiver_hit", f"hit_pos_{li}", hit_pos)
            stage("receiver_hit", f"hit_face_{li}", hit_face)
        with timer("splat"):
            for r in range(len(receivers)):
                Cb = gpu.uniform(c_bytes(dict(cvals, recv=r)))
                mb = gpu.storage(nbytes=4 * Hc * Wc * 3)
                gpu.dispatch(gpu.compute(cshader(isp, SPLAT, bugs)), [None, Cb, rcv_b, tn_b, hp, hf, tex_b, mb],
                             gpu.groups_for(P_))
                splats[li][r] = mb
        lt = np.zeros((8, 4), np.float32)
        if light["type"] == "directional":
            d = np.asarray(light["direction"], np.float64)
            lt[0, :3] = d / np.linalg.norm(d)
        else:
            lt[0, 3] = 1.0
            lt[1, :3] = light["position"]
        lt[2, :3] = light.get("radiance", [1, 1, 1])
        lt[3, :3], lt[4, :3], lt[5, :3] = lc.B[:, 0], lc.B[:, 1], lc.B[:, 2]
        lt[6, :3] = -lc.eye @ lc.B.T
        lt[6, 3] = 1e-3 * (lc.far - lc.near) + 2.0 * (2.0 * lc.sy / N)       # the shadow bias
        lt[7] = (lc.sx, lc.sy, 1.0 if lc.ortho else 0.0, N)
        lts.append(lt)

    # gather: each light's map filtered (rows, then columns), the lights summed
    with timer("gather"):
        r_ = g // 2
        if r_ > 0:
            x = np.arange(-r_, r_ + 1, dtype=np.float64)
            w = np.exp(-0.5 * (x / ((g - 1) / 6.0)) ** 2)
            w = w / w.sum()
            if min(Hc, Wc) - 1 < r_:
                r2 = max(min(Hc, Wc) - 1, 0)
                w = w[r_ - r2:r_ + r2 + 1]
                w = w / w.sum()
                r_ = r2
        else:
            w = np.ones(1)
        wb = gpu.storage(w.astype(np.float32))
        rad = np.zeros((len(lights), 4), np.float32)
        for li, light in enumerate(lights):
            rad[li, :3] = light.get("radiance", [1, 1, 1])
        rad_b = gpu.storage(rad)
        crgb_all = []
        for r in range(len(receivers)):
            cmap = gpu.storage(nbytes=4 * Hc * Wc)
            crgb = gpu.storage(nbytes=12 * Hc * Wc)
            smap = gpu.storage(nbytes=4 * Hc * Wc)
            for li in range(len(lights)):
                base = dict(Hcf=Hc, Wcf=Wc, Hc=Hc, Wc=Wc, gr=r_, nl=len(lights), pinf=np.inf, nan=np.nan)
                src = splats[li][r]
                if r_ > 0:
                    tmp = gpu.storage(nbytes=12 * Hc * Wc)
                    out = gpu.storage(nbytes=12 * Hc * Wc)
                    gsrc = gpu.compute(cshader(isp, GATHER, bugs))
                    gpu.dispatch(gsrc, [None, gpu.uniform(c_bytes(dict(base, light=0))), src, tmp, wb],
                                 (-(-Wc // 8), -(-Hc // 8)))
                    gpu.dispatch(gsrc, [None, gpu.uniform(c_bytes(dict(base, light=1))), tmp, out, wb],
                                 (-(-Wc // 8), -(-Hc // 8)))
                else:
                    out = src
                gpu.dispatch(gpu.compute(cshader(isp, ACCUM, bugs)),
                             [None, gpu.uniform(c_bytes(dict(base, light=li))), out, src, cmap, crgb, smap,
                              rad_b], gpu.groups_for(Hc * Wc))
            m = gpu.read(cmap, np.float32, (Hc, Wc))
            rgb = gpu.read(crgb, np.float32, (Hc, Wc, 3))
            stage("splat", f"splat_{r}", gpu.read(smap, np.float32, (Hc, Wc)))
            stage("gather", f"caustic_map_{r}", m)
            stage("gather", f"caustic_rgb_{r}", rgb)
            res[f"caustic_map_{r}"], res[f"caustic_rgb_{r}"] = m, rgb
            crgb_all.append(rgb)

    with timer("caustic_final"):
        # the single-surface pass's normals: the normals pass run on zfront (the eye's minmax zmin, one layer)
        nf = gpu.storage(nbytes=16 * n)
        gpu.dispatch(gpu.compute(isp.shader(isp.NORMALS, bugs)), [eye_out.P, eye_out.zmin, nf], (-(-W // 64), H, 1))
        nl = len(lights)
        cvals = dict(Hcf=Hc, Wcf=Wc, Hc=Hc, Wc=Wc, ior=mat["ior"], pinf=np.inf, nan=np.nan, tie=5e-3, nl=nl,
                     nr=len(receivers))
        imf = gpu.storage(nbytes=16 * n)
        ims = gpu.storage(nbytes=16 * n)
        shb = gpu.storage(nbytes=4 * n * nl)
        smb = gpu.storage(nbytes=4 * n * nl)
        gpu.dispatch(gpu.compute(cshader(isp, MARCH + FINAL, bugs)),
                     [eye_out.P, gpu.uniform(c_bytes(cvals)), dmin, rtri_b, rcv_b, tn_b, gpu.storage(np.stack(lts)),
                      gpu.storage(np.stack(lzmins)), gpu.storage(np.stack(crgb_all)), eye_out.zmin, eye_out.rdir,
                      eye_out.vdir, eye_out.trace, nf, imf, ims, shb, smb], gpu.groups_for(n))
        full = gpu.read(imf, np.float32, (H, W, 4))[..., :3].copy()
        single = gpu.read(ims, np.float32, (H, W, 4))[..., :3].copy()
        stage("caustic_final", "image_caustics", full)
        stage("caustic_final", "image_caustics_single", single)
        sh = gpu.read(shb, np.uint32, (nl, H, W)).astype(np.uint8)
        sm = gpu.read(smb, np.float32, (nl, H, W))
        for li in range(nl):
            stage("caustic_final", f"shadow_{li}", sh[li])
            stage("caustic_final", f"shadow_margin_{li}", sm[li])
        res["image_caustics"], res["image_caustics_single"], res["image"] = full, single, full
    return res
