"""The teaching notebooks run top to bottom on a real Jupyter kernel, at a small resolution, and their numbers hold.

Each notebook is executed by ``nbclient`` on the ``python3`` kernel (ipykernel,
started by jupyter_client with this interpreter) through ``notebooks/build.py``'s
:func:`execute`: a cell overriding the notebook's ``parameters`` cell sets a
small resolution, and a final cell prints the notebook's ``key`` dict as JSON,
whose numbers are asserted here (closed forms, equalities with ``rr.render``,
agreement with the exact reference). A notebook that raises fails with the
cell's index and first line. The timeout is a hang guard, not a speed target.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys

import pytest

pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

NB = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "notebooks"))
HANG_GUARD_S = 600


def _build_module():
    spec = importlib.util.spec_from_file_location("notebooks_build", os.path.join(NB, "build.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


build = _build_module()


def run(name, overrides):
    """Execute ``notebooks/<name>.ipynb`` at test size; its ``key`` dict (a failing cell fails the test, named)."""
    before = set(os.listdir(NB))
    try:
        _, seconds, key = build.execute(os.path.join(NB, name + ".ipynb"), overrides, timeout=HANG_GUARD_S,
                                        key_numbers=True)
    except build.NotebookError as e:
        pytest.fail(str(e), pytrace=False)
    assert set(os.listdir(NB)) == before, "a notebook wrote into notebooks/ (scratch files belong in a temp dir)"
    assert isinstance(key, dict), f"{name}: the notebook's last cell must define a dict `key`"
    # the kernel ran this interpreter (a fresh `pip install -e .[test]` venv has ipykernel's python3 kernelspec)
    assert os.path.samefile(key.pop("_executable"), sys.executable)
    print(f"{name}: {seconds:.1f} s at test size; key numbers: {json.dumps(key, default=str)[:2000]}")
    return key


# --------------------------------------------------------------------- the notebooks at test size
def test_imagespace_walkthrough():
    k = run("imagespace_walkthrough", "N = 48")
    # every hand-run pass equals the pipeline's buffers, bit for bit (zmin, bitmask, LDI, bounds, status, exit_dir)
    assert k["hand_equals_render"] is True
    # perspective-corrected central differences (eq. 3.2) beat forward differences (eq. 3.1), Fig. 3.4
    n = k["normal_median_deg"]
    assert n["central_1"] < n["forward_1"] and n["central_2"] < n["forward_1"]
    # against the exact Embree reference: a few degrees at the median, most status codes agree
    assert 0 < k["exit_median_deg"] < 8 and k["exit_p90_deg"] < 40
    assert k["status_agree"] > 0.7
    assert k["status_hist"][1] > 0 and sum(k["status_hist"]) == 48 * 48
    # the NumPy binary search of §3.6 for one pixel (S, E, P1..P5, R5) lands on the pipeline's recorded path_pos[1]
    assert k["binary_search_equals_pipeline"] is True and k["binary_search_max_diff"] < 1e-9
    assert k["binary_search_probes"] == 5
    # Fig. 3.7's 2x2 max halvings of a MIP level give search_bounds' value; a box-filtered MIP max never exceeds the
    # layer's true maximum, and equals it at f = 1
    assert k["mip_reduce_equals_search_bounds"] is True and k["mip_never_above_max"] is True
    # eq. 3.1 with unit pixel steps gives normals along the view axis: its error is the true normal's angle from it
    assert k["forward_vs_facing_deg"] < 3
    # the silhouette is where every estimator is worst (Fig. 3.4)
    assert all(s["rim_median"] > s["inside_median"] for s in k["normal_split_deg"].values())
    # eqs. 3.1, 3.2 and the 3x3 mesh written out in NumPy for one texel give layer_normals' normals
    assert k["normals_by_hand_max_diff"] < 1e-9
    # exercise 2: with eq. 3.2's normals the exit error is larger at the rim than inside
    rim, inside = k["ex2_rim_inside_deg"]["central δ=2"]
    assert rim > inside
    # exercise 3: with TIR followed, each former TIR pixel exits, is lost or reaches a limit (none stays TIR)
    assert k["ex3_former_tir"][3] == 0 and sum(k["ex3_former_tir"]) == k["status_hist"][3]
    assert all(g > 0 for g in k["grain_inside_deg"].values())


def test_caustics_walkthrough():
    k = run("caustics_walkthrough", "N = 48; PHOTONS = 64; MAP = 64; EXACT_PHOTONS = 256")
    # the hand-run light-space LDI, photon exits, receiver hits, splat and gathered maps equal the pipeline's
    assert k["ldi_equal"] and k["exit_equal"] and k["hits_equal"] and k["maps_equal"]
    # the splat deposits the landed photons' flux times the cosine between the floor and the map's axis ...
    assert k["flux_splat"] == pytest.approx(k["flux_landed"] * k["cos_theta"], rel=1e-6)
    # ... and the Gaussian gathering conserves it
    assert k["flux_gathered"] == pytest.approx(k["flux_splat"], rel=1e-9)
    assert k["flux_landed"] == pytest.approx(k["flux_is"], rel=1e-12)
    # against the exact photon reference: an error well above the reference's own noise, below 100 %
    assert 0 <= k["reference_noise"] < 0.1
    assert k["reference_noise"] < k["rel_l1"] < 1.0
    assert 0 < k["flux_is"] <= k["flux_exact"] * 1.05
    # exercise 2's scene (golden is_caustics_slanted): the eye-space march loses photons the exact test lands
    assert k["slanted_lost_eyespace"] > 0 and k["slanted_landed"][0] < k["slanted_landed"][1]
    # exercise 1: at every photon count much of the flux never reaches the floor, and the error stays far above the
    # reference's noise
    assert k["ex1_flux_ratio_max"] < 0.9 and k["ex1_min_rel_l1_over_noise"] > 5
    # exercise 3: Beer-Lambert with absorption (0, 1, 2) keeps red whole, green more than blue
    r, g, b = k["absorbed_rgb_ratio"]
    assert r == pytest.approx(1.0) and 0 < b < g < 1
    # the NumPy binary search with the contract's bilinear reads: no layer at the last probe of every photon the
    # package loses after its first interface, and R5 = the package's exit point of the photons out after two
    assert k["search_lost_agree"] == 1.0 and k["search_r5_max_dev"] < 1e-9
    # one photon's splat E = flux |n.V| / A_texel with bilinear weights, for every landed photon, and the gather's
    # Gaussian taps by hand give stage.splat.splat_0 and caustic_map_0 (float32 storage)
    assert k["splat_hand_dev"] < 1e-6 and k["gather_hand_dev"] < 1e-6


def test_volumetric_walkthrough():
    k = run("volumetric_walkthrough", "VOL = 32; PHOTONS = 16; N = 32")
    # the hand-run gradient (eq. 3) and octree (§4.2, §5.3) equal the pipeline's buffers
    assert k["field_equal"] and k["octree_equal"]
    assert k["paths_used"]["euler"] >= 10 and k["paths_used"]["rk4"] >= 10
    # photon_steps is the total over the photons: per photon, each step at least ds_min = 1 voxel, on paths that
    # cross the lens's box once (under twice its side)
    assert 1 <= k["photon_steps"] / k["photons_generated"] <= 2 * k["VOL"]
    # the Luneburg lens's closed form: parallel photons pass through the antipodal focus (forward Euler, eqs. 4-5,
    # within a voxel; RK4 ten times closer) and leave it at asin(b / R) from the axis (Bouguer's invariant)
    m, d = k["miss_median_vox"], k["exit_dir_median_deg"]
    assert m["euler"] < 0.6 and k["miss_max_vox"]["euler"] < 1.0
    assert m["rk4"] < 0.1 and m["rk4"] < m["euler"]
    assert d["rk4"] < 0.2 and d["rk4"] < d["euler"] < 2.0
    # the voxelized bunny's curved viewing pass against the exact mesh reference
    assert 0 < k["bunny_exit_median_deg"] < 15 and k["bunny_status_agree"] > 0.6
    # the notebook's NumPy march (Fig. 5 step, §5.3 clamp, eqs. 4-5 / RK4) retraces every recorded photon of the
    # graded blob within float32 rounding, and that photon's steps cross octree nodes of at least three levels
    assert k["proto_photons"] >= 10
    assert k["proto_max_dev_vox"]["euler"] < 1e-4 and k["proto_max_dev_vox"]["rk4"] < 1e-4
    assert len(k["blob_levels_on_path"]) >= 3
    # eq. 6 and the deposit walk by hand (every photon of an 8x8 photon texture, summed per z-slab) give the
    # package's stage.march.deposit within float32 summation
    assert k["deposit_hand_dev"] < 1e-5
    # Sun's viewing pass (§4.5) by hand for one pixel: the sum T sigma L p(cos) seg along the curved ray plus T L_env,
    # with Henyey-Greenstein at g = 0 and 0.5, gives the package's image there within float32 rounding
    assert set(k["view_hand_dev"]) == {"0.0", "0.5"} and max(k["view_hand_dev"].values()) < 1e-5


def test_levelmap_walkthrough():
    k = run("levelmap_walkthrough", "N = 48; MAP = 64; GRID = 32; PLANES = 10; EXACT_SAMPLES = 512")
    # eq. 2-8 written out by hand gives the package's refracted directions; the water mesh is the stage's
    assert k["water_equal"] and k["eq28_max_deg"] < 1e-4
    # the reference box is aligned with the flat-water refracted light, V = -T0 (§4.2.1), with orthogonal axes
    assert k["V_vs_T0_deg"] < 1e-6 and k["axes_orthogonality"] < 1e-9
    # the per-plane maps sum to the caustics map (eq. 4-18 accumulated with additive blending)
    assert k["plane_sum_rel_err"] < 1e-5
    # smart slicing re-slices each sub-box (eqs. 4-21/4-22, the default since contract_version 5): over the
    # flat floor it draws fewer planes than the 10-plane lattice, and every drawn plane is used at least once
    assert k["planes_total"][0] < 10 and all(1 <= u <= t <= 10 for u, t in zip(k["planes_used"], k["planes_total"]))
    # against the exact water reference
    assert k["rel_l1_floor"] < 0.3 and k["rel_l1_teapot"] < 0.3
    assert 0.7 < k["flux_ratio_floor"] < 1.3
    # the map stores irradiance on the receiver, Φ e^(-Kd) / A_d (eq. 4-18 times cos θ_t), read at each beam's centroid
    assert abs(k["map_over_E_median"] - 1) < 0.01
    assert k["map_over_Ic_median"] == pytest.approx(k["cos_t_median"], abs=0.01) and k["cos_t_median"] < 0.98
    # the ±ε acceptance (eq. 4-15, Fig. 4-14) by hand picks the plane that lights every lit texel; the drawn beam's
    # kept texels are lit on their plane's own map
    assert k["eps_mismatch_texels"] == 0 and k["eps"] > 0
    assert k["beam_planes"] >= 1 and k["beam_lit_ok"] is True


def test_error_vs_time():
    k = run("error_vs_time", "N = 48; REPEATS = 1; ITERATIONS = [1, 5]")
    # the live sweep ran every task on the in-process Dask cluster, each measured against the exact reference
    assert k["live_tasks"] == 4 and k["live_ok"] == 4
    # the binary search converges: on the sphere 5 iterations are far better than 1 (§3.6)
    assert k["live"]["sphere_5"] < 0.5 * k["live"]["sphere_1"]
    # the committed sweeps (benchmarks/results, read through benchmarks/specs): RK4 misses the Luneburg focus by
    # less than Euler; 50 reference planes beat 5 on the pool floor
    assert k["volumetric_best_miss"]["rk4"] < k["volumetric_best_miss"]["euler"]
    err = k["levelmap_err_by_planes"]
    assert err["50"] < err["5"]
    assert k["imagespace_front"] and k["levelmap_front"] and 0 < k["caustics_best_rel_l1"] < 1
    # δ is in pixels: in the committed sweeps the best δ grows with the image width
    best = {int(w): d for w, d in k["best_delta_by_width"].items()}
    assert best[max(best)] > best[min(best)]


def test_check_a_backend():
    k = run("check_a_backend", "CASE = 'is_sphere_1_5'")
    # the planted off-by-one slice is caught at its own pass, with the bitmask among the failing keys
    assert k["buggy_ok"] is False and k["buggy_stage"] == "voxelize"
    assert "stage.voxelize.bits" in k["buggy_failing"] and "exit_dir" in k["buggy_failing"]
    assert k["cli_returncode"] == 1
    # fixed, the same backend passes every key it supplies
    assert k["fixed_ok"] is True
    # a trace-only bug passes every earlier stage and is named at the trace
    assert k["eta_ok"] is False and k["eta_stage"] == "trace"
    assert not [key for key in k["eta_failing"] if key.startswith("stage.")]
    # the exercises: a half-float LDI is named at peel; with only exit_dir and status the report can name only trace
    assert k["f16_stage"] == "peel" and k["few_stage"] == "trace"
    # the image-space stages begin with rays; the catalogue is the package's golden folder
    assert k["case2_stages"][0] == "rays" and "trace" in k["case2_stages"]
    golden = os.path.join(os.path.dirname(NB), "refraction_ref", "data", "golden")
    assert k["catalogue_cases"] == len([f for f in os.listdir(golden) if f.endswith(".json")])


# --------------------------------------------------------------------- the folder and the runner
def test_every_notebook_is_listed_with_a_parameters_cell_and_exercises():
    import nbformat

    found = sorted(f[:-6] for f in os.listdir(NB) if f.endswith(".ipynb"))
    assert sorted(build.NOTEBOOKS) == found
    total = 0
    for name in found:
        path = os.path.join(NB, name + ".ipynb")
        total += os.path.getsize(path)
        nb = nbformat.read(path, as_version=4)
        nbformat.validate(nb)
        i = build.parameters_index(nb)
        assert all(c.cell_type != "code" for c in nb.cells[:i]), f"{name}: parameters is not the first code cell"
        assert any(c.cell_type == "markdown" and "## Exercises" in c.source for c in nb.cells), name
        assert "key = {" in nb.cells[-1].source, f"{name}: the last cell must define `key`"
        assert nb.metadata.get("kernelspec", {}).get("name") == "python3"
        learn = [c for c in nb.cells if "learn" in c.get("metadata", {}).get("tags", [])]
        assert len(learn) == 1, f"{name}: one cell tagged 'learn' makes docs/learn/{name}.png"
        for c in nb.cells:  # stored figures are PNG (small), never SVG or PDF
            for o in c.get("outputs", []):
                assert not set(o.get("data", {})) & {"image/svg+xml", "application/pdf"}, name
    assert total < 8e6, f"notebooks/ holds {total / 1e6:.1f} MB (limit 8 MB)"


#: notebooks whose exercises have answers (issue 31): all of them
ANSWERED = ["imagespace_walkthrough", "caustics_walkthrough", "volumetric_walkthrough", "levelmap_walkthrough",
            "error_vs_time", "check_a_backend"]


@pytest.mark.parametrize("name", ANSWERED)
def test_exercises_have_a_starter_and_a_collapsed_checked_answer_and_no_reprs(name):
    """Every exercise cell pair: a starter code cell, then a collapsed answer (tag `answer`, source hidden) that
    asserts; stored outputs print no object reprs (`<... at 0x...>`, matplotlib return values, a widget's
    `interactive(...)` or an IPython display object)."""
    import re

    import nbformat

    nb = nbformat.read(os.path.join(NB, name + ".ipynb"), as_version=4)
    ex = next(i for i, c in enumerate(nb.cells) if c.cell_type == "markdown" and "## Exercises" in c.source)
    answers = [i for i, c in enumerate(nb.cells) if "answer" in c.get("metadata", {}).get("tags", [])]
    assert len(answers) >= 3 and all(i > ex for i in answers), name
    for i in answers:
        c = nb.cells[i]
        assert c.cell_type == "code" and c.metadata.get("jupyter", {}).get("source_hidden") is True, (name, i)
        assert re.search(r"^assert ", c.source, re.M), f"{name}: answer cell {i} has no check"
        starter = nb.cells[i - 1]
        assert starter.cell_type == "code" and "answer" not in starter.metadata.get("tags", []), (name, i)
    reprs = [(i, o.data["text/plain"][:60]) for i, c in enumerate(nb.cells) if c.cell_type == "code"
             for o in c.get("outputs", []) if "text/plain" in o.get("data", {}) and "image/png" not in o.get("data", {})
             and re.search(r"<[\w.]+ (object )?at 0x|^(Text|<matplotlib|interactive\(|<IPython)", o.data["text/plain"])]
    reprs += [(i, "figure repr") for i, c in enumerate(nb.cells) if c.cell_type == "code"
              for o in c.get("outputs", []) if re.match(r"<Figure size", o.get("data", {}).get("text/plain", ""))
              and "image/png" not in o.get("data", {})]
    assert not reprs, f"{name}: object reprs in the stored outputs: {reprs}"


def test_notebooks_call_no_private_names_and_say_what_they_need():
    """What a student sees: no private name of the package imported or called (``_x``), sliders only through
    ``teach.sliders`` (no ipywidgets call whose return value prints), and a notebook that reads the checkout's
    ``benchmarks/`` says so in its first cell."""
    import re

    import nbformat

    for name in build.NOTEBOOKS:
        nb = nbformat.read(os.path.join(NB, name + ".ipynb"), as_version=4)
        code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
        private = re.findall(r"from refraction_ref[\w.]* import [^\n]*\b_(?!_)\w+|\brr\._(?!_)\w+|"
                             r"refraction_ref\.\w+\._(?!_)\w+", code)
        assert not private, f"{name}: private names in the cells: {private}"
        assert "widgets.interact" not in code and "import ipywidgets" not in code, f"{name}: sliders go through teach.py"
        if re.search(r"benchmarks|results_dir\(", code):
            assert "Needs a checkout" in nb.cells[0].source, f"{name}: reads benchmarks/ but its first cell does not say so"


def test_stored_outputs_come_from_the_packages_contract_version():
    """Each notebook's stored outputs were made under this package's contract_version (read from the .ipynb,
    not executed): the cell tagged `contract` printed it when `python notebooks/build.py` last ran the notebook."""
    import nbformat
    from refraction_ref.contract import CONTRACT_VERSION

    stored = {name: build.stored_contract_version(nbformat.read(os.path.join(NB, name + ".ipynb"), as_version=4))
              for name in build.NOTEBOOKS}
    stale = sorted(n for n, v in stored.items() if v != CONTRACT_VERSION)
    assert not stale, (f"stored outputs of another contract_version than the package's {CONTRACT_VERSION}: "
                       f"{ {n: stored[n] for n in stale} }; rebuild them: python notebooks/build.py {' '.join(stale)}")
    # the reader tells an old build and a notebook without the cell (or without its output) apart from a fresh one
    nb = nbformat.v4.new_notebook()
    cell = nbformat.v4.new_code_cell("print('contract_version', 5)", metadata={"tags": [build.CONTRACT_TAG]})
    nb.cells = [cell]
    assert build.stored_contract_version(nb) is None
    cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text="contract_version 5\n")]
    assert build.stored_contract_version(nb) == 5
    cell.metadata["tags"] = []
    assert build.stored_contract_version(nb) is None


def test_every_notebook_stores_its_key_numbers_under_this_contract_version():
    """`python notebooks/build.py` stores each notebook's full-size `key` dict in its metadata, made under the
    package's contract_version, and the stored outputs print the same version (read, not executed)."""
    import nbformat
    from refraction_ref.contract import CONTRACT_VERSION

    missing, stale = [], {}
    for name in build.NOTEBOOKS:
        nb = nbformat.read(os.path.join(NB, name + ".ipynb"), as_version=4)
        key = build.stored_key(nb)
        if not isinstance(key, dict) or not key:
            missing.append(name)
            continue
        meta_v = nb.metadata[build.META].get("contract_version")
        if not (meta_v == CONTRACT_VERSION == build.stored_contract_version(nb)):
            stale[name] = (meta_v, build.stored_contract_version(nb))
    assert not missing, f"no stored key numbers (rebuild them): python notebooks/build.py {' '.join(missing)}"
    assert not stale, (f"(metadata, printed) contract_version differ from the package's {CONTRACT_VERSION}: {stale}; "
                       f"rebuild: python notebooks/build.py {' '.join(stale)}")


def test_key_differences_names_what_changed_and_skips_timings():
    stored = {"a": 1.0, "b": {"x": [1, 2.5], "ok": True}, "stage_ms": 10.0, "name": "lens"}
    assert build.key_differences(stored, json.loads(json.dumps(stored))) == []
    # a timing changes freely; a relative change below KEY_RTOL passes, above it fails and is named
    assert build.key_differences(stored, dict(stored, stage_ms=99.0, a=1.0 + build.KEY_RTOL / 2)) == []
    d = build.key_differences(stored, dict(stored, a=1.01, b={"x": [1, 2.5], "ok": False}))
    assert d == ["key.a: 1.0 stored != 1.01 fresh", "key.b.ok: True stored != False fresh"]
    assert build.key_differences(stored, dict(stored, b={"x": [1], "ok": True})) == ["key.b.x: 2 items stored, 1 fresh"]
    assert build.key_differences({"a": 1}, {"a": 1, "c": 2}) == ["key.c: only in the fresh key"]


@pytest.mark.slow
@pytest.mark.parametrize("name", build.NOTEBOOKS)
def test_stored_key_numbers_equal_a_fresh_run(name):
    """Re-executes the notebook at the size it was stored at (its `parameters` cell as written) and compares its
    key numbers with the stored ones, within build.KEY_RTOL (relative); timings are skipped (build.TIMING_WORDS).
    Minutes per notebook: run with -m slow."""
    import nbformat

    stored = build.stored_key(nbformat.read(os.path.join(NB, name + ".ipynb"), as_version=4))
    assert isinstance(stored, dict), f"{name}: no stored key numbers; python notebooks/build.py {name}"
    fresh = run(name, None)
    diff = build.key_differences(stored, fresh)
    assert not diff, (f"{name}: the stored outputs are not a fresh run's ({len(diff)} differences): {diff[:8]}; "
                      f"rebuild: python notebooks/build.py {name}")


def test_sliders_fall_back_to_one_call_at_the_defaults(monkeypatch, capsys):
    """notebooks/teach.py: while build.py stores outputs (or without ipywidgets) a slider cell calls its function
    once, at each control's first value, and says so; with ipywidgets and a reader it builds the controls."""
    spec = importlib.util.spec_from_file_location("notebooks_teach", os.path.join(NB, "teach.py"))
    teach = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(teach)
    calls = []
    monkeypatch.setenv(teach.STATIC_ENV, "1")
    assert teach.sliders(lambda **kw: calls.append(kw), ds_min=(1.0, 0.25, 4.0, 0.25), integrator=["rk4", "euler"]) is False
    assert calls == [{"ds_min": 1.0, "integrator": "rk4"}] and "static" in capsys.readouterr().out
    if importlib.util.find_spec("ipywidgets") is not None:
        monkeypatch.delenv(teach.STATIC_ENV)
        calls.clear()
        assert teach.sliders(lambda **kw: calls.append(kw), planes=(50, 2, 200, 1), smart=[True, False]) is True
        assert calls == [{"planes": 50, "smart": True}]     # drawn once at the defaults when the controls appear


def test_a_failing_cell_is_named(tmp_path):
    import nbformat

    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [nbformat.v4.new_markdown_cell("# t"),
                nbformat.v4.new_code_cell("N = 1", metadata={"tags": ["parameters"]}),
                nbformat.v4.new_code_cell("x = N + 1"),
                nbformat.v4.new_code_cell("# divide\ny = x / (N - 2)\nraise ValueError(f'boom {x}')")]
    p = tmp_path / "bad.ipynb"
    nbformat.write(nb, str(p))
    with pytest.raises(build.NotebookError) as e:
        build.execute(str(p), "N = 2", timeout=120, cwd=str(tmp_path))
    msg = str(e.value)
    # the index is the stored notebook's (the injected parameters cell does not count)
    assert "bad.ipynb: cell 3 ('# divide')" in msg and "ZeroDivisionError" in msg
    # the hang guard names the cell that did not finish
    nb.cells[3].source = "# wait\nimport time\ntime.sleep(60)"
    nbformat.write(nb, str(p))
    with pytest.raises(build.NotebookError) as e:
        build.execute(str(p), None, timeout=8, cwd=str(tmp_path))
    assert "bad.ipynb: cell 3 ('# wait') did not finish within the hang guard of 8 s" in str(e.value)
