"""The CPU rasterizer against the per-pixel reference (exactness) and finite differences (gradients)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from gg_core.capture.cameras import Camera
from gg_core.gaussians.render import gsplat_available, render
from gg_core.gaussians.sh import rgb_to_sh0
from gg_core.gaussians.splats import Gaussians


def to_gaussians(scene: dict, dtype: torch.dtype) -> Gaussians:
    return Gaussians(**{k: torch.tensor(scene[k], dtype=dtype) for k in ("means", "quats", "scales", "opacities",
                                                                         "colors")})


def reference_of(reference, scene: dict, camera: Camera | None = None):
    cam = camera or scene["camera"]
    return reference.reference_render(scene["means"], scene["quats"], scene["scales"], scene["opacities"],
                                      scene["colors"], cam.K, cam.w2c, cam.width, cam.height, scene["background"])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_matches_per_pixel_reference(reference, seed, dtype):
    scene = reference.random_scene(seed)
    out = render(to_gaussians(scene, dtype), scene["camera"], torch.tensor(scene["background"], dtype=dtype))
    image, alpha, depth = reference_of(reference, scene)
    assert 0.3 < alpha.mean() < 0.99  # the scene covers the image with partial transparency
    assert out["image"].dtype == dtype
    _assert_close(out, image, alpha, depth)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_saturated_pixels_match_reference(reference, dtype):
    """Dense opaque layers: alpha clamps at 0.99 and pixels stop at the transmittance cut-off."""
    scene = reference.random_scene(3, n=150, opacity=(0.9, 1.0), scale=(0.1, 0.4))
    scene["opacities"][9:40] = 1.0  # alpha = min(0.99, o G) clamps near these centres
    out = render(to_gaussians(scene, dtype), scene["camera"], torch.tensor(scene["background"], dtype=dtype))
    cam = scene["camera"]
    image, alpha, depth, stopped = reference.reference_render(
        scene["means"], scene["quats"], scene["scales"], scene["opacities"], scene["colors"], cam.K, cam.w2c,
        cam.width, cam.height, scene["background"], return_stopped=True)
    assert stopped.mean() > 0.3  # many pixels reached the cut-off
    assert out["image"].dtype == dtype
    _assert_close(out, image, alpha, depth)


def _assert_close(out: dict, image: np.ndarray, alpha: np.ndarray, depth: np.ndarray) -> None:
    for name, ref in (("image", image), ("alpha", alpha), ("depth", depth)):
        err = np.abs(out[name].numpy() - ref).max()
        assert err < 1e-4, f"{name} differs from the reference by {err}"


def test_skewed_wide_camera_matches_reference(reference):
    scene = reference.random_scene(7, n=60, width=57, height=23)  # not a multiple of the tile size
    base = scene["camera"]
    K = base.K.copy()
    K[0, 1] = 4.0
    K[0, 0] *= 0.8
    cam = Camera("skew", K, base.R, base.t, base.width, base.height)
    out = render(to_gaussians(scene, torch.float64), cam, torch.tensor(scene["background"]))
    image, alpha, _ = reference_of(reference, scene, cam)
    assert np.abs(out["image"].numpy() - image).max() < 1e-9
    assert np.abs(out["alpha"].numpy() - alpha).max() < 1e-9


def test_culled_and_transparent_gaussians_draw_nothing(reference):
    scene = reference.random_scene(0)
    g = to_gaussians(scene, torch.float64)
    keep = torch.ones(len(g), dtype=torch.bool)
    keep[[0, 1, 2, 7]] = False  # behind the camera, inside the near plane, off-screen, opacity < 1/255
    bg = torch.tensor(scene["background"])
    full, subset = render(g, scene["camera"], bg), render(g[keep], scene["camera"], bg)
    assert torch.equal(full["image"], subset["image"])


def test_sh_degree0_equals_plain_colour(reference):
    scene = reference.random_scene(4)
    g = to_gaussians(scene, torch.float64)
    sh = torch.zeros(len(g), 16, 3, dtype=torch.float64)
    sh[:, 0] = rgb_to_sh0(g.colors)
    g_sh = replace(g, colors=None, sh=sh)
    a, b = render(g, scene["camera"]), render(g_sh, scene["camera"])
    assert torch.allclose(a["image"], b["image"], atol=1e-12)


def _loss(out: dict, weights: dict) -> torch.Tensor:
    return sum((out[k] * w).sum() for k, w in weights.items())


def _check_gradients(make_out, params: dict[str, torch.Tensor], weights: dict, h: float = 1e-6) -> None:
    for p in params.values():
        p.requires_grad_(True)
    _loss(make_out(), weights).backward()
    for name, p in params.items():
        analytic = p.grad.clone()
        numeric = torch.zeros_like(p)
        flat, nflat = p.data.view(-1), numeric.view(-1)
        for i in range(flat.numel()):
            old = flat[i].item()
            with torch.no_grad():
                flat[i] = old + h
                up = _loss(make_out(), weights).item()
                flat[i] = old - h
                down = _loss(make_out(), weights).item()
                flat[i] = old
            nflat[i] = (up - down) / (2 * h)
        rel = (numeric - analytic).norm() / numeric.norm()
        assert numeric.norm() > 0, f"{name}: loss does not depend on it (test scene too small?)"
        assert rel < 1e-3, f"gradient of {name}: relative error {rel:.2e}"


@pytest.mark.parametrize("use_sh", [False, True])
def test_gradients_match_finite_differences(reference, use_sh):
    scene = reference.random_scene(11, n=14, width=24, height=20)
    scene["opacities"][8:10] = 1.0  # some pixels with clamped alpha (zero gradient there)
    rng = np.random.default_rng(5)
    g = to_gaussians(scene, torch.float64)
    params = {"means": g.means.clone(), "quats": g.quats.clone(), "scales": g.scales.clone(),
              "opacities": g.opacities.clone(), "background": torch.tensor(scene["background"])}
    if use_sh:
        params["sh"] = torch.tensor(rng.normal(0, 0.3, (len(g), 16, 3)))
    else:
        params["colors"] = g.colors.clone()
    weights = {"image": torch.tensor(rng.random((20, 24, 3))), "alpha": torch.tensor(rng.random((20, 24))),
               "depth": torch.tensor(rng.random((20, 24)))}

    def make_out():
        colour = {"sh": params["sh"]} if use_sh else {"colors": params["colors"]}
        gs = Gaussians(params["means"], params["quats"], params["scales"], params["opacities"], **colour)
        return render(gs, scene["camera"], params["background"])

    _check_gradients(make_out, params, weights)


def test_float32_gradients_agree_with_float64(reference):
    scene = reference.random_scene(3)
    grads = {}
    for dtype in (torch.float32, torch.float64):
        g = to_gaussians(scene, dtype)
        means = g.means.clone().requires_grad_(True)
        colors = g.colors.clone().requires_grad_(True)
        out = render(replace(g, means=means, colors=colors), scene["camera"])
        (out["image"] * torch.linspace(0, 1, 3, dtype=dtype)).sum().backward()
        grads[dtype] = (means.grad.double(), colors.grad.double())
    for a, b in zip(grads[torch.float32], grads[torch.float64]):
        assert (a - b).norm() / b.norm() < 1e-4


def test_unknown_backend_is_rejected(reference):
    scene = reference.random_scene(0, n=10)
    with pytest.raises(ValueError, match="backend"):
        render(to_gaussians(scene, torch.float32), scene["camera"], backend="vulkan")


@pytest.mark.skipif(gsplat_available(), reason="only where gsplat cannot run")
def test_gsplat_backend_without_cuda_says_what_is_missing(reference):
    scene = reference.random_scene(0, n=10)
    with pytest.raises(RuntimeError, match="CUDA and the gsplat package"):
        render(to_gaussians(scene, torch.float32), scene["camera"], backend="gsplat")
