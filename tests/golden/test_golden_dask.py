"""``refraction-ref golden build`` on a Dask cluster: the same suite as a local, serial build.

Two small cases are built once here, serially, and once as the tasks of a
``LocalCluster`` of two single-thread worker processes; every case file is
the same bytes and the manifests agree but for the build times (and the
thread count each case ran with: results do not depend on it).
"""

from __future__ import annotations

import io
import json
import os

import numpy as np

import pytest

from refraction_ref.golden.build import build

CASES = "is_sphere_1_5,exact_caustics_sphere"


def _files(root):
    out = {}
    for r, _, fs in os.walk(root):
        for f in fs:
            if f not in ("manifest.json", "complete.json"):  # both hold build_s (the marker: the manifest's hash)
                with open(os.path.join(r, f), "rb") as fh:
                    out[os.path.relpath(os.path.join(r, f), root)] = fh.read()
    return out


def _manifest(root):
    with open(os.path.join(root, "manifest.json")) as f:
        m = json.load(f)
    for c in m["cases"].values():
        c.pop("build_s")
        c.pop("numba_threads")
    return m


def test_golden_build_on_two_dask_workers_equals_a_serial_build(tmp_path):
    pytest.importorskip("distributed")
    from distributed import Client, LocalCluster

    local, dist = str(tmp_path / "local"), str(tmp_path / "dask")
    build(local, only=CASES, log=lambda *_: None)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        m = build(dist, only=CASES, log=lambda *_: None, client=client)
    assert sorted(m["cases"]) == sorted(CASES.split(","))
    a, b = _files(local), _files(dist)
    assert sorted(a) == sorted(b) and len(a) >= 4
    for k in a:
        if k.endswith(".npz"):  # name the array that differs
            x, y = np.load(io.BytesIO(a[k])), np.load(io.BytesIO(b[k]))
            assert x.files == y.files, k
            for n in x.files:
                assert x[n].dtype == y[n].dtype and x[n].tobytes() == y[n].tobytes(), (k, n)
        assert a[k] == b[k], k
    assert _manifest(local) == _manifest(dist)
