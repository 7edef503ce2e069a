"""Correlated registration noise: the asked standard deviation, correlated at short range, not at long range,
independent between frames."""
from __future__ import annotations

import numpy as np
import pytest

from gg_core.diagnosis.noise import correlated_noise


def test_noise_has_the_asked_std_and_spatial_correlation():
    rng = np.random.default_rng(0)
    grid = np.stack(np.meshgrid(np.linspace(0, 0.6, 25), np.linspace(0, 0.6, 25)), -1).reshape(-1, 2)
    template = np.c_[grid[:, 0], np.zeros(len(grid)), grid[:, 1]]
    noise = correlated_noise(template, 0.002, 0.05, 200, rng)
    assert noise.shape == (200, len(template), 3)
    assert noise.std() == pytest.approx(0.002, rel=0.05)
    flat = noise[..., 0].T                                   # [V, T]
    centre, neighbour, corner = 12 * 25 + 12, 12 * 25 + 13, 0
    corr = np.corrcoef(flat[[centre, neighbour, corner]])
    assert corr[0, 1] > 0.8                                  # 2.5 cm apart: moves together
    assert abs(corr[0, 2]) < 0.2                             # 42 cm apart: independent
    lag_one = (noise[:-1] * noise[1:]).mean() / noise.var()  # frame-to-frame correlation
    assert abs(lag_one) < 0.05
