"""Initial appearance: colours from the images, then the Gaussian parameters fitted on the frozen mesh."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from gg_core.gaussians import build_texture, face_texture
from gg_core.gaussians.sh import C0
from gg_core.gaussians.texture import LOG_SCALE
from gg_core.registration.appearance import (AppearanceConfig, contrast_background, downsample_texture,
                                             fit_appearance, observed_colors)


def test_observed_colors_recover_the_true_face_colours(sheet_scene):
    s = sheet_scene
    start = face_texture(s.verts, s.faces)
    rgb, count = observed_colors(start, s.verts, s.faces, s.views)
    truth = (s.texture.params[:, 0:3] * C0 + 0.5).numpy()
    seen = count > 0
    assert seen.mean() > 0.9
    # each face centre's pixel mixes a few neighbouring faces at this resolution: close, not exact
    assert np.median(np.abs(rgb[seen] - truth[seen])) < 0.12


def test_fit_appearance_lowers_the_photometric_loss(sheet_scene):
    s = sheet_scene
    start = replace(s.texture, params=s.texture.params.clone())
    start.params[:, 0:48] = 0.0                                   # true shapes and opacities, grey colours
    fitted, log = fit_appearance(start, s.verts, s.faces, s.views, 60, config=AppearanceConfig(init_colors=False))
    # the release's learning rates are made for 10 000 steps: 60 steps from grey only begin the descent ...
    assert log["rgb_loss_after"] < 0.8 * log["rgb_loss_before"]
    assert len(log["loss"]) == 60 and fitted.params.shape == start.params.shape
    assert not torch.equal(fitted.params, start.params) and np.array_equal(fitted.face_ids, start.face_ids)
    # ... which is why the colours start from the images
    _, log_init = fit_appearance(start, s.verts, s.faces, s.views, 60)
    assert log_init["colored_from_images"] > 0.9 * len(start)
    assert log_init["rgb_loss_before"] < 0.65 * log["rgb_loss_before"]       # measured: 0.54
    assert log_init["rgb_loss_after"] < log_init["rgb_loss_before"]


def test_contrast_background_is_far_from_the_garment(sheet_scene):
    bg = contrast_background(sheet_scene.views)
    mean = sum((v.rgb * v.garment[..., None]).sum((0, 1)) for v in sheet_scene.views) / \
        sum(v.garment.sum() for v in sheet_scene.views)
    assert torch.all((bg - mean).abs() >= 0.1)


def test_downsampled_texture_averages_blocks_of_texels(sheet_scene):
    s = sheet_scene
    uvs = (s.verts[:, :2] - s.verts[:, :2].min(0)) / np.ptp(s.verts[:, :2], axis=0).max()
    fine = build_texture(s.verts, s.faces, 32, uvs=uvs, face_uvs=s.faces)
    fine.params[:, 0:3] = torch.tensor([0.3, -0.2, 0.1])
    coarse = downsample_texture(fine, s.verts, s.faces, 2)
    assert coarse.resolution == 16 and 0.15 < len(coarse) / len(fine) < 0.4
    assert torch.allclose(coarse.params[:, 0:3], torch.tensor([0.3, -0.2, 0.1]).expand(len(coarse), 3))
    # a coarse texel whose block is fully covered: log scale grew by log 2 over its fine texels' mean
    block = {}
    for (r, c), p in zip(fine.texels, fine.params):
        block.setdefault((r // 2, c // 2), []).append(p)
    (r, c), p = next(((tuple(t), p) for t, p in zip(coarse.texels, coarse.params) if len(block.get(tuple(t), [])) == 4))
    expected = torch.stack(block[(r, c)]).mean(0)[LOG_SCALE] + np.log(2)
    assert torch.allclose(p[LOG_SCALE], expected, atol=1e-6)
    assert downsample_texture(fine, s.verts, s.faces, 1) is fine
