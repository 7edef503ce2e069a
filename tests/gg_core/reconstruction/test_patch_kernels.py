import numpy as np
import pytest

from gg_core.capture.cameras import look_at
from gg_core.commands.bench_stereo import numpy_patches
from gg_core.reconstruction.patch_kernels import normalized_patches


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
    want = numpy_patches(points, cam, image, weight, mask)     # the formulation it replaced
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
