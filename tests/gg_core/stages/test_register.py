"""Stage 2 end to end on the tiny synthetic capture (6 cameras of 72x96 px: about 2 cm per pixel).

The product path only: stage 1 (gg template) reconstructs the template from the images, stage 2 registers it;
ground truth is read by the report's metrics alone.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from gg_core.capture.layout import Capture
from gg_core.commands.bench_register import _copy_stage1
from gg_core.geometry.meshio import read_mesh, read_obj
from gg_core.stages.register import (RegisterRequest, _settings, load_stage1, registration_texture, run_register,
                                     stereo_options)
from gg_core.stages.template import TemplateRequest, run_template

pytestmark = pytest.mark.slow

FRAMES, ITERATIONS = 3, 30
# measured before the texture refit (seed 0, 00_walk, 3 frames): CD 1.48 cm, p2m 1.41 cm, F@1cm 46 % - the template
# is 1.35 cm off at this resolution (2 cm per pixel), and registration cannot do much better than its template here
CD_BOUND_CM = 2.0


@pytest.fixture(scope="module")
def stage1(tiny_capture, tmp_path_factory):
    project = tmp_path_factory.mktemp("register") / "template"
    run_template(TemplateRequest(capture=tiny_capture, project=project, appearance_iterations=100, progress="none"))
    return project


def register(capture, stage1_project, project, **options):
    _copy_stage1(stage1_project, project)
    req = RegisterRequest(capture=capture, project=project, sequences=["00_walk"], frames=FRAMES,
                          iterations=ITERATIONS, renders=2, progress="none", **options)
    return run_register(req)


@pytest.fixture(scope="module")
def full(tiny_capture, stage1, tmp_path_factory):
    project = tmp_path_factory.mktemp("register") / "full"
    return project, register(tiny_capture, stage1, project)


def test_outputs_keep_the_template_topology_and_score_against_ground_truth(full, stage1):
    project, report_path = full
    report = json.loads(report_path.read_text())
    _, faces, _, _ = read_obj(stage1 / "stage1" / "template.obj")
    meshes = sorted((project / "stage2" / "00_walk" / "meshes").glob("*.ply"))
    assert [m.stem for m in meshes] == ["000000", "000001", "000002"]
    for m in meshes:
        verts, f = read_mesh(m)
        assert np.array_equal(f, faces) and np.isfinite(verts).all()
    assert len(list((project / "stage2" / "00_walk" / "renders").glob("*.png"))) == 2
    for m in meshes:     # 3 frames: the quadratic temporal filter's shortest window passes them through; pushing
        # out of the body again moves a few contact vertices whose nearest body point changed (measured: 9 / 3756
        # coordinates, up to 0.12 mm)
        np.testing.assert_allclose(read_mesh(m)[0], read_mesh(m.parent.parent / "refined" / m.name)[0], atol=5e-4)
    seq = report["sequences"]["00_walk"]
    for key in ("cd_cm", "p2m_cm", "fscore_1cm", "l_body", "s_per_frame"):
        assert key in seq and key in report["mean"]
    assert seq["frames"] == FRAMES and len(seq["per_frame"]) == FRAMES
    assert seq["cd_cm"] < CD_BOUND_CM and seq["p2m_cm"] < CD_BOUND_CM
    assert seq["alignment"]["mode"] == "body" and seq["alignment"]["from"] == "00_walk/000000"


def test_rerun_keeps_unchanged_frames_and_refits_after_a_change(full, tiny_capture, stage1, monkeypatch):
    from gg_core.registration.tracker import Tracker

    project, report_path = full
    meshes = [m for sub in ("fit", "refined", "meshes")
              for m in sorted((project / "stage2" / "00_walk" / sub).glob("*.ply"))]
    assert len(meshes) == 3 * FRAMES
    stamps = [m.stat().st_mtime_ns for m in meshes]
    with monkeypatch.context() as patch:                   # metrics and renders only, no fitting
        patch.setattr(Tracker, "fit_frame", lambda *a, **k: pytest.fail("an unchanged frame was fitted again"))
        register(tiny_capture, stage1, project)
    assert [m.stat().st_mtime_ns for m in meshes] == stamps
    # a different option invalidates every frame (each frame's key chains the previous one's)
    register(tiny_capture, stage1, project, seed=1)
    assert all(m.stat().st_mtime_ns != s for m, s in zip(meshes, stamps))


def test_only_rgb_lets_the_garment_into_the_body(full, tiny_capture, stage1, tmp_path_factory):
    """Without the geometric terms the photometric fit pushes vertices into the body (measured on this preset:
    L_body 3.1e-4 only-rgb vs 2.3e-5 full, F@1cm 40 % vs 46 %)."""
    project = tmp_path_factory.mktemp("register") / "only-rgb"
    only = json.loads(register(tiny_capture, stage1, project, ablation="only-rgb").read_text())["mean"]
    with_terms = json.loads(full[1].read_text())["mean"]
    assert only["l_body"] > 1e-6 and only["l_body"] > 5 * with_terms["l_body"]


def test_a_coarsened_texture_is_refitted_on_the_template_frame(tiny_capture, stage1):
    """Block-averaged texels render half transparent and blurred; the refit on the template's own frame must
    bring the photometric loss there back down (and a texture that was not coarsened is left alone)."""
    capture, project = Capture(tiny_capture), stage1
    loaded = load_stage1(project)
    kept, log_kept = registration_texture(capture, project, loaded, factor=1, refit=30)
    assert kept is loaded.texture and log_kept["steps"] == 0
    coarse, log_off = registration_texture(capture, project, loaded, factor=2, refit=0)
    refitted, log = registration_texture(capture, project, loaded, factor=2, refit=30)
    assert log_off["steps"] == 0 and log["steps"] == 30 and log["frame"] == "00_walk/000000"
    assert len(refitted) == len(coarse) < len(loaded.texture)
    assert log["rgb_loss_after"] < 0.9 * log["rgb_loss_before"]     # measured: 0.0090 -> 0.0073
    again, log_again = registration_texture(capture, project, loaded, factor=2, refit=30)
    assert log_again["reused"] and torch.equal(again.params, refitted.params)


def test_sequences_registered_in_parallel_workers_match_one_after_another(tiny_capture, stage1, tmp_path_factory):
    """Two sequences in two single-threaded worker processes give the meshes that one process gives registering
    them one after another (up to float summation order), and the report says how many workers ran."""
    meshes, reports = {}, {}
    for workers in (1, 2):
        project = tmp_path_factory.mktemp("register") / f"workers{workers}"
        _copy_stage1(stage1, project)
        path = run_register(RegisterRequest(capture=tiny_capture, project=project, frames=2, iterations=10,
                                            sequences=["00_walk", "01_arm_swing"], renders=0, workers=workers,
                                            texture_refit=0, progress="none"))
        reports[workers] = json.loads(path.read_text())
        meshes[workers] = {seq: [read_mesh(project / "stage2" / seq / "meshes" / f"{k:06d}.ply")[0]
                                 for k in range(2)] for seq in ("00_walk", "01_arm_swing")}
    assert reports[1]["workers"] == 1 and reports[2]["workers"] == 2
    assert list(reports[2]["sequences"]) == ["00_walk", "01_arm_swing"] and reports[2]["mean"]["wall_s_per_frame"] > 0
    for seq, frames in meshes[1].items():
        for one, two in zip(frames, meshes[2][seq]):
            assert np.abs(one - two).max() < 1e-3       # metres (measured on the dev machine: identical)


def test_stereo_options_carry_every_stereo_setting_of_the_tracker_config():
    from dataclasses import replace

    from gg_core.registration.tracker import TrackerConfig

    config = replace(TrackerConfig(), stereo_rounds=2, stereo_search=0.03, stereo_weighting="score",
                     stereo_stiffness=1.5, stereo_aggregate=1, stereo_curvature_gain=2.0, stereo_normal_smoothing=4)
    options = stereo_options(config)
    assert (options.search_in, options.search_out, options.rounds) == (0.03, 0.03, 2)
    assert (options.weighting, options.stiffness, options.aggregate) == ("score", 1.5, 1)
    assert (options.curvature_gain, options.normal_smoothing) == (2.0, 4)
    assert stereo_options(TrackerConfig()).normal_smoothing == TrackerConfig().stereo_normal_smoothing


def test_stereo_and_filter_settings_do_not_key_the_fits():
    """New stereo or temporal-filter settings rerun those steps over the stored fits, not the fits."""
    from dataclasses import asdict, replace

    from gg_core.registration.tracker import TrackerConfig

    def split(config):
        return _settings({"config": asdict(config), "ablation": "full", "align": "body"})

    base = split(TrackerConfig())
    stereo = split(replace(TrackerConfig(), stereo_frames=3, stereo_rounds=2))
    smooth = split(replace(TrackerConfig(), smooth_window=5))
    fitting = split(replace(TrackerConfig(), iterations=50))
    assert stereo["fit"] == base["fit"] and stereo["stereo"] != base["stereo"]
    assert smooth["fit"] == base["fit"] and smooth["stereo"] == base["stereo"]
    assert smooth["temporal"] != base["temporal"]
    assert fitting["fit"] != base["fit"] and fitting["stereo"] == base["stereo"]
    assert base["fit"]["ablation"] == "full" and "stereo_frames" in base["stereo"]
