"""Reproduce Chaudhari (2008) Tables 4.1 and 4.2 on this CPU, beside the thesis's GPU figures.

    python benchmarks/thesis_tables.py [--repeats 9]

Table 4.1: frames per second (= 1000 / pipeline ms, pipeline = sum of
``meta['timings_ms']``) at 32 and 16 layers, 256x256 and 512x512 image
resolution (= the voxel grid's xy resolution), 256 slices, for the rows we
have meshes for. Table 4.2: time per stage in ms for scenes I-A, I-B, II-A,
II-B at 256x256x256 and 512x512x256 (32 layers).

The thesis measured on an NVIDIA 8800 GTX, at the view of highest depth
complexity of each scene; we use the default front view (eye on +z, fov 30),
so the depth complexity (printed) is lower than the thesis's.

Writes ``benchmarks/results/table_4_1.csv`` and ``table_4_2.csv``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common as C  # noqa: E402
from refraction_ref.files import atomic_open  # noqa: E402

# Table 4.1 (FPS, NVIDIA 8800 GTX): {model: (triangles, {(layers, res): fps})}
THESIS_4_1 = {
    "Bunny-lowpoly": (15000, {(32, 256): 106, (32, 512): 57, (16, 256): 114, (16, 512): 71}),
    "Bunny and Bunny": (30000, {(32, 256): 48, (32, 512): 25, (16, 256): 90, (16, 512): 41}),
    "Bunny I": (69451, {(32, 256): 87, (32, 512): 36, (16, 256): 99, (16, 512): 60}),
    "Igea": (268686, {(32, 256): 53, (32, 512): 31, (16, 256): 77, (16, 512): 47}),
}
COLS_4_1 = ((32, 256), (32, 512), (16, 256), (16, 512))

# Table 4.2 (ms): {stage: {res: (I-A, I-B, II-A, II-B)}}
THESIS_4_2 = {
    "Min-Max Depths": {256: (2.085, 0.365, 2.086, 0.369), 512: (2.101, 0.428, 2.112, 0.404)},
    "Voxelization": {256: (2.235, 0.652, 2.176, 0.622), 512: (3.807, 1.358, 3.076, 1.312)},
    "Depth Layer Peeling": {256: (1.032, 1.044, 0.918, 0.907), 512: (2.968, 2.955, 2.705, 2.698)},
    "Parallel Reduction": {256: (0.573, 0.58, 0.574, 0.564), 512: (1.294, 1.266, 1.323, 1.306)},
    "Photon Generation": {256: (2.403, 0.608, 2.411, 0.613), 512: (2.428, 0.617, 2.431, 0.641)},
    "Photon Tracing": {256: (4.938, 4.889, 3.22, 2.99), 512: (8.665, 7.774, 5.691, 4.981)},
}
STAGE_OF = {"Min-Max Depths": "minmax", "Voxelization": "voxelize", "Depth Layer Peeling": "peel",
            "Parallel Reduction": "reduce", "Photon Generation": None, "Photon Tracing": "trace"}
SCENES_4_2 = ("I-A", "I-B", "II-A", "II-B")
THESIS_SCENE_TEXT = {"I-A": "two bunnies, 288,092 tris (2 x 144k Bunny II)", "I-B": "two bunnies, 30,000 tris",
                     "II-A": "one bunny (caption: 288,092)", "II-B": "one bunny (caption: 30,000)"}


def scene_builders():
    """name -> (builder(res, layers), our description)."""
    return {
        "Bunny-lowpoly": (lambda res, L: C.lowpoly_bunny_scene(res, layers=L), "bunny decimated to 15,000"),
        "Bunny and Bunny": (lambda res, L: C.two_bunnies_scene(res, lowpoly=True, layers=L),
                            "two decimated bunnies, 2 x 15,000"),
        "Bunny I": (lambda res, L: C.bunny_scene(res, layers=L), "the bunny, 69,451"),
        "Igea": (lambda res, L: C.igea_scene(res, layers=L), "Igea, 268,686"),
        "I-A": (lambda res, L: C.two_bunnies_scene(res, lowpoly=False, layers=L), "two full bunnies, 2 x 69,451"),
    }


ALIAS_4_2 = {"I-A": "I-A", "I-B": "Bunny and Bunny", "II-A": "Bunny I", "II-B": "Bunny-lowpoly"}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=9, help="timed renders per cell after two warm-ups (>= 3)")
    args = ap.parse_args(argv)
    reps = max(3, args.repeats)
    t_start = time.perf_counter()
    print(f"# Chaudhari 2008 Tables 4.1 / 4.2 on the CPU ({C.machine_line()}; git {C.git_rev()})")
    print(f"pipeline ms = sum of meta['timings_ms'], median over {reps} renders after two warm-ups; 256 slices, "
          "5 iterations, default front view (thesis: NVIDIA 8800 GTX, view of highest depth complexity)")
    try:
        print(f"low-poly bunny: {C.lowpoly_method()} -> {os.path.relpath(C.lowpoly_bunny_path(), C.REPO)}")
    except Exception as e:  # noqa: BLE001
        print(f"low-poly bunny unavailable: {e}")
    builders = scene_builders()
    cache, info, skipped = {}, {}, {}

    def run(name, res, layers):
        key = (name, res, layers)
        if key in cache or name in skipped:
            return cache.get(key)
        try:
            scene = builders[name][0](res, layers)
        except C.Skip as e:
            skipped[name] = str(e)
            print(f"  skip {name}: {e}")
            return None
        t = C.time_render(scene, reps)
        m = t["result"].meta
        info.setdefault(name, {"triangles": m.get("triangles", C.triangles(scene))})
        info[name][f"dc_{res}"] = m.get("depth_complexity_max")
        cache[key] = t
        print(f"  {name:<16s} {res}x{res}x256 {layers:2d} layers: {t['pipeline_ms']:7.1f} ms "
              f"({1000 / t['pipeline_ms']:5.1f} FPS), depth complexity max {m.get('depth_complexity_max')}",
              flush=True)
        return t

    # -- Table 4.1 -------------------------------------------------------------
    print("\nmeasuring Table 4.1 ...")
    rows41, csv41 = [], []
    for name, (tris_thesis, fps_thesis) in THESIS_4_1.items():
        cells = []
        for L, res in COLS_4_1:
            t = run(name, res, L)
            if t is None:
                cells.append("skipped")
                csv41.append({"model": name, "thesis_triangles": tris_thesis, "layers": L, "res": res,
                              "our_pipeline_ms": "", "our_fps": "", "thesis_fps": fps_thesis[(L, res)],
                              "note": skipped.get(name, "")})
                continue
            fps = 1000.0 / t["pipeline_ms"]
            cells.append(f"{fps:.1f} ({fps_thesis[(L, res)]})")
            csv41.append({"model": name, "thesis_triangles": tris_thesis, "our_triangles": info[name]["triangles"],
                          "layers": L, "res": res, "our_pipeline_ms": f"{t['pipeline_ms']:.3f}",
                          "our_total_ms": f"{t['total_ms']:.3f}", "our_fps": f"{fps:.2f}",
                          "thesis_fps": fps_thesis[(L, res)], "our_depth_complexity_max": info[name].get(f"dc_{res}"),
                          "other_load": f"{t['other_load']:.3f}",
                          "note": builders[name][1]})
        ours = f"{info[name]['triangles']:,}" if name in info else "-"
        rows41.append([name, f"{tris_thesis:,}", ours, *cells])

    # -- Table 4.2 -------------------------------------------------------------
    print("\nmeasuring Table 4.2 ...")
    res42 = {}
    for sc in SCENES_4_2:
        for res in (256, 512):
            res42[(sc, res)] = run(ALIAS_4_2[sc], res, 32)
    rows42, csv42 = [], []
    stage_rows = list(THESIS_4_2) + ["Shade (ours only)", "Total (sum)"]
    for stage in stage_rows:
        cells = []
        for res in (256, 512):
            for k, sc in enumerate(SCENES_4_2):
                t = res42[(sc, res)]
                thesis = THESIS_4_2[stage][res][k] if stage in THESIS_4_2 else (
                    sum(v[res][k] for v in THESIS_4_2.values()) if stage.startswith("Total") else None)
                if t is None:
                    ours = None
                elif stage == "Photon Generation":
                    ours = None
                elif stage.startswith("Shade"):
                    ours = t["stages_ms"].get("shade")
                elif stage.startswith("Total"):
                    ours = t["pipeline_ms"]
                else:
                    ours = t["stages_ms"].get(STAGE_OF[stage])
                o = "n/a" if ours is None else f"{ours:.2f}"
                th = "n/a" if thesis is None else f"{thesis:.3f}"
                cells.append(f"{o} ({th})")
                csv42.append({"stage": stage, "res": f"{res}x{res}x256", "scene": sc,
                              "our_ms": "" if ours is None else f"{ours:.3f}",
                              "thesis_ms": "" if thesis is None else f"{thesis:.3f}",
                              "our_scene": builders[ALIAS_4_2[sc]][1], "thesis_scene": THESIS_SCENE_TEXT[sc]})
        label = "Photon Tracing (ours: view-ray trace)" if stage == "Photon Tracing" else stage
        label = "Photon Generation (not in this issue)" if stage == "Photon Generation" else label
        rows42.append([label, *cells])

    # -- print -------------------------------------------------------------------
    print("\n## Table 4.1: frames per second, ours (thesis, NVIDIA 8800 GTX)\n")
    print(C.md_table(["Model", "thesis tris", "our tris", "32 L 256x256", "32 L 512x512", "16 L 256x256",
                      "16 L 512x512"], rows41))
    print("\nFPS = 1000 / pipeline ms (min/max pass to finished image, shade included). "
          "Bunny and Bunny: two decimated bunnies (the thesis row is 30,000 tris, i.e. two low-poly bunnies).")
    for name, why in skipped.items():
        print(f"skipped {name}: {why}")
    print("\n## Table 4.2: time per stage (ms), ours (thesis)\n")
    hdr = ["Stage"] + [f"{sc} {res}" for res in (256, 512) for sc in SCENES_4_2]
    print(C.md_table(hdr, rows42))
    print("\nScenes (ours / thesis): " + "; ".join(
        f"{sc}: {builders[ALIAS_4_2[sc]][1]} / {THESIS_SCENE_TEXT[sc]}" for sc in SCENES_4_2))
    print("'Photon Tracing' is for us the trace stage of the view rays (one ray per pixel through up to 32 "
          "layers); photon generation is not part of this issue (n/a). 'Shade' (environment look-up, "
          "absorption) has no row in the thesis. Thesis 'Total' sums its six rows (incl. photon generation). "
          "The thesis scenes I-A/II-A used the 144k Bunny II; we have the 69,451 bunny.")

    for fname, rows in (("table_4_1.csv", csv41), ("table_4_2.csv", csv42)):
        cols = []
        for r in rows:
            cols += [k for k in r if k not in cols]
        with atomic_open(C.results_path(fname), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=cols)
            w.writeheader()
            w.writerows(rows)
    el = time.perf_counter() - t_start
    print(f"\nwrote benchmarks/results/table_4_1.csv and table_4_2.csv; script took {el:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
