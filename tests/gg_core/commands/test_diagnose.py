"""`gg diagnose` and `gg bench diagnose`: command line contract (errors, output line) and the benchmark's scoring
(strength scaling, truth parameters in our units, parameter errors, confusion table, summary)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "diagnosis"))
sys.path.insert(0, str(Path(__file__).parents[1] / "physics"))

from diagnosis_helpers import write_blender_layout_capture, write_sim_capture  # noqa: E402

from gg_core.capture.layout import Capture  # noqa: E402
from gg_core.cli import main  # noqa: E402
from gg_core.commands.bench_diagnose import (BLENDER_DEFAULT_STEPS, CLOTH_STEPS, capture_of,  # noqa: E402
                                             case_name, confusion, effect_params, fold_gains, identified_truth,
                                             parameter_error,
                                             parameter_errors, reference_divergence_of, region_overlap,
                                             summarize, true_model_l2, truth_parameters)
from gg_core.diagnosis.blender_units import WIND_COEF  # noqa: E402
from gg_core.physics.forces import TERMS  # noqa: E402
from gg_core.stages.diagnose import DiagnoseRequest  # noqa: E402


def test_the_command_line_defaults_are_the_requests_and_parsing_imports_no_torch(tmp_path):
    import subprocess  # noqa: PLC0415

    from gg_core.cli import build_parser  # noqa: PLC0415
    from gg_core.stages.diagnose import DiagnoseRequest  # noqa: PLC0415

    args = build_parser().parse_args(["diagnose", str(tmp_path), "--project", str(tmp_path / "p")])
    for name in ("min_gain", "min_gain_mm", "bootstrap", "max_samples", "fit_horizon", "substeps", "vertex_mass"):
        assert getattr(args, name) == getattr(DiagnoseRequest, name), name
    probe = "import sys; from gg_core.cli import build_parser; build_parser(); print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[3])
    assert out.stdout.strip() == "False"          # `gg --help` and every command start without torch


def test_diagnose_refuses_a_missing_capture_with_one_line(tmp_path, capsys):
    assert main(["diagnose", str(tmp_path / "nowhere"), "--project", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gg: error: capture folder not found")


def test_diagnose_refuses_zero_workers_with_one_line(tmp_path, capsys):
    capture = write_sim_capture(tmp_path / "capture", n_frames=10)
    assert main(["diagnose", str(capture), "--project", str(tmp_path / "p"), "--workers", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--workers must be at least 1" in err[0]


def test_diagnose_refuses_a_rest_mesh_of_another_topology_with_one_line(tmp_path, capsys):
    from gg_core.geometry.meshio import write_ply

    capture = write_sim_capture(tmp_path / "capture", n_frames=10)
    write_ply(tmp_path / "rest.ply", np.zeros((5, 3)))
    assert main(["diagnose", str(capture), "--project", str(tmp_path / "p"), "--rest-mesh",
                 str(tmp_path / "rest.ply"), "--progress", "none"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "rest mesh has 5 vertices" in err[0]


def test_diagnose_command_prints_the_verdict(tmp_path, capsys):
    capture = write_sim_capture(tmp_path / "capture", n_frames=10)
    code = main(["diagnose", str(capture), "--project", str(tmp_path / "p"), "--substeps", "1",
                 "--baseline-iterations", "3", "--refit-iterations", "2", "--bootstrap", "10", "--workers", "1",
                 "--progress", "none"])
    assert code == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert line["verdict"] in ("none", "missing") and line["report"].endswith("diagnose.json")
    near = line["closest"]     # a none's near miss, with what it lacked; nothing beside a named effect
    assert near is None if line["verdict"] == "missing" else (near is None or near["why_not"])
    assert line["noise_hides_regions"] is False       # a noise-free capture of our own simulator
    assert (tmp_path / "p" / "reports" / "diagnose.html").is_file()


def test_bench_scoring():
    assert effect_params("wind", 0.5) == ["strength=500"]
    assert effect_params("air_drag", 1.0) == ["air_damping=10"]
    assert effect_params("none", 1.0) == []
    truth = {"effect": {"name": "gravity", "params": {"scale": 1.25, "tilt_deg": 12.0}},
             "material": {"gravity": [2.55, -12.0, 0.0]}}
    params = truth_parameters(truth)
    assert params == {"gravity.tilt": [pytest.approx(2.55 / 12.0), 0.0]}
    # our vertical gravity stays 9.81: the same tilt is a smaller offset (the offset's y is the free scale's)
    same_tilt = [9.81 * 2.55 / 12.0, 0.0, 0.0]
    assert parameter_error(params, {"gravity_offset.delta_g": same_tilt}) == pytest.approx(0.0, abs=1e-12)
    assert parameter_error(params, {"gravity_offset.delta_g": [0.8 * same_tilt[0], 0.0, 0.0]}) == pytest.approx(0.2)
    resimulated = {"effect": {"name": "gravity", "params": {}, "blender": {"gravity": [2.55, -12.0, 0.0]}},
                   "material": {"gravity": [0.0, -9.81, 0.0]}}             # the reference's material, recorded
    assert truth_parameters(resimulated) == params
    shrink = truth_parameters({"effect": {"name": "shrink", "params": {"factor": 0.15}}})
    assert parameter_error(shrink, {"region.rest_scale": 0.88}) == pytest.approx(0.2)
    assert parameter_error(shrink, None) is None
    drag = truth_parameters({"effect": {"name": "air_drag", "params": {"air_damping": 10.0}},
                             "material": {"blender_cloth": {"mass": 0.3}}, "preset": {"fps": 30}})
    assert drag == {"mass_damping.alpha": pytest.approx(10.0)}
    assert parameter_error(drag, {"mass_damping.alpha": 11.0}) == pytest.approx(0.1)
    friction = truth_parameters({"effect": {"name": "friction", "params": {"friction": 60.0}}})
    assert friction == {"body_friction.mu": pytest.approx(0.6)}
    assert parameter_error(friction, {"body_friction.mu": 0.3}) == pytest.approx(0.5)
    ours = truth_parameters({"effect": {"name": "friction", "params": {"friction": 60.0},
                                        "ours": {"terms": {"body_friction": {"mu": 1.05}}}}})
    assert ours == {"body_friction.mu": 1.05}                             # our simulator's own coefficient
    wind = truth_parameters({"effect": {"name": "wind", "params": {"strength": 1000.0},
                                        "ours": {"terms": {"wind": {"velocity": [0.7, 0.0, 0.0]}}}},
                             "material": {"ours": {"material": {"density": 0.15}}}})
    assert wind == {"wind.push": [pytest.approx(0.6 * 0.49 / 0.15), 0.0, 0.0]}   # face-on, at rest, per unit mass
    # a lighter fitted cloth needs slower air for the same push: the speed is not what the data fix
    lighter = {"wind.velocity": [0.7 * np.sqrt(0.9 * 0.05 / 0.15), 0.0, 0.0], "material.density": 0.05}
    assert parameter_error(wind, lighter) == pytest.approx(0.1)
    pressure = {"wind_pressure.pressure": [0.0, 0.0, 0.6 * 0.49 / 3], "material.density": 0.05}  # the same push, but
    assert parameter_error(wind, pressure) == pytest.approx(np.sqrt(2))                        # along z, not x
    assert parameter_error(wind, {"wind.velocity": [0.7, 0.0, 0.0]}) is None                    # no density refitted
    assert truth_parameters({"effect": {"name": "wind", "params": {"strength": 1000.0}}}) == {}   # Blender's
    assert WIND_COEF == TERMS["wind"].defaults["coef"]
    patch = truth_parameters({"effect": {"name": "stiff_patch", "params": {"factor": 30.0}}})
    refit = {"region.stretch_scale": 0.16, "region.bending_scale": 23.9}     # our simulator's patch, seed 2
    assert parameter_errors(patch, refit) == {"region.stretch_scale": pytest.approx(29.84 / 29),
                                              "region.bending_scale": pytest.approx(6.1 / 29)}
    assert parameter_error(patch, refit) == pytest.approx(29.84 / 29)   # both scales must be right
    cases = [{"true_class": "none", "predicted": "none", "correct": True, "heldout_gain": 0.0, "gap_closed": None,
              "parameter_error": None, "heldout_l2_before": 0.01, "true_effect_l2": None,
              "resolved_by_reference": False, "rollouts_first": None, "heldout_l2_after": 0.01,
              "heldout_reference_divergence_mm": 6.0},
             {"true_class": "gravity", "predicted": "gravity", "correct": True, "heldout_gain": 0.4,
              "cross_validated_gain": 0.3, "gap_closed": 0.9, "parameter_error": 0.1, "heldout_l2_before": 0.01,
              "true_effect_l2": 0.006, "cross_validated_true_effect_gain": 0.32,
              "cross_validated_gap_closed": 0.3 / 0.32, "parameter_error_all_recordings": 0.05,
              "resolved_by_reference": True, "rollouts_first": "wind", "true_model_gap_closed": 0.7,
              "heldout_l2_after": 0.006, "heldout_reference_divergence_mm": 5.0},
             {"true_class": "wind", "predicted": "gravity", "correct": False, "heldout_gain": 0.1,
              "cross_validated_gain": 0.2, "gap_closed": 0.3, "parameter_error": None, "heldout_l2_before": 0.01,
              "true_effect_l2": 0.0095, "cross_validated_true_effect_gain": 0.04, "cross_validated_gap_closed": 5.0,
              "resolved_by_reference": False, "rollouts_first": None}]
    summary = summarize(cases, min_gain=0.1)
    assert summary["accuracy_effect_present"] == 0.5 and summary["false_alarm_rate_none"] == 0.0
    # the wind case's true effect gains only 5 %: not detectable at a 10 % acceptance gain
    assert summary["detectable_cases"] == 1 and summary["accuracy_detectable"] == 1.0
    # nor does the reference resolve it: at twice Blender's steps it changes by more than itself
    assert summary["cases_resolved_by_reference"] == 1 and summary["accuracy_resolved_by_reference"] == 1.0
    assert summary["median_parameter_error"] == pytest.approx(0.1) and summary["median_gap_closed"] == 0.6
    assert summary["median_parameter_error_all_recordings"] == pytest.approx(0.05)   # pipeline.final_fit's
    assert summary["median_true_model_gap_closed"] == 0.7      # only captures of our simulator have a true model
    assert summary["mean_cross_validated_gain_when_named"] == pytest.approx(0.3)   # the wrongly named one not
    assert summary["median_cross_validated_gap_closed"] == pytest.approx(0.3 / 0.32)   # nor here
    assert summary["mean_cross_validated_true_effect_gain"] == pytest.approx(0.18)   # whatever was named
    assert summary["residual_tie_breaks"] == 1 and summary["residual_tie_breaks_right"] == 1   # rollouts: wind
    table = confusion(cases).splitlines()
    assert table[0].split()[-3:] == ["gravity", "none", "wind"]
    assert [int(v) for v in table[-1].split()[1:]] == [1, 0, 0]      # wind named gravity
    assert np.isfinite(summary["mean_heldout_gain_when_named"])
    # the floor under the held-out errors, over the cases that measured it (the wind case is an older run's)
    assert summary["mean_heldout_l2_after_mm"] == pytest.approx(8.0)
    assert summary["mean_heldout_reference_divergence_mm"] == pytest.approx(5.5)


def test_a_true_parameter_is_checked_against_the_range_the_recordings_leave_open():
    """bench: identified_truth on pipeline.final_fit's profiles (identify.py), through the same conversions as the
    parameter errors; an open end counts only to the profile's last factor."""
    grid = [0.25, 0.5, 1.0, 2.0, 4.0]
    patch = truth_parameters({"effect": {"name": "stiff_patch", "params": {"factor": 30.0}}})
    delivered = {"material.bending": 1e-4, "region.stretch_scale": 0.28, "region.bending_scale": 17.4}
    ranges = {"region.stretch_scale": {"range_factors": [None, None], "factors": grid},
              "region.bending_scale": {"range_factors": [0.8, None], "factors": grid}}
    assert identified_truth(patch, delivered, ranges) == {"region.stretch_scale": False,   # 30 > 4 x 0.28
                                                          "region.bending_scale": True}    # 17.4 x 0.8 .. x 4
    ranges["region.bending_scale"]["range_factors"] = [0.8, 1.5]
    assert identified_truth(patch, delivered, ranges)["region.bending_scale"] is False     # above 17.4 x 1.5
    tilt = {"gravity.tilt": [0.2, 0.0]}
    offset = {"gravity_offset.delta_g": [9.81 * 0.16, 0.0, 0.0]}                             # a tilt of 0.16
    assert identified_truth(tilt, offset, {"gravity_offset.delta_g": {"range_factors": [0.9, 1.3],
                                                                      "factors": grid}}) == {"gravity.tilt": True}
    assert identified_truth(tilt, offset, {"gravity_offset.delta_g": {"range_factors": [0.9, 1.2],
                                                                      "factors": grid}}) == {"gravity.tilt": False}
    assert identified_truth(tilt, None, {}) == {}
    cases = [{"true_class": "gravity", "predicted": "gravity", "correct": True, "heldout_gain": 0.4,
              "gap_closed": None, "parameter_error": 0.1, "heldout_l2_before": 0.01, "true_effect_l2": None,
              "cross_validated_gain": None, "resolved_by_reference": True, "rollouts_first": None,
              "truth_in_identified_range": truth}
             for truth in ({"gravity.tilt": True}, {"region.bending_scale": True, "region.stretch_scale": False}, {})]
    assert summarize(cases, min_gain=0.1)["truth_in_identified_range"] == 0.5   # every parameter must hold


def test_fold_gains_give_the_named_and_the_true_effect_per_held_out_recording():
    def trial(gain: float) -> dict:
        return {"heldout_gain": gain}

    report = {"cross_validation": {"folds": [
        {"heldout": ["arm"], "trials": {"gravity_offset": trial(0.54), "wind": trial(0.35)},
         "given_truth": {"gravity_offset": trial(0.54)}},
        {"heldout": ["walk"], "trials": {"gravity_offset": trial(0.012)},
         "given_truth": {"gravity_offset": trial(0.01)}},
        {"heldout": ["twist"], "trials": {}, "given_truth": {}}]}}
    assert fold_gains(report, "gravity_offset", "gravity_offset") == [
        {"heldout": ["arm"], "named_gain": 0.54, "true_effect_gain": 0.54},
        {"heldout": ["walk"], "named_gain": 0.012, "true_effect_gain": 0.01},
        {"heldout": ["twist"], "named_gain": None, "true_effect_gain": None}]
    assert [f["named_gain"] for f in fold_gains(report, None, "gravity_offset")] == [None] * 3   # nothing named
    assert fold_gains({}, "wind", None) == []          # reports without folds


def test_bench_captures_of_our_simulator_resimulate_the_blender_reference_of_their_seed(tmp_path):
    args = argparse.Namespace(cache=tmp_path, garment="sheet", truth_simulator="blender", cloth_steps=CLOTH_STEPS)
    reference = write_blender_layout_capture(tmp_path / case_name(args, "none", 0.0, 3))   # stands in for Blender's
    args.truth_simulator = "ours"
    name = case_name(args, "air_drag", 1.0, 3)
    capture = capture_of(args, name, 3, "air_drag", effect_params("air_drag", 1.0))
    assert name == f"ours_sheet_air_drag_s1_seed3_q{CLOTH_STEPS}" and capture == tmp_path / name
    # captures at Blender's own default steps keep the unsuffixed names of the older caches; others are cached apart
    blender_default = argparse.Namespace(**{**vars(args), "cloth_steps": BLENDER_DEFAULT_STEPS})
    assert case_name(blender_default, "none", 0.0, 3) == "ours_sheet_none_s0_seed3"
    finer = argparse.Namespace(**{**vars(args), "cloth_steps": 4 * CLOTH_STEPS})
    assert case_name(finer, "none", 0.0, 3) == f"ours_sheet_none_s0_seed3_q{4 * CLOTH_STEPS}"
    truth = json.loads((capture / "truth.json").read_text())
    assert truth["true_parameters"] == {"mass_damping.alpha": pytest.approx(10.0)}
    assert truth["material"]["ours"]["substeps"] == 4 and reference.name in truth["generator"]
    # the true model rolled out as the diagnosis simulates (its rest state and substeps): close to the recording,
    # closer than without the hidden damping; Blender's captures have no true model of ours
    report = {"train_sequences": ["a", "b"], "heldout_sequences": ["c"], "source": "gt"}
    request = DiagnoseRequest(capture=capture, project=tmp_path / "p")
    error = true_model_l2(request, report)
    undamped = truth | {"effect": truth["effect"] | {"ours": {"terms": {}, "region": None, "region_log_scales": {}}}}
    (capture / "truth.json").write_text(json.dumps(undamped))
    assert 0.0 < error < true_model_l2(request, report)
    assert true_model_l2(DiagnoseRequest(capture=reference, project=tmp_path / "q"), report) is None
    # the floor under every rollout: the capture against its twin at twice the steps, per recording
    divergence = reference_divergence_of(args, name, 3, "air_drag", effect_params("air_drag", 1.0))
    twin = json.loads((tmp_path / f"{name}_steps_x2" / "truth.json").read_text())
    assert twin["material"]["ours"]["substeps"] == 8
    assert sorted(divergence) == sorted(Capture(capture).sequences)
    assert all(0.0 < d < 0.05 for d in divergence.values())


def test_bench_runs_sharing_a_cache_generate_each_capture_once(tmp_path, monkeypatch):
    """Two runs asking for the same missing capture at once: one generates it, the other waits and reuses it."""
    import threading  # noqa: PLC0415
    import time  # noqa: PLC0415

    from gg_core.synth import generate as synth_generate  # noqa: PLC0415

    calls = []

    def slow_generate(req):
        calls.append(req.out)
        time.sleep(0.3)
        (Path(req.out) / "truth.json").parent.mkdir(parents=True, exist_ok=True)
        (Path(req.out) / "truth.json").write_text("{}")

    monkeypatch.setattr(synth_generate, "generate", slow_generate)
    args = argparse.Namespace(cache=tmp_path, garment="sheet", truth_simulator="blender", cloth_steps=CLOTH_STEPS,
                              frames=4, vertices=64)
    name = case_name(args, "none", 0.0, 1)
    got = []
    runs = [threading.Thread(target=lambda: got.append(capture_of(args, name, 1))) for _ in range(2)]
    for run in runs:
        run.start()
    for run in runs:
        run.join(timeout=30)
    assert got == [tmp_path / name] * 2 and calls == [tmp_path / name]


def test_region_overlap_scores_where_a_region_effect_was_placed():
    truth = np.array([1.0, 1.0, 1.0, 1.0, 0.0, 0.0])
    report = {"localization": {"region_vertices": [4, 5],
                               "scanned_regions": {"rest_length_region": {"region_vertices": [2, 3, 4]}}}}
    assert region_overlap(report, "rest_length_region", truth) == pytest.approx({"precision": 2 / 3, "recall": 0.5})
    assert region_overlap(report, "region_stiffness", truth) == {"precision": 0.0, "recall": 0.0}   # the maps'
    assert region_overlap(report, None, truth) is None and region_overlap(report, "region_stiffness", None) is None
    report["localization"]["region_choices"] = {"region_stiffness": {"region_vertices": [0, 1, 4]}}
    assert region_overlap(report, "region_stiffness", truth) == pytest.approx({"precision": 2 / 3, "recall": 0.5})
