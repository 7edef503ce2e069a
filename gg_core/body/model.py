"""The body model: a rest mesh with a joint tree, skinning weights and a small linear shape space.

Poses are local axis-angle rotations per joint, expressed in world-aligned axes at the rest pose (as in
SMPL): the rest pose is all-zero rotations, and a joint's rotation turns its whole subtree about the joint.
Posing is linear blend skinning in numpy, batched over frames, so a whole animation is one call.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

ASSET_DIR = Path(__file__).with_name("data")
# Frames skinned per block: bounds the [V, frames*12] per-vertex transform buffer to ~100 MB.
_FRAMES_PER_BLOCK = 128


def axis_angle_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rodrigues' formula, vectorized: [...,3] axis-angle (radians) -> [...,3,3] rotation matrices."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    small = angle < 1e-8
    axis = rotvec / np.where(small, 1.0, angle)
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    zero = np.zeros_like(x)
    cross = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], axis=-1).reshape(rotvec.shape[:-1] + (3, 3))
    s = np.sin(angle)[..., None]
    c = np.cos(angle)[..., None]
    out = np.eye(3) + s * cross + (1.0 - c) * (cross @ cross)
    # Below 1e-8 rad the first-order term is exact to double precision and avoids dividing by ~0.
    first_order = np.eye(3) + np.stack([zero, -rotvec[..., 2], rotvec[..., 1], rotvec[..., 2], zero,
                                        -rotvec[..., 0], -rotvec[..., 1], rotvec[..., 0], zero],
                                       axis=-1).reshape(rotvec.shape[:-1] + (3, 3))
    return np.where(small[..., None], first_order, out)


@dataclass
class BodyModel:
    """A skinned, shape-able body. Units metres, +Y up, facing +Z, feet on y=0, root at x=z=0."""

    rest_vertices: np.ndarray  # [V,3] float32, rest (A-)pose
    faces: np.ndarray  # [F,3] int32, outward-facing triangles
    joint_names: list[str]
    parents: np.ndarray  # [J] int, -1 for the root; parents come before their children
    rest_joints: np.ndarray  # [J,3] float32
    weights: np.ndarray  # [V,J] float32, rows sum to 1
    shape_basis: np.ndarray  # [S,V,3] float32, vertex offset per unit of each shape parameter
    shape_names: list[str]
    hand_mask: np.ndarray  # [V] bool, hand vertices (left out of garment collision)
    # [S,J,3] joint offset per unit of each shape parameter. When a source has none, joints follow the
    # skinning-weighted mean of their vertices' offsets, which keeps bones inside the reshaped limbs.
    joint_shape_basis: np.ndarray | None = None
    # Canonical (SMPL-X style) joint names -> this model's joint names, so motions work on any rig.
    aliases: dict[str, str] = field(default_factory=dict)
    name: str = "body"

    def __post_init__(self) -> None:
        self.parents = np.asarray(self.parents, dtype=np.int64)
        if (self.parents[1:] >= np.arange(1, len(self.parents))).any() or self.parents[0] != -1:
            raise ValueError("parents must list each joint after its parent, the root first")
        if self.joint_shape_basis is None:
            mass = self.weights.sum(axis=0)
            mean = np.einsum("vj,svk->sjk", self.weights, self.shape_basis) / np.maximum(mass, 1e-12)[None, :, None]
            self.joint_shape_basis = mean.astype(np.float32)

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    def joint(self, name: str) -> int:
        """Index of a joint by its own name or by its canonical alias (e.g. 'left_knee')."""
        name = self.aliases.get(name, name)
        try:
            return self.joint_names.index(name)
        except ValueError:
            known = sorted(set(self.aliases) | set(self.joint_names))
            raise InputError(f"unknown joint '{name}'", f"body '{self.name}'",
                             "use one of: " + ", ".join(known)) from None

    def shaped(self, shape: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Rest vertices [V,3] and rest joints [J,3] (float64) for shape parameters [S] (None: the default body)."""
        verts = self.rest_vertices.astype(np.float64)
        joints = self.rest_joints.astype(np.float64)
        if shape is not None:
            shape = np.asarray(shape, dtype=np.float64)
            if shape.shape != (len(self.shape_names),):
                raise ValueError(f"shape must have shape ({len(self.shape_names)},), got {shape.shape}")
            verts = verts + np.tensordot(shape, self.shape_basis, axes=1)
            joints = joints + np.tensordot(shape, self.joint_shape_basis, axes=1)
        return verts, joints

    def joint_transforms(self, rotations: np.ndarray, translation: np.ndarray | None = None,
                         shape: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """World rotations [T,J,3,3] and posed joint positions [T,J,3] (forward kinematics, float64)."""
        rotations = np.asarray(rotations, dtype=np.float64)
        if rotations.ndim != 3 or rotations.shape[1:] != (self.n_joints, 3):
            raise ValueError(f"rotations must have shape [T,{self.n_joints},3], got {rotations.shape}")
        n = rotations.shape[0]
        _, joints = self.shaped(shape)
        local = axis_angle_to_matrix(rotations)
        world = np.empty_like(local)
        posed = np.empty((n, self.n_joints, 3))
        world[:, 0] = local[:, 0]
        posed[:, 0] = joints[0]
        if translation is not None:
            posed[:, 0] += np.broadcast_to(np.asarray(translation, dtype=np.float64), (n, 3))
        offsets = joints[1:] - joints[self.parents[1:]]
        for j in range(1, self.n_joints):
            p = self.parents[j]
            world[:, j] = world[:, p] @ local[:, j]
            posed[:, j] = posed[:, p] + world[:, p] @ offsets[j - 1]
        return world, posed

    def posed_joints(self, rotations: np.ndarray, translation: np.ndarray | None = None,
                     shape: np.ndarray | None = None) -> np.ndarray:
        """Posed joint positions [T,J,3] (float64); cheap, for motion planning and contact tests."""
        rotations, translation, _ = _batched(rotations, translation)
        return self.joint_transforms(rotations, translation, shape)[1]

    def pose(self, rotations: np.ndarray, translation: np.ndarray | None = None,
             shape: np.ndarray | None = None) -> np.ndarray:
        """rotations [T,J,3] local axis-angle (or [J,3]); translation [T,3] (or [3]); shape [S] ->
        vertices [T,V,3] float32 ([V,3] when rotations were given without a frame axis)."""
        rotations, translation, single = _batched(rotations, translation)
        verts, joints = self.shaped(shape)
        world, posed = self.joint_transforms(rotations, translation, shape)
        out = skin(verts, self.weights, world, posed - np.einsum("tjab,jb->tja", world, joints))
        return out[0] if single else out


def skin(vertices: np.ndarray, weights: np.ndarray, rotations: np.ndarray, translations: np.ndarray) -> np.ndarray:
    """Linear blend skinning: vertices [V,3], weights [V,J], per-joint affine maps x -> R x + t given as
    rotations [T,J,3,3] and translations [T,J,3] -> [T,V,3] float32.

    The per-vertex blend of the J transforms is one dense matrix product [V,J] x [J, T*12], which BLAS
    runs faster than gathering the few non-zero weights per vertex."""
    n, n_joints = rotations.shape[:2]
    verts = vertices.astype(np.float32)
    w = weights.astype(np.float32)
    out = np.empty((n, len(verts), 3), dtype=np.float32)
    affine = np.concatenate([rotations, translations[..., None]], axis=-1).astype(np.float32)  # [T,J,3,4]
    for start in range(0, n, _FRAMES_PER_BLOCK):
        block = affine[start:start + _FRAMES_PER_BLOCK]
        m = len(block)
        blended = (w @ block.transpose(1, 0, 2, 3).reshape(n_joints, m * 12)).reshape(len(verts), m, 3, 4)
        out[start:start + m] = (np.einsum("vtab,vb->tva", blended[..., :3], verts)
                                + blended[..., 3].transpose(1, 0, 2))
    return out


def _batched(rotations: np.ndarray, translation: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None, bool]:
    rotations = np.asarray(rotations, dtype=np.float64)
    single = rotations.ndim == 2
    if single:
        rotations = rotations[None]
        if translation is not None:
            translation = np.asarray(translation, dtype=np.float64).reshape(1, 3)
    return rotations, translation, single


def load_body(name: str = "anny") -> BodyModel:
    """The body model `name`: 'anny' (the shipped default), or a path to SMPL-X model files (needs `smplx`)."""
    asset = ASSET_DIR / f"{name}_body.npz"
    if asset.is_file():
        return _load_asset(asset, name)
    path = Path(name).expanduser()
    if path.exists():
        from .smplx_body import load_smplx_body  # noqa: PLC0415 - optional dependency, only for SMPL-X paths

        return load_smplx_body(path)
    shipped = sorted(p.name[: -len("_body.npz")] for p in ASSET_DIR.glob("*_body.npz"))
    raise InputError(f"unknown body model '{name}'", "--body",
                     "use " + " or ".join(repr(s) for s in shipped) + " or a path to SMPL-X model files")


def _load_asset(path: Path, name: str) -> BodyModel:
    """Read a compact body asset written by tools/build_body_asset.py (sparse weights are densified)."""
    with np.load(path, allow_pickle=False) as z:
        n_verts = len(z["rest_vertices"])
        n_joints = len(z["joint_names"])
        weights = np.zeros((n_verts, n_joints), dtype=np.float32)
        rows = np.repeat(np.arange(n_verts), z["weight_joints"].shape[1])
        np.add.at(weights, (rows, z["weight_joints"].astype(np.int64).ravel()), z["weight_values"].ravel())
        aliases = dict(zip(z["alias_names"].tolist(), z["alias_joints"].tolist()))
        return BodyModel(
            rest_vertices=z["rest_vertices"], faces=z["faces"], joint_names=z["joint_names"].tolist(),
            parents=z["parents"], rest_joints=z["rest_joints"], weights=weights, shape_basis=z["shape_basis"],
            shape_names=z["shape_names"].tolist(), hand_mask=z["hand_mask"],
            joint_shape_basis=z["joint_shape_basis"], aliases=aliases, name=name)
