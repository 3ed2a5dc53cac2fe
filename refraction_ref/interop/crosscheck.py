"""``refraction-ref crosscheck``: the exact references checked against an independent renderer, Mitsuba 3.

For every case of the golden catalogue (:mod:`refraction_ref.golden.build`)
with an exact reference, the scene is exported to Mitsuba
(:mod:`refraction_ref.interop.mitsuba`) and measured three ways:

``paths`` (:mod:`.paths`)
    Every pixel's ray through Mitsuba's sensor, intersector and shading
    normals, refracted here, against our exact method's exits.
``images`` (:mod:`.images`)
    Our exact image against Mitsuba's through the pixel centres, with the
    Fresnel-free BSDF and with Mitsuba's own ``dielectric``.
``caustics`` (:mod:`.caustics`)
    Our exact caustic maps against Mitsuba's photons on the same receivers
    in our map frames.

Water scenes (the exact water reference, :mod:`refraction_ref.exact.water`;
:mod:`.water`): ``paths`` compares the eye rays refracted at the water,
``caustics`` Mitsuba's photons through the exported water mesh. The
volumetric cases are skipped: a graded-index volume bends rays continuously,
and no Mitsuba plugin does. :mod:`.report` judges the numbers against the
targets and writes the Markdown report.

Every case is one Dask task when ``workers`` (a ``LocalCluster``) or a
``scheduler`` is given, as ``golden build`` runs its cases.

References
----------
.. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org.
"""

from __future__ import annotations

import json
import os
import tempfile
import time

import numba
from distributed import as_completed

from ..cluster import dask_client
from ..contract import software_versions
from ..files import atomic_open
from ..golden.build import catalogue
from .caustics import caustics_case
from .figures import caustics_figure, images_figure, paths_figure
from .images import images_case
from .paths import paths_case
from .report import TARGETS, TIR_CHAOS, report_markdown
from .water import water_paths_case

__all__ = ["crosscheck_cases", "run_case", "run", "PARTS"]

#: the cross-checks, in the order they run
PARTS = ("paths", "images", "caustics")


def crosscheck_cases(only=None):
    """The golden catalogue's cases (or ``only`` those): every one gets a row, cases without a
    cross-check a reason (:func:`run_case`).

    Parameters
    ----------
    only : str or sequence of str, optional
        Case names (comma-separated or a list); None for every case.

    Returns
    -------
    list of dict
        The cases (:func:`refraction_ref.golden.build.catalogue`).
    """
    return catalogue(only)


def _has_caustics(case):
    s = case["scene"]
    return bool(s.get("lights")) and bool(s.get("receivers")) and (
        case["method"] == "exact" or case.get("reference") == "exact")


def _skip_reason(case):
    if case["method"] == "volumetric":
        return ("volumetric: a graded-index volume (continuous refraction) has no Mitsuba plugin (media "
                "scatter and absorb, they do not bend rays); no exact mesh reference to cross-check")
    if case["method"] == "exact" and not _has_caustics(case):
        return "exact method without receivers: nothing beyond the image-space cases' references"
    return None


def run_case(case, folder, parts=PARTS, figures=True):
    """Cross-check one case into ``folder``; its entry (numbers per part, figure files, or a skip reason).

    Paths and images run on the cases with an exact per-pixel reference
    (``reference: exact``), caustics on every case with lights and receivers
    whose method or reference is exact. A water scene's paths are its eye
    rays refracted at the water
    (:func:`~refraction_ref.interop.water.water_paths_case`), its caustics
    Mitsuba's photons through the water mesh
    (:func:`~refraction_ref.interop.water.mitsuba_water_photons`); its image
    is not cross-checked.

    Parameters
    ----------
    case : dict
        A catalogue case.
    folder : str
        The case's output folder (figures).
    parts : sequence of {'paths', 'images', 'caustics'}
        The cross-checks to run.
    figures : bool
        Write the PNG figures.

    Returns
    -------
    dict
        ``name``, ``purpose``, ``method``, and ``skipped`` (a reason) or the
        parts' numbers and ``seconds``.
    """
    t0 = time.perf_counter()
    entry = {"name": case["name"], "purpose": case["purpose"], "method": case["method"]}
    why = _skip_reason(case)
    if why:
        entry["skipped"] = why
        return entry
    os.makedirs(folder, exist_ok=True)
    water = case["scene"].get("water") is not None
    pixels = case.get("reference") == "exact" and not water
    name = case["name"]
    with tempfile.TemporaryDirectory(prefix="crosscheck-") as tmp:
        if "paths" in parts and water:  # the eye rays refracted at the water (the images are not cross-checked)
            num, pf = water_paths_case(case, os.path.join(tmp, "paths"))
            entry["paths"] = num
            if figures:
                num["figure"] = paths_figure(pf, os.path.join(folder, "paths.png"), name, "meets the water")
        if "paths" in parts and pixels:
            num, pf = paths_case(case, os.path.join(tmp, "paths"))
            entry["paths"] = num
            if figures:
                num["figure"] = paths_figure(pf, os.path.join(folder, "paths.png"), name)
        if "images" in parts and pixels:
            num, imf = images_case(case, os.path.join(tmp, "images"))
            entry["images"] = num
            if figures:
                num["figure"] = images_figure(imf, os.path.join(folder, "images.png"), name)
        if "caustics" in parts and _has_caustics(case):
            num, cf = caustics_case(case, os.path.join(tmp, "caustics"))
            entry["caustics"] = num
            if figures:
                num["figure"] = caustics_figure(cf, os.path.join(folder, "caustics.png"), name)
    entry["seconds"] = time.perf_counter() - t0
    return entry


def _case_task(case, parts, threads=1):
    """One case on a Dask worker: (name, entry, {figure file: bytes})."""
    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    with tempfile.TemporaryDirectory(prefix="crosscheck-case-") as d:
        entry = run_case(case, d, parts)
        files = {}
        for fn in os.listdir(d):
            with open(os.path.join(d, fn), "rb") as fh:
                files[fn] = fh.read()
    return case["name"], entry, files


def _versions(v):
    """``software_versions()`` with Mitsuba's and Dr.Jit's, where the ``crosscheck`` extra is installed."""
    try:  # Mitsuba is optional: a report of merged cases is written without it
        import drjit
        import mitsuba

        v = dict(v, mitsuba=mitsuba.__version__, drjit=drjit.__version__)
    except ImportError:
        pass
    return v


def run(out, only=None, parts=PARTS, workers=None, scheduler=None, log=print, report=None, merge=None):
    """Cross-check the catalogue (or ``only`` those cases) into ``out``: ``crosscheck.json``,
    ``crosscheck.md`` (or the Markdown file ``report``, its figure links relative to it) and
    ``<case>/*.png``. Cases run as Dask tasks with ``workers`` (a LocalCluster) or ``scheduler`` (as
    ``golden build``), else here one by one.

    Parameters
    ----------
    out : str
        Output folder (created when missing).
    only : str or sequence of str, optional
        Case names; None for the whole catalogue.
    parts : sequence of {'paths', 'images', 'caustics'}
        The cross-checks to run.
    workers : int, optional
        Processes of a local Dask cluster.
    scheduler : str or distributed.Client, optional
        Address of a running Dask scheduler, or an open Dask client to use (left open).
    log : callable
        ``log(str)`` for one line per finished case.
    report : str, optional
        Path of the Markdown report (default ``out/crosscheck.md``).
    merge : str, optional
        An earlier ``crosscheck.json``: its cases that this run does not redo
        are kept (their figures are not copied: give the same ``out``).

    Returns
    -------
    dict
        ``targets``, ``tir_chaos``, ``versions`` and ``cases`` (per case its
        :func:`run_case` entry), as written to ``crosscheck.json``.
    """
    cases = crosscheck_cases(only)
    entries = {}
    if merge:
        with open(merge) as fh:
            entries.update(json.load(fh)["cases"])
    os.makedirs(out, exist_ok=True)

    def done(name, entry, files=None):
        entries[name] = entry
        if files:
            os.makedirs(os.path.join(out, name), exist_ok=True)
            for fn, data in files.items():
                with open(os.path.join(out, name, fn), "wb") as fh:
                    fh.write(data)
        log(f"  {name}: " + (f"skipped ({entry['skipped'][:60]}...)" if "skipped" in entry else
                             f"{entry.get('seconds', 0):.0f} s"))

    if scheduler is None and workers is None:
        for c in cases:
            done(c["name"], run_case(c, os.path.join(out, c["name"]), parts))
    else:
        address, client = (scheduler, None) if isinstance(scheduler, str) else (None, scheduler)
        with dask_client(address, workers, 1, client) as client:  # closed quietly, as golden build's
            futures = [client.submit(_case_task, c, tuple(parts), pure=False) for c in cases]
            for fu in as_completed(futures):
                done(*fu.result())
    result = {"targets": TARGETS, "tir_chaos": list(TIR_CHAOS), "versions": _versions(software_versions()),
              "cases": dict(sorted(entries.items()))}
    with atomic_open(os.path.join(out, "crosscheck.json"), "w") as f:
        json.dump(result, f, indent=1, sort_keys=True, default=float)
    md = report or os.path.join(out, "crosscheck.md")
    link = os.path.relpath(os.path.abspath(out), os.path.dirname(os.path.abspath(md)))
    with atomic_open(md, "w") as f:
        f.write(report_markdown(result, "" if link == "." else link + "/"))
    return result
