"""Main-thread CPU per stage at 1 and 2 threads: a scaling measure that the VM's scheduling noise leaves alone.

    OMP_WAIT_POLICY=passive python benchmarks/cpu_scaling_proxy.py caustics|imagespace [N]

The stage timer's clock (``time.perf_counter``) is replaced by ``time.thread_time``,
so each stage reports the CPU time of the main thread. At one thread that is
the stage's CPU time; at two threads a parallel stage leaves about half of it
on the main thread and a serial one all of it (with ``OMP_WAIT_POLICY=passive``
no worker spins on the main thread's clock). Prints per stage the medians
of ``N`` renders at 1 and 2 threads (alternating) and their ratio. Used for
``results/scaling_issue33.md``'s second table.
"""
import os, sys, time, statistics
import numba
import refraction_ref as rr
data = os.path.join(os.path.dirname(rr.__file__), "data")
which = sys.argv[1]
sc = rr.load_scene(os.path.join(data, "caustics_default.json")) if which == "caustics" else rr.load_scene(None)
for p in (1, 2):
    numba.set_num_threads(p)
    rr.render(sc, method="imagespace")
real = time.perf_counter
time.perf_counter = time.thread_time
N = int(sys.argv[2]) if len(sys.argv) > 2 else 5
acc = {1: {}, 2: {}}
for _ in range(N):
    for p in (1, 2):
        numba.set_num_threads(p)
        r = rr.render(sc, method="imagespace")
        for k, v in r.meta["timings_ms"].items():
            acc[p].setdefault(k, []).append(v)
print(rr.__file__)
for k in acc[1]:
    a, b = statistics.median(acc[1][k]), statistics.median(acc[2][k])
    print(f"{k:>22} {a:8.2f} {b:8.2f}  {a / b if b else 0:5.2f}")
