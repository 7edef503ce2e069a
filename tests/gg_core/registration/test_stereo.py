import numpy as np
import torch

from gg_core.registration.stereo import stereo_refine
from gg_core.registration.views import View

from ..reconstruction.scenes import plane_image
from ..reconstruction.test_photo_consistency import _cameras, _plane


def test_stereo_refine_pulls_a_fit_onto_the_cloth():
    cams = _cameras()
    verts, faces = _plane(15, 0.3, 0.0)
    views = [View(c, torch.from_numpy(plane_image(c)).float(), torch.ones(c.height, c.width),
                  torch.zeros(c.height, c.width)) for c in cams]
    far_body = (np.array([[9.0, 9, 9], [9.1, 9, 9], [9, 9.1, 9]]), np.array([[0, 1, 2]]))
    start = verts + [0.0, 0.0, 0.012]                  # a fit that ended 1.2 cm in front of the cloth
    moved, log = stereo_refine(start, faces, views, far_body, search=0.02, rounds=2, stiffness=1.0,
                               aggregate=0, curvature_gain=1.5)
    assert np.abs(moved[:, 2]).mean() < 0.003
    assert np.abs(moved[:, :2] - start[:, :2]).max() < 1e-6       # moved along the plane's normal only
    assert len(log["rounds"]) == 2
