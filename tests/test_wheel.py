"""The package as users install it: every data file the code opens ships in the wheel.

``pip install -e`` reads ``refraction_ref/data`` from the checkout, so a package-data glob
that misses a sub-folder passes every other test and breaks every regular install (it
happened: ``data/*.json`` left out ``data/golden/*.json``, and ``golden build --only`` found
no case). This test builds the wheel as ``pip wheel`` does and reads its file list; CI also
installs that wheel non-editable in a fresh venv and renders from it (``.ci/run``).
"""
import importlib
import os
import pathlib
import shutil
import subprocess
import sys
import zipfile

import pytest

import refraction_ref as rr
from refraction_ref import meshes, warm
from refraction_ref.levelmap import pipeline as lm_pipeline

golden_build = importlib.import_module("refraction_ref.golden.build")

ROOT = pathlib.Path(__file__).resolve().parents[1]
PKG = ROOT / "refraction_ref"


def _opened_data_files():
    """The data files the code names, as paths relative to the package folder."""
    names = {f"data/{m}.ply" for m in meshes.BUILTIN_MESHES if m not in ("sphere", "plane")}
    names |= {os.path.relpath(c["path"], PKG) if "path" in c else f"data/golden/{c['name']}.json"
              for c in golden_build.catalogue()}
    names.add(os.path.relpath(os.path.join(os.path.dirname(warm.__file__), "data", "kernels.json"), PKG))
    names.add(os.path.relpath(lm_pipeline.DEFAULT_SCENE_PATH, PKG))
    names |= {"data/caustics_default.json", "data/volumetric_fig9.json"}
    return {n.replace(os.sep, "/") for n in names}


@pytest.fixture(scope="module")
def wheel_names(tmp_path_factory):
    # from a clean copy of the files git would ship: a checkout's own build/ and *.egg-info
    # (SOURCES.txt) feed setuptools' file list and can hide a glob that misses a folder
    src = tmp_path_factory.mktemp("src")
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True,
                           text=True).stdout.split("\n")
    files = [f for f in files if f and (ROOT / f).is_file()]
    if not files:
        pytest.skip("not a git checkout")
    for f in files:
        (src / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / f, src / f)
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "--quiet", "-w", str(out)],
                   check=True, capture_output=True, text=True)
    (whl,) = out.glob("refraction_ref-*.whl")
    with zipfile.ZipFile(whl) as z:
        return {n[len("refraction_ref/"):] for n in z.namelist() if n.startswith("refraction_ref/")}


def test_every_file_the_code_opens_is_in_the_wheel(wheel_names):
    opened = _opened_data_files()
    assert len([n for n in opened if n.startswith("data/golden/")]) == len(golden_build.catalogue())
    for n in sorted(opened):
        assert (PKG / n).is_file(), f"the code names {n}, which the checkout lacks"
    missing = sorted(opened - wheel_names)
    assert not missing, f"package data missing from the wheel: {missing} (pyproject.toml package-data)"


def test_every_tracked_data_file_is_in_the_wheel(wheel_names):
    tracked = subprocess.run(["git", "ls-files", "refraction_ref/data"], cwd=ROOT, capture_output=True,
                             text=True, check=True).stdout.split()
    if not tracked:
        pytest.skip("not a git checkout")
    missing = sorted(os.path.relpath(t, "refraction_ref").replace(os.sep, "/") for t in tracked
                     if os.path.relpath(t, "refraction_ref").replace(os.sep, "/") not in wheel_names)
    assert not missing, f"tracked data files missing from the wheel: {missing}"
    assert rr.__version__
