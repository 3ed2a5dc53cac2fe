"""WGSL of the WebGPU level-map backend (Tipprasert 2006, ch. 4), one shader per pass.

Every buffer and texture here is float32 (or an integer code): the arithmetic of
a shader. ``levelmap.py`` drives them with wgpu-py. Bugs planted for
``refraction-ref check`` are bits of the ``flags`` word each pass reads (the
driver sets them; ``levelmap.BUGS`` lists them), so that a planted bug runs
the same pipeline as the correct backend and changes one expression.

Conventions shared by every shader (``docs/oracle.md``): a receiver's map is
the orthographic view along ``-V`` of its reference box; map coordinates of a
world point ``p``, ``q = p - centre``: ``col = (q.U / w + 0.5) Wc``, ``row =
(q.W / d + 0.5) Hc``, ``zeta = -(q.V)``; texel (i, j) is row i, column j,
row 0 the first row of the texture (WebGPU's top-left origin: NDC ``y = +1``
is framebuffer row 0, so ``ndc_y = 1 - 2 row / Hc``).
"""

# bits of the flags word (levelmap.BUGS maps names to them)
F_PIXEL_CORNER = 1 << 0       # pixel centres at the corner (j, i) instead of (j + 0.5, i + 0.5)
F_Y_FLIP = 1 << 1             # the maps drawn with a bottom-left origin (ndc_y = 2 row / H - 1)
F_HALF_TEXEL_SPLAT = 1 << 2   # the intersection triangles drawn half a texel off the maps' grid
F_NEAREST_NORMAL = 1 << 3     # the water's Phong normal taken from the nearest vertex (no interpolation)
F_LINEAR_LOOKUP = 1 << 4      # the caustics map read by a bilinear fetch where eq. 4-19 takes the texel
F_THRESHOLD_TEST = 1 << 5     # the thesis's literal depth test |zeta - zeta_p| <= eps, not the acceptance index
F_NO_AD_FLOOR = 1 << 6        # A_d not raised to one texel
F_UNNORM_WATER_NORMAL = 1 << 7   # the view's Phong normal not renormalised
F_OTHER_DIAGONAL = 1 << 9     # the water quads split along the other diagonal
F_RECEIVER_COS_AXIS = 1 << 10  # eq. 4-18's receiver cosine against V (the plane) instead of the texel's normal
F_NO_CAST_DEPTH_TEST = 1 << 11  # casting without the depth test
F_DEPTH16 = 1 << 12           # the position map read back from a 16-bit unorm depth buffer
F_DEPTH24 = 1 << 13           # the position map read back from a 24-bit unorm depth buffer


COMMON = r"""
fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    // summed x a0 + y a1 + z a2, left to right (oracle: Porting rules: level map)
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

fn unit(v: vec3<f32>) -> vec3<f32> {
    let n = sqrt(dot3(v, v));
    if (n > 0.0) { return v / n; }
    return vec3<f32>(0.0);
}

// Snell in vector form (eq. 2-8) with the normal turned to face I; w = 1 when k >= 0
fn refract4(I: vec3<f32>, Nin: vec3<f32>, eta: f32) -> vec4<f32> {
    var N = Nin;
    var c = -dot3(I, N);
    if (c < 0.0) { N = -N; c = -c; }
    let k = 1.0 - eta * eta * (1.0 - c * c);
    if (k < 0.0) { return vec4<f32>(0.0, 0.0, 0.0, 0.0); }
    let T = unit(eta * I + (eta * c - sqrt(k)) * N);
    return vec4<f32>(T, 1.0);
}

// the water grid's faces: all (v00, v10, v01) first, then all (v10, v11, v01)
fn water_face(f: u32, n: u32, flags: u32) -> vec3<u32> {
    let half = n * n;
    var cell = f;
    var second = false;
    if (f >= half) { cell = f - half; second = true; }
    let i = cell / n;
    let j = cell % n;
    let v00 = i * (n + 1u) + j;
    let v01 = v00 + 1u;
    let v10 = v00 + n + 1u;
    let v11 = v10 + 1u;
    if ((flags & FLAG_OTHER_DIAGONAL) != 0u) {      // planted: the diagonal (x_j, z_i) - (x_j+1, z_i+1)
        if (second) { return vec3<u32>(v00, v11, v01); }
        return vec3<u32>(v00, v10, v11);
    }
    if (second) { return vec3<u32>(v10, v11, v01); }
    return vec3<u32>(v00, v10, v01);
}
"""


def _flags_consts():
    return "\n".join(f"const FLAG_{k[2:]}: u32 = {v}u;" for k, v in globals().items()
                     if k.startswith("F_") and isinstance(v, int)) + "\n"


# --------------------------------------------------------------------------- water (eqs. 2-8, 4-14)
WATER = r"""
struct Water {
    grid: vec4<f32>,     // n, sx, sz, height
    misc: vec4<f32>,     // eta, waves, lights, 0
    flags: vec4<u32>,
};
@group(0) @binding(0) var<uniform> P: Water;
@group(0) @binding(1) var<storage, read> waves: array<vec4<f32>>;    // (a, lambda, dx, dz), (phase, 0, 0, 0)
@group(0) @binding(2) var<storage, read> lights: array<vec4<f32>>;   // (type, dir), (position, w)
@group(0) @binding(3) var<storage, read_write> verts: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> norms: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> trans: array<vec4<f32>>;  // light-major: (T, ok)
@group(0) @binding(6) var<storage, read_write> beams: array<vec4<f32>>;  // light-major: (axis, flux)

const PI2: f32 = 6.283185307179586;

fn incident(l: u32, p: vec3<f32>) -> vec4<f32> {
    // the incident direction at p and the irradiance factor E (w, or w / r^2 for a point light)
    let a = lights[2u * l];
    let b = lights[2u * l + 1u];
    if (a.x < 0.5) { return vec4<f32>(unit(a.yzw), b.w); }
    let d = p - b.xyz;
    return vec4<f32>(unit(d), b.w / dot3(d, d));
}

@compute @workgroup_size(64)
fn vertices(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = u32(P.grid.x);
    let nv = (n + 1u) * (n + 1u);
    let v = gid.x + gid.y * 65535u * 64u;
    _ = beams[0];                                   // one bind group layout for both entry points
    if (v >= nv) { return; }
    let i = v / (n + 1u);
    let j = v % (n + 1u);
    // linspace(-s/2, s/2, n + 1), the last sample exactly s/2
    var x = -0.5 * P.grid.y + P.grid.y * (f32(j) / f32(n));
    var z = -0.5 * P.grid.z + P.grid.z * (f32(i) / f32(n));
    if (j == n) { x = 0.5 * P.grid.y; }
    if (i == n) { z = 0.5 * P.grid.z; }
    var h = P.grid.w;
    var hx = 0.0;
    var hz = 0.0;
    let nw = u32(P.misc.y);
    for (var k = 0u; k < nw; k = k + 1u) {
        let wa = waves[2u * k];
        let ph = waves[2u * k + 1u].x;
        let dn = sqrt(wa.z * wa.z + wa.w * wa.w);
        let dx = wa.z / dn;
        let dz = wa.w / dn;
        let kk = PI2 / wa.y;
        let arg = kk * (dx * x + dz * z) + ph;
        h = h + wa.x * sin(arg);
        let c = wa.x * kk * cos(arg);
        hx = hx + c * dx;
        hz = hz + c * dz;
    }
    let p = vec3<f32>(x, h, z);
    let N = unit(vec3<f32>(-hx, 1.0, -hz));       // the analytic normal of the height field
    verts[v] = vec4<f32>(p, 0.0);
    norms[v] = vec4<f32>(N, 0.0);
    var eta = P.misc.x;
    let nl = u32(P.misc.z);
    for (var l = 0u; l < nl; l = l + 1u) {
        let I = incident(l, p).xyz;
        let T = refract4(I, N, eta);
        var ok = 0.0;
        if (dot3(I, N) < 0.0 && T.w > 0.5 && T.y < 0.0) { ok = 1.0; }
        trans[l * nv + v] = vec4<f32>(T.xyz, ok);
    }
}

@compute @workgroup_size(64)
fn faces(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = u32(P.grid.x);
    let nv = (n + 1u) * (n + 1u);
    let nf = 2u * n * n;
    let f = gid.x + gid.y * 65535u * 64u;
    _ = waves[0];
    _ = norms[0];
    if (f >= nf) { return; }
    let fv = water_face(f, n, P.flags.x);
    let va = verts[fv.x].xyz;
    let vb = verts[fv.y].xyz;
    let vc = verts[fv.z].xyz;
    let m = cross(vb - va, vc - va);                // 2 A_w n_f
    let centroid = (va + vb + vc) / 3.0;
    let nl = u32(P.misc.z);
    for (var l = 0u; l < nl; l = l + 1u) {
        let ta = trans[l * nv + fv.x];
        let tb = trans[l * nv + fv.y];
        let tc = trans[l * nv + fv.z];
        let inc = incident(l, centroid);
        let proj = -dot3(m, inc.xyz) * 0.5;         // A_w cos(theta_i)
        var flux = 0.0;
        if (ta.w > 0.5 && tb.w > 0.5 && tc.w > 0.5 && proj > 0.0) { flux = inc.w * proj; }
        let s = ta.xyz + tb.xyz + tc.xyz;
        var axis = vec3<f32>(0.0, -1.0, 0.0);
        if (dot3(s, s) > 0.0) { axis = unit(s); }
        beams[l * nf + f] = vec4<f32>(axis, flux);
    }
}
"""

# --------------------------------------------------------------------------- level map (eqs. 4-10 to 4-13)
LEVEL_MAP = r"""
struct Box {
    c: vec4<f32>,        // centre, Hc
    U: vec4<f32>,        // U, Wc
    V: vec4<f32>,        // V, depth range R (clip z = 0.5 + zeta / R)
    W: vec4<f32>,        // W, the receiver r whose map this is
    ext: vec4<f32>,      // w, h, d, 0
    flags: vec4<u32>,
};
@group(0) @binding(0) var<uniform> B: Box;
@group(0) @binding(1) var<storage, read> corners: array<vec4<f32>>;   // per triangle corner: (xyz, receiver)
@group(0) @binding(2) var<storage, read> albedo: array<vec4<f32>>;    // per receiver

struct VOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) zeta: f32,
    @location(1) @interpolate(flat) n: vec3<f32>,
    @location(2) @interpolate(flat) owner: u32,
};

@vertex
fn vs(@builtin(vertex_index) vi: u32) -> VOut {
    let t = vi / 3u;
    let p0 = corners[3u * t].xyz;
    let p1 = corners[3u * t + 1u].xyz;
    let p2 = corners[3u * t + 2u].xyz;
    let cr = corners[vi];
    let q = cr.xyz - B.c.xyz;
    let Hc = B.c.w;
    let Wc = B.U.w;
    let col = (dot3(q, B.U.xyz) / B.ext.x + 0.5) * Wc;
    let row = (dot3(q, B.W.xyz) / B.ext.z + 0.5) * Hc;
    let zeta = -dot3(q, B.V.xyz);
    var o: VOut;
    var ny = 1.0 - row * (2.0 / Hc);
    if ((B.flags.x & FLAG_Y_FLIP) != 0u) { ny = row * (2.0 / Hc) - 1.0; }   // planted: GL's bottom-left
    o.pos = vec4<f32>(col * (2.0 / Wc) - 1.0, ny, 0.5 + zeta / B.V.w, 1.0);
    o.zeta = zeta;
    o.n = unit(cross(p1 - p0, p2 - p0));
    o.owner = u32(cr.w);
    return o;
}

struct FOut {
    @location(0) position: f32,
    @location(1) normal: vec4<f32>,
    @location(2) diffuse: vec4<f32>,      // albedo where the first surface is receiver r; alpha = own
};

@fragment
fn fs(in: VOut) -> FOut {
    var o: FOut;
    o.position = in.zeta;
    // a port that rebuilds zeta from its depth buffer (clip z = 0.5 + zeta / R) gets the buffer's steps
    if ((B.flags.x & FLAG_DEPTH16) != 0u) { o.position = (round(in.pos.z * 65535.0) / 65535.0 - 0.5) * B.V.w; }
    if ((B.flags.x & FLAG_DEPTH24) != 0u) { o.position = (round(in.pos.z * 16777215.0) / 16777215.0 - 0.5) * B.V.w; }
    o.normal = vec4<f32>(in.n, 0.0);
    o.diffuse = vec4<f32>(0.0);
    if (in.owner == u32(B.W.w)) { o.diffuse = vec4<f32>(albedo[in.owner].xyz, 1.0); }
    return o;
}
"""

# --------------------------------------------------------------------------- smart slicing (§4.7.2)
SLICING = r"""
struct Slice {
    a: vec4<f32>,        // h, depth levels L, Hc, Wc
    b: vec4<f32>,        // mode (0 lattice, 1 respace), n_planes, zlo, s
    flags: vec4<u32>,
};
@group(0) @binding(0) var<uniform> S: Slice;
@group(0) @binding(1) var posmap: texture_2d<f32>;
@group(0) @binding(2) var difmap: texture_2d<f32>;
@group(0) @binding(3) var<storage, read_write> hist: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read> level_box: array<i32>;       // per depth level: its sub-box, -1 empty
@group(0) @binding(5) var<storage, read> boxes: array<vec4<f32>>;     // per sub-box: z0, s_b, k_b, first_b
@group(0) @binding(6) var<storage, read_write> pidx: array<i32>;      // per texel: the plane that accepts it
@group(0) @binding(7) var<storage, read_write> bounds: array<atomic<u32>>;  // per plane: min j, min i, max j, max i

fn texel(gid: vec3<u32>) -> vec4<f32> {
    // (zeta, own and finite, i, j); own < 0.5 outside the map
    let Hc = u32(S.a.z);
    let Wc = u32(S.a.w);
    let k = gid.x + gid.y * 65535u * 64u;
    if (k >= Hc * Wc) { return vec4<f32>(0.0, 0.0, -1.0, -1.0); }
    let i = k / Wc;
    let j = k % Wc;
    let z = textureLoad(posmap, vec2<i32>(i32(j), i32(i)), 0).x;
    let own = textureLoad(difmap, vec2<i32>(i32(j), i32(i)), 0).w;
    var ok = 0.0;
    if (own > 0.5 && abs(z) < 3.0e38) { ok = 1.0; }
    return vec4<f32>(z, ok, f32(i), f32(j));
}

fn level_of(z: f32) -> i32 {
    let h = S.a.x;
    return i32(floor((z + h / 2.0) / h * S.a.y));
}

@compute @workgroup_size(64)
fn profile(@builtin(global_invocation_id) gid: vec3<u32>) {
    _ = level_box[0];                               // one bind group layout for both entry points
    _ = boxes[0];
    _ = pidx[0];
    _ = atomicLoad(&bounds[0]);
    let t = texel(gid);
    if (t.y < 0.5) { return; }
    let lv = level_of(t.x);
    if (lv >= 0 && lv < i32(S.a.y)) { atomicAdd(&hist[lv], 1u); }
}

@compute @workgroup_size(64)
fn accept(@builtin(global_invocation_id) gid: vec3<u32>) {
    _ = atomicLoad(&hist[0]);
    let t = texel(gid);
    if (t.z < 0.0) { return; }
    let k = u32(t.z) * u32(S.a.w) + u32(t.w);
    var p = -1;
    if (t.y > 0.5) {
        if (S.b.x > 0.5) {                        // respace: the nearest plane of the texel's own sub-box
            let lv = level_of(t.x);
            if (lv >= 0 && lv < i32(S.a.y)) {
                let b = level_box[lv];
                if (b >= 0) {
                    let bx = boxes[b];
                    var q = 0.0;
                    if (bx.z > 1.5) { q = clamp(floor((t.x - bx.x) / bx.y + 0.5), 0.0, bx.z - 1.0); }
                    p = i32(bx.w + q);
                }
            }
        } else {                                  // the lattice: one floor (eq. 4-15)
            let kf = floor((t.x - S.b.z) / S.b.w);
            if (kf >= 0.0 && kf < S.b.y) { p = i32(kf); }
        }
    }
    pidx[k] = p;
    if (p >= 0) {                                 // the texels each plane accepts: its scissor (§6.1)
        let b = 4u * u32(p);
        atomicMin(&bounds[b], u32(t.w));
        atomicMin(&bounds[b + 1u], u32(t.z));
        atomicMax(&bounds[b + 2u], u32(t.w));
        atomicMax(&bounds[b + 3u], u32(t.z));
    }
}
"""

# --------------------------------------------------------------------------- caustics (eqs. 4-15, 4-18)
BEAMS = r"""
struct Beams {
    c: vec4<f32>,        // box centre, Hc
    U: vec4<f32>,        // U, Wc
    V: vec4<f32>,        // V, K (water.absorption)
    W: vec4<f32>,        // W, the texel's area (w / Wc) (d / Hc)
    ext: vec4<f32>,      // w, h, d, n (water resolution)
    acc: vec4<f32>,      // eps = s / 2 (the thesis's threshold, planted test only), planes in this batch,
                         // 1 when the beams come compacted per plane (culling = bounds), 0
    flags: vec4<u32>,    // bugs, this light's first vertex in trans, its first face in beams, the batch's first plane
};
"""

# each edge ray (water vertex) meets each plane of a batch once: (col, row, lambda, reaches)
INTERSECT = r"""
@group(0) @binding(0) var<uniform> C: Beams;
@group(0) @binding(1) var<storage, read> verts: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> trans: array<vec4<f32>>;    // (T, ok) per light and vertex
@group(0) @binding(3) var<storage, read> planes: array<f32>;         // zeta of each plane drawn
@group(0) @binding(4) var<storage, read_write> hits: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = u32(C.ext.w);
    let nv = (n + 1u) * (n + 1u);
    let k = gid.x + gid.y * 65535u * 64u;
    if (k >= nv * u32(C.acc.y)) { return; }
    let q = k / nv;
    let id = k % nv;
    let zp = planes[C.flags.w + q];
    let Hc = C.c.w;
    let Wc = C.U.w;
    let p = verts[id].xyz - C.c.xyz;
    let T = trans[C.flags.y + id].xyz;
    // the edge ray in map space: origin (col, row, zeta), rates per unit length
    let oc = (dot3(p, C.U.xyz) / C.ext.x + 0.5) * Wc;
    let orow = (dot3(p, C.W.xyz) / C.ext.z + 0.5) * Hc;
    let oz = -dot3(p, C.V.xyz);
    let dc = dot3(T, C.U.xyz) * Wc / C.ext.x;
    let dr = dot3(T, C.W.xyz) * Hc / C.ext.z;
    let dz = -dot3(T, C.V.xyz);
    let lam = (zp - oz) / dz;
    let cc = oc + lam * dc;
    let rr = orow + lam * dr;
    var ok = 1.0;
    if (!(dz > 0.0) || !(lam >= 0.0) || !(abs(cc) < 4194304.0) || !(abs(rr) < 4194304.0)) { ok = 0.0; }
    hits[k] = vec4<f32>(cc, rr, lam, ok);
}
"""

# culling = bounds (§6.1): per plane of a batch, the beams that reach it and can touch the texels it
# accepts, appended to the plane's list; the plane's indirect draw counts them
CULL = r"""
@group(0) @binding(0) var<uniform> C: Beams;
@group(0) @binding(1) var<storage, read> hits: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> beams: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> rects: array<vec4<f32>>;        // per plane: first and last texel (j, i)
@group(0) @binding(4) var<storage, read_write> lists: array<u32>;        // per plane of the batch: its beams
@group(0) @binding(5) var<storage, read_write> args: array<atomic<u32>>; // per plane: indirect draw arguments

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = u32(C.ext.w);
    let nv = (n + 1u) * (n + 1u);
    let nf = 2u * n * n;
    let k = gid.x + gid.y * 65535u * 64u;
    if (k >= nf * u32(C.acc.y)) { return; }
    let q = k / nf;
    let f = k % nf;
    let bm = beams[C.flags.z + f];
    if (!(bm.w > 0.0)) { return; }
    let fv = water_face(f, n, C.flags.x);
    let h0 = hits[q * nv + fv.x];
    let h1 = hits[q * nv + fv.y];
    let h2 = hits[q * nv + fv.z];
    if (h0.w < 0.5 || h1.w < 0.5 || h2.w < 0.5) { return; }
    let p = C.flags.w + q;
    let rc = rects[p];
    if (rc.x > rc.z) { return; }
    // texel centres (j + 0.5, i + 0.5) of the rectangle, one texel of margin for the snap
    if (max(max(h0.x, h1.x), h2.x) < rc.x - 0.5 || min(min(h0.x, h1.x), h2.x) > rc.z + 1.5) { return; }
    if (max(max(h0.y, h1.y), h2.y) < rc.y - 0.5 || min(min(h0.y, h1.y), h2.y) > rc.w + 1.5) { return; }
    let slot = atomicAdd(&args[4u * p], 3u) / 3u;
    lists[q * nf + slot] = f;
}
"""

# the intersection triangles drawn and splatted (eq. 4-15 depth test, eq. 4-18)
CAUSTICS = r"""
@group(0) @binding(0) var<uniform> C: Beams;
@group(0) @binding(1) var<storage, read> hits: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> beams: array<vec4<f32>>;    // (axis, flux) per light and face
@group(0) @binding(3) var<storage, read> planes: array<f32>;         // zeta of each plane drawn
@group(0) @binding(4) var<storage, read> pidx: array<i32>;
@group(0) @binding(5) var posmap: texture_2d<f32>;
@group(0) @binding(6) var nrmmap: texture_2d<f32>;
@group(0) @binding(7) var<storage, read> lists: array<u32>;          // culling = bounds: each plane's beams

struct VOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) lam: f32,                                   // the edge rays' lengths, interpolated
    @location(1) @interpolate(flat) axis: vec4<f32>,         // beam axis t, tdz
    @location(2) @interpolate(flat) bp: vec2<f32>,           // B, plane index
};

@vertex
fn vs(@builtin(vertex_index) vi: u32, @builtin(instance_index) inst: u32) -> VOut {
    let corner = vi % 3u;
    let n = u32(C.ext.w);
    let nv = (n + 1u) * (n + 1u);
    var f = vi / 3u;                                  // every beam, the plane the instance
    var plane = inst;
    if (C.acc.z > 0.5) {                              // compacted: first vertex 3 nf q, the list of plane q
        let nf = 2u * n * n;
        let q = vi / (3u * nf);
        f = lists[q * nf + (vi % (3u * nf)) / 3u];
        plane = C.flags.w + q;
    }
    let fv = water_face(f, n, C.flags.x);
    let Hc = C.c.w;
    let Wc = C.U.w;
    let bm = beams[C.flags.z + f];
    let base = (plane - C.flags.w) * nv;
    let h0 = hits[base + fv.x];
    let h1 = hits[base + fv.y];
    let h2 = hits[base + fv.z];
    var o: VOut;
    if (!(bm.w > 0.0) || h0.w < 0.5 || h1.w < 0.5 || h2.w < 0.5) {
        o.pos = vec4<f32>(-2.0, -2.0, 0.5, 1.0);        // beams that do not reach this plane: no area
        o.lam = 0.0;
        o.axis = vec4<f32>(0.0);
        o.bp = vec2<f32>(0.0, f32(plane));
        return o;
    }
    var hc = h0;
    if (corner == 1u) { hc = h1; }
    if (corner == 2u) { hc = h2; }
    let t = bm.xyz;
    let tdz = -dot3(t, C.V.xyz);
    var inv_tv = 0.0;
    if (tdz > 1e-12) { inv_tv = 1.0 / tdz; }
    let af = (h1.x - h0.x) * (h2.y - h0.y) - (h1.y - h0.y) * (h2.x - h0.x);   // unsnapped, texels
    var ad = max(0.5 * abs(af), 1.0);
    if ((C.flags.x & FLAG_NO_AD_FLOOR) != 0u) { ad = 0.5 * abs(af); }
    let Bv = bm.w * inv_tv / (ad * C.W.w);
    var col = hc.x;
    var row = hc.y;
    if ((C.flags.x & FLAG_HALF_TEXEL_SPLAT) != 0u) { col = col + 0.5; row = row + 0.5; }
    var ny = 1.0 - row * (2.0 / Hc);
    if ((C.flags.x & FLAG_Y_FLIP) != 0u) { ny = row * (2.0 / Hc) - 1.0; }
    o.pos = vec4<f32>(col * (2.0 / Wc) - 1.0, ny, 0.5, 1.0);
    o.lam = hc.z;
    o.axis = vec4<f32>(t, tdz);
    o.bp = vec2<f32>(Bv, f32(plane));
    return o;
}

struct FOut {
    @location(0) total: f32,      // the pair's caustics map (additive)
    @location(1) own: f32,        // this plane's own map (plane_maps)
};

@fragment
fn fs(in: VOut) -> FOut {
    let j = i32(floor(in.pos.x));
    let i = i32(floor(in.pos.y));
    let Wc = i32(C.U.w);
    let plane = u32(in.bp.y);
    let z = textureLoad(posmap, vec2<i32>(j, i), 0).x;
    if ((C.flags.x & FLAG_THRESHOLD_TEST) != 0u) {
        // planted: the thesis's words, |p' - z'| within eps on both sides, on every own texel
        if (pidx[i * Wc + j] < 0) { discard; }                 // not an own texel of this map
        if (!(abs(z - planes[plane]) <= C.acc.x)) { discard; }
    } else {
        if (pidx[i * Wc + j] != i32(plane)) { discard; }     // the depth test: the texel's accepting plane
    }
    var nrm = textureLoad(nrmmap, vec2<i32>(j, i), 0).xyz;
    if ((C.flags.x & FLAG_RECEIVER_COS_AXIS) != 0u) { nrm = C.V.xyz; }
    var g = abs(dot3(in.axis.xyz, nrm));
    let K = C.V.w;
    if (K > 0.0) { g = g * exp(-K * in.lam - (K / in.axis.w) * (z - planes[plane])); }
    var o: FOut;
    o.total = in.bp.x * g;
    o.own = o.total;
    return o;
}
"""

# --------------------------------------------------------------------------- casting (eq. 4-20)
CASTING = r"""
struct Cast {
    a: vec4<f32>,        // Hc, Wc, lights L, receiver r
    flags: vec4<u32>,
};
struct BoxL {             // one light's box for this receiver
    c: vec4<f32>,         // centre, texel size max(w / Wc, d / Hc)
    U: vec4<f32>,         // U, w
    V: vec4<f32>,         // V, h
    W: vec4<f32>,         // W, d
};
@group(0) @binding(0) var<uniform> P: Cast;
@group(0) @binding(1) var<storage, read> boxes: array<BoxL>;
@group(0) @binding(2) var posmaps: texture_2d_array<f32>;     // per light
@group(0) @binding(3) var difmaps: texture_2d_array<f32>;     // per light; alpha = own
@group(0) @binding(4) var nrm0: texture_2d<f32>;              // light 0's normal map
@group(0) @binding(5) var cmaps: texture_2d_array<f32>;       // per light: the caustics maps
@group(0) @binding(6) var<storage, read_write> castmap: array<f32>;   // receivers x Hc x Wc

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let Hc = u32(P.a.x);
    let Wc = u32(P.a.y);
    let k = gid.x + gid.y * 65535u * 64u;
    if (k >= Hc * Wc) { return; }
    let i = k / Wc;
    let j = k % Wc;
    let ij = vec2<i32>(i32(j), i32(i));
    var out = textureLoad(cmaps, ij, 0, 0).x;                 // light 0, whole
    let z0 = textureLoad(posmaps, ij, 0, 0).x;
    let own0 = textureLoad(difmaps, ij, 0, 0).w;
    if (own0 > 0.5 && abs(z0) < 3.0e38) {
        let b0 = boxes[0];
        var ci = f32(j) + 0.5;
        var ri = f32(i) + 0.5;
        if ((P.flags.x & FLAG_PIXEL_CORNER) != 0u) { ci = f32(j); ri = f32(i); }
        let p = b0.c.xyz + ((ci / f32(Wc) - 0.5) * b0.U.w) * b0.U.xyz
                + ((ri / f32(Hc) - 0.5) * b0.W.w) * b0.W.xyz - z0 * b0.V.xyz;
        let n0 = textureLoad(nrm0, ij, 0).xyz;
        let nl = u32(P.a.z);
        for (var l = 1u; l < nl; l = l + 1u) {
            let bl = boxes[l];
            let q = p - bl.c.xyz;
            let col = (dot3(q, bl.U.xyz) / bl.U.w + 0.5) * f32(Wc);
            let row = (dot3(q, bl.W.xyz) / bl.W.w + 0.5) * f32(Hc);
            let z = -dot3(q, bl.V.xyz);
            let a = floor(row);
            let b = floor(col);
            if (a < 0.0 || a >= f32(Hc) || b < 0.0 || b >= f32(Wc)) { continue; }
            let ab = vec2<i32>(i32(b), i32(a));
            if (textureLoad(difmaps, ab, l, 0).w < 0.5) { continue; }
            let tol = 2.0 * max(bl.c.w, b0.c.w) / max(abs(dot3(n0, bl.V.xyz)), 0.05);
            let zl = textureLoad(posmaps, ab, l, 0).x;
            if (!(abs(zl - z) <= tol) && (P.flags.x & FLAG_NO_CAST_DEPTH_TEST) == 0u) { continue; }
            out = out + textureLoad(cmaps, ab, l, 0).x;      // unweighted (eq. 4-20)
        }
    }
    if (!(abs(out) < 3.0e38)) { out = 0.0; }                 // NaN and inf written as 0
    castmap[u32(P.a.w) * Hc * Wc + k] = out;
}
"""

# --------------------------------------------------------------------------- the camera's view (§4.6, eq. 4-19)
VIEW_COMMON = r"""
struct Cam {
    eye: vec4<f32>,      // eye, W
    r: vec4<f32>,        // view x axis, H
    u: vec4<f32>,        // view y axis, sx
    f: vec4<f32>,        // unit view direction, sy
    clip: vec4<f32>,     // near, far, eta, K
    misc: vec4<f32>,     // ambient, receivers, Hc, Wc
    sizes: vec4<f32>,    // water resolution n, supers, 0, 0
    flags: vec4<u32>,
};
struct RBox {            // receiver r's light-0 box: the frame its caustics map is looked up in
    c: vec4<f32>,        // centre, 0
    U: vec4<f32>,        // U, w
    W: vec4<f32>,        // W, d
    albedo: vec4<f32>,
};
"""

VIEW_FUNCS = r"""
fn ray_dir(px: f32, py: f32) -> vec3<f32> {
    // the primary ray through screen point (px, py) (pixel units; the centre of (i, j) is (j + 0.5, i + 0.5))
    let W = cam.eye.w;
    let H = cam.r.w;
    let x = (px / W * 2.0 - 1.0) * cam.u.w;
    let y = (1.0 - py / H * 2.0) * cam.f.w;
    let s = 1.0 / sqrt(x * x + y * y + 1.0);
    return (x * s) * cam.r.xyz + (y * s) * cam.u.xyz + s * cam.f.xyz;   // (x s) r + (y s) u + (-s)(-f)
}

fn pixel_centre(i: u32, j: u32) -> vec2<f32> {
    if ((cam.flags.x & FLAG_PIXEL_CORNER) != 0u) { return vec2<f32>(f32(j), f32(i)); }
    return vec2<f32>(f32(j) + 0.5, f32(i) + 0.5);
}

fn shade(Q: vec3<f32>, r: u32, dist: f32) -> vec3<f32> {
    // eq. 4-19: albedo (I_c + ambient) exp(-K dist), I_c the texel of light 0's box holding Q
    let b = rboxes[r];
    let Hc = cam.misc.z;
    let Wc = cam.misc.w;
    let q = Q - b.c.xyz;
    let col = (dot3(q, b.U.xyz) / b.U.w + 0.5) * Wc;
    let row = (dot3(q, b.W.xyz) / b.W.w + 0.5) * Hc;
    let base = r * u32(Hc) * u32(Wc);
    var Ic = 0.0;
    if ((cam.flags.x & FLAG_LINEAR_LOOKUP) != 0u) {
        // planted: a bilinear fetch (texel centres at +0.5, clamped), as textureSample with a linear filter
        let x = clamp(col - 0.5, 0.0, Wc - 1.0);
        let y = clamp(row - 0.5, 0.0, Hc - 1.0);
        let x0 = floor(x);
        let y0 = floor(y);
        let x1 = min(x0 + 1.0, Wc - 1.0);
        let y1 = min(y0 + 1.0, Hc - 1.0);
        let fx = x - x0;
        let fy = y - y0;
        let w = u32(Wc);
        let a = castmap[base + u32(y0) * w + u32(x0)];
        let bb = castmap[base + u32(y0) * w + u32(x1)];
        let c = castmap[base + u32(y1) * w + u32(x0)];
        let d = castmap[base + u32(y1) * w + u32(x1)];
        Ic = (a * (1.0 - fx) + bb * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy;
    } else {
        let j = u32(clamp(floor(col), 0.0, Wc - 1.0));
        let i = u32(clamp(floor(row), 0.0, Hc - 1.0));
        Ic = castmap[base + i * u32(Wc) + j];
    }
    var tr = 1.0;
    let K = cam.clip.w;
    if (K > 0.0 && dist > 0.0) { tr = exp(-K * dist); }
    return b.albedo.xyz * (Ic + cam.misc.x) * tr;
}
"""

IMAGE_DIRECT = r"""
@group(0) @binding(0) var<uniform> cam: Cam;
@group(0) @binding(1) var<storage, read> corners: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> rboxes: array<RBox>;
@group(0) @binding(3) var<storage, read> castmap: array<f32>;

struct VOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) depth: f32,                          // view depth, perspective-correct
    @location(1) @interpolate(flat) owner: u32,
};

@vertex
fn vs(@builtin(vertex_index) vi: u32) -> VOut {
    let cr = corners[vi];
    let p = cr.xyz - cam.eye.xyz;
    let x = dot3(p, cam.r.xyz);
    let y = dot3(p, cam.u.xyz);
    let d = dot3(p, cam.f.xyz);                       // -z_view
    let near = cam.clip.x;
    let far = cam.clip.y;
    var o: VOut;
    // clip w = d: col = (x / (d sx) / 2 + 1/2) W, row = (1/2 - y / (d sy) / 2) H after the divide
    o.pos = vec4<f32>(x / cam.u.w, y / cam.f.w, (d - near) * (far / (far - near)), d);
    o.depth = d;
    o.owner = u32(cr.w);
    return o;
}

@fragment
fn fs(in: VOut) -> @location(0) vec4<f32> {
    var px = in.pos.xy;
    if ((cam.flags.x & FLAG_PIXEL_CORNER) != 0u) { px = px - vec2<f32>(0.5); }
    let D = ray_dir(px.x, px.y);
    let Q = cam.eye.xyz + D * (in.depth / dot3(D, cam.f.xyz));
    return vec4<f32>(shade(Q, in.owner, 0.0), 1.0);
}
"""

WATER_VIS = r"""
@group(0) @binding(0) var<uniform> cam: Cam;
@group(0) @binding(1) var<storage, read> verts: array<vec4<f32>>;

struct VOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) @interpolate(flat) face: u32,
};

@vertex
fn vs(@builtin(vertex_index) vi: u32) -> VOut {
    let f = vi / 3u;
    let fv = water_face(f, u32(cam.sizes.x), cam.flags.x);
    let p = verts[fv[vi % 3u]].xyz - cam.eye.xyz;
    let x = dot3(p, cam.r.xyz);
    let y = dot3(p, cam.u.xyz);
    let d = dot3(p, cam.f.xyz);
    let near = cam.clip.x;
    let far = cam.clip.y;
    var o: VOut;
    o.pos = vec4<f32>(x / cam.u.w, y / cam.f.w, (d - near) * (far / (far - near)), d);
    o.face = f + 1u;
    return o;
}

@fragment
fn fs(in: VOut) -> @location(0) u32 {
    return in.face;
}
"""

VIEW = r"""
@group(0) @binding(0) var<uniform> cam: Cam;
@group(0) @binding(1) var<storage, read> corners: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> rboxes: array<RBox>;
@group(0) @binding(3) var<storage, read> castmap: array<f32>;
@group(0) @binding(4) var<storage, read> verts: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> norms: array<vec4<f32>>;
@group(0) @binding(6) var vis: texture_2d<u32>;
@group(0) @binding(7) var<storage, read> nodes: array<vec4<f32>>;      // super-clusters, then clusters: (lo, first), (hi, count)
@group(0) @binding(8) var<storage, read> slots: array<u32>;            // triangle index of each clustered slot
@group(0) @binding(9) var<storage, read_write> status: array<i32>;
@group(0) @binding(10) var<storage, read_write> wpos: array<vec4<f32>>;
@group(0) @binding(11) var<storage, read_write> wdir: array<vec4<f32>>;
@group(0) @binding(12) var<storage, read_write> rpos: array<vec4<f32>>;   // receiver point, water length
@group(0) @binding(13) var<storage, read_write> colour: array<vec4<f32>>;

const EPS_BARY: f32 = 1.0e-6;

fn slab(o: vec3<f32>, inv: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>, tmax: f32) -> bool {
    let t0 = (lo - o) * inv;
    let t1 = (hi - o) * inv;
    let tn = max(max(min(t0.x, t1.x), min(t0.y, t1.y)), max(min(t0.z, t1.z), 0.0));
    let tf = min(min(max(t0.x, t1.x), max(t0.y, t1.y)), min(max(t0.z, t1.z), tmax));
    return tn <= tf;
}

// Moller-Trumbore, float32, barycentrics inclusive within EPS_BARY: (t, u, v, hit)
fn mt(o: vec3<f32>, D: vec3<f32>, v0: vec3<f32>, v1: vec3<f32>, v2: vec3<f32>) -> vec4<f32> {
    let e1 = v1 - v0;
    let e2 = v2 - v0;
    let pv = cross(D, e2);
    let det = dot3(e1, pv);
    if (det == 0.0) { return vec4<f32>(0.0, 0.0, 0.0, 0.0); }
    let inv = 1.0 / det;
    let tv = o - v0;
    let u = dot3(tv, pv) * inv;
    let qv = cross(tv, e1);
    let v = dot3(D, qv) * inv;
    let t = dot3(e2, qv) * inv;
    return vec4<f32>(t, u, v, 1.0);
}

// the first receiver triangle along o + t D (t >= 0): (t on the triangle's plane, triangle, hit)
fn first_receiver(o: vec3<f32>, D: vec3<f32>) -> vec3<f32> {
    let inv = 1.0 / D;
    var best = 3.0e38;
    var bi = 0xffffffffu;
    let ns = u32(cam.sizes.y);
    for (var s = 0u; s < ns; s = s + 1u) {
        let a = nodes[2u * s];
        let b = nodes[2u * s + 1u];
        if (!slab(o, inv, a.xyz, b.xyz, best)) { continue; }
        let c0 = u32(a.w);
        let c1 = c0 + u32(b.w);
        for (var c = c0; c < c1; c = c + 1u) {
            let ca = nodes[2u * c];
            let cb = nodes[2u * c + 1u];
            if (!slab(o, inv, ca.xyz, cb.xyz, best)) { continue; }
            let t0 = u32(ca.w);
            let t1 = t0 + u32(cb.w);
            for (var k = t0; k < t1; k = k + 1u) {
                let tri = slots[k];
                let h = mt(o, D, corners[3u * tri].xyz, corners[3u * tri + 1u].xyz, corners[3u * tri + 2u].xyz);
                if (h.w < 0.5) { continue; }
                if (h.y < -EPS_BARY || h.z < -EPS_BARY || h.y + h.z > 1.0 + EPS_BARY) { continue; }
                if (!(h.x >= 0.0)) { continue; }
                if (h.x < best || (h.x == best && tri < bi)) { best = h.x; bi = tri; }
            }
        }
    }
    if (bi == 0xffffffffu) { return vec3<f32>(0.0, 0.0, 0.0); }
    // the hit recomputed on the triangle's plane (v0, (v1 - v0) x (v2 - v0))
    let v0 = corners[3u * bi].xyz;
    let n = cross(corners[3u * bi + 1u].xyz - v0, corners[3u * bi + 2u].xyz - v0);
    let dn = dot3(D, n);
    var t = 0.0;
    if (dn != 0.0) { t = dot3(v0 - o, n) / dn; }
    return vec3<f32>(t, f32(bi), 1.0);
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let W = u32(cam.eye.w);
    let H = u32(cam.r.w);
    let j = gid.x;
    let i = gid.y;
    if (i >= H || j >= W) { return; }
    let k = i * W + j;
    let pc = pixel_centre(i, j);
    let D = ray_dir(pc.x, pc.y);
    let eye = cam.eye.xyz;
    let nanv = bitcast<f32>(0x7fc00000u);
    let nan4 = vec4<f32>(nanv, nanv, nanv, nanv);
    var st = 0;
    var P = nan4;
    var Tw = nan4;
    var origin = eye;
    var dir = D;
    let face = textureLoad(vis, vec2<i32>(i32(j), i32(i)), 0).x;
    if (face > 0u) {
        let fv = water_face(face - 1u, u32(cam.sizes.x), cam.flags.x);
        let va = verts[fv.x].xyz;
        let vb = verts[fv.y].xyz;
        let vc = verts[fv.z].xyz;
        // Moller-Trumbore twice: from the eye, then again from that estimate of the hit (origin
        // re-based): the barycentrics from a far origin lose |eye - v0| / |edge| ulps in float32
        let h0 = mt(eye, D, va, vb, vc);
        let o2 = eye + h0.x * D;
        let h = mt(o2, D, va, vb, vc);
        let u = h.y;
        let v = h.z;
        let p = o2 + h.x * D;
        var n = (1.0 - u - v) * norms[fv.x].xyz + u * norms[fv.y].xyz + v * norms[fv.z].xyz;
        if ((cam.flags.x & FLAG_NEAREST_NORMAL) != 0u) {
            n = norms[fv.x].xyz;
            if (u >= v && u >= 1.0 - u - v) { n = norms[fv.y].xyz; }
            if (v > u && v >= 1.0 - u - v) { n = norms[fv.z].xyz; }
        }
        if ((cam.flags.x & FLAG_UNNORM_WATER_NORMAL) == 0u) { n = unit(n); }
        var eta = cam.clip.z;
        let T = refract4(D, n, eta);
        P = vec4<f32>(p, 0.0);
        if (T.w < 0.5) {
            st = 4;                                    // totally reflected: black, not followed
        } else {
            st = 1;
            Tw = vec4<f32>(T.xyz, 0.0);
            origin = p;
            dir = T.xyz;
        }
    } else {
        st = 3;
    }
    var Q = nan4;
    var col = vec3<f32>(0.0);
    if (st == 1 || st == 3) {
        let hit = first_receiver(origin, dir);
        if (hit.z > 0.5) {
            let q = origin + hit.x * dir;
            let owner = u32(corners[3u * u32(hit.y)].w);
            var dist = 0.0;
            if (st == 1) { dist = length(q - origin); }
            Q = vec4<f32>(q, dist);
            col = shade(q, owner, dist);
        } else {
            if (st == 1) { st = 2; } else { st = 0; }
        }
    }
    status[k] = st;
    wpos[k] = P;
    wdir[k] = Tw;
    rpos[k] = Q;
    colour[k] = vec4<f32>(col, 0.0);
}
"""


def source(*parts):
    """A WGSL module: the flag constants, the shared functions and ``parts``."""
    return _flags_consts() + COMMON + "".join(parts)
