"""Quaternion <-> matrix conversions and composition."""
from __future__ import annotations

import torch
from scipy.spatial.transform import Rotation

from gg_core.gaussians.rotations import quat_multiply, quat_to_rotmat, rotmat_to_quat


def _random_quats(n: int) -> torch.Tensor:
    q = torch.randn(n, 4, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    return q / q.norm(dim=1, keepdim=True)


def test_quat_to_rotmat_matches_scipy():
    q = _random_quats(100)
    expected = Rotation.from_quat(q[:, [1, 2, 3, 0]].numpy()).as_matrix()  # scipy is (x, y, z, w)
    assert torch.allclose(quat_to_rotmat(3.0 * q), torch.tensor(expected), atol=1e-12)


def test_rotmat_to_quat_roundtrip_including_half_turns():
    q = _random_quats(200)
    half_turns = torch.tensor([[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [0, 0.6, 0.8, 0]], dtype=torch.float64)
    q = torch.cat((q, half_turns))
    back = rotmat_to_quat(quat_to_rotmat(q))
    same_sign = torch.where(q[:, :1] < 0, -q, q)
    close = torch.isclose(back, same_sign, atol=1e-12).all(1) | torch.isclose(back, -same_sign, atol=1e-12).all(1)
    assert close.all()
    m = quat_to_rotmat(q).requires_grad_(True)
    rotmat_to_quat(m).sum().backward()
    assert torch.isfinite(m.grad).all()


def test_multiply_composes_rotations():
    a, b = _random_quats(50), _random_quats(50).flip(0)
    assert torch.allclose(quat_to_rotmat(quat_multiply(a, b)), quat_to_rotmat(a) @ quat_to_rotmat(b), atol=1e-12)
