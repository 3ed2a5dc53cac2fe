"""``refraction-ref golden build DIR``: render the catalogue with the oracle into a golden suite.

Layout of a suite (``docs/oracle.md``, "Conformance")::

    DIR/manifest.json            contract and software versions, CPU, per case its stage order and
                                 per key: sha256, shape, dtype, stage, tolerance
    DIR/complete.json            the completion marker, written last: the cases and the manifest's
                                 sha256 (``check`` refuses a suite without it: a build that stopped)
    DIR/<case>/scene.json        the resolved scene (volume arrays beside it as .npy)
    DIR/<case>/golden.npz        the method under test: final keys and every stage buffer
    DIR/<case>/reference.npz     the exact reference's result, for information (not judged)
    DIR/<case>/batches.npz       K independent photon batches of noisy maps (exact methods)

Deterministic: two builds on one machine and one set of versions give
identical hashes (results are bit-identical whatever the thread count);
across machines only the tolerances are promised.

On a cluster (``--scheduler tcp://HOST:PORT``, or ``--workers N`` for a
``LocalCluster`` of N single-thread worker processes) every case is one
Dask task: the worker renders the case into a folder of its own and sends
its files back, and this process writes them and the manifest, so the
workers need no shared file system and the suite is the one a local build
writes (the same arrays, hashes and manifest entries but ``build_s``).
"""

from __future__ import annotations

import copy
import glob
import hashlib
import json
import os
import time

import numpy as np

from ..contract import CONTRACT_VERSION, software_versions
from ..files import atomic_open, atomic_path
from .tolerances import tolerance_for

__all__ = ["catalogue", "build", "case_scene", "array_sha256", "key_stage", "stage_order", "FINAL_KEY_STAGES",
           "COMPLETE", "CATALOGUE_DIR", "SEED_KEY", "photon_quantum"]

#: the scene key of the exact reference's one seed, of its photons and of its water samples: batch ``b`` of a
#: noisy case renders with it set to ``b``
SEED_KEY = "exact.photon_seed"

#: the completion marker of a suite, written after everything else (``check`` refuses a suite without it)
COMPLETE = "complete.json"

CATALOGUE_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "golden")


def catalogue(only=None):
    """The cases shipped in ``refraction_ref/data/golden`` (sorted by name), optionally a subset.

    Parameters
    ----------
    only : str or sequence of str, optional
        Case names (a comma-separated string or a list), in the order wanted;
        None or empty for every case.

    Returns
    -------
    list of dict
        Each case's JSON (``scene``, the method and the rest) with its ``name``.

    Raises
    ------
    SceneError
        For a name in ``only`` that is not a case (naming the known ones).
    """
    from ..validation import SceneError

    cases = {}
    for p in sorted(glob.glob(os.path.join(CATALOGUE_DIR, "*.json"))):
        with open(p) as f:
            c = json.load(f)
        c["name"] = os.path.splitext(os.path.basename(p))[0]
        cases[c["name"]] = c
    if only:
        names = [n.strip() for n in (only.split(",") if isinstance(only, str) else only) if n.strip()]
        bad = [n for n in names if n not in cases]
        if bad:
            raise SceneError(f"golden: unknown case {', '.join(repr(b) for b in bad)}; the catalogue has "
                             f"{', '.join(cases)}")
        return [cases[n] for n in names]
    return list(cases.values())


def _centres(n):
    x = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    return np.meshgrid(x, x, x, indexing="ij")


def _generate_volume(spec):
    """Index volumes the catalogue names instead of storing arrays in JSON (bounds [-1, 1]^3)."""
    n = int(spec["n"])
    X, Y, Z = _centres(n)
    if spec["generator"] == "luneburg":  # n = sqrt(2 - r^2 / R^2) inside radius R (Luneburg 1944)
        R = float(spec.get("radius", 0.8))
        r2 = (X ** 2 + Y ** 2 + Z ** 2) / R ** 2
        return np.where(r2 < 1, np.sqrt(np.maximum(2 - r2, 1.0)), 1.0)
    if spec["generator"] == "step":  # a cube of constant index with sharp faces
        h = float(spec.get("half", 0.45))
        inside = (np.abs(X) < h) & (np.abs(Y) < h) & (np.abs(Z) < h)
        return np.where(inside, float(spec["ior"]), 1.0)
    raise ValueError(f"unknown volume generator {spec['generator']!r}")


def case_scene(case, folder, overrides=None):
    """Write the case's scene (and generated volume) into ``folder`` and load it from there.

    Parameters
    ----------
    case : dict
        A case of :func:`catalogue`; its ``scene`` is copied, and a ``volume``
        with a ``generator`` is generated into ``volume_ior.npy``.
    folder : str
        Folder for ``scene.json`` (created when missing).
    overrides : dict, optional
        Dotted-key overrides passed to :func:`~refraction_ref.scene.load_scene`.

    Returns
    -------
    Scene
        The scene loaded from ``folder/scene.json``.
    """
    from ..scene import load_scene

    os.makedirs(folder, exist_ok=True)
    raw = copy.deepcopy(case["scene"])
    vol = raw.get("volume")
    if isinstance(vol, dict) and "generator" in vol:
        a = _generate_volume(vol)
        with atomic_path(os.path.join(folder, "volume_ior.npy")) as tmp:
            np.save(tmp, a)
        raw["volume"] = {"ior": "volume_ior.npy", "bounds": [[-1, -1, -1], [1, 1, 1]]}
    path = os.path.join(folder, "scene.json")
    with atomic_open(path, "w") as f:
        json.dump(raw, f, indent=1)
    return load_scene(path, overrides)


def array_sha256(a):
    """sha256 of an array's dtype, shape and bytes (C order).

    Parameters
    ----------
    a : array_like
        Any array.

    Returns
    -------
    str
        Hex digest of ``dtype.str``, ``shape`` and the C-ordered bytes.
    """
    a = np.ascontiguousarray(a)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.view(np.uint8).tobytes() if a.size else b"")
    return h.hexdigest()


#: (key pattern, stage): owners that the stages' ``makes`` do not give; the first match whose stage is in
#: the graph wins. Final keys assembled from a stage's buffers under another name, the final image of a
#: scene with caustics (made by ``caustic_final``, although ``shade`` makes an ``image`` too), and stage
#: buffers stored by one stage but computed by an earlier pass (docs/oracle.md, "Conformance").
FINAL_KEY_STAGES = (
    ("image", "caustic_final"),              # with receivers the final image is the caustic pass's
    ("image_refraction", "shade"),           # ... and the refraction-only view the shading pass's
    ("hit", "trace"),                        # imagespace: status != 0 of the trace
    ("ray_origin", "trace"),                 # exact: the trace makes its primary rays (imagespace: rays)
    ("ray_dir", "trace"),
    ("ray_origin", "view"),                  # volumetric: the curved-ray viewing pass (§4.5) also
    ("ray_dir", "view"),                     # makes the per-pixel keys its stage does not list
    ("interfaces", "view"),
    ("path_length", "view"),
    ("ior", "voxelize"),                     # volumetric: the index volume (stage.voxelize.ior_volume)
    ("volume_bounds", "voxelize"),
    ("photon_*", "march"),                   # volumetric: the march's photon results
    ("caustic_map_*", "caustics"),           # volumetric caustics (made inside the stage's arrays)
    ("caustic_frame_*", "caustics"),
    ("caustic_rgb_*", "caustics"),
    ("caustic_frame_*", "planes"),           # exact water: the map's rectangle is the receiver's box
    ("stage.caustics.planes_[0-9]*", "planes"),  # level map: the plane offsets follow from the box (eqs. 4-1..4-9)
)
#: owners in FINAL_KEY_STAGES that win over a stage making a buffer of the same name
_OVERRIDES = ("image",)


def stage_order(stages):
    """The order stages are judged in: a topological order of the graph, the registered order among equals.

    Every stage comes after the stages whose buffers it reads (``Stage.after``),
    so the first failing stage in this order is one whose inputs all passed.
    Inspection stages are included (their buffers can be supplied and judged).

    Parameters
    ----------
    stages : sequence of Stage
        A method's registered stages (``name`` and ``after`` of each).

    Returns
    -------
    list of str
        Stage names.
    """
    names = [s.name for s in stages]
    after = {s.name: [u for u in s.after if u in names] for s in stages}
    order, done = [], set()
    while len(order) < len(names):
        nxt = next((n for n in names if n not in done and all(u in done for u in after[n])), None)
        if nxt is None:  # a cycle cannot be registered (after names earlier stages); keep the rest as listed
            order += [n for n in names if n not in done]
            break
        order.append(nxt)
        done.add(nxt)
    return order


def key_stage(key, stages):
    """The stage that makes an array key (``docs/oracle.md``, "Conformance").

    ``stage.<s>.<b>`` -> s (or the owner :data:`FINAL_KEY_STAGES` names); a
    final key -> the last stage whose ``makes`` holds it (``exit_dir`` ->
    ``trace``; in the volumetric method ``exit_pos`` -> ``view``, after the
    march's photon ``exit_pos``), else its :data:`FINAL_KEY_STAGES` owner.

    Parameters
    ----------
    key : str
        An array key of a result.
    stages : sequence of Stage
        The method's registered stages (``name`` and ``makes`` of each).

    Returns
    -------
    str
        The stage name.

    Raises
    ------
    KeyError
        For a final key no stage owns (add it to :data:`FINAL_KEY_STAGES`).
    """
    import fnmatch

    names = {s.name for s in stages}
    table = [owner for pat, owner in FINAL_KEY_STAGES if owner in names and fnmatch.fnmatchcase(key, pat)]
    if key.startswith("stage."):
        return table[0] if table else key.split(".")[1]
    makers = [st.name for st in stages if key in st.makes]
    if table and (key in _OVERRIDES or not makers):
        return table[0]
    if makers:
        return makers[-1]
    raise KeyError(f"golden build: no stage owns the final key {key!r}; name its stage in "
                   "refraction_ref.golden.build.FINAL_KEY_STAGES")


def photon_quantum(scene):
    """The irradiance one photon of the exact references deposits in one texel (flux / texel area).

    For the exact photon reference: the largest photon flux of the light's
    window (:func:`~refraction_ref.caustics.light.window_samples`) over the
    smallest texel area of the receivers' maps; for the exact water
    reference: one water sample's area over the texel area. Per unit light
    (the maps are for lights of unit strength) times the largest radiance.

    Parameters
    ----------
    scene : Scene
        A case's loaded scene (with ``water`` for the exact water reference,
        else receivers and lights for the exact photon reference).

    Returns
    -------
    float
        Irradiance of one photon in one texel (radiance units).
    """
    d = scene.data
    rad = max([float(np.max(lt["radiance"])) for lt in d["lights"]] + [1.0])
    if d.get("water") is not None:
        from ..levelmap.pipeline import planes_pass

        boxes = [b for row in planes_pass(scene)["boxes"] for b in row]
        sx, sz = (float(v) for v in d["water"]["size"])
        M = int(d["exact"]["water_samples"])
        return rad * (sx / M) * (sz / M) / min(b.texel_area for b in boxes)
    from ..caustics.light import window_samples
    from ..caustics.receivers import receiver_set
    from ..lights import light_camera
    from ..meshes import scene_geometry

    geom = scene_geometry(scene)
    n = int(d["exact"]["photons"])
    rs = receiver_set(scene, d["lights"][0], int(d["caustics"]["map_size"]))
    flux = max(float(window_samples(light_camera(lt, geom.vertices, n), n, 0)[2].max()) for lt in d["lights"])
    return rad * flux / min(b.texel_area for b in rs.boxes)


def _save_npz(path, arrays):
    # keys in sorted order: the order stages finish in (which may follow the thread count) does not
    # reach the file, so a build on any worker writes the same bytes
    with atomic_path(path) as tmp:
        np.savez_compressed(tmp, **dict(sorted(arrays.items())))


def build(folder, only=None, progress=False, log=print, scheduler=None, workers=None, threads=1, client=None):
    """Render the catalogue (or ``only`` those cases) into a golden suite in ``folder``.

    Parameters
    ----------
    folder : str
    only : str or list of str, optional
        Case names (the other cases of an existing suite are kept).
    progress : bool
    log : callable
        Called with one line per case built.
    scheduler : str, optional
        Address of a Dask cluster (``tcp://HOST:PORT``): the cases are its tasks.
    workers : int, optional
        Without ``scheduler``: a ``LocalCluster`` of this many worker processes
        (``threads`` threads each) builds the cases; None builds them here.
    threads : int
        Numba threads of each case on a cluster (results do not depend on it).
    client : distributed.Client, optional
        Use this client (tests).

    Returns
    -------
    dict
        The manifest written to ``folder/manifest.json``.
    """
    cases = catalogue(only)
    os.makedirs(folder, exist_ok=True)
    mpath = os.path.join(folder, "manifest.json")
    marker = os.path.join(folder, COMPLETE)
    if os.path.exists(marker):  # from here until the last case is written the suite is not complete
        os.remove(marker)
    manifest = {"contract_version": CONTRACT_VERSION, "versions": software_versions(), "cases": {}}
    if os.path.exists(mpath):  # a partial rebuild (--only) keeps the other cases
        with open(mpath) as f:
            old = json.load(f)
        if old.get("contract_version") == CONTRACT_VERSION:
            manifest["cases"] = old.get("cases", {})

    def done(name, entry):
        manifest["cases"][name] = entry
        log(f"  {name}: {entry['method']}, {len(entry['keys'])} arrays, {entry['build_s']:.1f} s")
        with atomic_open(mpath, "w") as f:  # after every case: an interrupted build keeps what it made
            json.dump(manifest, f, indent=1, sort_keys=True)

    if scheduler is None and workers is None and client is None:
        for case in cases:
            done(case["name"], _build_case(case, os.path.join(folder, case["name"]), progress))
        _mark_complete(folder, manifest)
        return manifest
    from distributed import as_completed

    from ..cluster import dask_client

    with dask_client(scheduler, workers, 1, client) as client:  # closed quietly: no shutdown noise
        futures = [client.submit(_case_task, case, int(threads), pure=False) for case in cases]
        for fu in as_completed(futures):
            name, entry, files = fu.result()
            d = os.path.join(folder, name)
            os.makedirs(d, exist_ok=True)
            for rel, data in sorted(files.items()):
                with atomic_path(os.path.join(d, rel)) as tmp:
                    with open(tmp, "wb") as f:
                        f.write(data)
            done(name, entry)
    _mark_complete(folder, manifest)
    return manifest


def _mark_complete(folder, manifest):
    """Write the completion marker, last: the cases built and the sha256 of the manifest it completes."""
    with open(os.path.join(folder, "manifest.json"), "rb") as f:
        sha = hashlib.sha256(f.read()).hexdigest()
    with atomic_open(os.path.join(folder, COMPLETE), "w") as f:
        json.dump({"cases": sorted(manifest["cases"]), "manifest_sha256": sha,
                   "contract_version": manifest["contract_version"]}, f, indent=1)


def _case_task(case, threads=1):
    """One case built on a Dask worker into a folder of its own: (name, manifest entry, {file: bytes})."""
    import tempfile

    import numba

    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    with tempfile.TemporaryDirectory(prefix="golden-") as tmp:
        d = os.path.join(tmp, case["name"])
        entry = _build_case(case, d)
        files = {}
        for root, _, fs in os.walk(d):
            for fn in fs:
                p = os.path.join(root, fn)
                with open(p, "rb") as f:
                    files[os.path.relpath(p, d)] = f.read()
    return case["name"], entry, files


def _geometry_arrays(scene):
    """The placed triangles every pass rasterizes (``docs/backends.md``: ``geometry.npz``).

    A port outside this package cannot reproduce the mesh loading bit for bit
    (trimesh's vertex merging, ``fit``, ``transform``, ``deform``), so the
    suite carries its result: the objects' world-space triangles merged in
    object order, and the object each triangle belongs to.
    """
    from ..meshes import scene_geometry

    g = scene_geometry(scene)
    return {"vertices": np.asarray(g.vertices, np.float64), "faces": np.asarray(g.faces, np.int64),
            "face_object": np.asarray(g.face_object, np.int32)}


def _build_case(case, d, progress=False):
    """Render one case into folder ``d``; its manifest entry."""
    from ..graph import get_method
    from ..render import render

    t0 = time.perf_counter()
    scene = case_scene(case, d)
    method = case["method"]
    res = render(scene, method=method, keep="stages", progress=progress)
    stages = get_method(method).stages(scene)
    noisy = bool(case.get("batches"))
    keys = {}
    for k, a in sorted(res.arrays.items()):
        keys[k] = {"sha256": array_sha256(a), "shape": list(a.shape), "dtype": a.dtype.str,
                   "stage": key_stage(k, stages),
                   "tolerance": tolerance_for(k, noisy=noisy, dtype=a.dtype)}
    _save_npz(os.path.join(d, "golden.npz"), res.arrays)
    entry = {"method": method, "purpose": case["purpose"], "stages": stage_order(stages),
             "keys": keys, "files": ["scene.json", "golden.npz"], "numba_threads": res.meta["numba_threads"]}
    if scene.data["objects"]:
        _save_npz(os.path.join(d, "geometry.npz"), _geometry_arrays(scene))
        entry["files"].append("geometry.npz")
    if noisy:
        K = int(case["batches"])
        maps = {}
        for b in range(K):
            r = render(scene, method=method, overrides={SEED_KEY: b})
            for k, a in r.arrays.items():
                if k.startswith("caustic_map_"):
                    maps.setdefault(k, []).append(a)
        _save_npz(os.path.join(d, "batches.npz"), {k: np.stack(v) for k, v in maps.items()})
        q = photon_quantum(scene)
        for k in maps:
            keys[k]["tolerance"]["quantum"] = q
        entry["batches"] = {"count": K, "seed_key": SEED_KEY, "keys": sorted(maps), "quantum": q}
        entry["files"].append("batches.npz")
    if case.get("reference"):
        ref = render(scene, method=case["reference"])
        _save_npz(os.path.join(d, "reference.npz"), ref.arrays)
        entry["reference"] = case["reference"]
        entry["files"].append("reference.npz")
    entry["build_s"] = time.perf_counter() - t0
    return entry
