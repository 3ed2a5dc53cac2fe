"""The image-space trace against its memory floor (issue 33, item 4).

    python benchmarks/trace_floor.py [--repeats 7]

1. **What the trace reads per ray** on the default bunny (512^2, the seed's
   knobs: 5 search iterations, bilinear filtering, central normals with
   delta 2), counted from the code of ``imagespace/trace.py`` and
   ``imagespace/normals.py`` and the render's own per-pixel outputs
   (``interfaces``, ``status``):

   * the first layer at the ray's own pixel: 1 texel;
   * per event (one application of Snell's law): the filtered normal (the
     bilinear footprint's 4 texels, then each of the 4 texels' central
     differences: its own depth and 4 neighbours at +-delta: 4 + 4 x 5 =
     24 texels) and, after a forward refraction, the early-termination test
     (``total`` int32, ``zback`` and ``thr`` float64, the layer's depth:
     24 bytes);
   * per search (events - 1 of them: a ray's last event is followed by no
     search, or by one that fails; the count below takes the lower bound):
     ``iterations`` probes and the last probe's surface point, each a
     bilinear ``sample_depth`` (4 texels): 6 x 4 = 24 texels;
   * 4 bytes per texel (the LDI is float32);
   * written per pixel: ``exit_pos``, ``exit_dir``, ``last_dir`` (float64
     x 3 each), ``path_length`` (float64), ``interfaces`` (int32),
     ``status`` (int8).

2. **The machine's bandwidth** on one thread: a NumPy sum and copy, and a
   Numba read (sum of a float32 stream) and copy kernel, over 256 MB, best
   of 5.

3. **The floors**: the *stream floor* moves every texel read above from
   memory (no cache reuse at all: the issue's count); the *compulsory
   floor* moves each input byte once (the LDI, ``total``, ``zback``,
   ``thr``) and writes each output once.

4. **The measured trace**: the ``trace`` stage's median over ``--repeats``
   renders after warm-up, one Numba thread.

Writes ``results/trace_floor.json`` and ``results/trace_floor.md``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numba as nb
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common as C  # noqa: E402

from refraction_ref.files import atomic_open  # noqa: E402
from refraction_ref.status import EXITED, MISSED, TIR  # noqa: E402

rr = C.rr

TEXEL_BYTES = 4  # float32 LDI
NORMAL_TEXELS = 4 + 4 * 5  # bilinear footprint + 4 central-difference normals (own depth + 4 neighbours)
EARLY_EXIT_BYTES = 4 + 8 + 8 + 4  # total (int32), zback, thr (float64), the layer's depth (float32)
OUT_BYTES = 3 * 3 * 8 + 8 + 4 + 1  # exit_pos, exit_dir, last_dir, path_length, interfaces, status


@nb.njit(cache=True, fastmath=True)  # fastmath: the adds reassociate and vectorise, so the loads set the pace
def _read_stream(a):
    s = np.float32(0.0)
    for i in range(a.shape[0]):
        s += a[i]
    return s


@nb.njit(cache=True)
def _copy_stream(a, b):
    for i in range(a.shape[0]):
        b[i] = a[i]


def bandwidth(nbytes=256 * 2**20, repeats=5):
    """One-thread bandwidth (GB/s): NumPy sum / copy, Numba read / copy, best of ``repeats``."""
    a64 = np.random.default_rng(0).random(nbytes // 8)
    b64 = np.empty_like(a64)
    a32 = a64.astype(np.float32)
    b32 = np.empty_like(a32)
    _read_stream(a32[:16])
    _copy_stream(a32[:16], b32[:16])
    out = {}
    for name, fn, moved in (("numpy_sum", lambda: a64.sum(), a64.nbytes),
                            ("numpy_copy", lambda: np.copyto(b64, a64), 2 * a64.nbytes),
                            ("numba_read", lambda: _read_stream(a32), a32.nbytes),
                            ("numba_copy", lambda: _copy_stream(a32, b32), 2 * a32.nbytes)):
        fn()
        best = min(_timed(fn) for _ in range(repeats))
        out[name] = moved / best / 1e9
    return out


def _timed(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def count(res, iterations):
    """Per-ray reads of the trace from a render's outputs (see the module docstring)."""
    st = res.arrays["status"].ravel()
    nint = res.arrays["interfaces"].ravel().astype(np.int64)
    hit = st != MISSED
    events = nint + (st == TIR)
    searches = np.maximum(events - 1, 0)
    forward_refr = nint  # every non-TIR refraction runs the early-termination test (forward rays)
    texels = hit * 1 + events * NORMAL_TEXELS + searches * (iterations + 1) * 4
    other = forward_refr * EARLY_EXIT_BYTES
    n_hit = int(hit.sum())
    return {
        "pixels": int(st.size), "rays_hit": n_hit,
        "exited_fraction": float((st[hit] == EXITED).mean()),
        "interfaces_mean": float(nint[hit].mean()), "events_mean": float(events[hit].mean()),
        "searches_mean": float(searches[hit].mean()), "probes_per_search": iterations + 1,
        "texels_per_probe": 4, "texels_per_normal": NORMAL_TEXELS, "bytes_per_texel": TEXEL_BYTES,
        "texels_per_ray": float(texels[hit].mean()),
        "read_bytes_per_ray": float((texels * TEXEL_BYTES + other)[hit].mean()),
        "read_bytes": int((texels * TEXEL_BYTES + other).sum()),
        "write_bytes": int(st.size * OUT_BYTES),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args(argv)
    before = nb.get_num_threads()
    nb.set_num_threads(1)
    try:
        bw = bandwidth()
        sc = rr.load_scene(None)
        p = sc.data["imagespace"]
        for _ in range(C.WARMUP):
            res = rr.render(sc, method="imagespace", keep="stages")
        times = []
        for _ in range(a.repeats):
            times.append(rr.render(sc, method="imagespace").meta["timings_ms"]["trace"])
        trace_ms = statistics.median(times)
        # where the time goes: the trace's own cost per search iteration and of the bilinear filter
        variants = {}
        for name, over in (("iterations_0", {"imagespace.iterations": 0}),
                           ("iterations_10", {"imagespace.iterations": 10}),
                           ("filter_nearest", {"imagespace.filter": "nearest"})):
            sv = rr.load_scene(None, over)
            rr.render(sv, method="imagespace")
            variants[name] = statistics.median(rr.render(sv, method="imagespace").meta["timings_ms"]["trace"]
                                               for _ in range(max(3, a.repeats // 2)))
    finally:
        nb.set_num_threads(before)
    c = count(res, int(p["iterations"]))
    ldi = res.arrays["stage.peel.ldi"]
    H, W = res.arrays["status"].shape
    compulsory = ldi.nbytes + H * W * (4 + 8 + 8)  # LDI, total, zback, thr read once
    read_bw = max(bw["numba_read"], bw["numpy_sum"]) * 1e9
    copy_bw = max(bw["numba_copy"], bw["numpy_copy"]) * 1e9  # bytes moved per second, read + write
    stream_ms = (c["read_bytes"] / read_bw + 2 * c["write_bytes"] / copy_bw) * 1e3
    compulsory_ms = (compulsory / read_bw + 2 * c["write_bytes"] / copy_bw) * 1e3
    ns_per_ray = trace_ms * 1e6 / c["rays_hit"]
    searches = c["searches_mean"] * c["rays_hit"]
    ns_per_iteration = (variants["iterations_10"] - variants["iterations_0"]) * 1e6 / (10 * searches)
    out = {"machine": C.machine_line(), "rev": C.git_rev(), "bandwidth_GBps": bw, "counts": c,
           "ldi_shape": list(ldi.shape), "ldi_bytes": int(ldi.nbytes), "compulsory_read_bytes": int(compulsory),
           "stream_floor_ms": stream_ms, "compulsory_floor_ms": compulsory_ms, "trace_ms_1thread": trace_ms,
           "trace_samples_ms": times, "ratio_to_stream_floor": trace_ms / stream_ms,
           "ratio_to_compulsory_floor": trace_ms / compulsory_ms, "ns_per_hit_ray": ns_per_ray,
           "variants_trace_ms": variants, "ns_per_search_iteration": ns_per_iteration,
           "bytes_per_search_iteration": 4 * TEXEL_BYTES}
    C.write_json("trace_floor.json", out)
    for k, v in out.items():
        print(f"{k}: {v}")
    with atomic_open(C.results_path("trace_floor.md"), "w") as f:
        f.write(report(out) + "\n")
    return out


def report(o):
    """The note: counts, bandwidth, floors, the measured trace and where the rest goes."""
    c, bw, v = o["counts"], o["bandwidth_GBps"], o["variants_trace_ms"]
    it_ms = v["iterations_10"] - v["iterations_0"]
    probe_ms = o["ns_per_search_iteration"] * c["searches_mean"] * c["rays_hit"] * 5 / 1e6
    return "\n".join([
        "# The image-space trace against its memory floor (issue 33, item 4)", "",
        f"{o['machine']}, rev {o['rev']}; the default bunny, 512x512, one Numba thread "
        "(`python benchmarks/trace_floor.py`, numbers in `trace_floor.json`).", "",
        "## What the trace reads per ray", "",
        "| quantity | value |", "|---|---|",
        f"| rays that hit the object | {c['rays_hit']:,} of {c['pixels']:,} pixels ({100 * c['exited_fraction']:.1f} % exit) |",
        f"| layers in the LDI | {o['ldi_shape'][0]} (float32, {o['ldi_bytes'] / 2**20:.1f} MiB) |",
        f"| interfaces (Snell events) per ray | {c['events_mean']:.2f} (refractions {c['interfaces_mean']:.2f}) |",
        f"| searches per ray | {c['searches_mean']:.2f} (events - 1) |",
        f"| probes per search | {c['probes_per_search']} (5 bisection steps and the last probe's surface point) |",
        f"| texels per probe (bilinear) | {c['texels_per_probe']} |",
        f"| texels per normal (bilinear, central differences) | {c['texels_per_normal']} |",
        f"| bytes per texel | {c['bytes_per_texel']} |",
        f"| texels read per ray | {c['texels_per_ray']:.1f} |",
        f"| bytes read per ray (texels and the early-exit test) | {c['read_bytes_per_ray']:.0f} |",
        f"| bytes read, all rays | {c['read_bytes'] / 1e6:.1f} MB; written (outputs, every pixel) {c['write_bytes'] / 1e6:.1f} MB |",
        "", "## The machine's bandwidth (one thread, 256 MB streams, best of 5)", "",
        "| stream | GB/s |", "|---|---|",
        *[f"| {k} | {val:.2f} |" for k, val in bw.items()],
        "", "## Floor against the measured trace", "",
        "| | ms | measured / floor |", "|---|---|---|",
        f"| stream floor (every texel read from memory, outputs written) | {o['stream_floor_ms']:.2f} | "
        f"{o['ratio_to_stream_floor']:.1f}x |",
        f"| compulsory floor (each input byte once, outputs written) | {o['compulsory_floor_ms']:.2f} | "
        f"{o['ratio_to_compulsory_floor']:.1f}x |",
        f"| **measured trace, 1 thread** (median of {len(o['trace_samples_ms'])}) | {o['trace_ms_1thread']:.1f} | |",
        f"| trace with 0 / 10 search iterations | {v['iterations_0']:.1f} / {v['iterations_10']:.1f} | |",
        f"| trace with `filter = nearest` | {v['filter_nearest']:.1f} | |",
        "", "## Where the rest goes", "",
        f"* Memory is not what the trace waits for: it reads {c['read_bytes'] / 1e6:.0f} MB of texels "
        f"({c['texels_per_ray']:.0f} per ray) and the whole LDI is {o['ldi_bytes'] / 2**20:.1f} MiB, which "
        "fits this machine's 32 MiB L3; the probes of a ray stay within a few pixels of its own, and "
        "neighbouring rays read the same texels, so nearly every read hits L1/L2.",
        f"* The filter is: `filter = nearest` runs the trace in {v['filter_nearest']:.0f} ms against "
        f"{o['trace_ms_1thread']:.0f} ms bilinear. Per event the bilinear normal is four central-difference "
        "normals (24 texel reads, 8 unprojections with a division each, 5 normalisations with a square root) "
        "blended, where nearest filtering computes one.",
        f"* The search iterations: 0 and 10 iterations take {v['iterations_0']:.0f} and "
        f"{v['iterations_10']:.0f} ms ({o['ns_per_search_iteration']:.0f} ns per iteration and search, "
        f"{o['bytes_per_search_iteration']} bytes of texels each; this VM's run-to-run noise is about "
        f"+-30 % on one thread), so the default 5 take about "
        f"{100 * 5 * (v['iterations_10'] - v['iterations_0']) / 10 / o['trace_ms_1thread']:.0f} % of the trace. "
        "The rest is per event and per ray: the filtered normal, Snell's law, the early-exit test, the "
        "first layer and the outputs.",
        "* Target (within 3x of the floor on one thread): missed. What stands in the way is arithmetic per "
        "event (the filtered normal above), not memory traffic: the trace is compute-bound. Closing the gap "
        "would take normals read from a precomputed per-layer normal buffer (the `normals` stage already "
        "makes one) instead of recomputed per event and per corner, which changes the normal's rounding: "
        "this issue requires bit-identical outputs, so it is not done here.",
        "* Timings on this 2-vCPU VM swing by tens of percent between runs even when idle (the same trace "
        "took 45 to 114 ms on one thread in the scaling runs of the same hour); the ratios above are "
        "order-of-magnitude statements.",
    ])


if __name__ == "__main__":
    main()
