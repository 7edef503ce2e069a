import numpy as np
import torch

from gg_core.registration.stereo import border_rings, stereo_refine
from gg_core.registration.views import View

from ..reconstruction.scenes import plane_image
from ..reconstruction.test_photo_consistency import _cameras, _plane


def test_border_rings_grow_inwards_one_ring_at_a_time():
    verts, faces = _plane(7, 0.3, 0.0)                 # 7 x 7 grid: rings of 24, 16, 8, 1 vertices
    sizes = [int(border_rings(faces, len(verts), r).sum()) for r in range(4)]
    assert sizes == [24, 40, 48, 49]


def test_stereo_refine_pulls_a_fit_onto_the_cloth_but_keeps_the_border():
    cams = _cameras()
    verts, faces = _plane(15, 0.3, 0.0)
    views = [View(c, torch.from_numpy(plane_image(c)).float(), torch.ones(c.height, c.width),
                  torch.zeros(c.height, c.width)) for c in cams]
    far_body = (np.array([[9.0, 9, 9], [9.1, 9, 9], [9, 9.1, 9]]), np.array([[0, 1, 2]]))
    start = verts + [0.0, 0.0, 0.012]                  # a fit that ended 1.2 cm in front of the cloth
    moved, log = stereo_refine(start, faces, views, far_body, search=0.02, rounds=2, hold_rings=1,
                               hold=np.zeros(len(verts), bool))
    held = border_rings(faces, len(verts), 1)
    np.testing.assert_allclose(moved[held], start[held], atol=1e-4)
    assert np.abs(moved[~border_rings(faces, len(verts), 4), 2]).mean() < 0.003
    assert len(log["rounds"]) == 2
