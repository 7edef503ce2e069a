import numpy as np
import pytest

from gg_core.capture.cameras import look_at
from gg_core.reconstruction.patch_kernels import normalized_patches
from gg_core.reconstruction.visual_hull import bilinear


def _reference(points, cam, image, weight, mask):
    """The numpy formulation the kernel replaced: project, sample, weight, centre per channel, unit length."""
    m, p = points.shape[:2]
    uv, _ = cam.project(points.reshape(-1, 3))
    colour = bilinear(image, uv[:, 0], uv[:, 1]).reshape(m, p, 3)
    w = np.broadcast_to(weight, (m, p))
    if mask is not None:
        w = w * bilinear(mask, uv[:, 0], uv[:, 1]).reshape(m, p)
        w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-12)
    colour = (colour - np.einsum("mpc,mp->mc", colour, w)[:, None, :]) * np.sqrt(w)[..., None]
    colour = colour.reshape(m, p * 3)
    return colour / np.maximum(np.linalg.norm(colour, axis=1, keepdims=True), 1e-6)


@pytest.mark.parametrize("masked", [False, True])
def test_patches_match_the_numpy_formulation(masked):
    rng = np.random.default_rng(0)
    cam = look_at("c", np.array([0.3, 0.2, 1.5]), np.zeros(3), 40.0, 48, 40)
    image = rng.random((40, 48, 3)).astype(np.float32)
    mask = (rng.random((40, 48)) > 0.3).astype(np.float32) if masked else None
    # patches around the view's centre and some reaching past the image border (clamped samples)
    points = rng.normal(0.0, 0.4, (60, 1, 3)) + rng.normal(0.0, 0.01, (60, 9, 3))
    weight = rng.random(9)
    weight /= weight.sum()
    got = normalized_patches(points, cam, image, weight, mask)
    want = _reference(points, cam, image, weight, mask)
    assert got.dtype == np.float32 and got.shape == (60, 27)
    np.testing.assert_allclose(got, want, atol=1e-6)
    lengths = np.linalg.norm(got, axis=1)
    assert np.all((np.abs(lengths - 1) < 1e-5) | (lengths < 1e-5))


def test_a_flat_patch_stays_zero_instead_of_dividing_by_zero():
    cam = look_at("c", np.array([0.0, 0.0, 1.0]), np.zeros(3), 40.0, 16, 16)
    image = np.full((16, 16, 3), 0.5, np.float32)
    points = np.zeros((1, 4, 3)) + np.array([[[0.0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0.01, 0.01, 0]]])
    got = normalized_patches(points, cam, image, np.full(4, 0.25))
    assert np.all(np.isfinite(got)) and np.abs(got).max() < 1e-6
