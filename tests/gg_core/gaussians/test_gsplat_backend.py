"""gsplat (CUDA) against the CPU rasterizer. Skipped without CUDA and gsplat (as on the dev machines)."""
from __future__ import annotations

import pytest
import torch

from gg_core.gaussians.render import gsplat_available, render
from gg_core.gaussians.splats import Gaussians

pytestmark = pytest.mark.skipif(not gsplat_available(), reason="needs CUDA and the gsplat package")


def test_gsplat_matches_cpu_backend_in_images_and_gradients(reference):
    scene = reference.random_scene(5, n=200, width=96, height=64, extremes=False)
    results = {}
    for backend, device in (("cpu", "cpu"), ("gsplat", "cuda")):
        params = {k: torch.tensor(scene[k], dtype=torch.float32, device=device, requires_grad=True)
                  for k in ("means", "quats", "scales", "opacities", "colors")}
        out = render(Gaussians(**params), scene["camera"], torch.tensor(scene["background"], dtype=torch.float32,
                                                                        device=device), backend=backend)
        out["image"].sum().backward()
        results[backend] = (out["image"].detach().cpu(), {k: p.grad.cpu() for k, p in params.items()})
    (img_c, g_c), (img_g, g_g) = results["cpu"], results["gsplat"]
    diff = (img_c - img_g).abs()
    assert diff.mean() < 2e-3 and diff.max() < 0.05  # only faint 3-sigma tails differ
    for k in ("means", "colors", "opacities"):
        cos = torch.nn.functional.cosine_similarity(g_c[k].flatten(), g_g[k].flatten(), dim=0)
        assert cos > 0.98, f"{k}: gradient cosine {cos:.3f}"


def test_auto_backend_picks_gsplat_for_cuda_tensors(reference):
    scene = reference.random_scene(1, n=20)
    g = Gaussians(**{k: torch.tensor(scene[k], dtype=torch.float32, device="cuda")
                     for k in ("means", "quats", "scales", "opacities", "colors")})
    assert render(g, scene["camera"])["image"].device.type == "cuda"
