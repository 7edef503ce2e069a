"""Acceptance of the synthetic capture (issue 3), measured on the tiny preset."""
import json

import numpy as np
import pytest
import trimesh

from gg_core.capture.layout import Capture
from gg_core.capture.validate import validate_capture
from gg_core.cli import main
from gg_core.synth.quality import (body_frames, gt_frames, mean_displacement, penetration,
                                   projection_consistency, trajectory_difference)

# the slow generator tests run on one worker so the other keeps the stage tests going
pytestmark = pytest.mark.xdist_group("synth_tiny")


def test_penetration_counts_vertices_deeper_than_5mm():
    sphere = trimesh.creation.icosphere(3)
    pts = sphere.vertices[:100] * np.r_[np.full(10, 0.98), np.full(90, 1.02)][:, None]  # 10 at 2 cm inside
    frac = penetration(pts[None], sphere.vertices[None], sphere.faces)
    assert frac[0] == pytest.approx(0.10)
    assert penetration(pts[None], sphere.vertices[None], sphere.faces, depth=0.03)[0] == 0.0



@pytest.mark.slow
@pytest.mark.bpy
def test_tiny_capture_passes_inspect(tiny_capture):
    report = validate_capture(tiny_capture)
    assert report.problems == []
    assert report.truth
    assert main(["inspect", str(tiny_capture), "--progress", "none"]) == 0
    truth = json.loads((tiny_capture / "truth.json").read_text())
    assert truth["effect"]["name"] == "none"
    assert truth["garment"]["vertices"] == len(gt_frames(Capture(tiny_capture).sequences["00_walk"])[0])
    assert truth["split"]["heldout_sequences"] and truth["split"]["heldout_cameras"]


@pytest.mark.slow
@pytest.mark.bpy
def test_visible_ground_truth_projects_into_the_garment_mask(tiny_capture):
    for seq in Capture(tiny_capture).sequences.values():
        body, faces = body_frames(seq)
        scores = projection_consistency(seq, gt_frames(seq), body, faces)
        assert len(scores) == 6
        assert min(scores.values()) >= 0.98, scores


@pytest.mark.slow
@pytest.mark.bpy
def test_projection_check_fails_on_the_wrong_frame(tiny_capture):
    """The check can fail: ground truth shifted 3 cm sideways no longer fits the masks."""
    seq = Capture(tiny_capture).sequence("00_walk")
    body, faces = body_frames(seq)
    shifted = gt_frames(seq) + [0.03, 0.0, 0.0]
    assert min(projection_consistency(seq, shifted, body, faces, tolerance_px=0).values()) < 0.9


@pytest.mark.slow
@pytest.mark.bpy
def test_garment_moves_and_stays_out_of_the_body(tiny_capture):
    for seq in Capture(tiny_capture).sequences.values():
        garment = gt_frames(seq)
        body, faces = body_frames(seq)
        assert mean_displacement(garment) > 1e-3                     # > 1 mm per frame at 30 fps
        assert penetration(garment, body, faces).max() <= 0.01


@pytest.mark.slow
@pytest.mark.bpy
def test_wind_changes_the_trajectories(tiny_capture, tiny_wind_truth):
    diff = trajectory_difference(tiny_capture, tiny_wind_truth)
    assert set(diff) == {"00_walk", "01_arm_swing"}
    for d in diff.values():
        assert d["mean_m"] > 2e-3 and d["max_m"] > 1e-2
    truth = json.loads((tiny_wind_truth / "truth.json").read_text())
    assert truth["effect"]["blender"]["force_fields"][0]["type"] == "WIND"
