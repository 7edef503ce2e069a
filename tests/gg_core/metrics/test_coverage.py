import numpy as np
import pytest

from gg_core.capture.cameras import look_at
from gg_core.metrics.coverage import camera_counts, stereo_coverage


def _square(z: float, half: float = 0.5, n: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A flat n x n grid square in the plane z, facing +z or -z (either side counts)."""
    g = np.linspace(-half, half, n + 1)
    x, y = np.meshgrid(g, g, indexing="ij")
    verts = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return verts, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _cameras(eyes: list[tuple[float, float, float]]):
    return [look_at(f"c{k}", np.array(e), np.zeros(3), 60.0, 200, 200) for k, e in enumerate(eyes)]


def test_counts_cameras_on_either_side_and_by_facing_angle():
    verts, faces = _square(0.0)
    # two cameras face the square head-on (one from each side), one views it at ~80 degrees from its normal
    cams = _cameras([(0, 0, 3.0), (0, 0, -3.0), (3.0, 0, 0.55)])
    _, counts = camera_counts(verts, faces, cams, n_samples=500, cosines=(0.1, 0.5))
    assert counts.shape == (2, 500)
    assert (counts[1] == 2).all()             # the grazing camera is not within 60 degrees anywhere
    assert (counts[0] >= 2).all() and (counts[0] == 3).mean() > 0.5   # but within 84 degrees of most points


def test_occluder_hides_the_surface_from_a_camera():
    verts, faces = _square(0.0)
    wall = _square(1.0, half=2.0)             # a large sheet between the square and the first camera
    cams = _cameras([(0, 0, 3.0), (0, 0, -3.0)])
    free = stereo_coverage(verts, faces, cams, n_samples=300)
    hidden = stereo_coverage(verts, faces, cams, [wall], n_samples=300)
    assert free["cos_0.5"]["fewer_than_two_pct"] == 0.0
    assert hidden["cos_0.5"]["fewer_than_two_pct"] == pytest.approx(100.0)
    assert hidden["cos_0.5"]["unseen_pct"] == 0.0          # the camera behind still sees it


def test_a_surface_hides_itself():
    # a box's far wall is hidden from a camera by its near wall: the share seen by fewer than two cameras grows
    near, far = _square(0.2), _square(-0.2)
    verts = np.concatenate([near[0], far[0]])
    faces = np.concatenate([near[1], far[1] + len(near[0])])
    cams = _cameras([(0, 0, 3.0), (0.5, 0, 3.0)])
    cov = stereo_coverage(verts, faces, cams, n_samples=400)
    assert 40.0 < cov["cos_0.5"]["fewer_than_two_pct"] < 60.0   # the far sheet: half the area
