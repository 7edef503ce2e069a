"""Spherical harmonics: the basis against scipy's complex SH, and colour evaluation."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.special import sph_harm_y

from gg_core.gaussians.sh import degree_of, eval_sh, rgb_to_sh0, sh_basis


def test_basis_is_the_real_sh_with_condon_shortley_phase():
    """3DGS/gsplat order and signs: sqrt2 Im Y_l^|m| (m < 0), Y_l^0, sqrt2 Re Y_l^m (m > 0), scipy's Y."""
    d = np.random.default_rng(0).normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    polar, azimuth = np.arccos(d[:, 2]), np.arctan2(d[:, 1], d[:, 0])
    basis = sh_basis(torch.tensor(d), 3).numpy()
    k = 0
    for l in range(4):
        for m in range(-l, l + 1):
            y = sph_harm_y(l, abs(m), polar, azimuth)
            expected = np.sqrt(2) * y.imag if m < 0 else (y.real if m == 0 else np.sqrt(2) * y.real)
            assert np.allclose(basis[:, k], expected, atol=1e-12), (l, m)
            k += 1


def test_eval_sh_adds_half_clamps_and_ignores_direction_length():
    sh = torch.zeros(2, 9, 3, dtype=torch.float64)
    sh[:, 0] = rgb_to_sh0(torch.tensor([0.2, 0.7, -0.4], dtype=torch.float64))
    sh[1, 3, 0] = 1.0  # degree-1 x term on red only
    dirs = torch.tensor([[0.0, 0, 5], [-3.0, 0, 0]], dtype=torch.float64)
    rgb = eval_sh(sh, dirs)
    assert torch.allclose(rgb[0], torch.tensor([0.2, 0.7, 0.0], dtype=torch.float64))  # negative clamped to 0
    assert torch.isclose(rgb[1, 0], torch.tensor(0.2 + 0.4886025119029199, dtype=torch.float64))  # -C1 * (-1)


def test_coefficient_counts():
    assert [degree_of(k) for k in (1, 4, 9, 16)] == [0, 1, 2, 3]
    with pytest.raises(ValueError):
        degree_of(5)
