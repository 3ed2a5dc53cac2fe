"""WebGPU backend of the image-space multiple-refraction method (Chaudhari 2008), WGSL through wgpu-py.

Written from ``docs/oracle.md`` ("Porting rules: image-space", "Stage buffers",
"Conformance") and ``docs/backends.md`` by an author who did not read the
package's source. The passes are the thesis's GPU passes, one pipeline each,
float32 arithmetic throughout as shaders do:

=============  ====================================================================================
``rays``       compute: one invocation per pixel, the view-space direction through the pixel centre
``minmax``     render pipeline, no culling, no depth test: the fragment shader ``atomicMin`` /
               ``atomicMax``-es its depth's bits into the pixel's words (§3.3's min-max blending)
``voxelize``   render pipeline again: each fragment adds (``blend = add``) or ors its slice bit into
               the pixel's 32-bit words of a storage buffer with ``atomicAdd`` / ``atomicOr`` (§3.3)
``peel``       compute: per pixel, the n-th set bit of the bitmask (``firstTrailingBit``) to the
               layer's depth, every layer written (§3.4.2's separate pass; the LDI is a storage
               buffer, (layers, H, W) float32: on lavapipe texture stores and loads cost 1.4-3x a
               buffer's)
``reduce``     compute: the MIP level (a box filter over the present texels), then a parallel
               max/min reduction in workgroup memory (§3.7)
``normals``    compute: perspective-corrected central differences per layer (§3.5, eq. 3.2)
``trace``      compute: per pixel, Snell at each interface and the 5-step binary search against
               the next layer, bounded by the reduced maximum, the thesis's stop rules (§3.6-3.7)
``shade``      compute: the environment along the last direction, Beer-Lambert (§3.8)
=============  ====================================================================================

On scenes with lights and receivers the caustic stages follow
(``imagespace_caustics.py``). ``run(golden_dir, out_dir)`` writes
``out_dir/<case>/result.npz`` for ``refraction-ref check``; ``bugs=`` plants
the mistakes GPU porters make (``BUGS``)::

    python examples/webgpu_backend/imagespace.py GOLDEN_DIR CAND_DIR [--cases a,b] [--bug NAME]

The only thing taken from the package is its public scene loader
(``refraction_ref.load_scene``, which fills in the defaults); the triangles are
the golden case's ``geometry.npz``.

References
----------
P. Chaudhari, *Real-Time Multiple Refractions Through Deformable Objects*,
M.S. thesis, UMBC, 2008, §3.2-3.8.
"""
from __future__ import annotations

import importlib.util
import json
import os
import struct
import sys
import time
from types import SimpleNamespace

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def _load(name):
    spec = importlib.util.spec_from_file_location(f"webgpu_{name}", os.path.join(HERE, f"{name}.py"))
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


gpu = _load("gpu")

MISSED, EXITED, LIMIT, TIR, LOST = 0, 1, 2, 3, 4

#: planted bugs of the eye passes: name -> (the pass that holds it, what a porter got wrong)
BUGS = {
    "half_pixel": ("rays", "pixel centres at the corner: (j, i) instead of (j + 0.5, i + 0.5)"),
    "cull_back": ("minmax", "the render pipeline's cull_mode left at 'back' (back faces culled) in minmax and "
                            "voxelize"),
    "depth16": ("minmax", "zmin/zmax kept in a 16-bit unorm depth buffer (z = far (d - near) / (d (far - near)) "
                          "quantized to 1/65535)"),
    "depth24": ("minmax", "zmin/zmax kept in a 24-bit unorm depth buffer (quantized to 1/16777215)"),
    "nonatomic_bits": ("voxelize", "the bitmask word read, or-ed/added and stored back without atomics "
                                   "(atomicLoad then atomicStore)"),
    "bits_replace": ("voxelize", "the bitmask word written, not blended: the fragment's word replaces the "
                                 "pixel's (a colour target without additive or logical-or blending)"),
    "mip_drop_odd": ("reduce", "the MIP level sized floor(H / f) x floor(W / f): the last odd row and column "
                               "of blocks dropped"),
    "texture_y_flip": ("trace", "the layers (and their normals) read with a bottom-left origin, as an OpenGL "
                                "texture coordinate: row i reads row H - 1 - i"),
    "nearest_sampling": ("trace", "the layers sampled at the nearest texel where the contract samples "
                                  "bilinearly (filter = bilinear)"),
    "hw_interp": ("trace", "not a bug: the vertex shader outputs clip positions (w = d) and the rasterizer "
                           "snaps and interpolates on its own (lavapipe interpolates 1/d from the unsnapped "
                           "positions: the depths move within the slope term, the trace's points beyond 1e-5)"),
    "wrong_bound_layer": ("trace", "the search bound read from the layer just crossed (bounds_hi[t - 1]) "
                                   "instead of the layer searched"),
}

# ----------------------------------------------------------------------------- parameters
_VEC = ("r", "u", "b", "c0", "c1", "c2", "t", "eye", "absorption", "col0", "col1")
_F32 = ("sx", "sy", "Wf", "Hf", "near", "far", "Sf", "inv_sm1", "ior", "oior", "bound_margin", "exit_thr",
        "tiles", "pinf", "ninf", "nan", "fwd_eps")
_U32 = ("W", "H", "K", "NL", "ortho", "iters", "max_int", "tir", "bilinear", "delta", "record", "blend_or",
        "global_slicing", "mipf", "hb", "wb", "margin_on", "env_const", "absorb", "forward_normals", "first_ortho",
        "peel_all")


def params_decl():
    """The WGSL declaration of the uniform block every pass reads (camera, knobs, sentinels)."""
    lines = [f"  {n}: vec4f," for n in _VEC] + [f"  {n}: f32," for n in _F32] + [f"  {n}: u32," for n in _U32]
    return "struct P {\n" + "\n".join(lines) + "\n}\n"


def params_bytes(vals):
    """The uniform block's bytes from ``vals`` (name -> value; missing names are 0)."""
    out = b""
    for n in _VEC:
        v = np.zeros(4, np.float32)
        x = np.asarray(vals.get(n, 0.0), np.float64).ravel()
        v[:len(x)] = x
        out += v.tobytes()
    for n in _F32:
        out += struct.pack("<f", float(vals.get(n, 0.0)))
    for n in _U32:
        out += struct.pack("<I", int(vals.get(n, 0)))
    return out


# ----------------------------------------------------------------------------- WGSL
COMMON = """
@group(0) @binding(0) var<uniform> p: P;
fn isfin(x: f32) -> bool { return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u; }
fn to_world_dir(v: vec3f) -> vec3f { return v.x * p.r.xyz + v.y * p.u.xyz + v.z * p.b.xyz; }
fn to_world_pt(v: vec3f) -> vec3f { return v.x * p.r.xyz + v.y * p.u.xyz + v.z * p.b.xyz + p.eye.xyz; }
// the contract's unproject: a view point at depth d seen at continuous screen (col, row); orthographic: no d
fn unproject(col: f32, row: f32, d: f32) -> vec3f {
  if (p.ortho != 0u) {
    return vec3f((col * (2.0 / p.Wf) - 1.0) * p.sx, (1.0 - row * (2.0 / p.Hf)) * p.sy, -d);
  }
  return vec3f((col * (2.0 / p.Wf) - 1.0) * p.sx * d, (1.0 - row * (2.0 / p.Hf)) * p.sy * d, -d);
}
"""

RAYS = """
@group(0) @binding(1) var<storage, read_write> rdir: array<vec4f>;
@group(0) @binding(2) var<storage, read_write> vdir: array<vec4f>;
@compute @workgroup_size(64, 1)
fn main(@builtin(global_invocation_id) g: vec3u) {
  if (g.x >= p.W || g.y >= p.H) { return; }
  let o = select(0.5, 0.0, BUG_HALF_PIXEL);
  let x = ((f32(g.x) + o) / p.Wf * 2.0 - 1.0) * p.sx;
  let y = (1.0 - (f32(g.y) + o) / p.Hf * 2.0) * p.sy;
  let s = 1.0 / sqrt(x * x + y * y + 1.0);
  let v = vec3f(x * s, y * s, -s);
  let idx = g.y * p.W + g.x;
  vdir[idx] = vec4f(v, 0.0);
  rdir[idx] = vec4f(to_world_dir(v), 0.0);
}
"""

# minmax and voxelize: the mesh drawn by the render pipeline (no culling, no depth test); the colour
# target is a dummy with write mask 0, the fragments' output goes to storage buffers with atomics
RASTER = """
@group(0) @binding(1) var<storage, read_write> zmin_b: array<atomic<u32>>;
@group(0) @binding(2) var<storage, read_write> zmax_b: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read> zlo: array<f32>;
@group(0) @binding(4) var<storage, read> zhi: array<f32>;
@group(0) @binding(5) var<storage, read_write> bits: array<atomic<u32>>;
struct VO { @builtin(position) pos: vec4f, @location(0) @interpolate(linear) q: f32 }
@vertex
fn vs(@location(0) x: vec3f) -> VO {
  // the contract's to_view, x B[:, 0] + y B[:, 1] + z B[:, 2] + t, in that order
  let v = x.x * p.c0.xyz + x.y * p.c1.xyz + x.z * p.c2.xyz + p.t.xyz;
  let d = -v.z;
  var o: VO;
  if (SNAP) {
    // the contract's rasterization step 2: the vertex projected to pixel units and rounded to the 1/256
    // sub-pixel grid here, so that the rasterizer's coverage AND its attribute set-up both see the snapped
    // triangle (lavapipe interpolates attributes from the float positions it is given, not from its own
    // 8-bit snapped ones); w = 1, so the hardware divides by nothing and the viewport maps the value back
    // to exactly X / 256 pixels. Near clipping, which w = 1 loses, is done on the host (no case clips).
    var col: f32;
    var row: f32;
    if (p.ortho != 0u) {
      col = (v.x / p.sx * 0.5 + 0.5) * p.Wf;
      row = (0.5 - v.y / p.sy * 0.5) * p.Hf;
      o.q = d;
    } else {
      col = (v.x / (d * p.sx) * 0.5 + 0.5) * p.Wf;
      row = (0.5 - v.y / (d * p.sy) * 0.5) * p.Hf;
      o.q = 1.0 / d;
    }
    let X = round(col * 256.0);                          // round half to even, as rint
    let Y = round(row * 256.0);
    o.pos = vec4f(X / (128.0 * p.Wf) - 1.0, 1.0 - Y / (128.0 * p.Hf), 0.5, 1.0);
    return o;
  }
  if (p.ortho != 0u) {
    o.pos = vec4f(v.x / p.sx, v.y / p.sy, 0.5, 1.0);   // no clipping in depth (no far plane)
    o.q = d;                                           // orthographic: depth interpolated linearly
  } else {
    // w = d: clip z = d - near clips at the near plane exactly and never at a far plane (z <= w)
    o.pos = vec4f(v.x / p.sx, v.y / p.sy, d - p.near, d);
    o.q = 1.0 / d;                                     // 1/d is affine on screen: interpolated linearly
  }
  return o;
}
fn frag_depth(q: f32) -> f32 { return select(1.0 / q, q, p.ortho != 0u); }
fn pixel(pos: vec4f) -> u32 { return u32(pos.y) * p.W + u32(pos.x); }
@fragment
fn fs_minmax(i: VO) -> @location(0) vec4f {
  var d = frag_depth(i.q);
  if (BUG_DEPTH_BITS > 0u) {
    // a depth buffer's unorm value: z = far (d - near) / (d (far - near)), quantized, and back
    let m = f32((1u << BUG_DEPTH_BITS) - 1u);
    let z = round(p.far * (d - p.near) / (d * (p.far - p.near)) * m) / m;
    d = p.near * p.far / (p.far - z * (p.far - p.near));
  }
  // positive floats order as their bits: min/max blending through integer atomics
  atomicMin(&zmin_b[pixel(i.pos)], bitcast<u32>(d));
  atomicMax(&zmax_b[pixel(i.pos)], bitcast<u32>(d));
  return vec4f(0.0);
}
@fragment
fn fs_voxelize(i: VO) -> @location(0) vec4f {
  let pix = pixel(i.pos);
  let d = frag_depth(i.q);
  let lo = zlo[pix];
  let rng = zhi[pix] - lo;
  var s = 0u;
  if (rng > 0.0) {
    let q = floor((d - lo) / rng * (p.Sf - 1.0) + 0.5);   // round half up to the nearest slice
    s = u32(clamp(q, 0.0, p.Sf - 1.0));
  }
  let w = pix * p.K + s / 32u;
  let m = 1u << (s % 32u);
  if (BUG_NONATOMIC) {
    let old = atomicLoad(&bits[w]);
    atomicStore(&bits[w], select(old + m, old | m, p.blend_or != 0u));
  } else if (BUG_REPLACE) {
    atomicStore(&bits[w], m);
  } else if (p.blend_or != 0u) {
    atomicOr(&bits[w], m);
  } else {
    atomicAdd(&bits[w], m);                 // the thesis's additive blending: carries into the next bit
  }
  return vec4f(0.0);
}
"""

# minmax's resolve: the depth bits to floats (+-inf where no fragment) and the global extrema
MINMAX_RESOLVE = """
@group(0) @binding(1) var<storage, read> zmin_b: array<u32>;
@group(0) @binding(2) var<storage, read> zmax_b: array<u32>;
@group(0) @binding(3) var<storage, read_write> zmin: array<f32>;
@group(0) @binding(4) var<storage, read_write> zmax: array<f32>;
@group(0) @binding(5) var<storage, read_write> glob: array<atomic<u32>>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) g: vec3u) {
  let pix = g.x;
  if (pix >= p.W * p.H) { return; }
  let a = zmin_b[pix];
  let b = zmax_b[pix];
  zmin[pix] = bitcast<f32>(a);            // cleared to +inf's bits
  if (b == 0u) { zmax[pix] = p.ninf; } else { zmax[pix] = bitcast<f32>(b); }
  if (b != 0u) {
    atomicMin(&glob[0], a);
    atomicMax(&glob[1], b);
  }
}
"""

# voxelize's slice range per pixel: local (zmin, zmax) or global (gmin, gmax)
SLICE_RANGE = """
@group(0) @binding(1) var<storage, read> zmin: array<f32>;
@group(0) @binding(2) var<storage, read> zmax: array<f32>;
@group(0) @binding(3) var<storage, read> glob: array<u32>;
@group(0) @binding(4) var<storage, read_write> zlo: array<f32>;
@group(0) @binding(5) var<storage, read_write> zhi: array<f32>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) g: vec3u) {
  let pix = g.x;
  if (pix >= p.W * p.H) { return; }
  if (p.global_slicing != 0u) {
    zlo[pix] = bitcast<f32>(glob[0]);
    zhi[pix] = select(p.ninf, bitcast<f32>(glob[1]), glob[1] != 0u);
  } else {
    zlo[pix] = zmin[pix];
    zhi[pix] = zmax[pix];
  }
}
"""

PEEL = """
@group(0) @binding(1) var<storage, read> zlo: array<f32>;
@group(0) @binding(2) var<storage, read> zhi: array<f32>;
@group(0) @binding(3) var<storage, read> bits: array<u32>;
@group(0) @binding(4) var<storage, read_write> ldi: array<f32>;   // (layers, H, W)
@group(0) @binding(5) var<storage, read_write> dc: array<i32>;
@group(0) @binding(6) var<storage, read_write> maxdc: array<atomic<u32>>;
@compute @workgroup_size(64, 1)
fn main(@builtin(global_invocation_id) g: vec3u) {
  if (g.x >= p.W || g.y >= p.H) { return; }
  let pix = g.y * p.W + g.x;
  let lo = zlo[pix];
  let rng = zhi[pix] - lo;
  var layer = 0u;
  var total = 0u;
  for (var k = 0u; k < p.K; k++) {
    var w = bits[pix * p.K + k];
    total += countOneBits(w);
    loop {
      if (w == 0u || layer >= p.NL) { break; }
      let b = 32u * k + firstTrailingBit(w);       // the next set slice, front to back
      ldi[layer * p.W * p.H + pix] = lo + f32(b) * p.inv_sm1 * rng;
      layer += 1u;
      w = w & (w - 1u);
    }
  }
  loop {
    if (layer >= p.NL) { break; }
    ldi[layer * p.W * p.H + pix] = p.pinf;
    layer += 1u;
  }
  dc[pix] = i32(total);
  atomicMax(&maxdc[0], total);
}
"""

# reduce, step 1: the MIP level, f x f blocks averaged over their present texels
MIP = """
@group(0) @binding(1) var<storage, read> ldi: array<f32>;
@group(0) @binding(2) var<storage, read_write> mhi: array<f32>;
@group(0) @binding(3) var<storage, read_write> mlo: array<f32>;
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) g: vec3u) {
  if (g.x >= p.wb || g.y >= p.hb) { return; }
  let layer = i32(g.z);
  var sum = 0.0;
  var n = 0u;
  for (var yy = 0u; yy < p.mipf; yy++) {
    for (var xx = 0u; xx < p.mipf; xx++) {
      let i = g.y * p.mipf + yy;
      let j = g.x * p.mipf + xx;
      if (i < p.H && j < p.W) {
        let d = ldi[(u32(layer) * p.H + i) * p.W + j];
        if (isfin(d)) { sum += d; n += 1u; }
      }
    }
  }
  let idx = (g.z * p.hb + g.y) * p.wb + g.x;
  if (n > 0u) {
    let mean = sum / f32(n);
    mhi[idx] = mean;
    mlo[idx] = mean;
  } else {
    mhi[idx] = p.ninf;
    mlo[idx] = p.pinf;
  }
}
"""

# reduce, step 2: parallel max/min reduction of each layer's MIP level in workgroup memory
REDUCE = """
@group(0) @binding(1) var<storage, read> mhi: array<f32>;
@group(0) @binding(2) var<storage, read> mlo: array<f32>;
@group(0) @binding(3) var<storage, read> glob: array<u32>;
@group(0) @binding(4) var<storage, read_write> bhi: array<f32>;
@group(0) @binding(5) var<storage, read_write> blo: array<f32>;
var<workgroup> shi: array<f32, 256>;
var<workgroup> slo: array<f32, 256>;
@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) li: u32, @builtin(workgroup_id) wg: vec3u) {
  let layer = wg.x;
  let n = p.hb * p.wb;
  var h = p.ninf;
  var l = p.pinf;
  for (var k = li; k < n; k += 256u) {
    h = max(h, mhi[layer * n + k]);
    l = min(l, mlo[layer * n + k]);
  }
  shi[li] = h;
  slo[li] = l;
  workgroupBarrier();
  for (var s = 128u; s > 0u; s = s >> 1u) {
    if (li < s) {
      shi[li] = max(shi[li], shi[li + s]);
      slo[li] = min(slo[li], slo[li + s]);
    }
    workgroupBarrier();
  }
  if (li == 0u) {
    var hi = shi[0];
    var lo = slo[0];
    if (p.margin_on != 0u && glob[1] != 0u) {
      let margin = p.bound_margin * (bitcast<f32>(glob[1]) - bitcast<f32>(glob[0]));
      if (isfin(hi)) { hi = hi + margin; }
      if (isfin(lo)) { lo = lo - margin; }
    }
    bhi[layer] = hi;
    blo[layer] = lo;
  }
}
"""

NORMALS = """
@group(0) @binding(1) var<storage, read> ldi: array<f32>;
@group(0) @binding(2) var<storage, read_write> nrm: array<vec4f>;
fn ld(l: i32, i: i32, j: i32) -> f32 {
  if (i < 0 || j < 0 || i >= i32(p.H) || j >= i32(p.W)) { return p.pinf; }
  return ldi[(u32(l) * p.H + u32(i)) * p.W + u32(j)];
}
@compute @workgroup_size(64, 1)
fn main(@builtin(global_invocation_id) g: vec3u) {
  if (g.x >= p.W || g.y >= p.H) { return; }
  let l = i32(g.z);
  let i = i32(g.y);
  let j = i32(g.x);
  let d = ld(l, i, j);
  if (!isfin(d)) {
    nrm[(u32(l) * p.H + u32(i)) * p.W + u32(j)] = vec4f(p.nan, p.nan, p.nan, 0.0);
    return;
  }
  var n: vec3f;
  if (p.forward_normals != 0u) {
    // eq. 3.1: forward differences in pixel units, a term 0 where the neighbour is absent
    let dr = ld(l, i, j + 1);
    let du = ld(l, i - 1, j);
    let gx = select(0.0, dr - d, isfin(dr));
    let gy = select(0.0, du - d, isfin(du));
    let v = vec3f(gx, gy, 1.0);
    n = v * (1.0 / sqrt(dot(v, v)));
  } else {
    // eq. 3.2, perspective-corrected: each neighbour unprojected at its own pixel centre and depth
    let dl_ = i32(p.delta);
    var jr = j + dl_; var dr = ld(l, i, jr);
    if (!isfin(dr)) { jr = j; dr = d; }
    var jl = j - dl_; var dl = ld(l, i, jl);
    if (!isfin(dl)) { jl = j; dl = d; }
    var iu = i - dl_; var du = ld(l, iu, j);
    if (!isfin(du)) { iu = i; du = d; }
    var id = i + dl_; var dd = ld(l, id, j);
    if (!isfin(dd)) { id = i; dd = d; }
    var gx = 0.0;
    if (jr != jl) {
      let xr = unproject(f32(jr) + 0.5, f32(i) + 0.5, dr).x;
      let xl = unproject(f32(jl) + 0.5, f32(i) + 0.5, dl).x;
      if (xr != xl) { gx = (dr - dl) / (xr - xl); }
    }
    var gy = 0.0;
    if (iu != id) {
      let yu = unproject(f32(j) + 0.5, f32(iu) + 0.5, du).y;
      let yd = unproject(f32(j) + 0.5, f32(id) + 0.5, dd).y;
      if (yu != yd) { gy = (du - dd) / (yu - yd); }
    }
    let s = 1.0 / sqrt(gx * gx + gy * gy + 1.0);
    n = vec3f(gx * s, gy * s, s);
  }
  nrm[(u32(l) * p.H + u32(i)) * p.W + u32(j)] = vec4f(n, 0.0);
}
"""

TRACE = """
@group(0) @binding(1) var<storage, read> vdir: array<vec4f>;
@group(0) @binding(2) var<storage, read> rdir: array<vec4f>;
@group(0) @binding(3) var<storage, read> ldi: array<f32>;
@group(0) @binding(4) var<storage, read> nrm: array<vec4f>;
@group(0) @binding(5) var<storage, read> dc: array<i32>;
@group(0) @binding(6) var<storage, read> zmax: array<f32>;
@group(0) @binding(7) var<storage, read> zlo: array<f32>;
@group(0) @binding(8) var<storage, read> zhi: array<f32>;
@group(0) @binding(9) var<storage, read> bhi: array<f32>;
@group(0) @binding(10) var<storage, read> blo: array<f32>;
struct TraceOut { exit_pos: vec4f, exit_dir: vec4f, last_dir: vec4f, plen: f32, nint: i32, status: i32, pad: i32 }
@group(0) @binding(11) var<storage, read_write> outp: array<TraceOut>;
@group(0) @binding(12) var<storage, read_write> rec: array<vec4f>;

fn texel(t: u32, i: i32, j: i32) -> f32 {
  var ii = i;
  if (BUG_TEX_YFLIP) { ii = i32(p.H) - 1 - i; }
  return ldi[(t * p.H + u32(ii)) * p.W + u32(j)];
}
fn ntexel(t: u32, i: i32, j: i32) -> vec3f {
  var ii = i;
  if (BUG_TEX_YFLIP) { ii = i32(p.H) - 1 - i; }
  return nrm[(t * p.H + u32(ii)) * p.W + u32(j)].xyz;
}
fn inimg(i: i32, j: i32) -> bool { return i >= 0 && j >= 0 && i < i32(p.H) && j < i32(p.W); }
fn bilinear() -> bool { return p.bilinear != 0u && !BUG_NEAREST; }

// a layer sampled at continuous (r, c): +inf off the image or where the texel lacks the layer; the
// bilinear blend of the four texels around the position where all four hold it, else the texel's depth
fn sample(t: u32, r: f32, c: f32) -> f32 {
  if (!(r >= 0.0 && r < p.Hf && c >= 0.0 && c < p.Wf)) { return p.pinf; }
  let dc_ = texel(t, i32(floor(r)), i32(floor(c)));
  if (!isfin(dc_) || !bilinear()) { return dc_; }
  let u = c - 0.5;
  let v = r - 0.5;
  let j0f = floor(u);
  let i0f = floor(v);
  let fx = u - j0f;
  let fy = v - i0f;
  let j0 = i32(j0f);
  let i0 = i32(i0f);
  if (inimg(i0, j0) && inimg(i0 + 1, j0 + 1)) {
    let d00 = texel(t, i0, j0);
    let d01 = texel(t, i0, j0 + 1);
    let d10 = texel(t, i0 + 1, j0);
    let d11 = texel(t, i0 + 1, j0 + 1);
    if (isfin(d00) && isfin(d01) && isfin(d10) && isfin(d11)) {
      let top = d00 + fx * (d01 - d00);
      let bot = d10 + fx * (d11 - d10);
      return top + fy * (bot - top);
    }
  }
  return dc_;
}

// the normal at (r, c): the same footprint as the depth, the four normals faced to the first one
fn normal_at(t: u32, r: f32, c: f32) -> vec3f {
  let n0 = ntexel(t, i32(floor(r)), i32(floor(c)));
  if (!bilinear()) { return n0; }
  let u = c - 0.5;
  let v = r - 0.5;
  let j0f = floor(u);
  let i0f = floor(v);
  let fx = u - j0f;
  let fy = v - i0f;
  let j0 = i32(j0f);
  let i0 = i32(i0f);
  if (inimg(i0, j0) && inimg(i0 + 1, j0 + 1) && isfin(texel(t, i0, j0)) && isfin(texel(t, i0, j0 + 1))
      && isfin(texel(t, i0 + 1, j0)) && isfin(texel(t, i0 + 1, j0 + 1))) {
    let n00 = ntexel(t, i0, j0);
    var n01 = ntexel(t, i0, j0 + 1);
    var n10 = ntexel(t, i0 + 1, j0);
    var n11 = ntexel(t, i0 + 1, j0 + 1);
    if (dot(n01, n00) < 0.0) { n01 = -n01; }
    if (dot(n10, n00) < 0.0) { n10 = -n10; }
    if (dot(n11, n00) < 0.0) { n11 = -n11; }
    let top = n00 + fx * (n01 - n00);
    let bot = n10 + fx * (n11 - n10);
    let o = top + fy * (bot - top);
    let l2 = dot(o, o);
    if (l2 > 0.0) { return o * (1.0 / sqrt(l2)); }
    return n00;
  }
  return n0;
}

// Snell's law with total internal reflection (.w = 1: the mirror direction)
fn refract_(v: vec3f, n_in: vec3f, eta: f32) -> vec4f {
  var n = n_in;
  var c = -dot(v, n);
  if (c < 0.0) { n = -n; c = -c; }
  let k = 1.0 - eta * eta * (1.0 - c * c);
  if (k < 0.0) {
    let w = v + 2.0 * c * n;
    return vec4f(w * (1.0 / sqrt(dot(w, w))), 1.0);
  }
  let w = eta * v + (eta * c - sqrt(k)) * n;
  return vec4f(w * (1.0 / sqrt(dot(w, w))), 0.0);
}

// the trace's projection: (row, col), or (-1, -1) behind the eye or off the image
fn screen(P: vec3f) -> vec2f {
  if (!(-P.z > 0.0)) { return vec2f(-1.0, -1.0); }
  var row: f32;
  var col: f32;
  if (p.ortho != 0u) {
    col = (P.x / p.sx * 0.5 + 0.5) * p.Wf;
    row = (0.5 - P.y / p.sy * 0.5) * p.Hf;
  } else {
    let inv = 1.0 / -P.z;
    row = 0.5 * p.Hf - P.y * inv * (0.5 * p.Hf / p.sy);
    col = P.x * inv * (0.5 * p.Wf / p.sx) + 0.5 * p.Wf;
  }
  if (!(row >= 0.0 && row < p.Hf && col >= 0.0 && col < p.Wf)) { return vec2f(-1.0, -1.0); }
  return vec2f(row, col);
}
fn even(g: i32) -> bool { return (g & 1) == 0; }
fn nanv() -> vec4f { return vec4f(p.nan, p.nan, p.nan, 0.0); }

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u) {
  let idx = gid.x + gid.y * 65535u * 64u;
  if (idx >= p.W * p.H) { return; }
  let i = i32(idx / p.W);
  let j = i32(idx % p.W);
  for (var k = 0u; k < p.record; k++) {
    rec[(idx * p.record + k) * 2u] = nanv();
    rec[(idx * p.record + k) * 2u + 1u] = nanv();
  }
  var o: TraceOut;
  o.plen = 0.0;
  o.nint = 0;
  let rd = rdir[idx];
  var d0 = p.pinf;
  if (p.NL > 0u) { d0 = texel(0u, i, j); }
  if (!isfin(d0)) {
    o.exit_pos = nanv(); o.exit_dir = rd; o.last_dir = rd; o.status = 0;
    outp[idx] = o;
    return;
  }
  var v: vec3f;
  var q: vec3f;
  if (p.first_ortho != 0u) {
    v = vec3f(0.0, 0.0, -1.0);                          // a directional light's photon: along -z
    q = unproject(f32(j) + 0.5, f32(i) + 0.5, d0);
  } else {
    v = vdir[idx].xyz;
    q = v * (d0 / -v.z);                                // the first hit: on the primary ray at layer 0
  }
  var pp = q;
  var t = 0u;
  var ti = i;
  var tj = j;
  var rq = f32(i) + 0.5;
  var cq = f32(j) + 0.5;
  var g = -1;
  var fwd = true;
  var events = 0u;
  var nint = 0;
  var plen = 0.0;
  var st = -1;
  loop {
    if (even(g)) { plen += length(q - pp); }
    pp = q;
    var g2 = i32(t);
    if (!fwd) { g2 = i32(t) - 1; }
    let n1 = select(p.oior, p.ior, even(g));
    let n2 = select(p.oior, p.ior, even(g2));
    var nn: vec3f;
    if (bilinear()) { nn = normal_at(t, rq, cq); } else { nn = ntexel(t, ti, tj); }
    let rw = refract_(v, nn, n1 / n2);
    let tir = rw.w > 0.5;
    if (events < p.record) {
      rec[(idx * p.record + events) * 2u] = vec4f(to_world_pt(pp), 0.0);
      rec[(idx * p.record + events) * 2u + 1u] = vec4f(to_world_dir(rw.xyz), 0.0);
    }
    events += 1u;
    if (tir && p.tir == 0u) { st = 3; break; }           // last_dir keeps the incident v
    v = rw.xyz;
    if (!tir) {
      g = g2;
      nint += 1;
      if (g == -1) { st = 1; break; }
      if (fwd) {
        let hk = u32(ti) * p.W + u32(tj);
        var thr = (zhi[hk] - zlo[hk]) * (p.exit_thr / (p.Sf - 1.0));
        if (!isfin(thr)) { thr = 0.0; }
        if (i32(t) >= dc[hk] - 1 || zmax[hk] - texel(t, ti, tj) <= thr) { st = 1; break; }
      }
    }
    if (events >= p.max_int) { st = select(2, 3, tir); break; }
    let dd = -v.z;
    let outside = !even(g);
    var zb: f32;
    if (dd > p.fwd_eps) {
      fwd = true;
      t = u32(g + 1);
      if (t >= p.NL) { st = 2; break; }
      if (BUG_WRONG_BOUND) { zb = bhi[t - 1u]; } else { zb = bhi[t]; }
    } else if (dd < -p.fwd_eps && p.tir != 0u) {
      fwd = false;
      t = u32(g);
      zb = blo[t];
    } else {
      st = select(4, 1, outside && dd < 0.0);
      break;
    }
    if (!isfin(zb) || (fwd && zb <= -pp.z) || (!fwd && zb >= -pp.z)) { st = select(4, 1, outside); break; }
    let E = pp + ((zb - -pp.z) / dd) * v;
    var a = 0.0;
    var b = 1.0;
    var m = 1.0;
    for (var it = 0u; it < p.iters; it++) {
      m = 0.5 * (a + b);
      let P = pp + m * (E - pp);
      let rc = screen(P);
      var ls = p.pinf;
      if (rc.x >= 0.0) { ls = sample(t, rc.x, rc.y); }
      var behind = false;
      if (isfin(ls)) {
        if (fwd) { behind = -P.z >= ls; } else { behind = -P.z <= ls; }
      }
      if (behind) { b = m; } else { a = m; }
    }
    let P = pp + m * (E - pp);                        // endpoint = probe: the last probe P_n
    let rc = screen(P);
    rq = rc.x;
    cq = rc.y;
    var dq = p.pinf;
    if (rq >= 0.0) { dq = sample(t, rq, cq); }
    if (!isfin(dq)) { st = select(4, 1, outside); break; }
    q = unproject(cq, rq, dq);                         // R_n: the line of sight through P_n at the layer
    ti = i32(floor(rq));
    tj = i32(floor(cq));
  }
  o.nint = nint;
  o.plen = plen;
  o.status = st;
  let vw = vec4f(to_world_dir(v), 0.0);
  o.last_dir = vw;
  if (st == 1) {
    o.exit_pos = vec4f(to_world_pt(pp), 0.0);
    o.exit_dir = vw;
  } else {
    o.exit_pos = nanv();
    o.exit_dir = nanv();
  }
  outp[idx] = o;
}
"""

# the layers present, L = min(layers, depth complexity) (all of them with peel_all), as indirect dispatch
# arguments: the MIP (x, y, L), the reduction (L, 1, 1), the normals (x, y, L)
ARGS = """
@group(0) @binding(1) var<storage, read> maxdc: array<u32>;
@group(0) @binding(2) var<storage, read_write> args: array<u32>;
@compute @workgroup_size(1)
fn main() {
  var L = min(maxdc[0], p.NL);
  if (p.peel_all != 0u) { L = p.NL; }
  args[0] = (p.wb + 7u) / 8u; args[1] = (p.hb + 7u) / 8u; args[2] = L;
  args[3] = L; args[4] = 1u; args[5] = 1u;
  args[6] = (p.W + 63u) / 64u; args[7] = p.H; args[8] = L;
}
"""

SHADE = """
struct TraceOut { exit_pos: vec4f, exit_dir: vec4f, last_dir: vec4f, plen: f32, nint: i32, status: i32, pad: i32 }
@group(0) @binding(1) var<storage, read> tr: array<TraceOut>;
@group(0) @binding(2) var<storage, read_write> img: array<vec4f>;
const PI: f32 = 3.14159265358979;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) g: vec3u) {
  let idx = g.x;
  if (idx >= p.W * p.H) { return; }
  let L = tr[idx].last_dir.xyz;
  var c = vec3f(0.0);
  if (isfin(L.x) && isfin(L.y) && isfin(L.z)) {
    if (p.env_const != 0u) {
      c = p.col0.xyz;
    } else {
      let u = atan2(L.x, -L.z) / (2.0 * PI) + 0.5;
      let v = acos(clamp(L.y, -1.0, 1.0)) / PI;
      let k = (i32(floor(u * p.tiles)) + i32(floor(v * (p.tiles / 2.0)))) % 2;
      c = select(p.col0.xyz, p.col1.xyz, k == 1);
    }
    if (p.absorb != 0u) { c = c * exp(-p.absorption.xyz * (tr[idx].plen * p.ior)); }
  }
  img[idx] = vec4f(c, 0.0);
}
"""


def shader(body, bugs=()):
    """A pass's WGSL: the uniform block, the common functions, the planted bugs as constants, the body."""
    bugs = set(bugs)
    depth_bits = 16 if "depth16" in bugs else 24 if "depth24" in bugs else 0
    consts = (f"const BUG_HALF_PIXEL: bool = {str('half_pixel' in bugs).lower()};\n"
              f"const BUG_DEPTH_BITS: u32 = {depth_bits}u;\n"
              f"const BUG_NONATOMIC: bool = {str('nonatomic_bits' in bugs).lower()};\n"
              f"const BUG_REPLACE: bool = {str('bits_replace' in bugs).lower()};\n"
              f"const BUG_TEX_YFLIP: bool = {str('texture_y_flip' in bugs).lower()};\n"
              f"const BUG_NEAREST: bool = {str('nearest_sampling' in bugs).lower()};\n"
              f"const SNAP: bool = {str('hw_interp' not in bugs).lower()};\n"
              f"const BUG_WRONG_BOUND: bool = {str('wrong_bound_layer' in bugs).lower()};\n")
    return params_decl() + consts + COMMON + body


# ----------------------------------------------------------------------------- host set-up
class View(SimpleNamespace):
    """A camera the passes run on: the eye (perspective) or a light (orthographic or perspective)."""


def eye_view(cam):
    """The eye's view ("Camera scalars, frames and projections"), float64 on the host."""
    W, H = int(cam["width"]), int(cam["height"])
    sy = np.tan(np.radians(cam["fov_y"]) / 2.0)
    sx = np.tan(np.radians(cam["fov_y"]) / 2.0) * W / H
    eye = np.asarray(cam["eye"], np.float64)
    f = np.asarray(cam["target"], np.float64) - eye
    f = f / np.linalg.norm(f)
    r = np.cross(f, np.asarray(cam["up"], np.float64))
    r = r / np.linalg.norm(r)
    u = np.cross(r, f)
    return View(W=W, H=H, sx=sx, sy=sy, eye=eye, B=np.stack([r, u, -f]), near=float(cam["near"]),
                far=float(cam["far"]), ortho=False)


def knobs(data):
    """The ``imagespace`` knobs this backend implements; the others refused by name."""
    k = dict(data["imagespace"])
    for key, want in {"depth": "bitmask", "peeling": "separate", "endpoint": "probe"}.items():
        if k[key] != want:
            raise NotImplementedError(f"imagespace.{key} = {k[key]!r} is not implemented by the WebGPU "
                                      f"backend (only {want!r})")
    if k.get("grid") is not None:
        raise NotImplementedError("imagespace.grid is not implemented by the WebGPU backend")
    if k["normals"] not in ("central", "forward"):
        raise NotImplementedError(f"imagespace.normals = {k['normals']!r} is not implemented "
                                  "(only 'central' and 'forward')")
    return SimpleNamespace(**k)


def view_params(view, k, mat, env=None, first_ortho=None, record=None):
    """The uniform block of one view: camera, knobs, material and environment."""
    B, eye = view.B, view.eye
    H, W = view.H, view.W
    S = int(k.slices)
    f = 1 if k.bounds == "global" else max(1, -(-max(H, W) // int(k.mip_size)))
    vals = dict(
        r=B[0], u=B[1], b=B[2], c0=B[:, 0], c1=B[:, 1], c2=B[:, 2], t=-eye @ B.T, eye=eye,
        sx=view.sx, sy=view.sy, Wf=W, Hf=H, near=view.near, far=view.far, Sf=S, inv_sm1=1.0 / (S - 1),
        ior=mat["ior"], oior=mat["outside_ior"], bound_margin=k.bound_margin, exit_thr=k.exit_threshold,
        pinf=np.inf, ninf=-np.inf, nan=np.nan, fwd_eps=1e-9,
        W=W, H=H, K=S // 32, NL=int(k.layers), ortho=int(view.ortho), iters=int(k.iterations),
        max_int=int(k.max_interfaces), tir=int(bool(k.tir)), bilinear=int(k.filter == "bilinear"),
        delta=int(k.delta), record=int(k.record if record is None else record), blend_or=int(k.blend == "or"),
        global_slicing=int(k.slicing == "global"), mipf=f, hb=-(-H // f), wb=-(-W // f),
        margin_on=int(k.bounds == "mip"), forward_normals=int(k.normals == "forward"), peel_all=int(bool(k.peel_all)),
        first_ortho=int(view.ortho if first_ortho is None else first_ortho),
        absorption=mat["absorption"], absorb=int(np.any(np.asarray(mat["absorption"]) > 0)),
    )
    if env is not None:
        cols = np.asarray(env.get("colors", [[0.9, 0.9, 0.9], [0.1, 0.1, 0.1]]), np.float64)
        inten = float(env.get("intensity", 1.0))
        vals["col0"] = (cols[0] * inten).astype(np.float32)
        vals["col1"] = (cols[1 if len(cols) > 1 else 0] * inten).astype(np.float32)
        vals["tiles"] = float(env.get("tiles", 48))
        if env.get("type", "checker") == "constant":
            vals["env_const"] = 1
        elif env.get("type", "checker") != "checker":
            raise NotImplementedError(f"environment.type = {env.get('type')!r} is not implemented by the WebGPU "
                                      "backend (checker, constant)")
    return vals


def run_view(view, k, mat, verts, faces, bugs=(), timer=None, env=None, first_ortho=None, record=None,
             stop_after=None, tag="eye"):
    """Every eye pass (``rays`` .. ``shade``) of one view on the GPU; returns GPU buffers and read-backs.

    ``verts`` (V, 3) float32 world, ``faces`` (F, 3) uint32. ``stop_after = "minmax"`` stops there (a
    light's shadow map); ``env`` None skips ``shade``. Buffers are allocated once per
    ``tag`` (the eye, each light) and size, and reused by later frames, as a renderer does; what must
    start cleared is cleared by each frame.
    """
    bugs = tuple(bugs)
    timer = timer or gpu.Timer(enabled=False)
    H, W = view.H, view.W
    n = H * W
    K = int(k.slices) // 32
    NL = int(k.layers)
    vals = view_params(view, k, mat, env, first_ortho, record)
    P = gpu.uniform(params_bytes(vals))
    out = SimpleNamespace(view=view, vals=vals, P=P)

    def buf(name, nbytes, extra=0):
        return gpu.cached((tag, name, int(nbytes), extra), lambda: gpu.storage(nbytes=nbytes, extra=extra))

    with timer("rays"):
        out.rdir = buf("rdir", 16 * n)
        out.vdir = buf("vdir", 16 * n)
        gpu.dispatch(gpu.compute(shader(RAYS, bugs)), [P, out.rdir, out.vdir], (-(-W // 64), H))

    vb = gpu.vertex(np.ascontiguousarray(verts, np.float32))
    ib = gpu.vertex(np.ascontiguousarray(faces, np.uint32).ravel(), index=True)
    cull = "back" if "cull_back" in bugs else "none"
    layout = [(12, [("float32x3", 0, 0)])]
    raster = shader(RASTER, bugs)
    with timer("minmax"):
        zmin_b = buf("zmin_b", 4 * n)
        gpu.write(zmin_b, np.full(n, 0x7F800000, np.uint32))          # +inf's bits
        zmax_b = buf("zmax_b", 4 * n)
        gpu.clear(zmax_b)
        gpu.draw(gpu.render(raster, layout, "vs", "fs_minmax", cull_mode=cull),
                 [P, zmin_b, zmax_b], [vb], faces.size, (W, H), index_buffer=ib)
        out.zmin = buf("zmin", 4 * n)
        out.zmax = buf("zmax", 4 * n)
        out.glob = buf("glob", 8)
        gpu.write(out.glob, np.array([0x7F800000, 0], np.uint32))
        gpu.dispatch(gpu.compute(shader(MINMAX_RESOLVE, bugs)),
                     [P, zmin_b, zmax_b, out.zmin, out.zmax, out.glob], gpu.groups_for(n))
    if stop_after == "minmax":
        return out

    with timer("voxelize"):
        out.zlo = buf("zlo", 4 * n)
        out.zhi = buf("zhi", 4 * n)
        gpu.dispatch(gpu.compute(shader(SLICE_RANGE, bugs)),
                     [P, out.zmin, out.zmax, out.glob, out.zlo, out.zhi], gpu.groups_for(n))
        out.bits = buf("bits", 4 * n * K)
        gpu.clear(out.bits)
        gpu.draw(gpu.render(raster, layout, "vs", "fs_voxelize", cull_mode=cull),
                 [P, None, None, out.zlo, out.zhi, out.bits], [vb], faces.size, (W, H), index_buffer=ib)

    with timer("peel"):
        out.ldi = buf("ldi", 4 * NL * n)
        out.dc = buf("dc", 4 * n)
        out.maxdc = buf("maxdc", 4)
        gpu.clear(out.maxdc)
        gpu.dispatch(gpu.compute(shader(PEEL, bugs)),
                     [P, out.zlo, out.zhi, out.bits, out.ldi, out.dc, out.maxdc],
                     (-(-W // 64), H))

    with timer("reduce"):
        f, hb, wb = vals["mipf"], vals["hb"], vals["wb"]
        if "mip_drop_odd" in bugs:
            hb, wb = max(H // f, 1), max(W // f, 1)
            P2 = gpu.uniform(params_bytes(dict(vals, hb=hb, wb=wb)))
        else:
            P2 = P
        # the layers present (min(layers, depth complexity)) size the next dispatches on the GPU itself
        out.args = buf("args", 36, extra=gpu._flags().INDIRECT)
        gpu.dispatch(gpu.compute(shader(ARGS, bugs)), [P2, out.maxdc, out.args], (1, 1, 1))
        mhi = buf("mhi", 4 * NL * hb * wb)
        mlo = buf("mlo", 4 * NL * hb * wb)
        gpu.dispatch_indirect(gpu.compute(shader(MIP, bugs)), [P2, out.ldi, mhi, mlo], out.args, 0)
        out.bhi = buf("bhi", 4 * NL)
        out.blo = buf("blo", 4 * NL)
        gpu.write(out.bhi, np.full(NL, -np.inf, np.float32))          # layers present nowhere
        gpu.write(out.blo, np.full(NL, np.inf, np.float32))
        gpu.dispatch_indirect(gpu.compute(shader(REDUCE, bugs)), [P2, mhi, mlo, out.glob, out.bhi, out.blo],
                              out.args, 12)

    with timer("normals"):
        out.nrm = buf("nrm", 16 * NL * n)
        gpu.dispatch_indirect(gpu.compute(shader(NORMALS, bugs)),
                              [P, out.ldi, out.nrm], out.args, 24)

    with timer("trace"):
        R = max(int(vals["record"]), 1)
        out.trace = buf("trace", 64 * n)
        out.rec = buf("rec", 32 * n * R)
        gpu.dispatch(gpu.compute(shader(TRACE, bugs)),
                     [P, out.vdir, out.rdir, out.ldi, out.nrm, out.dc, out.zmax,
                      out.zlo, out.zhi, out.bhi, out.blo, out.trace, out.rec], gpu.groups_for(n))

    if env is not None:
        with timer("shade"):
            out.img = buf("img", 16 * n)
            gpu.dispatch(gpu.compute(shader(SHADE, bugs)), [P, out.trace, out.img], gpu.groups_for(n))
    gpu.finish()
    return out


TRACE_DT = np.dtype([("exit_pos", "<f4", 4), ("exit_dir", "<f4", 4), ("last_dir", "<f4", 4), ("plen", "<f4"),
                     ("nint", "<i4"), ("status", "<i4"), ("pad", "<i4")])


def read_trace(out):
    """The trace's per-pixel record back on the host (a structured array, one row per pixel)."""
    return gpu.read(out.trace, TRACE_DT, (out.view.H * out.view.W,))


def read_view(out, k, peel_all=False):
    """The stage buffers of one view, read back, in the contract's names, shapes and dtypes."""
    v = out.view
    H, W = v.H, v.W
    K = int(k.slices) // 32
    NL = int(k.layers)
    f64 = lambda a: np.asarray(a, np.float64)
    st = {}
    st["rays"] = {"ray_origin": np.broadcast_to(f64(np.float32(v.eye)), (H, W, 3)).copy(),
                  "ray_dir": f64(gpu.read(out.rdir, np.float32, (H, W, 4))[..., :3])}
    st["minmax"] = {"zmin": f64(gpu.read(out.zmin, np.float32, (H, W))),
                    "zmax": f64(gpu.read(out.zmax, np.float32, (H, W)))}
    st["voxelize"] = {"bits": gpu.read(out.bits, np.uint32, (H, W, K)),
                      "zlo": f64(gpu.read(out.zlo, np.float32, (H, W))),
                      "zhi": f64(gpu.read(out.zhi, np.float32, (H, W)))}
    maxdc = int(gpu.read(out.maxdc, np.uint32)[0])
    L = NL if peel_all else min(NL, maxdc)
    ldi = gpu.read(out.ldi, np.float32, (NL, H, W))[:L]
    st["peel"] = {"ldi": ldi, "depth_complexity": gpu.read(out.dc, np.int32, (H, W)).astype(np.int16)}
    st["reduce"] = {"bounds_hi": f64(gpu.read(out.bhi, np.float32, (NL,))[:L]),
                    "bounds_lo": f64(gpu.read(out.blo, np.float32, (NL,))[:L])}
    st["normals"] = {"normals": f64(gpu.read(out.nrm, np.float32, (NL, H, W, 4))[:L, ..., :3])}
    tr = read_trace(out)
    trace = {
        "exit_pos": f64(tr["exit_pos"][:, :3]).reshape(H, W, 3),
        "exit_dir": f64(tr["exit_dir"][:, :3]).reshape(H, W, 3),
        "last_dir": f64(tr["last_dir"][:, :3]).reshape(H, W, 3),
        "interfaces": tr["nint"].astype(np.int16).reshape(H, W),
        "path_length": f64(tr["plen"]).reshape(H, W),
        "status": tr["status"].astype(np.int8).reshape(H, W),
    }
    R = int(out.vals["record"])
    if R > 0:
        rec = gpu.read(out.rec, np.float32, (H, W, R, 2, 4))
        trace["path_pos"] = f64(rec[..., 0, :3])
        trace["path_dir"] = f64(rec[..., 1, :3])
    st["trace"] = trace
    if hasattr(out, "img"):
        st["shade"] = {"image": gpu.read(out.img, np.float32, (H, W, 4))[..., :3].copy()}
    return st


# ----------------------------------------------------------------------------- driver
def load_case(scene_path):
    """Scene data (defaults filled by the package's loader), float32 triangles and the shared material."""
    import refraction_ref as rr
    data = rr.load_scene(scene_path).data
    with np.load(os.path.join(os.path.dirname(scene_path), "geometry.npz")) as g:
        V, F = g["vertices"], g["faces"]
    objs = data["objects"]
    mat = {"ior": float(objs[0]["material"]["ior"]) if objs else 1.0,
           "outside_ior": float(data.get("outside_ior", 1.0)),
           "absorption": np.asarray(objs[0]["material"]["absorption"] if objs else [0, 0, 0], np.float64)}
    return data, V, F, mat


def render_case(scene_path, bugs=(), timer=None):
    """All passes for one scene on the GPU; returns the result dict in the golden's key names."""
    bugs = tuple(bugs)
    unknown = set(bugs) - set(all_bugs())
    if unknown:
        raise ValueError(f"unknown planted bug(s) {sorted(unknown)}; known: {sorted(all_bugs())}")
    data, V, F, mat = load_case(scene_path)
    k = knobs(data)
    view = eye_view(data["camera"])
    verts = V.astype(np.float32)
    faces = F.astype(np.uint32)
    out = run_view(view, k, mat, verts, faces, bugs, timer, env=data["environment"])
    st = read_view(out, k, bool(k.peel_all))
    st["geometry"] = {"absorption": np.asarray(mat["absorption"], np.float64)}
    res = {f"stage.{s}.{b}": a for s, bufs in st.items() for b, a in bufs.items()}
    tr = st["trace"]
    res["ray_origin"], res["ray_dir"] = st["rays"]["ray_origin"], st["rays"]["ray_dir"]
    for key in ("exit_pos", "exit_dir", "interfaces", "path_length", "status"):
        res[key] = tr[key]
    res["hit"] = tr["status"] != MISSED
    res["depth_complexity"] = st["peel"]["depth_complexity"]
    caustics = bool(data.get("lights")) and bool(data.get("receivers"))
    res["image_refraction" if caustics else "image"] = st["shade"]["image"]
    if caustics and os.path.exists(os.path.join(HERE, "imagespace_caustics.py")):
        cmod = caustics_module()
        res.update(cmod.run_caustics(SimpleNamespace(**globals()), data, view, k, mat, V, F, out, st, bugs, timer))
    return res


def caustics_module():
    """``imagespace_caustics.py`` beside this file (loaded once)."""
    mod = sys.modules.get("webgpu_imagespace_caustics")
    return mod if mod is not None else _load("imagespace_caustics")


def all_bugs():
    """Every planted bug, the eye passes' and the caustic stages': name -> (pass, what)."""
    b = dict(BUGS)
    if os.path.exists(os.path.join(HERE, "imagespace_caustics.py")):
        b.update(caustics_module().BUGS)
    return b


def imagespace_cases(golden_dir):
    """The image-space cases of a golden suite (``manifest.cases.<case>.method``)."""
    with open(os.path.join(golden_dir, "manifest.json")) as fh:
        man = json.load(fh)
    return sorted(n for n, cs in man["cases"].items() if cs.get("method") == "imagespace")


def run(golden_dir, out_dir, cases=None, bugs=(), timer=None, verbose=False):
    """Write ``out_dir/<case>/result.npz`` for the suite's image-space cases (or ``cases``); returns them."""
    cases = imagespace_cases(golden_dir) if cases is None else list(cases)
    for case in cases:
        t0 = time.perf_counter()
        res = render_case(os.path.join(golden_dir, case, "scene.json"), bugs, timer)
        os.makedirs(os.path.join(out_dir, case), exist_ok=True)
        np.savez(os.path.join(out_dir, case, "result.npz"), **res)
        if verbose:
            print(f"  {case}: {len(res)} arrays, {time.perf_counter() - t0:.1f} s", flush=True)
    return cases


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("golden", help="a golden suite (refraction-ref golden build)")
    ap.add_argument("out", help="the candidate folder to write (CAND/<case>/result.npz)")
    ap.add_argument("--cases", default=None, help="comma-separated cases (default: every image-space case)")
    ap.add_argument("--bug", default="", help="planted bug(s), comma-separated: " + ", ".join(sorted(all_bugs())))
    a = ap.parse_args(argv)
    ok, why = gpu.available()
    if not ok:
        ap.exit(2, f"imagespace.py: {why}\n")
    print(f"adapter: {why}", flush=True)
    run(a.golden, a.out, a.cases.split(",") if a.cases else None, [b for b in a.bug.split(",") if b],
        verbose=True)


if __name__ == "__main__":
    main()
