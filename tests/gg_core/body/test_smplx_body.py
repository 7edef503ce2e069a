"""SMPL-X body: re-posed rest pose (checked on the shipped body), optional package, user model files."""
from __future__ import annotations

import importlib.util
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gg_core.body.model import load_body
from gg_core.body.motions import animate
from gg_core.body.smplx_body import bake_rest_pose, grounded, load_smplx_body
from gg_core.errors import InputError

HAS_SMPLX = importlib.util.find_spec("smplx") is not None
# Folder or file of user-supplied SMPL-X models (download-gated, so none ship with the project).
SMPLX_MODELS = os.environ.get("GG_SMPLX_MODELS", "")


def test_baked_rest_pose_is_exact_for_pose_and_shape():
    body = load_body()
    pose = np.zeros((body.n_joints, 3))
    pose[body.joint("left_shoulder")] = [0.0, 0.0, 0.6]
    pose[body.joint("right_knee")] = [0.8, 0.0, 0.0]
    baked = bake_rest_pose(body, pose)
    np.testing.assert_allclose(baked.rest_vertices, body.pose(pose), atol=1e-5)
    np.testing.assert_allclose(baked.rest_joints, body.posed_joints(pose)[0], atol=1e-5)
    shape = np.linspace(-0.2, 0.2, len(body.shape_names))
    zero = np.zeros((body.n_joints, 3))
    np.testing.assert_allclose(baked.pose(zero, shape=shape), body.pose(pose, shape=shape), atol=1e-5)


def test_grounded_puts_the_feet_on_the_floor_under_the_root():
    body = load_body()
    moved = grounded(_shifted(body))
    assert moved.rest_vertices[:, 1].min() == pytest.approx(0.0, abs=1e-6)
    np.testing.assert_allclose(moved.rest_joints[0, [0, 2]], 0.0, atol=1e-6)
    np.testing.assert_allclose(moved.rest_vertices - moved.rest_joints[0],
                               body.rest_vertices - body.rest_joints[0], atol=1e-5)


def _shifted(body):
    offset = np.array([0.3, 0.5, -0.7], dtype=np.float32)
    return replace(body, rest_vertices=body.rest_vertices + offset, rest_joints=body.rest_joints + offset)


def test_missing_model_files_are_an_input_error(tmp_path):
    with pytest.raises(InputError, match="no SMPL-X model file found"):
        load_smplx_body(tmp_path)
    with pytest.raises(InputError, match="unknown body model"):
        load_body(str(tmp_path / "absent"))


@pytest.mark.skipif(HAS_SMPLX, reason="the smplx package is installed")
def test_missing_smplx_package_is_an_input_error_with_the_fix(tmp_path):
    model = tmp_path / "SMPLX_NEUTRAL.npz"
    model.write_bytes(b"")
    with pytest.raises(InputError, match="'smplx' package is not installed.*pip install smplx"):
        load_body(str(model))


@pytest.mark.skipif(not (HAS_SMPLX and SMPLX_MODELS and Path(SMPLX_MODELS).exists()),
                    reason="needs the smplx package and SMPL-X model files in $GG_SMPLX_MODELS")
def test_smplx_body_is_an_a_posed_body_that_motions_drive():
    body = load_body(SMPLX_MODELS)
    assert body.n_joints == 55 and len(body.rest_vertices) == 10475
    assert body.rest_vertices[:, 1].min() == pytest.approx(0.0, abs=1e-6)
    arm = body.rest_joints[body.joint("left_wrist")] - body.rest_joints[body.joint("left_shoulder")]
    assert 35 < np.degrees(np.arctan2(-arm[1], abs(arm[0]))) < 55
    assert 500 < body.hand_mask.sum() < 3000
    np.testing.assert_allclose(body.weights.sum(axis=1), 1.0, atol=1e-4)
    verts = animate(body, "walk", 20, settle_frames=5)
    assert np.isfinite(verts).all() and np.abs(verts[..., 1].min(axis=1)).max() < 0.015
