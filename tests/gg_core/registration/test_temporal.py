import numpy as np
import pytest

from gg_core.registration.temporal import smooth_trajectories


def _motion(t: np.ndarray) -> np.ndarray:
    """[T, 4, 3] four vertices on a quadratic path (a constant acceleration), each with its own offset."""
    offsets = np.arange(12, dtype=np.float64).reshape(1, 4, 3) * 0.01
    path = np.stack([0.02 * t, 0.5 - 0.003 * t ** 2, 0.01 * t], axis=1)[:, None, :]
    return path + offsets


def test_quadratic_motion_passes_unchanged_and_jitter_shrinks():
    t = np.arange(30, dtype=np.float64)
    clean = _motion(t)
    np.testing.assert_allclose(smooth_trajectories(clean, 7, 2), clean, atol=1e-12)
    jitter = np.random.default_rng(0).normal(0.0, 0.003, clean.shape)
    smoothed = smooth_trajectories(clean + jitter, 7, 2)
    before = np.abs(jitter).mean()
    after = np.abs(smoothed - clean).mean()
    assert after < 0.75 * before            # the SG(7, 2) filter keeps about 0.6 of white noise's amplitude


def test_short_sequences_use_a_shorter_window_or_none():
    clean = _motion(np.arange(4, dtype=np.float64))
    noisy = clean + np.random.default_rng(1).normal(0.0, 0.003, clean.shape)
    out = smooth_trajectories(noisy, 7, 2)      # 4 frames: window 3, which a quadratic fits exactly
    np.testing.assert_allclose(out, noisy, atol=1e-12)
    two = noisy[:2]
    np.testing.assert_array_equal(smooth_trajectories(two, 7, 2), two)
    five = _motion(np.arange(5, dtype=np.float64)) + 0.003
    np.testing.assert_allclose(smooth_trajectories(five, 7, 2), five, atol=1e-12)


def test_even_window_is_refused():
    with pytest.raises(ValueError, match="odd"):
        smooth_trajectories(np.zeros((9, 2, 3)), 6, 2)
