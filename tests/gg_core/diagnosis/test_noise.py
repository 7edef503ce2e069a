"""Correlated registration noise: the asked standard deviation, correlated at short range, not at long range,
independent between frames."""
from __future__ import annotations

import numpy as np
import pytest

from gg_core.diagnosis.noise import SMOOTH_WINDOW, correlated_noise, noise_level, smooth_in_time


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


def _swing(n_frames: int = 24) -> np.ndarray:
    """[T,V,3] smooth motion of a 100-vertex patch: a 5 cm, 0.8 Hz swing at 30 fps (peak 0.25 m/s)."""
    t = np.arange(n_frames)[:, None, None] / 30.0
    base = np.random.default_rng(1).uniform(-0.2, 0.2, (1, 100, 3))
    return base + 0.05 * np.sin(2 * np.pi * 0.8 * t + base[..., :1] * 3)


@pytest.mark.parametrize("sigma", [0.0005, 0.0015])
def test_noise_level_estimates_frame_independent_noise(sigma):
    clean = _swing()
    assert noise_level(clean) < 1e-4                         # smooth motion: small third differences
    noisy = clean + np.random.default_rng(2).normal(0, sigma, clean.shape)
    assert noise_level(noisy) == pytest.approx(sigma, rel=0.15)


def test_smoothing_keeps_cubic_motion_and_removes_most_noise():
    t = np.arange(24, dtype=float)[:, None, None]
    cubic = np.random.default_rng(3).normal(size=(1, 50, 3)) * (1 + 0.1 * t - 0.01 * t ** 2 + 1e-4 * t ** 3)
    h = SMOOTH_WINDOW // 2
    assert np.allclose(smooth_in_time(cubic), cubic[h:-h])               # centred frames only
    clean = _swing()
    noise = np.random.default_rng(4).normal(0, 0.0015, clean.shape)
    velocity_error = lambda x, ref: np.diff(x - ref, axis=0).std()        # noqa: E731
    assert velocity_error(smooth_in_time(clean + noise), clean[h:-h]) < 0.35 * velocity_error(clean + noise, clean)
    with pytest.raises(ValueError, match="too few"):
        smooth_in_time(clean[:SMOOTH_WINDOW - 1])
