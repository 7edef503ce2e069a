"""Procedural motions: smooth, plausible speeds, feet on the floor, deterministic, settle blending."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from gg_core.body.model import load_body
from gg_core.body.motions import GRAVITY, MOTIONS, animate, motion
from gg_core.errors import InputError

FPS = 30
N = 75  # 2.5 s: at least one full cycle of every motion
SETTLE = 15


@pytest.fixture(scope="module")
def body():
    return load_body()


@pytest.fixture(scope="module")
def clips(body):
    return {name: animate(body, name, N, fps=FPS, settle_frames=SETTLE) for name in MOTIONS}


def test_required_motions_exist():
    assert {"walk", "arm_swing", "torso_twist", "squat", "jump", "idle", "rest"} <= set(MOTIONS)


@pytest.mark.parametrize("name", MOTIONS)
def test_motion_is_finite_smooth_and_plausibly_fast(body, clips, name):
    verts = clips[name]
    assert verts.shape == (SETTLE + N, len(body.rest_vertices), 3) and np.isfinite(verts).all()
    speed = np.linalg.norm(np.diff(verts, axis=0), axis=-1) * FPS
    accel = np.linalg.norm(verts[2:] - 2 * verts[1:-1] + verts[:-2], axis=-1) * FPS**2
    assert speed[:, body.hand_mask].max() < 4.0  # m/s
    assert speed.max() < 5.0
    assert accel.max() < 40.0  # m/s^2, settle blend included (a foot's swing peaks near 30)
    if name != "rest":
        assert speed.max() > 0.1


@pytest.mark.parametrize("name", MOTIONS)
def test_motion_has_no_gross_self_penetration(body, clips, name):
    """Hands stay clear of the trunk and legs, and skinning keeps the body's volume (no collapse)."""
    dominant = body.weights.argmax(axis=1)
    arm_joints = [j for j in range(body.n_joints) if _descends_from(body, j, ("left_collar", "right_collar"))]
    rest_volume = trimesh.Trimesh(body.rest_vertices, body.faces, process=False).volume
    trunk = ~np.isin(dominant, arm_joints)
    for frame in clips[name][::6]:
        assert cKDTree(frame[trunk]).query(frame[body.hand_mask])[0].min() > 0.05
        volume = trimesh.Trimesh(frame, body.faces, process=False).volume
        assert 0.9 < volume / rest_volume < 1.05


def _descends_from(body, joint, names):
    roots = {body.joint(n) for n in names}
    while joint >= 0:
        if joint in roots:
            return True
        joint = body.parents[joint]
    return False


@pytest.mark.parametrize("name", [m for m in MOTIONS if m != "jump"])
def test_feet_stay_on_the_floor(body, clips, name):
    """Exactly on it, except the walk, whose contact height is smoothed over the foot-to-foot hand-over."""
    lowest = clips[name][..., 1].min(axis=1)
    assert np.abs(lowest).max() < (0.015 if name == "walk" else 0.002)


def test_walk_swings_the_legs_and_bobs(body, clips):
    verts = clips["walk"][SETTLE:]
    left_sole = (body.rest_vertices[:, 1] < 0.02) & (body.rest_vertices[:, 0] > 0)
    lift = verts[:, left_sole, 1].min(axis=1)
    assert lift.max() > 0.04  # the swing foot clears the floor
    assert lift.min() < 0.005  # and comes back to it
    rotations, translation = motion(body, "walk", N, fps=FPS)
    assert 0.01 < np.ptp(translation[:, 1]) < 0.06  # pelvis bob, metres peak to peak
    bob_accel = np.diff(translation[:, 1], 2) * FPS**2
    assert np.abs(bob_accel).max() < 10.0  # m/s^2: no jolt when the contact passes from foot to foot
    wrist = body.posed_joints(rotations, translation)[:, body.joint("left_wrist")]
    ankle = body.posed_joints(rotations, translation)[:, body.joint("right_ankle")]
    # Arm counter-swing: the left hand goes forward with the right foot.
    assert np.corrcoef(wrist[:, 2], ankle[:, 2])[0, 1] > 0.8


def test_squat_lowers_the_pelvis_with_planted_feet(body):
    rotations, translation = motion(body, "squat", 90, fps=FPS)
    joints = body.posed_joints(rotations, translation)
    assert joints[:, 0, 1].min() < body.rest_joints[0, 1] - 0.2
    ankles = joints[:, [body.joint("left_ankle"), body.joint("right_ankle")]]
    rest = body.rest_joints[[body.joint("left_ankle"), body.joint("right_ankle")]]
    assert np.abs(ankles[..., [0, 2]] - rest[:, [0, 2]]).max() < 0.02


def test_jump_is_ballistic_in_the_air_and_lands_on_the_floor(body, clips):
    rotations, translation = motion(body, "jump", 75, fps=FPS)
    lowest = clips["jump"][SETTLE:, :, 1].min(axis=1)
    airborne = lowest > 0.01
    assert lowest.max() > 0.08  # feet clear the floor
    assert airborne.sum() >= 8 and np.abs(lowest[~airborne]).max() < 0.01
    flight = np.flatnonzero(airborne)
    inner = flight[(flight > flight[0]) & (flight < flight[0] + airborne.sum() - 1)]
    accel = (translation[inner + 1, 1] - 2 * translation[inner, 1] + translation[inner - 1, 1]) * FPS**2
    np.testing.assert_allclose(accel, -GRAVITY, atol=0.2)


@pytest.mark.parametrize("name", MOTIONS)
def test_zero_amplitude_is_the_rest_pose(body, name):
    rotations, translation = motion(body, name, 10, fps=FPS, amplitude=0.0)
    np.testing.assert_allclose(rotations, 0.0, atol=1e-12)
    np.testing.assert_allclose(translation, 0.0, atol=1e-6)


def test_motions_are_deterministic_per_seed(body):
    a = motion(body, "walk", 30, seed=3)
    b = motion(body, "walk", 30, seed=3)
    c = motion(body, "walk", 30, seed=4)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    difference = np.abs(a[0] - c[0]).max()
    assert 1e-3 < difference < 0.3  # a seed varies phase and amplitude a little, not the motion


def test_settle_frames_start_at_rest_and_join_the_motion(body, clips):
    verts = clips["torso_twist"]
    np.testing.assert_allclose(verts[0], body.rest_vertices, atol=1e-5)
    np.testing.assert_allclose(verts[1], body.rest_vertices, atol=3e-3)  # eases out of rest
    rotations, translation = motion(body, "torso_twist", N, fps=FPS)
    np.testing.assert_allclose(verts[SETTLE:], body.pose(rotations, translation), atol=1e-5)


def test_unknown_motion_lists_the_valid_names(body):
    with pytest.raises(InputError, match="unknown motion 'moonwalk'.*walk, arm_swing"):
        motion(body, "moonwalk", 10)
    with pytest.raises(InputError, match="amplitude"):
        motion(body, "walk", 10, amplitude=-1.0)
