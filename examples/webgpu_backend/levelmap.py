"""A WebGPU backend of the level-map method (Tipprasert 2006, ch. 4), in WGSL driven by wgpu-py.

Written from ``docs/oracle.md`` ("Porting rules: level map", "Level map",
"Stage buffers", "Conformance") and ``docs/backends.md`` alone, by an author
who did not read the package's source, and shaped as the thesis's GPU passes:

``water``
    a compute shader per water vertex (the height field, its analytic
    normal, eq. 2-8 per light) and per face (the illumination volume,
    eq. 4-14: beam axis and flux).
``planes``
    the reference box and its planes (eqs. 4-1 to 4-9): view-volume set-up,
    computed on the host in float64 as the thesis sets up its orthographic
    view (``glOrtho``); float32 cannot hold the contract's 1e-7 set-up
    tolerance (``LEVELMAP.md``).
``level_map``
    the position, normal and diffuse maps drawn by the **render pipeline**:
    every receiver triangle seen orthographically along ``-V``, depth test
    ``less`` (nearest wins, ties to the earlier triangle), no culling, three
    colour targets.
``caustics``
    smart slicing (a compute shader profiles the position map's depth levels
    with atomics; the host lays the sub-boxes' planes, as the thesis reads
    its profile back; a compute shader writes each texel's accepting plane),
    then per plane one draw of every beam's intersection triangle (vertex
    pulling: the vertex shader intersects the beam's three edge rays with the
    plane, eq. 4-15), the fragment shader's depth test against the texel's
    accepting plane and eq. 4-18, **additively blended** into an ``r32float``
    caustics map (and the plane's own layer, ``plane_maps``).
``casting``
    a compute shader per texel of light 0's map: the other lights' maps cast
    into it by projective texturing with a depth test (eq. 4-20).
``image``
    ``image_direct`` drawn by the render pipeline (the receivers from the
    camera, nearest fragment, eq. 4-19 in the fragment shader); ``image``:
    the water mesh drawn from the camera into a face-id target (a visibility
    buffer), then a compute shader per pixel: Moller-Trumbore on that face,
    the renormalised Phong normal, Snell, a ray cast against the receivers
    (two-level clusters of triangles) and eq. 4-19.

Arithmetic is float32 throughout on the device; the stage buffers are read
back and written with the contract's dtypes for ``refraction-ref check``.

Usage::

    python examples/webgpu_backend/levelmap.py GOLDEN_DIR CAND_DIR [--cases a,b] [--bug NAME]
    refraction-ref check CAND_DIR --golden GOLDEN_DIR

References
----------
N. Tipprasert, *An Interactive Rendering Method for Water-Side Scene with
Caustics Using Level Map Method*, M.Eng. thesis, Chulalongkorn University,
2006: §4.2.1 (eqs. 4-1 to 4-9), §4.2.2 (eqs. 4-10 to 4-13), §4.3 (eqs. 2-8,
4-14), §4.4-4.5 (eqs. 4-15 to 4-18, Fig. 4-15), §4.6 (eq. 4-19), §4.7.1
(eq. 4-20, Fig. 4-17), §4.7.2 (smart slicing, eqs. 4-21, 4-22).
"""
from __future__ import annotations

import importlib.util
import json
import os
import sys
import tempfile
import time
from contextlib import contextmanager

import numpy as np

os.environ.setdefault("XDG_RUNTIME_DIR", tempfile.gettempdir())   # silences wgpu-native's loader warning

HERE = os.path.dirname(os.path.abspath(__file__))


def _load(name):
    spec = importlib.util.spec_from_file_location(f"webgpu_{name}", os.path.join(HERE, f"{name}.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


S = _load("levelmap_wgsl")

INSTALL_LINES = ("apt-get install -y mesa-vulkan-drivers", 'pip install -e ".[webgpu]"')

#: Planted bugs: name -> (what a porter does, how it is planted). Flags are bits the shaders read.
BUGS = {
    "pixel_corner": "pixel centres at the corner (j, i) instead of (j + 0.5, i + 0.5): the camera's "
                    "primary rays and casting's texel centres",
    "y_flip": "the maps drawn with OpenGL's bottom-left origin (ndc_y = 2 row / Hc - 1) in WebGPU, "
              "whose framebuffer row 0 is the top",
    "cull_back": "back faces culled (cull_mode back, front ccw) in every render pipeline: folded beams vanish",
    "nearest_normal": "the water's normal at the eye ray's hit taken from the nearest vertex, not "
                      "interpolated (nearest sampling where the contract blends)",
    "linear_lookup": "the caustics map read with a bilinear fetch where eq. 4-19 takes the texel that holds the point",
    "depth16": "the position map rebuilt from a 16-bit unorm depth buffer (depth16unorm)",
    "depth24": "the position map rebuilt from a 24-bit unorm depth buffer (depth24plus) over the scene's depth range",
    "half_texel_splat": "the caustics map half a texel off: intersection triangles drawn at col + 0.5, row + 0.5",
    "no_blend": "the splat without additive blending (blend replace: the last fragment wins)",
    "threshold_test": "the thesis's literal depth test |p' - z'| <= eps (eq. 4-15) on both sides, not one floor",
    "no_ad_floor": "A_d not raised to one texel (eq. 4-18 as the thesis writes it)",
    "other_diagonal": "the water quads split along the other diagonal",
    "inverted_eta": "water.ior / outside_ior for the relative index at the water",
    "receiver_cos_axis": "eq. 4-18's receiver cosine taken against the plane normal V, not the texel's normal",
    "unnormalised_water_normal": "the view's Phong normal not renormalised",
}
_FLAG = {"depth16": S.F_DEPTH16, "depth24": S.F_DEPTH24, "pixel_corner": S.F_PIXEL_CORNER, "y_flip": S.F_Y_FLIP, "half_texel_splat": S.F_HALF_TEXEL_SPLAT,
         "nearest_normal": S.F_NEAREST_NORMAL, "linear_lookup": S.F_LINEAR_LOOKUP,
         "threshold_test": S.F_THRESHOLD_TEST, "no_ad_floor": S.F_NO_AD_FLOOR,
         "unnormalised_water_normal": S.F_UNNORM_WATER_NORMAL, "other_diagonal": S.F_OTHER_DIAGONAL,
         "receiver_cos_axis": S.F_RECEIVER_COS_AXIS}


# =============================================================================== device
class Gpu:
    """The process's wgpu device and the pipelines compiled on it (once per source and state).

    Its own device (not ``gpu.py``'s shared one): the additive splat needs ``float32-blendable``
    and the maps' ``r32float`` textures bound for ``textureLoad`` ``float32-filterable``.
    """

    _inst = None

    def __init__(self):
        import wgpu
        self.wgpu = wgpu
        self.adapter = wgpu.gpu.request_adapter_sync(power_preference="high-performance")
        if self.adapter is None:
            raise RuntimeError("no wgpu adapter")
        need = ["float32-blendable", "float32-filterable"]
        missing = [f for f in need if f not in self.adapter.features]
        if missing:
            raise RuntimeError(f"the adapter lacks {missing}")
        lim = self.adapter.limits
        self.device = self.adapter.request_device_sync(
            required_features=need,
            required_limits={k: lim[k] for k in ("max-storage-buffer-binding-size", "max-buffer-size",
                                                 "max-storage-buffers-per-shader-stage",
                                                 "max-color-attachment-bytes-per-sample") if k in lim})
        self.cache = {}

    @classmethod
    def get(cls):
        if cls._inst is None:
            cls._inst = Gpu()
        return cls._inst

    def describe(self):
        i = self.adapter.info
        return f"{i['device']}, {i['adapter_type']}, {i['backend_type']}"

    # ---- buffers and textures
    def storage(self, data=None, nbytes=None):
        U = self.wgpu.BufferUsage
        usage = U.STORAGE | U.COPY_SRC | U.COPY_DST
        if data is not None:
            a = np.ascontiguousarray(data)
            if a.nbytes == 0:
                a = np.zeros(4, np.uint32)
            return self.device.create_buffer_with_data(data=a, usage=usage)
        return self.device.create_buffer(size=max(int(nbytes), 16), usage=usage)

    def uniform(self, *vec4s):
        """A uniform buffer of vec4 rows; each row 4 float32 or (tagged "u") 4 uint32."""
        raw = b""
        for row in vec4s:
            if isinstance(row, tuple) and row and row[0] == "u":
                raw += np.asarray(list(row[1:]) + [0] * (5 - len(row)), np.uint32).tobytes()
            else:
                raw += np.asarray(list(row) + [0] * (4 - len(row)), np.float32).tobytes()
        U = self.wgpu.BufferUsage
        return self.device.create_buffer_with_data(data=raw, usage=U.UNIFORM | U.COPY_DST)

    def read(self, buf, dtype, shape):
        a = np.frombuffer(self.device.queue.read_buffer(buf), dtype=dtype)
        return a[:int(np.prod(shape))].reshape(shape).copy()

    def texture(self, w, h, layers, fmt, render=True, storage=False):
        U = self.wgpu.TextureUsage
        usage = U.TEXTURE_BINDING | U.COPY_SRC | U.COPY_DST
        if render:
            usage |= U.RENDER_ATTACHMENT
        if storage:
            usage |= U.STORAGE_BINDING
        return self.device.create_texture(size=(int(w), int(h), int(layers)), format=fmt, usage=usage)

    def read_texture(self, tex, layer, dtype, channels=1):
        W, H, _ = tex.size
        bpr = W * np.dtype(dtype).itemsize * channels
        raw = self.device.queue.read_texture({"texture": tex, "origin": (0, 0, int(layer)), "mip_level": 0},
                                             {"offset": 0, "bytes_per_row": bpr, "rows_per_image": H},
                                             (W, H, 1))
        a = np.frombuffer(raw, dtype=dtype)[:H * W * channels]
        return a.reshape((H, W, channels) if channels > 1 else (H, W)).copy()

    @staticmethod
    def layer(tex, l, array=False):
        if array:
            return tex.create_view(dimension="2d-array")
        return tex.create_view(dimension="2d", base_array_layer=int(l), array_layer_count=1)

    # ---- pipelines
    def module(self, src):
        m = self.cache.get(("module", src))
        if m is None:
            m = self.device.create_shader_module(code=src)
            self.cache[("module", src)] = m
        return m

    def compute(self, src, entry):
        k = ("compute", src, entry)
        p = self.cache.get(k)
        if p is None:
            p = self.device.create_compute_pipeline(layout="auto",
                                                    compute={"module": self.module(src), "entry_point": entry})
            self.cache[k] = p
        return p

    def render(self, src, targets, depth=None, cull="none"):
        """A render pipeline of ``vs``/``fs``; ``targets`` is a list of (format, blend or None)."""
        k = ("render", src, repr(targets), depth, cull)
        p = self.cache.get(k)
        if p is None:
            m = self.module(src)
            ts = []
            for fmt, blend in targets:
                t = {"format": fmt}
                if blend is not None:
                    t["blend"] = blend
                ts.append(t)
            kw = {}
            if depth is not None:
                kw["depth_stencil"] = {"format": depth, "depth_write_enabled": True, "depth_compare": "less"}
            p = self.device.create_render_pipeline(
                layout="auto", vertex={"module": m, "entry_point": "vs", "buffers": []},
                primitive={"topology": "triangle-list", "cull_mode": cull, "front_face": "ccw"},
                fragment={"module": m, "entry_point": "fs", "targets": ts}, **kw)
            self.cache[k] = p
        return p

    def bind(self, pipeline, resources):
        entries = []
        for i, r in enumerate(resources):
            if r is None:
                continue
            if isinstance(r, self.wgpu.GPUBuffer):
                entries.append({"binding": i, "resource": {"buffer": r, "offset": 0, "size": r.size}})
            else:
                entries.append({"binding": i, "resource": r})
        return self.device.create_bind_group(layout=pipeline.get_bind_group_layout(0), entries=entries)

    def dispatch(self, pipeline, resources, n, size=64, enc=None):
        own = enc is None
        enc = enc or self.device.create_command_encoder()
        cp = enc.begin_compute_pass()
        cp.set_pipeline(pipeline)
        cp.set_bind_group(0, self.bind(pipeline, resources))
        if isinstance(n, tuple):
            cp.dispatch_workgroups(*n)
        else:
            g = max(1, -(-int(n) // size))
            cp.dispatch_workgroups(min(g, 65535), -(-g // 65535), 1)
        cp.end()
        if own:
            self.device.queue.submit([enc.finish()])

    def finish(self):
        """Wait for the queue: read back a 16-byte buffer (mapping it waits for all earlier work).

        ``queue.on_submitted_work_done_sync`` raises a cffi TypeError in wgpu-py 0.32 on wgpu-native.
        """
        if "fence" not in self.cache:
            self.cache["fence"] = self.storage(nbytes=16)
        self.device.queue.read_buffer(self.cache["fence"])


def available():
    """``(True, adapter)`` when wgpu and an adapter with the features are there, else ``(False, why)``."""
    try:
        import wgpu  # noqa: F401
    except Exception as exc:
        return False, f"wgpu is not importable ({exc!r}); install: {'; '.join(INSTALL_LINES)}"
    try:
        return True, Gpu.get().describe()
    except Exception as exc:
        return False, f"no usable wgpu adapter ({exc}); install: {'; '.join(INSTALL_LINES)}"


class Timer:
    """Per-pass wall-clock milliseconds, the queue drained at both ends (``with timer("water"):``)."""

    def __init__(self, gpu):
        self.gpu = gpu
        self.times = {}

    @contextmanager
    def __call__(self, name):
        self.gpu.finish()
        t0 = time.perf_counter()
        yield
        self.gpu.finish()
        self.times[name] = self.times.get(name, 0.0) + (time.perf_counter() - t0) * 1e3


# =============================================================================== scene (host)
def _unit(v):
    v = np.asarray(v, np.float64)
    n = np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2])
    return v / n[..., None] if v.ndim > 1 else v / n


def _dot(p, a):
    return p[..., 0] * a[0] + p[..., 1] * a[1] + p[..., 2] * a[2]


def resolve(scene):
    """The blocks the level map reads, defaults filled in (oracle: Scene blocks, levelmap, water, caustics)."""
    cam = {"eye": [0, 0, 2.6], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y": 30, "width": 512,
           "height": 512, "near": 0.1, "far": 10}
    cam.update(scene.get("camera") or {})
    water = {"size": [4, 4], "height": 0.0, "resolution": 128, "ior": 1.33, "absorption": 0.0, "waves": []}
    water.update(scene.get("water") or {})
    water["waves"] = [dict({"amplitude": 0.02, "wavelength": 0.5, "direction": [1, 0], "phase": 0.0}, **w)
                      for w in water["waves"]]
    lm = {"planes": 50, "smart_spacing": "respace", "culling": "none", "smart_slicing": True,
          "depth_levels": 32, "variant": "levelmap"}
    ca = {"map_size": 512, "placement": "component", "shadows": True, "ambient": 0.1}
    for k, v in (scene.get("levelmap") or {}).items():
        (ca if k in ca else lm)[k] = v          # levelmap.map_size etc.: aliases of the caustics block
    ca.update({k: v for k, v in (scene.get("caustics") or {}).items() if k in ca})
    if lm["variant"] != "levelmap" or lm["smart_spacing"] not in ("respace", "lattice"):
        raise ValueError("webgpu levelmap ports variant = levelmap with smart_spacing respace (or lattice "
                         "with smart slicing off)")
    if lm["smart_slicing"] and lm["smart_spacing"] != "respace":
        raise ValueError("webgpu levelmap: smart_spacing = lattice with smart slicing is not ported")
    lights = [dict({"type": "directional", "direction": [0, -1, 0], "position": None, "radiance": [1, 1, 1]}, **l)
              for l in scene.get("lights", [{}])]
    return cam, water, lm, ca, lights, scene.get("receivers") or [], float(scene.get("outside_ior", 1.0))


def builtin_mesh(name, size=None):
    """A receiver mesh before placement (oracle: Built-in meshes)."""
    if name == "plane":
        sx, sz = size if size is not None else (4.0, 4.0)
        v = np.array([[-sx / 2, 0, -sz / 2], [sx / 2, 0, -sz / 2], [sx / 2, 0, sz / 2], [-sx / 2, 0, sz / 2]],
                     np.float64)
        return v, np.array([[0, 2, 1], [0, 3, 2]], np.int64)
    import trimesh
    if name == "sphere":
        m = trimesh.creation.icosphere(subdivisions=5, radius=0.5)
    else:
        path = name if os.path.exists(str(name)) else None
        if path is None:                       # the other built-ins ship as files of the package's data
            import refraction_ref
            cand = os.path.join(os.path.dirname(refraction_ref.__file__), "data", f"{name}.ply")
            path = cand if os.path.exists(cand) else None
        if path is None:
            raise ValueError(f"webgpu levelmap: receiver mesh {name!r} not found")
        m = trimesh.load(path, force="mesh")
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def place(rec):
    """World vertices, faces, origin P0 and albedo of a receiver (oracle: Conventions, mesh placement)."""
    v, f = builtin_mesh(rec.get("mesh", "plane"), rec.get("size"))
    if rec.get("fit") is not None:
        lo, hi = v.min(0), v.max(0)
        v = (v - (lo + hi) / 2) * (float(rec["fit"]) / np.max(hi - lo))
    t = rec.get("transform") or {}
    ax, ay, az = np.radians(np.asarray(t.get("rotate", [0, 0, 0]), np.float64))
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    R = rz @ ry @ rx
    p0 = np.asarray(t.get("translate", [0, 0, 0]), np.float64)
    vs = v * float(t.get("scale", 1.0))
    w = np.stack([_dot(vs, R[0]), _dot(vs, R[1]), _dot(vs, R[2])], -1) + p0
    return w, f, p0, np.asarray(rec.get("albedo", [0.8, 0.8, 0.8]), np.float64)


def refract64(I, N, eta):
    """Eq. 2-8 on the host (float64 set-up; float32 when given float32): T or None under total reflection."""
    c = -(I[0] * N[0] + I[1] * N[1] + I[2] * N[2])
    if c < 0:
        N, c = -N, -c
    k = 1.0 - eta * eta * (1.0 - c * c)
    if k < 0:
        return None
    return _unit(eta * I + (eta * c - np.sqrt(k)) * N)


# =============================================================================== passes
def water_pass(gpu, water, lights, eta, flags):
    """Vertices, normals, refracted directions and illumination volumes (compute; eqs. 2-8, 4-14)."""
    n = int(water["resolution"])
    nv, nf, L = (n + 1) ** 2, 2 * n * n, len(lights)
    wav = []
    for w in water["waves"]:
        wav += [[w["amplitude"], w["wavelength"], w["direction"][0], w["direction"][1]], [w["phase"], 0, 0, 0]]
    lig = []
    for li in lights:
        w = float(np.mean(li["radiance"]))
        if li["type"] == "point":
            lig += [[1, 0, 0, 0], list(li["position"]) + [w]]
        else:
            lig += [[0] + list(li["direction"]), [0, 0, 0, w]]
    u = gpu.uniform((n, water["size"][0], water["size"][1], water["height"]),
                    (eta, len(water["waves"]), L, 0), ("u", flags))
    bw = gpu.storage(np.asarray(wav or [[0, 1, 1, 0], [0, 0, 0, 0]], np.float32))
    bl = gpu.storage(np.asarray(lig, np.float32))
    verts, norms = gpu.storage(nbytes=16 * nv), gpu.storage(nbytes=16 * nv)
    trans, beams = gpu.storage(nbytes=16 * nv * L), gpu.storage(nbytes=16 * nf * L)
    src = S.source(S.WATER)
    res = [u, bw, bl, verts, norms, trans, beams]
    enc = gpu.device.create_command_encoder()
    gpu.dispatch(gpu.compute(src, "vertices"), res, nv, enc=enc)
    gpu.dispatch(gpu.compute(src, "faces"), res, nf, enc=enc)
    gpu.device.queue.submit([enc.finish()])
    return {"n": n, "nv": nv, "nf": nf, "verts": verts, "norms": norms, "trans": trans, "beams": beams}


def planes_pass(rverts, p0, light, eta, n_planes, placement, dt=np.float64):
    """The reference box and its lattice of planes (eqs. 4-1 to 4-9) on the host, in float64.

    ``dt = np.float32`` does the same arithmetic in float32 (the ``setup = "float32"`` experiment:
    what a port computing its view volumes in shader precision gets).
    """
    rverts, p0, eta = np.asarray(rverts, dt), np.asarray(p0, dt), dt(eta)
    if light["type"] == "point":
        Ld = _unit(p0 - np.asarray(light["position"], dt))
    else:
        Ld = _unit(np.asarray(light["direction"], dt))
    T0 = refract64(Ld, np.array([0.0, 1.0, 0.0], dt), eta)
    T0 = _unit(T0)
    V = -T0
    N = np.array([0.0, 0.0, 1.0], dt) if abs(V[2]) < 0.9 else np.array([1.0, 0.0, 0.0], dt)
    U = _unit(np.cross(V, N))
    W = _unit(np.cross(U, V))
    q = rverts - p0
    loc = np.stack([_dot(q, U), _dot(q, V), _dot(q, W)], -1)
    centre = p0.copy()
    if placement == "component":
        ext = 2.0 * np.abs(loc).max(0)
    elif placement == "thesis":
        far = np.argmax(np.abs(loc), axis=0)
        ext = 2.0 * np.sqrt(np.sum(loc[far] ** 2, axis=1))
    elif placement == "tight":
        lo, hi = loc.min(0), loc.max(0)
        mid = (lo + hi) / 2
        centre = p0 + mid[0] * U + mid[1] * V + mid[2] * W
        ext = hi - lo
    else:
        raise ValueError(f"placement {placement!r}")
    ext = np.maximum(ext, dt(1e-6) * ext.max())
    w, h, d = ext
    if placement == "tight":
        s = h / dt(n_planes)
        zeta = -h / 2 + s * (np.arange(n_planes, dtype=dt) + dt(0.5))
        zlo = -h / 2
    elif n_planes == 1:
        s, zeta, zlo = h, np.zeros(1, dt), -h / 2
    else:
        s = h / dt(n_planes - 1)
        zeta = -h / 2 + s * np.arange(n_planes, dtype=dt)
        zlo = -h / dt(2.0) - s / dt(2.0)
    box = np.stack([centre, U, V, W, np.array([w, h, d], dt)])
    return {"box": box, "zeta": zeta, "s": s, "zlo": zlo, "n": n_planes, "tight": placement == "tight"}


def frame(box):
    """caustic_frame_r: (origin, u, v, normal) of a box (oracle: Map frame and texel centres), in its dtype."""
    c, U, V, W, (w, h, d) = box
    u, v = w * U, d * W
    return np.stack([c - u / 2 - v / 2 + (h / 2) * V, u, v, V])


def _box_rows(box, Hc, Wc):
    c, U, V, W, ext = [np.asarray(x, np.float64) for x in box]
    return c, U, V, W, ext


def level_map_pass(gpu, corners, albedo, box, r, R_depth, Hc, Wc, tex, l, flags, bugs):
    """The position, normal and diffuse maps of (r, l): the receivers drawn along -V (render pipeline)."""
    c, U, V, W, ext = _box_rows(box, Hc, Wc)
    u = gpu.uniform(tuple(c) + (Hc,), tuple(U) + (Wc,), tuple(V) + (R_depth,), tuple(W) + (r,),
                    tuple(ext) + (0,), ("u", flags))
    cull = "back" if "cull_back" in bugs else "none"
    p = gpu.render(S.source(S.LEVEL_MAP), [("r32float", None), ("rgba32float", None), ("rgba32float", None)],
                   depth="depth32float", cull=cull)
    depth = gpu.texture(Wc, Hc, 1, "depth32float", render=True)
    enc = gpu.device.create_command_encoder()
    rp = enc.begin_render_pass(
        color_attachments=[
            {"view": gpu.layer(tex["pos"], l), "load_op": "clear", "store_op": "store",
             "clear_value": (np.inf, 0, 0, 0)},
            {"view": gpu.layer(tex["nrm"], l), "load_op": "clear", "store_op": "store", "clear_value": (0, 0, 0, 0)},
            {"view": gpu.layer(tex["dif"], l), "load_op": "clear", "store_op": "store", "clear_value": (0, 0, 0, 0)}],
        depth_stencil_attachment={"view": depth.create_view(), "depth_load_op": "clear", "depth_store_op": "store",
                                  "depth_clear_value": 1.0})
    rp.set_pipeline(p)
    rp.set_bind_group(0, gpu.bind(p, [u, corners, albedo]))
    rp.draw(int(corners.size // 16))
    rp.end()
    gpu.device.queue.submit([enc.finish()])


def slicing_pass(gpu, pl, lm, Hc, Wc, tex, l, flags, dt=np.float64):
    """Smart slicing (§4.7.2): the depth profile on the device, the planes laid on the host, the acceptance map.

    Returns the planes (zeta, float64), the planes used, and the per-texel accepting plane (device buffer).
    """
    src = S.source(S.SLICING)
    h = dt(pl["box"][4][1])
    L = int(lm["depth_levels"])
    n_planes = int(pl["n"])
    respace = bool(lm["smart_slicing"])
    hist = gpu.storage(nbytes=4 * L)
    pidx = gpu.storage(nbytes=4 * Hc * Wc)
    nb = max(n_planes, L * max(n_planes, 1)) if respace else n_planes   # more than any plane count
    bounds = gpu.storage(np.tile(np.array([0xFFFFFFFF, 0xFFFFFFFF, 0, 0], np.uint32), nb))
    u = gpu.uniform((h, L, Hc, Wc), (1.0 if respace else 0.0, n_planes, pl["zlo"], pl["s"]), ("u", flags))
    posv, difv = gpu.layer(tex["pos"], l), gpu.layer(tex["dif"], l)
    if respace:
        dummy_lb, dummy_b = gpu.storage(np.zeros(L, np.int32)), gpu.storage(np.zeros(4, np.float32))
        gpu.dispatch(gpu.compute(src, "profile"), [u, posv, difv, hist, dummy_lb, dummy_b, pidx, bounds],
                     Hc * Wc)
        counts = gpu.read(hist, np.uint32, (L,))
        # the sub-boxes: runs of non-empty levels, each re-sliced by eq. 4-22 and §4.2.1
        level_box = np.full(L, -1, np.int32)
        boxes, zeta = [], []
        a = 0
        while a < L:
            if counts[a] == 0:
                a += 1
                continue
            e = a
            while e < L and counts[e] > 0:
                e += 1
            z0, z1, hr = -h / 2 + h * dt(a) / dt(L), -h / 2 + h * dt(e) / dt(L), (e - a) / L
            lattice = n_planes if pl["tight"] else max(n_planes - 1, 1)
            k = max(int(round(hr * lattice)), 1)
            first = len(zeta)
            if k == 1:
                zeta.append((z0 + z1) / 2)
                sb = dt(1.0)
            else:
                sb = (z1 - z0) / dt(k - 1)
                zeta += [z0 + sb * dt(q) for q in range(k)]
            level_box[a:e] = len(boxes)
            boxes.append([z0, sb, k, first])
            a = e
        zeta = np.asarray(zeta, dt)
        used = np.arange(len(zeta), dtype=np.int64)
        gpu.dispatch(gpu.compute(src, "accept"),
                     [u, posv, difv, hist, gpu.storage(level_box), gpu.storage(np.asarray(boxes or [[0] * 4], np.float32)),
                      pidx, bounds], Hc * Wc)
    else:
        zeta = pl["zeta"]
        used = np.arange(n_planes, dtype=np.int64)
        gpu.dispatch(gpu.compute(src, "accept"),
                     [u, posv, difv, hist, gpu.storage(np.zeros(L, np.int32)), gpu.storage(np.zeros(4, np.float32)),
                      pidx, bounds], Hc * Wc)
    eps = pl["s"] / 2.0
    if respace and len(zeta) > 1:
        eps = float(np.min(np.diff(zeta))) / 2.0
    scissor = None
    if lm["culling"] == "bounds":                 # each plane's accepted texels: (x, y, w, h), None if none
        b = gpu.read(bounds, np.uint32, (nb, 4))[:len(zeta)]
        scissor = [None if r_[2] < r_[0] else (int(r_[0]), int(r_[1]), int(r_[2] - r_[0] + 1), int(r_[3] - r_[1] + 1))
                   for r_ in b]
    return zeta, used, pidx, eps, scissor


def caustics_pass(gpu, wat, l, box, zeta, used, pidx, eps, K, Hc, Wc, tex, flags, bugs, scissor=None):
    """Every beam's intersection triangle on every used plane, splatted additively (render pipeline).

    ``scissor`` (``culling = bounds``, §6.1): per plane the rectangle of the texels it accepts, or
    None where it accepts none (nothing drawn); a compute pass then lists per plane the beams that
    reach it and can touch that rectangle, and the plane's draw is indirect over its list. Without
    it every beam is drawn on every plane over the whole map (``culling = none``, the thesis's
    cost). The maps are the same either way.
    """
    c, U, V, W, ext = _box_rows(box, Hc, Wc)
    texel_area = (ext[0] / Wc) * (ext[2] / Hc)
    nv = wat["nv"]
    k = len(used)
    batch = max(1, min(k, (64 << 20) // (16 * nv)))      # planes whose edge-ray hits fit one 64 MiB buffer

    nf = wat["nf"]
    compact = scissor is not None and "threshold_test" not in bugs

    def params(first, count):
        return gpu.uniform(tuple(c) + (Hc,), tuple(U) + (Wc,), tuple(V) + (K,), tuple(W) + (texel_area,),
                           tuple(ext) + (wat["n"],), (eps, count, 1.0 if compact else 0.0, 0),
                           ("u", flags, l * nv, l * nf, first))
    blend = None if "no_blend" in bugs else {"color": {"operation": "add", "src_factor": "one", "dst_factor": "one"},
                                              "alpha": {"operation": "add", "src_factor": "one", "dst_factor": "one"}}
    cull = "back" if "cull_back" in bugs else "none"
    pi = gpu.compute(S.source(S.BEAMS, S.INTERSECT), "main")
    p = gpu.render(S.source(S.BEAMS, S.CAUSTICS), [("r32float", blend), ("r32float", blend)], cull=cull)
    planes = gpu.storage(np.asarray(zeta[used] if k else [0.0], np.float32))
    pm = gpu.texture(Wc, Hc, max(k, 1), "r32float")
    hits = gpu.storage(nbytes=16 * nv * batch)
    if compact:
        # per plane: its accepted texels' rectangle, and indirect arguments (count, 1, 3 nf q_batch, 0)
        rects = np.array([[1, 1, 0, 0] if scissor[used[q]] is None else
                          [scissor[used[q]][0], scissor[used[q]][1], scissor[used[q]][0] + scissor[used[q]][2] - 1,
                           scissor[used[q]][1] + scissor[used[q]][3] - 1] for q in range(k)] or [[1, 1, 0, 0]],
                         np.float32)
        args = np.zeros((max(k, 1), 4), np.uint32)
        args[:, 1] = 1
        args[:k, 2] = 3 * nf * (np.arange(k) % batch)
        U_ = gpu.wgpu.BufferUsage
        argbuf = gpu.device.create_buffer_with_data(data=args, usage=U_.STORAGE | U_.INDIRECT | U_.COPY_DST)
        rectbuf = gpu.storage(rects)
        lists = gpu.storage(nbytes=4 * nf * batch)
        pc = gpu.compute(S.source(S.BEAMS, S.CULL), "main")
    else:
        lists = gpu.storage(nbytes=16)
    enc = gpu.device.create_command_encoder()
    if k == 0:                                    # nothing to draw: the map cleared
        rp = enc.begin_render_pass(color_attachments=[
            {"view": gpu.layer(tex["cmap"], l), "load_op": "clear", "store_op": "store", "clear_value": (0, 0, 0, 0)},
            {"view": gpu.layer(pm, 0), "load_op": "clear", "store_op": "store", "clear_value": (0, 0, 0, 0)}])
        rp.end()
    for first in range(0, k, batch):
        count = min(batch, k - first)
        u = params(first, count)
        # the beams' intersections: each edge ray with each plane of the batch (compute)
        gpu.dispatch(pi, [u, wat["verts"], wat["trans"], planes, hits], nv * count, enc=enc)
        if compact:                               # §6.1: each plane's beams that can touch its texels
            gpu.dispatch(pc, [u, hits, wat["beams"], rectbuf, lists, argbuf], nf * count, enc=enc)
        bg = gpu.bind(p, [u, hits, wat["beams"], planes, pidx, gpu.layer(tex["pos"], l), gpu.layer(tex["nrm"], l),
                          lists])
        for q in range(first, first + count):
            # their splats: the intersection triangles drawn, depth-tested, added (render)
            rp = enc.begin_render_pass(color_attachments=[
                {"view": gpu.layer(tex["cmap"], l), "load_op": "clear" if q == 0 else "load", "store_op": "store",
                 "clear_value": (0, 0, 0, 0)},
                {"view": gpu.layer(pm, q), "load_op": "clear", "store_op": "store", "clear_value": (0, 0, 0, 0)}])
            if compact:
                if scissor[used[q]] is None:
                    rp.end()
                    continue
                rp.set_scissor_rect(*scissor[used[q]])
            rp.set_pipeline(p)
            rp.set_bind_group(0, bg)
            if compact:
                rp.draw_indirect(argbuf, 16 * q)  # the plane's culled list
            else:
                rp.draw(3 * nf, 1, 0, q)          # every beam; instance index = the plane
            rp.end()
    gpu.device.queue.submit([enc.finish()])
    return pm, k


def casting_pass(gpu, r, boxes, R, Hc, Wc, tex, cast, flags):
    """Light 0's map plus every other light's map cast into it (compute; eq. 4-20)."""
    rows = []
    for box in boxes:
        c, U, V, W, (w, h, d) = box
        rows += [list(c) + [max(w / Wc, d / Hc)], list(U) + [w], list(V) + [h], list(W) + [d]]
    u = gpu.uniform((Hc, Wc, len(boxes), r), ("u", flags))
    p = gpu.compute(S.source(S.CASTING), "main")
    gpu.dispatch(p, [u, gpu.storage(np.asarray(rows, np.float32)), gpu.layer(tex["pos"], 0, True),
                     gpu.layer(tex["dif"], 0, True), gpu.layer(tex["nrm"], 0), gpu.layer(tex["cmap"], 0, True), cast],
                 Hc * Wc)


def clusters(corners, ranges, size=32):
    """Two-level clusters of the receivers' triangles for the view's ray cast (host, as a BVH build).

    Per receiver, triangles in Morton order of their centroids, ``size`` to a cluster, ``size``
    clusters to a super-cluster; boxes padded by 1e-5 of the scene's extent (float32 slab tests).
    Returns (nodes (2 (S + C), 4) float32, slots (T,) uint32, S).
    """
    tri = corners[:, :3].reshape(-1, 3, 3).astype(np.float64)
    lo_all, hi_all = tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0)
    pad = 1e-5 * float(np.max(hi_all - lo_all)) + 1e-7
    slots, cl = [], []
    for a, b in ranges:
        idx = np.arange(a, b)
        if len(idx) == 0:
            continue
        cen = tri[idx].mean(1)
        lo, hi = cen.min(0), cen.max(0)
        g = np.clip(((cen - lo) / np.maximum(hi - lo, 1e-30) * 1023).astype(np.int64), 0, 1023)
        code = np.zeros(len(idx), np.int64)
        for bit in range(10):
            for ax in range(3):
                code |= ((g[:, ax] >> bit) & 1) << (3 * bit + ax)
        idx = idx[np.argsort(code, kind="stable")]
        for s in range(0, len(idx), size):
            part = idx[s:s + size]
            first = len(slots)
            slots.extend(part.tolist())
            pts = tri[part].reshape(-1, 3)
            cl.append((pts.min(0) - pad, pts.max(0) + pad, first, len(part)))
    sup = []
    for s in range(0, len(cl), size):
        part = cl[s:s + size]
        sup.append((np.min([p[0] for p in part], 0), np.max([p[1] for p in part], 0), s, len(part)))
    ns = len(sup)
    nodes = []
    for lo, hi, first, cnt in sup:
        nodes += [list(lo) + [ns + first], list(hi) + [cnt]]
    for lo, hi, first, cnt in cl:
        nodes += [list(lo) + [first], list(hi) + [cnt]]
    return np.asarray(nodes, np.float32), np.asarray(slots, np.uint32), ns


def camera(cam):
    """The camera's float64 frame (oracle: Camera scalars, frames and projections)."""
    W, H = int(cam["width"]), int(cam["height"])
    sy = np.tan(np.radians(cam["fov_y"]) / 2.0)
    sx = np.tan(np.radians(cam["fov_y"]) / 2.0) * W / H
    eye = np.asarray(cam["eye"], np.float64)
    f = _unit(np.asarray(cam["target"], np.float64) - eye)
    r = _unit(np.cross(f, np.asarray(cam["up"], np.float64)))
    u = np.cross(r, f)
    return W, H, sx, sy, eye, r, u, f


def image_pass(gpu, cam, wat, corners, corners_host, owner_ranges, rboxes, cast, eta, K, ambient, Hc, Wc, flags, bugs, timer):
    """The camera's view: ``image_direct`` (render) and the view through the water (render + compute)."""
    W, H, sx, sy, eye, r, u, f = camera(cam)
    nodes, slots, ns = clusters(corners_host, owner_ranges)
    cu = gpu.uniform(tuple(eye) + (W,), tuple(r) + (H,), tuple(u) + (sx,), tuple(f) + (sy,),
                     (cam["near"], cam["far"], eta, K), (ambient, len(rboxes), Hc, Wc),
                     (wat["n"], ns, 0, 0), ("u", flags))
    rb = []
    for box, alb in rboxes:
        c, U, V, Wv, (w, h, d) = box
        rb += [list(c) + [0], list(U) + [w], list(Wv) + [d], list(alb) + [0]]
    rbuf = gpu.storage(np.asarray(rb, np.float32))
    cull = "back" if "cull_back" in bugs else "none"
    with timer("image_direct"):
        p = gpu.render(S.source(S.VIEW_COMMON, S.VIEW_FUNCS, S.IMAGE_DIRECT), [("rgba32float", None)],
                       depth="depth32float", cull=cull)
        col = gpu.texture(W, H, 1, "rgba32float")
        dep = gpu.texture(W, H, 1, "depth32float")
        enc = gpu.device.create_command_encoder()
        rp = enc.begin_render_pass(
            color_attachments=[{"view": col.create_view(), "load_op": "clear", "store_op": "store",
                                "clear_value": (0, 0, 0, 0)}],
            depth_stencil_attachment={"view": dep.create_view(), "depth_load_op": "clear",
                                      "depth_store_op": "store", "depth_clear_value": 1.0})
        rp.set_pipeline(p)
        rp.set_bind_group(0, gpu.bind(p, [cu, corners, rbuf, cast]))
        rp.draw(int(corners.size // 16))
        rp.end()
        gpu.device.queue.submit([enc.finish()])
    with timer("image_water"):
        pv = gpu.render(S.source(S.VIEW_COMMON, S.WATER_VIS), [("r32uint", None)], depth="depth32float", cull=cull)
        vis = gpu.texture(W, H, 1, "r32uint")
        dep2 = gpu.texture(W, H, 1, "depth32float")
        enc = gpu.device.create_command_encoder()
        rp = enc.begin_render_pass(
            color_attachments=[{"view": vis.create_view(), "load_op": "clear", "store_op": "store",
                                "clear_value": (0, 0, 0, 0)}],
            depth_stencil_attachment={"view": dep2.create_view(), "depth_load_op": "clear",
                                      "depth_store_op": "store", "depth_clear_value": 1.0})
        rp.set_pipeline(pv)
        rp.set_bind_group(0, gpu.bind(pv, [cu, wat["verts"]]))
        rp.draw(3 * wat["nf"])
        rp.end()
        gpu.device.queue.submit([enc.finish()])
    with timer("image_view"):
        n = W * H
        st, wpos, wdir, rpos, colour = (gpu.storage(nbytes=4 * n), gpu.storage(nbytes=16 * n),
                                        gpu.storage(nbytes=16 * n), gpu.storage(nbytes=16 * n),
                                        gpu.storage(nbytes=16 * n))
        pc = gpu.compute(S.source(S.VIEW_COMMON, S.VIEW_FUNCS, S.VIEW), "main")
        gpu.dispatch(pc, [cu, corners, rbuf, cast, wat["verts"], wat["norms"], vis.create_view(),
                          gpu.storage(nodes), gpu.storage(slots), st, wpos, wdir, rpos, colour],
                     (-(-W // 8), -(-H // 8), 1))
    out = {}
    cd = gpu.read_texture(col, 0, np.float32, 4)
    out["image_direct"] = np.ascontiguousarray(cd[..., :3])
    out["object_mask_direct"] = cd[..., 3] > 0.5
    status = gpu.read(st, np.int32, (H, W))
    out["view_status"] = status.astype(np.int8)
    out["water_pos"] = gpu.read(wpos, np.float32, (H, W, 4))[..., :3].astype(np.float64)
    out["water_dir"] = gpu.read(wdir, np.float32, (H, W, 4))[..., :3].astype(np.float64)
    rq = gpu.read(rpos, np.float32, (H, W, 4)).astype(np.float64)
    out["receiver_pos"] = np.ascontiguousarray(rq[..., :3])
    out["water_length"] = np.ascontiguousarray(rq[..., 3])
    out["image"] = np.ascontiguousarray(gpu.read(colour, np.float32, (H, W, 4))[..., :3])
    out["object_mask"] = (status == 1) | (status == 3)
    return out


# =============================================================================== the whole method
def render(scene, bugs=(), timer=None, setup="float64"):
    """Every pass of the level map for one scene (a dict as in ``scene.json``); returns the arrays.

    ``timer`` (a ``Timer``) collects per-pass milliseconds. ``setup = "float32"`` computes the boxes,
    planes and frames in float32 too (an experiment: check's set-up tolerance of 1e-7 rejects it).
    """
    dt = {"float64": np.float64, "float32": np.float32}[setup]
    unknown = set(bugs) - set(BUGS)
    if unknown:
        raise ValueError(f"unknown bugs {sorted(unknown)}; known: {sorted(BUGS)}")
    gpu = Gpu.get()
    timer = timer or Timer(gpu)
    cam, water, lm, ca, lights, receivers, outside_ior = resolve(scene)
    flags = 0
    for b in bugs:
        flags |= _FLAG.get(b, 0)
    eta = outside_ior / float(water["ior"])
    eta_planes = eta
    if "inverted_eta" in bugs:
        eta = eta_planes = 1.0 / eta
    Hc = Wc = int(ca["map_size"])
    n_planes = int(lm["planes"])
    K = float(water["absorption"])
    recs = [place(rr) for rr in receivers]
    tris = [v[f_] for v, f_, _, _ in recs]
    owner = np.concatenate([np.full(len(f_), k) for k, (_, f_, _, _) in enumerate(recs)])
    allt = np.concatenate(tris)                                    # (T, 3, 3) float64, level_map's order
    corners_host = np.concatenate([allt.astype(np.float32).reshape(-1, 3),
                                   np.repeat(owner, 3).astype(np.float32)[:, None]], 1)
    ranges, a = [], 0
    for t_ in tris:
        ranges.append((a, a + len(t_)))
        a += len(t_)
    out = {}
    with timer("water"):
        corners = gpu.storage(corners_host)
        albedo = gpu.storage(np.asarray([list(x[3]) + [0] for x in recs], np.float32))
        wat = water_pass(gpu, water, lights, eta, flags)
    out["stage.water.water_vertices"] = gpu.read(wat["verts"], np.float32, (wat["nv"], 4))[:, :3].astype(np.float64)
    out["stage.water.water_normals"] = gpu.read(wat["norms"], np.float32, (wat["nv"], 4))[:, :3].astype(np.float64)
    L = len(lights)
    cast = gpu.storage(nbytes=4 * max(len(recs), 1) * Hc * Wc)
    rboxes = []
    for r, (rv, _, p0, alb) in enumerate(recs):
        tex = {"pos": gpu.texture(Wc, Hc, L, "r32float"), "nrm": gpu.texture(Wc, Hc, L, "rgba32float"),
               "dif": gpu.texture(Wc, Hc, L, "rgba32float"), "cmap": gpu.texture(Wc, Hc, L, "r32float")}
        boxes = []
        for l, light in enumerate(lights):
            tag = f"{r}_{l}"
            with timer("planes"):
                pl = planes_pass(rv, p0, light, eta_planes, n_planes, ca["placement"], dt)
            box = pl["box"]
            boxes.append(box)
            # the depth range of the map's depth buffer: every receiver's zeta inside (0, 1)
            q = allt.reshape(-1, 3) - box[0]
            R_depth = 4.0 * float(np.max(np.abs(_dot(q, box[2])))) + 1.0
            mine = corners if ca["shadows"] else gpu.storage(corners_host[3 * ranges[r][0]:3 * ranges[r][1]])
            with timer("level_map"):
                level_map_pass(gpu, mine, albedo, box, r, R_depth, Hc, Wc, tex, l, flags, bugs)
            with timer("smart_slicing"):
                zeta, used, pidx, eps, scissor = slicing_pass(gpu, pl, lm, Hc, Wc, tex, l, flags, dt)
            with timer("caustics"):
                pm, k = caustics_pass(gpu, wat, l, box, zeta, used, pidx, eps, K, Hc, Wc, tex, flags, bugs,
                                      scissor)
            out[f"stage.planes.box_{tag}"] = box.astype(np.float64)
            out[f"stage.caustics.planes_{tag}"] = np.asarray(zeta, np.float64)
            out[f"stage.caustics.planes_used_{tag}"] = used
            pos = gpu.read_texture(tex["pos"], l, np.float32)
            out[f"stage.level_map.position_{tag}"] = pos.astype(np.float64)
            out[f"stage.level_map.normal_{tag}"] = gpu.read_texture(tex["nrm"], l, np.float32, 4)[..., :3].astype(np.float64)
            out[f"stage.level_map.diffuse_{tag}"] = np.ascontiguousarray(
                gpu.read_texture(tex["dif"], l, np.float32, 4)[..., :3])
            out[f"stage.caustics.caustic_map_{tag}"] = gpu.read_texture(tex["cmap"], l, np.float32).astype(np.float64)
            out[f"stage.plane_maps.plane_maps_{tag}"] = np.stack(
                [gpu.read_texture(pm, q_, np.float32) for q_ in range(k)]) if k else np.zeros((0, Hc, Wc), np.float32)
            out[f"stage.plane_maps.plane_index_{tag}"] = used.copy()
        with timer("casting"):
            casting_pass(gpu, r, boxes, len(recs), Hc, Wc, tex, cast, flags)
        rboxes.append((boxes[0], alb))
        fr = frame(boxes[0]).astype(np.float64)
        out[f"stage.casting.caustic_frame_{r}"] = out[f"caustic_frame_{r}"] = fr
    casts = gpu.read(cast, np.float32, (max(len(recs), 1), Hc, Wc))
    for r in range(len(recs)):
        out[f"stage.casting.caustic_map_{r}"] = out[f"caustic_map_{r}"] = np.ascontiguousarray(casts[r])
    view = image_pass(gpu, cam, wat, corners, corners_host, ranges, rboxes, cast, eta, K, float(ca["ambient"]), Hc, Wc,
                      flags, bugs, timer)
    for k_, a_ in view.items():
        out[f"stage.image.{k_}"] = a_
        if k_ in ("image", "object_mask", "image_direct", "object_mask_direct"):
            out[k_] = a_
    return out


def run(golden_dir, out_dir, cases=None, bugs=(), timings=None, setup="float64"):
    """Write ``out_dir/<case>/result.npz`` for the level-map cases of a golden suite; returns the cases.

    ``timings`` (a dict) receives per case the per-pass milliseconds.
    """
    with open(os.path.join(golden_dir, "manifest.json")) as fh:
        manifest = json.load(fh)
    if cases is None:
        cases = sorted(c for c, m in manifest["cases"].items() if m.get("method") == "levelmap")
    for case in cases:
        with open(os.path.join(golden_dir, case, "scene.json")) as fh:
            scene = json.load(fh)
        t = Timer(Gpu.get())
        arrays = render(scene, bugs, t, setup)
        if timings is not None:
            timings[case] = t.times
        os.makedirs(os.path.join(out_dir, case), exist_ok=True)
        np.savez(os.path.join(out_dir, case, "result.npz"), **arrays)
    return list(cases)


if __name__ == "__main__":
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("golden")
    ap.add_argument("out")
    ap.add_argument("--cases", default=None, help="NAME,... (default: every levelmap case of the suite)")
    ap.add_argument("--bug", action="append", default=[], choices=sorted(BUGS))
    ap.add_argument("--setup", default="float64", choices=("float64", "float32"),
                    help="the boxes, planes and frames on the host in float64 (default) or float32 (experiment)")
    a = ap.parse_args()
    ok, why = available()
    if not ok:
        sys.exit(why)
    done = run(a.golden, a.out, a.cases.split(",") if a.cases else None, a.bug, setup=a.setup)
    print(f"wrote {len(done)} cases to {a.out} ({why}); now: refraction-ref check {a.out} --golden {a.golden}")
