"""What the photometric fit sees of one frame: per camera the image, the garment and background masks, and the
body of that frame as an occluder of the garment's Gaussians.

Loss mask (REFERENCE §1): garment pixels and background pixels count, the body (and anything else in the
foreground that is not the garment) is ignored: clip(garment + (1 - foreground), 0, 1). Views can be
downscaled for coarse-to-fine fitting (area-averaged images; masks area-averaged then thresholded at one half,
so that every pixel is either counted or ignored); the camera's intrinsics are scaled with the image so that
pixel centres stay at +0.5.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence as Seq

import numpy as np
import torch

from ..capture.cameras import Camera
from ..capture.images import read_mask, read_rgb
from ..capture.layout import FOREGROUND_MASK, GARMENT_MASK, Sequence
from ..errors import InputError
from ..geometry.meshio import read_mesh
from ..geometry.raycast import RayCaster


@dataclass(frozen=True)
class View:
    """One camera's observation of one frame (float32 tensors, image rows top-down)."""

    camera: Camera
    rgb: torch.Tensor          # [H, W, 3] in [0, 1]
    garment: torch.Tensor      # [H, W] 1.0 on garment pixels, else 0.0
    background: torch.Tensor   # [H, W] 1.0 on pixels outside the person (not foreground), else 0.0
    occluder: RayCaster | None = None   # the frame's body (shared by the frame's views)

    @property
    def loss_mask(self) -> torch.Tensor:
        """[H, W] weight of each pixel in the photometric loss: garment plus background, body ignored."""
        return (self.garment + self.background).clamp(0.0, 1.0)

    def target(self, background: torch.Tensor) -> torch.Tensor:
        """The image the garment render is compared with: background pixels replaced by the render's background
        colour (the capture's real background is not modelled), garment pixels as recorded."""
        b = self.background[..., None]
        return self.rgb * (1 - b) + background.to(self.rgb.dtype) * b

    def scaled(self, scale: float) -> "View":
        """This view at `scale` times the resolution (area-averaged images, scaled intrinsics)."""
        if scale == 1.0:
            return self
        cam = self.camera
        width, height = max(1, round(cam.width * scale)), max(1, round(cam.height * scale))
        sx, sy = width / cam.width, height / cam.height
        K = np.diag([sx, sy, 1.0]) @ cam.K
        stack = torch.cat((self.rgb, self.garment[..., None], self.background[..., None]), dim=-1).numpy()
        small = torch.from_numpy(_resize_area(stack, width, height))
        return replace(self, camera=replace(cam, K=K, width=width, height=height), rgb=small[..., :3].contiguous(),
                       garment=(small[..., 3] > 0.5).float(), background=(small[..., 4] > 0.5).float())


def _resize_area(image: np.ndarray, width: int, height: int) -> np.ndarray:
    import cv2  # noqa: PLC0415 - opencv only where images are resized

    return np.ascontiguousarray(cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA), np.float32)


def load_body(sequence: Sequence, frame: str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of the body mesh of `frame`; InputError when the sequence has none for it."""
    return read_mesh(sequence.body_path(frame))


def load_views(sequence: Sequence, frame: str, camera_ids: Seq[str] | None = None, scale: float = 1.0,
               body: tuple[np.ndarray, np.ndarray] | None = None) -> list[View]:
    """Views of `frame` from the given cameras (default all), optionally downscaled, with the frame's body
    (read from the capture unless `body` = (verts, faces) is given) as the occluder of every view."""
    cameras = sequence.cameras
    ids = list(cameras) if camera_ids is None else list(camera_ids)
    unknown = [c for c in ids if c not in cameras]
    if unknown:
        raise InputError(f"unknown cameras {unknown}", sequence.root / "cameras.json",
                         f"choose from: {', '.join(cameras)}")
    if not ids:
        raise InputError("no cameras selected", sequence.root, "select at least one camera")
    body_verts, body_faces = load_body(sequence, frame) if body is None else body
    occluder = RayCaster([(body_verts, body_faces)])
    views = []
    for cid in ids:
        cam = cameras[cid]
        rgb = read_rgb(sequence.image_path(cid, frame))
        garment = read_mask(sequence.image_path(cid, frame, GARMENT_MASK))
        foreground = read_mask(sequence.image_path(cid, frame, FOREGROUND_MASK)) | garment
        if rgb.shape[:2] != (cam.height, cam.width) or garment.shape != rgb.shape[:2] or \
                foreground.shape != rgb.shape[:2]:
            raise InputError(f"image or mask size {rgb.shape[1]}x{rgb.shape[0]} differs from the camera's "
                             f"{cam.width}x{cam.height}", sequence.root / cid,
                             "write images and masks at the calibrated resolution")
        views.append(View(cam, torch.from_numpy(rgb), torch.from_numpy(garment.astype(np.float32)),
                          torch.from_numpy((~foreground).astype(np.float32)), occluder).scaled(scale))
    if not any(bool(v.garment.any()) for v in views):
        raise InputError(f"the garment masks of frame '{frame}' are empty in every camera", sequence.root,
                         "check the garment_masks folders (non-zero pixels mark the garment)")
    return views
