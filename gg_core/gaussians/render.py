"""`render`: one differentiable entry point over the rasterizer backends."""
from __future__ import annotations

from typing import Sequence

import torch

from ..capture.cameras import Camera
from .projection import EPS2D, NEAR_PLANE, camera_tensors, project
from .splats import Gaussians

BACKENDS = ("auto", "cpu", "gsplat")


def gsplat_available() -> bool:
    """True when CUDA is usable and gsplat imports (the GPU backend can run)."""
    if not torch.cuda.is_available():
        return False
    try:
        import gsplat  # noqa: F401, PLC0415
    except ImportError:
        return False
    return True


def render(gaussians: Gaussians, camera: Camera, background: torch.Tensor | Sequence[float] = (0.0, 0.0, 0.0),
           backend: str = "auto", near: float = NEAR_PLANE, eps2d: float = EPS2D) -> dict[str, torch.Tensor]:
    """Render `gaussians` seen by `camera`; differentiable w.r.t. every Gaussian tensor and the background.

    Returns {"image": [H,W,3], "alpha": [H,W], "depth": [H,W]} where image = colour composited over
    `background`, alpha = 1 - final transmittance and depth = sum of blending weight * camera z
    (divide by alpha for the expected depth). backend "auto" uses gsplat for CUDA tensors when it
    imports, else the numba CPU rasterizer.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown rasterizer backend {backend!r}; choose one of {BACKENDS}")
    if gaussians.dtype not in (torch.float32, torch.float64):
        raise TypeError(f"Gaussians must be float32 or float64, got {gaussians.dtype}")
    bg = torch.as_tensor(background, dtype=gaussians.dtype, device=gaussians.device).reshape(3)
    if backend == "auto":
        backend = "gsplat" if gaussians.device.type == "cuda" and gsplat_available() else "cpu"
    if backend == "gsplat":
        if not gsplat_available():
            raise RuntimeError("the gsplat backend needs CUDA and the gsplat package (pip install gsplat)")
        from .gsplat_backend import render_gsplat  # noqa: PLC0415 - needs CUDA and gsplat

        return render_gsplat(gaussians, camera, bg, near=near, eps2d=eps2d)
    if gaussians.device.type != "cpu":
        raise ValueError("the CPU rasterizer needs CPU tensors (install gsplat for CUDA tensors)")
    from .cpu_backend import rasterize  # noqa: PLC0415 - imports numba kernels

    K, w2c = camera_tensors(camera.K, camera.w2c, gaussians.dtype)
    screen = project(gaussians, K, w2c, camera.width, camera.height, near=near, eps2d=eps2d)
    return rasterize(screen, camera.width, camera.height, bg)
