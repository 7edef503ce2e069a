"""SMPL-X as a BodyModel, from model files the user supplies (SMPL-X is download-gated; none ship here).

Read through the `smplx` package, imported only when a path is given. The SMPL-X template is a T-pose; it
is re-posed into the same A-pose as the default body (upper arms 45 degrees down) so garments tailored on
one fit the other. Pose-dependent corrective blend shapes are left out: BodyModel is plain LBS.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from .model import BodyModel

N_JOINTS = 55  # SMPL-X kinematic joints: body 22, jaw, 2 eyes, 2 x 15 finger joints
NUM_BETAS = 10
A_POSE_DEG = 45.0
_FIX = "download SMPL-X from https://smpl-x.is.tue.mpg.de and pass SMPLX_NEUTRAL.npz or its folder"


def _model_file(path: Path) -> Path:
    """The SMPL-X file itself, or SMPLX_NEUTRAL.{npz,pkl} in `path` or in `path`/smplx."""
    if path.is_file():
        return path
    for folder in (path, path / "smplx"):
        for ext in ("npz", "pkl"):
            candidate = folder / f"SMPLX_NEUTRAL.{ext}"
            if candidate.is_file():
                return candidate
    raise InputError("no SMPL-X model file found", path, _FIX)


def load_smplx_body(path: str | Path) -> BodyModel:
    """A BodyModel from SMPL-X model files (neutral unless a gendered file is given), in the A-pose."""
    path = Path(path).expanduser()
    model_file = _model_file(path)
    try:
        import smplx  # noqa: PLC0415 - optional dependency
    except ImportError:
        raise InputError("the 'smplx' package is not installed", path,
                         "install it into the project environment: .venv/bin/pip install smplx") from None
    try:
        model = smplx.SMPLX(str(model_file), num_betas=NUM_BETAS, use_pca=False, flat_hand_mean=True,
                            ext=model_file.suffix[1:])
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(f"cannot read the SMPL-X model ({exc})", model_file, _FIX) from None
    t_pose = t_pose_body(model, name=f"smplx:{model_file.stem}")
    rotations = np.zeros((N_JOINTS, 3))
    rotations[t_pose.joint("left_shoulder"), 2] = -np.radians(A_POSE_DEG)  # +X arm swung down about +Z
    rotations[t_pose.joint("right_shoulder"), 2] = np.radians(A_POSE_DEG)
    return grounded(bake_rest_pose(t_pose, rotations))


def t_pose_body(model, name: str) -> BodyModel:
    """The BodyModel of a loaded `smplx.SMPLX` module in its own T-pose and frame (LBS part only)."""
    from smplx.joint_names import JOINT_NAMES  # noqa: PLC0415 - optional dependency

    template = model.v_template.detach().double().numpy()
    shapedirs = model.shapedirs.detach().double().numpy()[:, :, :NUM_BETAS]  # [V,3,S]
    regressor = model.J_regressor.detach().double().numpy()[:N_JOINTS]  # [J,V]
    weights = model.lbs_weights.detach().double().numpy()[:, :N_JOINTS]
    parents = model.parents.detach().numpy()[:N_JOINTS].astype(np.int64)
    parents[0] = -1
    shape_basis = shapedirs.transpose(2, 0, 1)
    names = list(JOINT_NAMES[:N_JOINTS])
    return BodyModel(
        rest_vertices=template.astype(np.float32), faces=np.asarray(model.faces, dtype=np.int32),
        joint_names=names, parents=parents, rest_joints=(regressor @ template).astype(np.float32),
        weights=weights.astype(np.float32), shape_basis=shape_basis.astype(np.float32),
        shape_names=[f"beta{i}" for i in range(shape_basis.shape[0])],
        hand_mask=_hand_mask(weights, names, parents),
        joint_shape_basis=np.einsum("jv,svk->sjk", regressor, shape_basis).astype(np.float32), name=name)


def _hand_mask(weights: np.ndarray, names: list[str], parents: np.ndarray) -> np.ndarray:
    """Vertices mostly bound to a wrist or finger joint."""
    hand = np.zeros(len(names), dtype=bool)
    for j in range(len(names)):
        hand[j] = names[j] in ("left_wrist", "right_wrist") or (parents[j] >= 0 and hand[parents[j]])
    return weights[:, hand].sum(axis=1) > 0.5


def bake_rest_pose(body: BodyModel, rotations: np.ndarray) -> BodyModel:
    """The same body with `rotations` [J,3] as its new rest pose (weights kept).

    LBS is linear in the shape parameters at a fixed pose, so posing each shape direction gives the exact
    shape basis of the new rest pose."""
    rotations = np.asarray(rotations, dtype=np.float64)[None]
    n_shapes = len(body.shape_names)
    shapes = np.vstack([np.zeros(n_shapes), np.eye(n_shapes)])
    verts = np.stack([body.pose(rotations, shape=s)[0].astype(np.float64) for s in shapes])
    joints = np.stack([body.posed_joints(rotations, shape=s)[0] for s in shapes])
    return replace(body, rest_vertices=verts[0].astype(np.float32), rest_joints=joints[0].astype(np.float32),
                   shape_basis=(verts[1:] - verts[0]).astype(np.float32),
                   joint_shape_basis=(joints[1:] - joints[0]).astype(np.float32))


def grounded(body: BodyModel) -> BodyModel:
    """The body moved so its feet rest on y=0 and its root joint is at x=z=0."""
    offset = -np.array([body.rest_joints[0, 0], body.rest_vertices[:, 1].min(), body.rest_joints[0, 2]],
                       dtype=np.float32)
    return replace(body, rest_vertices=body.rest_vertices + offset, rest_joints=body.rest_joints + offset)
