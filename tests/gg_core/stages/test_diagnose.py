"""Diagnosis end to end. Captures simulated by our own simulator (fast, exact): a hidden horizontal gravity
offset is found, named and refitted; without a hidden force the verdict is "none". Blender captures with hidden
effects (bpy, slow): the same on physics the simulator never generated."""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "diagnosis"))
sys.path.insert(0, str(Path(__file__).parents[1] / "physics"))

from diagnosis_helpers import hanging_sheet, side_strip, write_sim_capture  # noqa: E402

from gg_core.errors import InputError  # noqa: E402
from gg_core.geometry.meshio import read_mesh, write_ply  # noqa: E402
from gg_core.physics.fitting import Observed  # noqa: E402
from gg_core.physics.material import MATERIAL_SPEC  # noqa: E402
from gg_core.physics.model_file import read_model  # noqa: E402
from gg_core.stages.diagnose import DiagnoseRequest, denoise, run_diagnose  # noqa: E402

FAST = {"substeps": 1, "baseline_iterations": 10, "refit_iterations": 6, "bootstrap": 30,
        "progress": "none"}


@pytest.fixture(scope="module")
def tilted(tmp_path_factory) -> Path:
    return write_sim_capture(tmp_path_factory.mktemp("diag") / "tilted",
                             {"gravity_offset": {"delta_g": (2.0, 0.0, 0.0)}})


def test_hidden_gravity_tilt_is_named_refitted_and_improves_heldout(tilted, tmp_path):
    project = tmp_path / "project"
    report_path = run_diagnose(DiagnoseRequest(capture=tilted, project=project, workers=2, **FAST))
    report = json.loads(report_path.read_text())
    assert report["verdict"] == "missing"
    assert report["accepted"] == ["gravity_offset"] and report["accepted_classes"] == ["gravity"]
    effect = report["effects"][0]
    assert effect["name"] == "gravity_offset" and effect["uncertainty"]["inclusion_probability"] >= 0.9
    assert effect["refit"]["gravity_offset.delta_g"][0] == pytest.approx(2.0, rel=0.2)
    # refitted on all three recordings once confirmed (pipeline.final_fit): what the report's sentence states
    final = effect["refit_all_recordings"]
    assert final == report["final_fit"]["refit"] and final["gravity_offset.delta_g"][0] == pytest.approx(2.0, rel=0.2)
    starts = report["final_fit"]["starts_train_rollout_l2"]     # the split's fit and each other fold's, compared
    assert "the split's fit" in starts and report["final_fit"]["start"].split(", refitted")[0] in starts
    assert report["final_fit"]["train_rollout_l2"] > 0
    # ... and delivered as a model file gg simulate rolls out: the garment with the tilt and the final fit's values
    model = read_model(report["outputs"]["model"])
    assert dict(model.terms)["gravity_offset"]["delta_g"] == final["gravity_offset.delta_g"]
    assert model.cloth.flat and model.cloth.n_vertices == len(read_mesh(project / "diagnose" / "template.ply")[0])
    assert float(model.cloth.material.density[0]) == pytest.approx(final["material.density"])
    assert report["heldout_l2_after"] < 0.5 * report["heldout_l2_before"] and report["closest"] is None
    # the recordings hang off the baseline's rollouts along the tilt (+x), not across it
    lag = report["baseline"]["train_rollout_lag_x_mm"], report["baseline"]["train_rollout_lag_z_mm"]
    assert lag[0] > 3.0 * abs(lag[1]) and lag[0] > 0.5
    assert report["baseline"]["held_material"] == []     # ground truth: the density is fitted
    # noise-free recordings stretch about as the fitted cloth does: the activity map is not blind
    assert 0.5 < report["localization"]["activity_excess"] < 1.5 and not report["localization"]["activity_blind"]
    assert report["train_sequences"] == ["a", "b"] and report["heldout_sequences"] == ["c"]
    vertex_map = np.load(project / "diagnose" / "residual_vertex.npy")
    template, _ = read_mesh(project / "diagnose" / "template.ply")
    assert vertex_map.shape == (len(template),) and vertex_map.max() > 0
    frames = json.loads((project / "diagnose" / "residual_frame.json").read_text())
    assert set(frames["sequences"]) == {"a", "b"} and frames["unit"] == "m/s^2"
    page = (project / "reports" / "diagnose.html").read_text()
    assert "data:image/png;base64," in page and "Missing gravity offset" in page
    # resumable: unchanged inputs keep the result (the worker count is not an input: the refits do not depend on it)
    written = report_path.stat().st_mtime_ns
    assert run_diagnose(DiagnoseRequest(capture=tilted, project=project, workers=1, **FAST)) == report_path
    assert report_path.stat().st_mtime_ns == written


def test_nothing_hidden_gives_verdict_none(tmp_path):
    capture = write_sim_capture(tmp_path / "plain")
    # as the benchmark asks: a "true effect" trialled whatever the selection says, in every fold, never named
    report = json.loads(run_diagnose(DiagnoseRequest(capture=capture, project=tmp_path / "p", workers=1,
                                                     reference=["gravity_offset"], **FAST)).read_text())
    assert report["verdict"] == "none" and report["accepted"] == []
    assert report["heldout_l2_after"] == report["heldout_l2_before"] and report["final_fit"] is None
    assert report["outputs"]["model"] is None and not (tmp_path / "p" / "diagnose" / "model.npz").exists()
    folds = report["cross_validation"]["folds"]
    assert [f["heldout"] for f in folds] == [["c"], ["a"], ["b"]]
    assert all(set(f["given_truth"]) == {"gravity_offset"} for f in folds)
    assert folds[0]["given_truth"]["gravity_offset"]["heldout_l2"] == \
        report["reference_trials"]["gravity_offset"]["heldout_l2"]
    assert report["cross_validation"]["given_truth"]["gravity_offset"]["heldout_gain"] < 0.1   # nothing to gain
    near = report["closest"]       # the candidate nearest to being named, and what it lacked (verdict.closest)
    assert near["name"] in {e["name"] for e in report["effects"] if not e["implausible"]} and near["why_not"]
    assert near["heldout_gain"] == report["cross_validation"]["candidates"][near["name"]]["heldout_gain"]


def test_hidden_rest_length_change_is_scanned_named_and_refitted_on_its_own_region(tmp_path):
    """With the unloaded garment given, a seam-like strip 10 % shorter at rest is found by the region scan (chosen
    on the training rollouts, again in each fold), named, and refitted on every recording starting only from fits
    made on the delivered region (pipeline._trialled_model)."""
    v, f, _ = hanging_sheet()
    strip = side_strip(v)
    capture = write_sim_capture(tmp_path / "shrunk", region=(strip.astype(np.float64), {"rest": np.log(0.9)}))
    write_ply(tmp_path / "rest.ply", v, f)
    report = json.loads(run_diagnose(DiagnoseRequest(capture=capture, project=tmp_path / "p", workers=2,
                                                     rest_mesh=str(tmp_path / "rest.ply"), **FAST)).read_text())
    assert report["verdict"] == "missing" and report["accepted"] == ["rest_length_region"]
    scanned = report["localization"]["scanned_regions"]["rest_length_region"]
    found = np.zeros(len(v), bool)
    found[scanned["region_vertices"]] = True
    # the region is whole pooling patches (about 12 vertices on this 49-vertex sheet), so it holds part of the
    # strip and its neighbours: measured 5 of its 11 vertices on the strip, which covers 29 % of the sheet
    assert strip[found].mean() > 1.4 * strip.mean()
    rolled = scanned["rollouts"]
    assert rolled["train_rollout_l2"] < rolled["train_rollout_l2_before"] and rolled["scale"] < 1.0
    # measured: 17.0 -> 12.8 mm held out (-25 %; -24 % over the folds), the delivered scale 0.889
    assert report["heldout_l2_after"] < 0.85 * report["heldout_l2_before"]
    assert report["heldout_gain_cross_validated"] > 0.15
    final = report["final_fit"]
    assert final["refit"]["region.rest_scale"] == pytest.approx(0.9, abs=0.03)
    # the final fit compares the split's fit and those folds' fits made on the same region (here every fold's
    # own scan chose it)
    assert "the split's fit" in final["starts_train_rollout_l2"]
    assert len(final["starts_train_rollout_l2"]) <= len(report["cross_validation"]["folds"])


def test_registered_meshes_are_read_from_the_project(tilted, tmp_path):
    project = tmp_path / "project"
    with pytest.raises(InputError, match="no registered garment meshes"):
        run_diagnose(DiagnoseRequest(capture=tilted, project=project, source="registered", **FAST))
    for seq in ("a", "b", "c"):
        shutil.copytree(tilted / seq / "gt" / "garment", project / "stage2" / seq / "meshes")
    fast = dict(FAST, bootstrap=10, refit_iterations=2, baseline_iterations=4)
    report = json.loads(run_diagnose(DiagnoseRequest(capture=tilted, project=project, source="registered",
                                                     **fast)).read_text())
    assert report["source"] == "registered" and report["effects"]
    # measured recordings hold the density at the default (pipeline.held_material); ground truth fits it
    assert report["baseline"]["held_material"] == ["density"]
    assert report["baseline"]["density"] == pytest.approx(MATERIAL_SPEC["density"][0], rel=1e-9)


@pytest.fixture(scope="module")
def blender_capture(tmp_path_factory):
    """Small ground-truth-only Blender captures (3 sequences x 16 frames, ~400-vertex skirt, seed 0), made on first
    use: `"gravity"` with tilted, stronger gravity, `"none"` with the reference physics. Each test makes only the
    one it reads, so where xdist runs the two tests on different workers neither makes both. At Blender's own
    default steps per frame, not the benchmark's 20: a tilt is resolved there, and the captures take a quarter of
    the time."""
    from gg_core.commands.bench_diagnose import BLENDER_DEFAULT_STEPS, effect_params, preset
    from gg_core.synth.generate import SynthRequest, generate

    root = tmp_path_factory.mktemp("blender_diag")
    made: dict[str, Path] = {}

    def make(effect: str) -> Path:
        if effect not in made:
            generate(SynthRequest(preset=preset(16, 400, BLENDER_DEFAULT_STEPS), out=root / effect, effect=effect,
                                  effect_params=effect_params(effect, 1.0), render=False, progress="none"))
            made[effect] = root / effect
        return made[effect]

    return make


# Four L-BFGS iterations per confirming refit (the command's default is 8). The tilt test, the suite's longest,
# trials the two candidates explaining most of the residual (the tilt and wind, its rival) and cross-validates
# both. The `none` test trials the four explaining most: the likeliest false alarms (of the seven that act, the
# other three gained -8 to +1.4 % held out when all seven were trialled). Measured alone, 2 cores (session 51,
# `pytest -k blender --durations`): tilt 650 s with three trials (baseline 95 s, trials 176 s, folds 283 s, joint and
# final fit 66 s), `none` 426 s with seven (trials 314 s); inside the 22-minute suite 1032 / 735 s, its critical
# path; with these trials 876 / 353 s in a 17-minute suite. Not cheaper by a coarser skirt: at ~300 vertices
# (336) the `none` capture gives a false alarm, anisotropic stretch accepted at -19.7 % held out (-13.6 % over the
# folds), where at 429 vertices it loses 19.6 %.
BLENDER = {"baseline_iterations": 10, "refit_iterations": 4, "bootstrap": 40, "progress": "none"}
BLENDER_TILT = {**BLENDER, "max_trials": 2, "fold_finalists": 2}
BLENDER_NONE = {**BLENDER, "max_trials": 4}


@pytest.mark.bpy
@pytest.mark.slow
def test_blender_gravity_tilt_is_named(blender_capture, tmp_path):
    report = json.loads(run_diagnose(DiagnoseRequest(capture=blender_capture("gravity"), project=tmp_path,
                                                     **BLENDER_TILT)).read_text())
    assert report["accepted_classes"][:1] == ["gravity"]
    folds = report["cross_validation"]["candidates"]
    # the other trial was cross-validated too: wind (session 51, torch's default threads). With three trials and one
    # thread anisotropic stretch had been the finalist instead (session 48: a tie the thread count broke)
    rivals = [n for n, c in folds.items() if n != "gravity_offset" and c["folds"] == 3]
    assert folds["gravity_offset"]["folds"] == 3 and len(rivals) == BLENDER_TILT["fold_finalists"] - 1
    assert report["heldout_l2_after"] < 0.9 * report["heldout_l2_before"]
    effect = next(e for e in report["effects"] if e["name"] == report["accepted"][0])
    for fit in ("refit", "refit_all_recordings"):      # the split's fit and the one on every recording (final_fit)
        delta_g = effect[fit]["gravity_offset.delta_g"]
        assert delta_g[0] > 0.5 and abs(delta_g[2]) < 0.5 * delta_g[0]      # tilted towards +X (azimuth 0)


@pytest.mark.bpy
@pytest.mark.slow
def test_blender_reference_physics_gives_verdict_none(blender_capture, tmp_path):
    report = json.loads(run_diagnose(DiagnoseRequest(capture=blender_capture("none"), project=tmp_path,
                                                     **BLENDER_NONE)).read_text())
    assert report["verdict"] == "none"


def _loaded(noise: float, n_frames: int = 20) -> dict:
    t = np.arange(n_frames)[:, None, None] / 30.0
    garment = np.random.default_rng(0).uniform(-0.2, 0.2, (1, 60, 3)) + 0.05 * np.sin(2 * np.pi * 0.8 * t)
    garment = garment + np.random.default_rng(1).normal(0, noise, garment.shape)
    body = np.repeat(np.arange(n_frames, dtype=float)[:, None, None], 10, 1).repeat(3, 2)
    return {n: (Observed(n, garment.copy(), body.copy(), 30.0), None, None) for n in ("a", "b")}


def test_noisy_sequences_are_smoothed_and_trimmed_clean_ones_left_alone(tmp_path):
    req = DiagnoseRequest(capture=tmp_path, project=tmp_path)
    clean = _loaded(0.0)
    result = denoise(req, clean)
    assert not result.smoothed and result.level_mm < 0.1 and clean["a"][0].garment.shape == (20, 60, 3)
    noisy = _loaded(0.0015)
    result = denoise(req, noisy)
    obs = noisy["a"][0]
    assert result.smoothed and result.level_mm == pytest.approx(1.5, rel=0.15)
    assert obs.garment.shape == (12, 60, 3) and obs.body[0, 0, 0] == 4.0    # 4 frames dropped at each end
    assert result.to_json()["filter"]["window"] == 9
    req.denoise = "off"
    assert not denoise(req, _loaded(0.0015)).smoothed
    with pytest.raises(InputError, match="too short"):
        denoise(DiagnoseRequest(capture=tmp_path, project=tmp_path, denoise="on"), _loaded(0.0, n_frames=10))


def test_the_rest_state_is_the_given_unloaded_mesh_else_the_first_frame(tmp_path):
    from gg_core.geometry.meshio import write_ply
    from gg_core.stages.diagnose import rest_state

    first = np.random.default_rng(0).uniform(size=(12, 3))
    log = {"remeshed": False, "observed_vertices": 12}
    assert rest_state(DiagnoseRequest(capture=tmp_path, project=tmp_path), first, log) is first
    write_ply(tmp_path / "rest.ply", first * 1.1)
    req = DiagnoseRequest(capture=tmp_path, project=tmp_path, rest_mesh=str(tmp_path / "rest.ply"))
    assert np.allclose(rest_state(req, first, log), first * 1.1)
    with pytest.raises(InputError, match="12"):
        rest_state(req, first[:10], log)                       # another topology
    with pytest.raises(InputError, match="remeshed"):
        rest_state(req, first, {"remeshed": True, "observed_vertices": 7000})
