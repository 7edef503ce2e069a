"""Views of one frame: masks, loss mask, downscaling with consistent intrinsics, bad input."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from PIL import Image

from gg_core.capture.layout import Capture
from gg_core.errors import InputError
from gg_core.registration.views import load_views


def test_load_views_masks_and_loss_mask(small_capture):
    seq = Capture(small_capture).sequence("seq0")
    views = load_views(seq, "000001")
    assert [v.camera.id for v in views] == ["cam00", "cam01", "cam02"]
    v = views[0]
    assert v.rgb.shape == (30, 40, 3) and v.rgb.dtype == torch.float32
    # the fixture's garment and foreground masks are the same square: garment counts, the rest is background
    assert float(v.garment.sum()) == 10 * 13 and torch.equal(v.loss_mask, torch.ones(30, 40))
    assert v.occluder is not None and v.occluder is views[1].occluder      # one body per frame
    bg = torch.tensor([1.0, 0.0, 0.0])
    target = v.target(bg)
    assert torch.equal(target[0, 0], bg) and torch.equal(target[15, 20], v.rgb[15, 20])


def test_body_pixels_are_ignored(small_capture):
    seq = Capture(small_capture).sequence("seq0")
    path = seq.image_path("cam00", "000000", "foreground_masks")
    fg = np.zeros((30, 40), np.uint8)
    fg[5:25, 5:35] = 255                                  # person larger than the garment square
    Image.fromarray(fg).save(path)
    v = load_views(seq, "000000", ["cam00"])[0]
    body = (v.garment == 0) & (v.background == 0)
    assert int(body.sum()) == 20 * 30 - 10 * 13
    assert float(v.loss_mask[body].max()) == 0.0


def test_downscaled_view_projects_points_to_scaled_pixels(small_capture):
    seq = Capture(small_capture).sequence("seq0")
    v = load_views(seq, "000000", ["cam01"])[0]
    half = v.scaled(0.5)
    assert (half.camera.width, half.camera.height) == (20, 15) and half.rgb.shape == (15, 20, 3)
    points = np.array([[0.1, 1.0, 0.05], [-0.2, 1.2, 0.1]])
    full_px, _ = v.camera.project(points)
    half_px, _ = half.camera.project(points)
    assert np.allclose(half_px, 0.5 * full_px)           # pixel edges map to pixel edges (centres at +0.5)
    assert torch.allclose(half.rgb[0, 0], v.rgb[:2, :2].mean((0, 1)), atol=1e-6)
    assert set(torch.unique(half.garment).tolist()) <= {0.0, 1.0}


def test_bad_input_raises_input_errors(small_capture):
    seq = Capture(small_capture).sequence("seq0")
    with pytest.raises(InputError, match="unknown cameras"):
        load_views(seq, "000000", ["cam09"])
    (small_capture / "seq0" / "body" / "000002.ply").unlink()
    with pytest.raises(InputError, match="no body mesh for frame '000002'"):
        load_views(seq, "000002")
    for cam in ("cam00", "cam01", "cam02"):
        Image.fromarray(np.zeros((30, 40), np.uint8)).save(seq.image_path(cam, "000001", "garment_masks"))
    with pytest.raises(InputError, match="garment masks of frame '000001' are empty"):
        load_views(seq, "000001")
