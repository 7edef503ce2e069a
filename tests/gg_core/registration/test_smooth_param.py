"""The smooth vertex parameterization and the uniform Adam optimizer."""
from __future__ import annotations

import numpy as np
import torch

from gg_core.registration.smooth_param import SmoothParam, UniformAdam, smoothing_matrix


def strip() -> tuple[np.ndarray, np.ndarray]:
    verts = np.array([[i * 0.1, j * 0.1, 0.0] for i in range(4) for j in range(2)])
    faces = np.array([[2 * i, 2 * i + 2, 2 * i + 3] for i in range(3)]
                     + [[2 * i, 2 * i + 3, 2 * i + 1] for i in range(3)])
    return verts, faces


def test_decode_inverts_encode_and_its_gradient_is_the_same_solve():
    verts, faces = strip()
    param = SmoothParam(faces, len(verts), 5.0)
    u = torch.tensor(param.encode(verts), requires_grad=True)
    assert np.allclose(param.decode(u).detach().numpy(), verts, atol=1e-12)
    assert torch.autograd.gradcheck(param.decode, (u,), eps=1e-6, atol=1e-8)


def test_the_matrix_is_identity_plus_lam_times_the_graph_laplacian():
    verts, faces = strip()
    m = smoothing_matrix(faces, len(verts), 2.0).toarray()
    assert np.allclose(m, m.T)
    assert np.allclose(m.sum(1), 1.0)               # Laplacian rows sum to zero
    assert m[0, 0] == 1.0 + 2.0 * 3                  # vertex 0 has three neighbours (1, 2 and 3)
    assert m[0, 3] == -2.0 and m[0, 5] == 0.0


def test_uniform_adam_scales_all_entries_by_one_second_moment():
    x = torch.zeros(3, requires_grad=True)
    opt = UniformAdam([x], lr=0.1)
    x.grad = torch.tensor([1.0, 0.1, -0.5])
    opt.step()
    # first step: m_hat = g, v_hat = max g^2 = 1 -> the step is lr * g (relative sizes kept, unlike Adam's sign)
    assert np.allclose(x.detach().numpy(), [-0.1, -0.01, 0.05], atol=1e-6)
