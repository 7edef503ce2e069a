import numpy as np

from gg_core.reconstruction.mask_vote import garment_vote

from .scenes import ring_cameras, sphere_mesh


def _upper_half_mask(cam, centre_y: float) -> np.ndarray:
    """Pixels above the image of the horizontal plane y = centre_y through the sphere's centre (approximately:
    the row where the sphere's centre projects)."""
    uv, _ = cam.project(np.array([[0.0, centre_y, 0.0]]))
    mask = np.zeros((cam.height, cam.width))
    mask[: int(round(uv[0, 1]))] = 1.0
    return mask


def test_vote_separates_the_masked_half_and_ignores_hidden_cameras():
    verts, faces = sphere_mesh(0.3)
    cams = ring_cameras(6, height=0.0, size=(80, 80))
    vote, weight = garment_vote(verts, faces, cams, [_upper_half_mask(c, 0.0) for c in cams])
    y = verts[:, 1]
    assert np.all(weight[np.abs(y) < 0.25] > 0)         # the poles are too grazing for a ring at their height
    seen = weight > 0
    assert np.all(vote[seen & (y > 0.05)] > 0.5) and np.all(vote[seen & (y < -0.05)] < 0.5)
    # one camera: vertices on the far side of the sphere get no vote even though they project into the mask
    vote1, weight1 = garment_vote(verts, faces, cams[:1], [np.ones((80, 80))])
    towards = (verts @ cams[0].center) / np.linalg.norm(cams[0].center)
    assert np.all(weight1[towards < -0.05] == 0) and np.all(vote1[towards > 0.15] == 1.0)
