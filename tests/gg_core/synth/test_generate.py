import json
import shutil

import numpy as np
import pytest

from gg_core.capture.layout import Capture
from gg_core.cli import main
from gg_core.synth.blender_frame import from_blender, scene_gravity
from gg_core.synth.quality import gt_frames

from .conftest import generate_tiny

# the slow generator tests run on one worker so the other keeps the stage tests going
pytestmark = pytest.mark.xdist_group("synth_tiny")


@pytest.mark.slow
@pytest.mark.bpy
def test_same_seed_same_truth_and_resume_skips_finished_work(tiny_capture, tmp_path):
    out = tmp_path / "again"
    generate_tiny(out, render=False)
    for name, seq in Capture(tiny_capture).sequences.items():
        np.testing.assert_array_equal(gt_frames(seq), gt_frames(Capture(out).sequence(name)))
    # a finished capture: nothing simulated or rendered again
    copy = tmp_path / "copy"
    shutil.copytree(tiny_capture, copy)
    removed = copy / "00_walk" / "cam03" / "rgb_images" / "000005.png"
    removed.unlink()
    kept = [copy / "00_walk" / "cameras.json", *(copy / "00_walk" / "body").glob("*.ply"),
            *(copy / "00_walk" / "gt" / "garment").glob("*.ply")]
    stamps = [p.stat().st_mtime_ns for p in kept]
    report = json.loads(generate_tiny(copy, check=False).read_text())
    # untouched, so the stages that key their results on file times (template, register, behaviour) resume too
    assert [p.stat().st_mtime_ns for p in kept] == stamps
    walk = report["timings"]["sequences"]["00_walk"]
    assert walk["resumed_simulation"] and walk["rendered_views"] == 1
    assert report["timings"]["sequences"]["01_arm_swing"]["rendered_views"] == 0
    assert removed.is_file()


@pytest.mark.slow
@pytest.mark.bpy
def test_blender_is_given_the_gravity_setting_under_which_the_cloth_falls_at_the_truths(tiny_capture):
    truth = json.loads((tiny_capture / "truth.json").read_text())
    fps = truth["preset"]["fps"]
    setting = truth["material"]["blender_scene_gravity"]
    np.testing.assert_allclose(setting, scene_gravity(truth["material"]["gravity"], fps))
    # Blender's cloth falls at 0.001 fps^2 of the setting (measured in tests/gg_core/diagnosis/test_blender_units.py)
    np.testing.assert_allclose(from_blender(np.array(setting)) * 0.001 * fps ** 2, truth["material"]["gravity"])
    jobs = sorted((tiny_capture / ".synth").glob("*/job.json"))
    assert jobs
    for job in jobs:
        assert json.loads(job.read_text())["scene_gravity"] == setting


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["synth", "--out", str(tmp_path / "x"), "--effect", "wind", "--effect-param", "gust=3"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gg: error:") and "\n" not in err
    assert main(["synth", "--out", str(tmp_path / "x"), "--motions", "moonwalk"]) == 2
    assert not (tmp_path / "x").exists()
