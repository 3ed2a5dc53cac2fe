"""Small generic wgpu-py helpers shared by the WebGPU example backends.

One device per process (``device()``), storage and uniform buffers from NumPy
arrays, read-back, compute and render pipelines compiled once per WGSL source,
one-call dispatch and draw, textures, and a per-pass wall-clock timer that
waits for the queue (``Timer``). Nothing here knows about any method: the
image-space and level-map backends build their passes on it.

Headless on Mesa's lavapipe (Vulkan on the CPU) or on any GPU wgpu finds::

    apt-get install -y mesa-vulkan-drivers
    pip install -e ".[webgpu]"

``available()`` says whether an adapter is there (and why not), so tests can
skip with those two lines.
"""
from __future__ import annotations

import hashlib
import os
import tempfile
import time
from contextlib import contextmanager

import numpy as np

# wgpu-native (through the Vulkan loader) warns on stderr when this is unset; harmless, silenced
os.environ.setdefault("XDG_RUNTIME_DIR", tempfile.gettempdir())

INSTALL_LINES = ("apt-get install -y mesa-vulkan-drivers", 'pip install -e ".[webgpu]"')

_DEVICE = None
_ADAPTER = None
_PIPELINES: dict = {}

#: features requested when the adapter offers them (the image-space backend requires none; float32-blendable
#: lets a render pass add into an r32float target, as the level map's additive splats do)
WANTED_FEATURES = ("timestamp-query", "shader-float32-atomic", "float32-blendable", "float32-filterable")


def available():
    """``(True, adapter description)`` when a wgpu adapter is found, else ``(False, why)``."""
    try:
        import wgpu  # noqa: F401
    except Exception as exc:  # ImportError, or a broken native library
        return False, f"wgpu is not importable ({exc!r}); install: {'; '.join(INSTALL_LINES)}"
    try:
        a = adapter()
    except Exception as exc:
        return False, f"no wgpu adapter ({exc!r}); install: {'; '.join(INSTALL_LINES)}"
    if a is None:
        return False, f"no wgpu adapter; install: {'; '.join(INSTALL_LINES)}"
    return True, describe()


def adapter():
    """The process's adapter (``power_preference='high-performance'``), found once."""
    global _ADAPTER
    if _ADAPTER is None:
        import wgpu
        _ADAPTER = wgpu.gpu.request_adapter_sync(power_preference="high-performance")
    return _ADAPTER


def describe():
    """One line naming the adapter: device, type and backend (``llvmpipe (LLVM 15.0.6, 256 bits), CPU, Vulkan``)."""
    info = adapter().info
    return f"{info['device']}, {info['adapter_type']}, {info['backend_type']}"


def device():
    """The process's device, created once with the adapter's largest storage-buffer limits."""
    global _DEVICE
    if _DEVICE is None:
        a = adapter()
        feats = [f for f in WANTED_FEATURES if f in a.features]
        lim = a.limits
        want = {k: lim[k] for k in ("max-storage-buffer-binding-size", "max-buffer-size",
                                    "max-storage-buffers-per-shader-stage",
                                    "max-compute-invocations-per-workgroup",
                                    "max-compute-workgroup-size-x") if k in lim}
        _DEVICE = a.request_device_sync(required_features=feats, required_limits=want)
    return _DEVICE


# ----------------------------------------------------------------------------- buffers
def _flags():
    import wgpu
    return wgpu.BufferUsage


def storage(data=None, nbytes=None, extra=0):
    """A storage buffer (copy source and destination too) holding ``data`` or ``nbytes`` zero bytes."""
    U = _flags()
    usage = U.STORAGE | U.COPY_SRC | U.COPY_DST | extra
    dev = device()
    if data is not None:
        a = np.ascontiguousarray(data)
        if a.nbytes == 0:                     # WebGPU refuses empty bindings: one padding word
            a = np.zeros(1, np.uint32)
        return dev.create_buffer_with_data(data=a, usage=usage)
    return dev.create_buffer(size=max(int(nbytes), 4), usage=usage)   # created zeroed (WebGPU)


def uniform(data):
    """A uniform buffer holding ``data`` (a NumPy array or bytes; padded to 16 bytes)."""
    U = _flags()
    raw = np.ascontiguousarray(data).tobytes() if not isinstance(data, (bytes, bytearray)) else bytes(data)
    raw += b"\0" * (-len(raw) % 16)
    return device().create_buffer_with_data(data=raw, usage=U.UNIFORM | U.COPY_DST)


def vertex(data, index=False):
    """A vertex buffer (or, ``index=True``, an index buffer) holding ``data``."""
    U = _flags()
    return device().create_buffer_with_data(data=np.ascontiguousarray(data),
                                            usage=(U.INDEX if index else U.VERTEX) | U.COPY_DST)


def read(buf, dtype, shape=None):
    """Copy a buffer back into a NumPy array of ``dtype`` (reshaped to ``shape``)."""
    raw = device().queue.read_buffer(buf)
    a = np.frombuffer(raw, dtype=dtype).copy()
    if shape is not None:
        n = int(np.prod(shape))
        a = a[:n].reshape(shape)
    return a


def write(buf, data, offset=0):
    """Upload ``data`` into ``buf`` at ``offset`` bytes."""
    device().queue.write_buffer(buf, offset, np.ascontiguousarray(data))


def fill(buf, value, dtype=np.uint32):
    """Fill a whole buffer with one 4-byte value (``value`` read as ``dtype``)."""
    n = buf.size // np.dtype(dtype).itemsize
    write(buf, np.full(n, value, dtype))


# ----------------------------------------------------------------------------- pipelines
def _module(src):
    key = hashlib.sha1(src.encode()).hexdigest()
    mod = _PIPELINES.get(("module", key))
    if mod is None:
        mod = device().create_shader_module(code=src)
        _PIPELINES[("module", key)] = mod
    return mod, key


def compute(src, entry="main"):
    """A compute pipeline (automatic layout) for WGSL ``src``'s ``entry``; compiled once per source."""
    mod, key = _module(src)
    ck = ("compute", key, entry)
    p = _PIPELINES.get(ck)
    if p is None:
        p = device().create_compute_pipeline(layout="auto", compute={"module": mod, "entry_point": entry})
        _PIPELINES[ck] = p
    return p


def render(src, vertex_layouts, vs="vs", fs="fs", target_format="r8unorm", write_mask=0,
           cull_mode="none", topology="triangle-list", blend=None):
    """A render pipeline for WGSL ``src`` (automatic layout); compiled once per arguments.

    ``vertex_layouts`` is a list of ``(array_stride, [(format, offset, shader_location), ...])``;
    the single colour target has ``target_format`` and ``write_mask`` (0: the fragment shader
    writes only storage buffers, the target is a dummy the render pass needs).
    """
    mod, key = _module(src)
    rk = ("render", key, vs, fs, repr(vertex_layouts), target_format, write_mask, cull_mode, topology, repr(blend))
    p = _PIPELINES.get(rk)
    if p is None:
        target = {"format": target_format, "write_mask": write_mask}
        if blend is not None:
            target["blend"] = blend
        p = device().create_render_pipeline(
            layout="auto",
            vertex={"module": mod, "entry_point": vs,
                    "buffers": [{"array_stride": s, "step_mode": "vertex",
                                 "attributes": [{"format": f, "offset": o, "shader_location": loc}
                                                for f, o, loc in attrs]}
                                for s, attrs in vertex_layouts]},
            primitive={"topology": topology, "cull_mode": cull_mode, "front_face": "ccw"},
            fragment={"module": mod, "entry_point": fs, "targets": [target]},
        )
        _PIPELINES[rk] = p
    return p


def _entry(i, r):
    import wgpu
    if isinstance(r, wgpu.GPUBuffer):
        return {"binding": i, "resource": {"buffer": r, "offset": 0, "size": r.size}}
    if isinstance(r, wgpu.GPUTexture):
        return {"binding": i, "resource": r.create_view()}
    return {"binding": i, "resource": r}       # a texture view or a sampler


def bind_group(pipeline, resources, group=0):
    """A bind group of ``pipeline``'s group ``group``: binding i is ``resources[i]`` (None skips i)."""
    return device().create_bind_group(layout=pipeline.get_bind_group_layout(group),
                                      entries=[_entry(i, r) for i, r in enumerate(resources) if r is not None])


def dispatch(pipeline, resources, groups, encoder=None):
    """Run ``pipeline`` over ``groups`` (x, y, z) workgroups with bind group 0 = ``resources``.

    With ``encoder`` the pass is recorded there (submit it yourself); else it is submitted now.
    """
    own = encoder is None
    enc = device().create_command_encoder() if own else encoder
    cp = enc.begin_compute_pass()
    cp.set_pipeline(pipeline)
    cp.set_bind_group(0, bind_group(pipeline, resources))
    g = tuple(groups) + (1,) * (3 - len(groups))
    cp.dispatch_workgroups(*[int(x) for x in g])
    cp.end()
    if own:
        device().queue.submit([enc.finish()])


def dispatch_indirect(pipeline, resources, args, offset=0):
    """Run ``pipeline`` with its workgroup counts read from ``args`` (three u32 at ``offset`` bytes),
    written there by an earlier pass: the GPU sizes the dispatch without a read-back."""
    enc = device().create_command_encoder()
    cp = enc.begin_compute_pass()
    cp.set_pipeline(pipeline)
    cp.set_bind_group(0, bind_group(pipeline, resources))
    cp.dispatch_workgroups_indirect(args, int(offset))
    cp.end()
    device().queue.submit([enc.finish()])


def clear(buf):
    """Zero a whole buffer on the GPU (``clear_buffer``)."""
    enc = device().create_command_encoder()
    enc.clear_buffer(buf)
    device().queue.submit([enc.finish()])


_CACHE: dict = {}


def cached(key, make):
    """A resource kept across frames under ``key`` (made by ``make()`` the first time): a renderer allocates
    its buffers and textures once, not per frame. Callers re-initialise what must start cleared."""
    r = _CACHE.get(key)
    if r is None:
        r = _CACHE[key] = make()
    return r


def groups_for(n, size=64):
    """Workgroups of ``size`` covering ``n`` invocations in x (more than 65535 fold into y)."""
    g = max(1, -(-int(n) // size))
    if g <= 65535:
        return (g, 1, 1)
    return (65535, -(-g // 65535), 1)


def draw(pipeline, resources, vertex_buffers, count, size, index_buffer=None, instances=1, target=None,
         fmt="r8unorm", load="clear", clear_value=(0, 0, 0, 0)):
    """Draw ``count`` vertices (or indices) into a ``size`` = (width, height) colour target.

    Without ``target`` the pass draws into a dummy texture of format ``fmt`` (the pipeline's target
    format, written with mask 0 by the backends here: the fragment shader's real output is what it
    writes to the storage buffers of ``resources``). With ``target`` (a texture, or a texture view) the
    colour goes there, cleared to ``clear_value`` first (``load="clear"``) or kept (``load="load"``),
    e.g. for additive blending across draws; read it back with ``read_texture``.
    """
    import wgpu
    dev = device()
    w, h = int(size[0]), int(size[1])
    if target is None:
        view = _target(w, h, fmt).create_view()
        store = wgpu.StoreOp.discard
    else:
        view = target.create_view() if isinstance(target, wgpu.GPUTexture) else target
        store = wgpu.StoreOp.store
    enc = dev.create_command_encoder()
    rp = enc.begin_render_pass(color_attachments=[{
        "view": view, "load_op": wgpu.LoadOp.clear if load == "clear" else wgpu.LoadOp.load,
        "store_op": store, "clear_value": clear_value}])
    rp.set_pipeline(pipeline)
    if any(r is not None for r in resources):
        rp.set_bind_group(0, bind_group(pipeline, resources))
    for slot, vb in enumerate(vertex_buffers):
        rp.set_vertex_buffer(slot, vb)
    if index_buffer is not None:
        rp.set_index_buffer(index_buffer, wgpu.IndexFormat.uint32)
        rp.draw_indexed(int(count), int(instances))
    else:
        rp.draw(int(count), int(instances))
    rp.end()
    dev.queue.submit([enc.finish()])


def render_target(width, height, fmt="r32float"):
    """A colour target a render pass draws into and ``read_texture`` reads back."""
    import wgpu
    U = wgpu.TextureUsage
    return device().create_texture(size=(int(width), int(height), 1), format=fmt,
                                   usage=U.RENDER_ATTACHMENT | U.COPY_SRC | U.COPY_DST | U.TEXTURE_BINDING)


def _target(w, h, fmt="r8unorm"):
    key = ("target", w, h, fmt)
    t = _PIPELINES.get(key)
    if t is None:
        import wgpu
        t = device().create_texture(size=(w, h, 1), format=fmt,
                                    usage=wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC)
        _PIPELINES[key] = t
    return t


# ----------------------------------------------------------------------------- textures
_BYTES = {"r32float": 4, "r32uint": 4, "rgba32float": 16, "rg32float": 8, "r8unorm": 1, "rgba8unorm": 4,
          "r16float": 2, "depth32float": 4}


def texture(data, fmt="r32float", layers=1, usage_extra=0):
    """A 2D (array) texture from ``data`` of shape (layers, H, W[, C]) or (H, W[, C]), sampled and copied."""
    import wgpu
    a = np.ascontiguousarray(data)
    if a.ndim == 2 or (a.ndim == 3 and layers == 1 and a.shape[0] != 1 and _BYTES[fmt] > 4):
        a = a[None]
    L, H, W = a.shape[:3]
    U = wgpu.TextureUsage
    t = device().create_texture(size=(W, H, L), format=fmt,
                                usage=U.TEXTURE_BINDING | U.COPY_DST | U.COPY_SRC | usage_extra)
    bpr = W * _BYTES[fmt]
    device().queue.write_texture({"texture": t, "origin": (0, 0, 0)}, a,
                                 {"offset": 0, "bytes_per_row": bpr, "rows_per_image": H}, (W, H, L))
    return t


def empty_texture(width, height, layers=1, fmt="r32float", storage=True):
    """An uninitialised 2D array texture (zeroed by WebGPU) a compute pass writes (``storage``) and others read."""
    import wgpu
    U = wgpu.TextureUsage
    usage = U.TEXTURE_BINDING | U.COPY_SRC | U.COPY_DST | (U.STORAGE_BINDING if storage else 0)
    return device().create_texture(size=(int(width), int(height), max(int(layers), 1)), format=fmt, usage=usage)


def array_view(tex):
    """A ``2d-array`` view of every layer of ``tex`` (a one-layer texture defaults to a ``2d`` view)."""
    return tex.create_view(dimension="2d-array")


def read_texture(tex, dtype, channels=1):
    """A texture (all its array layers) back as (layers, H, W[, channels]) of ``dtype``."""
    W, H, L = tex.size
    bpp = np.dtype(dtype).itemsize * channels
    bpr = W * bpp
    pad = -(-bpr // 256) * 256                 # rows padded to 256 bytes
    raw = device().queue.read_texture({"texture": tex, "origin": (0, 0, 0), "mip_level": 0},
                                      {"offset": 0, "bytes_per_row": pad, "rows_per_image": H}, (W, H, L))
    a = np.frombuffer(raw, np.uint8).reshape(L, H, pad)[:, :, :bpr].copy().view(dtype)
    return a.reshape((L, H, W, channels) if channels > 1 else (L, H, W))


def sampler(filter="linear"):
    """A clamp-to-edge sampler with ``filter`` ("linear" or "nearest") for both magnification and minification."""
    return device().create_sampler(mag_filter=filter, min_filter=filter, address_mode_u="clamp-to-edge",
                                   address_mode_v="clamp-to-edge")


# ----------------------------------------------------------------------------- timing
_FENCE = None


def finish():
    """Wait until the queue has run everything submitted.

    (wgpu-py 0.32's ``on_submitted_work_done_sync`` fails on a callback signature; reading back a
    4-byte buffer maps it after the queue's earlier work, which is the same wait.)
    """
    global _FENCE
    if _FENCE is None:
        _FENCE = storage(nbytes=4)
    device().queue.read_buffer(_FENCE)


class Timer:
    """Per-pass wall-clock times: ``with timer("peel"): ...`` waits for the queue at both ends.

    ``times[name]`` lists every measurement (a pass run several times, or several frames).
    """

    def __init__(self, enabled=True):
        self.enabled = enabled
        self.times: dict[str, list[float]] = {}

    @contextmanager
    def __call__(self, name):
        if not self.enabled:
            yield
            return
        finish()
        t0 = time.perf_counter()
        yield
        finish()
        self.times.setdefault(name, []).append((time.perf_counter() - t0) * 1e3)

    def median(self):
        """name -> median milliseconds."""
        return {k: float(np.median(v)) for k, v in self.times.items()}
