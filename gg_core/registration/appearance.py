"""Initial appearance (stage 1): fit the Gaussian texture's parameters to one frame with the mesh frozen.

Loss: L_rgb + w_pos L_pos + w_scale L_scale with L_pos = ||max(|mu| - eps_pos, 0)||_2 and
L_scale = ||max(s - eps_scale, 0)||_2 in face-local units (REFERENCE §2: eps_pos 1, weight 1e-2; eps_scale 0.6,
weight 1): Gaussians may not wander off or grow past their face. Adam with one learning rate per parameter
group (REFERENCE §4's release rates; the higher SH bands at 1/20 of the base colour rate as in 3D Gaussian
splatting). The release runs 10 000 iterations; far fewer suffice here because the base colours start from
the images: every Gaussian takes the mean colour of the garment pixels its surface point projects to in the
cameras that see it unoccluded (by the body and by the garment itself).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace

import numpy as np
import torch

from ..gaussians import RayCaster, build_texture, rgb_to_sh0, surface_points
from ..gaussians import texture as tex
from ..gaussians.texture import GaussianTexture
from ..jobs import Progress
from .photometric import render_view, rgb_loss, visible_gaussians
from .views import View


@dataclass
class AppearanceConfig:
    lr_color: float = 2.5e-3       # SH band 0
    lr_sh_rest: float = 2.5e-3 / 20
    lr_opacity: float = 0.05
    lr_scale: float = 5e-3         # log scale
    lr_rotation: float = 1e-3
    lr_offset: float = 4e-4        # face-local offset mu
    eps_pos: float = 1.0
    w_pos: float = 1e-2
    eps_scale: float = 0.6
    w_scale: float = 1.0
    init_colors: bool = True
    seed: int = 0

    def rates_scaled(self, factor: float) -> "AppearanceConfig":
        """The same fit with every learning rate times `factor` (a refit that starts close needs fewer steps)."""
        return replace(self, **{lr: getattr(self, lr) * factor for _, _, lr in GROUPS})


# (name, channel slice, learning-rate attribute of AppearanceConfig), in channel order
GROUPS = (("color", slice(0, 3), "lr_color"), ("sh_rest", slice(3, 48), "lr_sh_rest"),
          ("opacity", slice(tex.OPACITY, tex.OPACITY + 1), "lr_opacity"), ("scale", tex.LOG_SCALE, "lr_scale"),
          ("rotation", tex.ROTATION, "lr_rotation"), ("offset", tex.OFFSET, "lr_offset"))


def contrast_background(views: list[View]) -> torch.Tensor:
    """A render background far from the garment's colour (per channel 1 where the garment is dark, else 0), so
    garment Gaussians drawn over background pixels cost as much as possible."""
    total = sum(float(v.garment.sum()) for v in views)
    mean = sum((v.rgb * v.garment[..., None]).sum((0, 1)) for v in views) / max(total, 1e-12)
    return (mean < 0.5).to(torch.float32)


def observed_colors(texture: GaussianTexture, verts: np.ndarray, faces: np.ndarray,
                    views: list[View]) -> tuple[np.ndarray, np.ndarray]:
    """(mean RGB [T, 3], number of views [T]) of the garment pixels each Gaussian's surface point projects to in
    the views that see it past the body and the garment itself."""
    points = surface_points(texture, torch.from_numpy(np.asarray(verts, np.float64)), faces).numpy()
    own = RayCaster([(verts, faces)])
    total = np.zeros((len(points), 3))
    count = np.zeros(len(points))
    for view in views:
        cam = view.camera
        seen = visible_gaussians(texture, torch.from_numpy(points), faces, view).numpy()
        seen &= ~own.segment_blocked(cam.center, points, eps=1e-3)
        uv, z = cam.project(points)
        col = np.floor(uv[:, 0]).astype(np.int64)
        row = np.floor(uv[:, 1]).astype(np.int64)
        seen &= (z > 0) & (col >= 0) & (col < cam.width) & (row >= 0) & (row < cam.height)
        idx = np.flatnonzero(seen)
        garment = view.garment.numpy()[row[idx], col[idx]] > 0.5
        idx = idx[garment]
        total[idx] += view.rgb.numpy()[row[idx], col[idx]]
        count[idx] += 1
    return total / np.maximum(count, 1)[:, None], count


def fit_appearance(texture: GaussianTexture, verts: np.ndarray | torch.Tensor, faces: np.ndarray,
                   views: list[View], iterations: int, progress: Progress | None = None,
                   config: AppearanceConfig | None = None,
                   background: torch.Tensor | None = None) -> tuple[GaussianTexture, dict]:
    """Optimize the texture's Gaussian parameters on the frozen mesh (verts, faces) against `views`.

    One view per iteration, in shuffled passes over all views. Returns a new texture and a log with the loss
    per iteration, the background colour used, the mean L_rgb over all views before and after, and seconds.
    """
    cfg = config or AppearanceConfig()
    start = time.perf_counter()
    verts_t = torch.as_tensor(np.asarray(verts, np.float64) if not isinstance(verts, torch.Tensor)
                              else verts.detach().double(), dtype=torch.float32)
    faces = np.asarray(faces, np.int64)
    bg = contrast_background(views) if background is None else torch.as_tensor(background, dtype=torch.float32)
    params = texture.params.detach().to(torch.float32).clone()
    n_colored = 0
    if cfg.init_colors:
        rgb, count = observed_colors(texture, verts_t.double().numpy(), faces, views)
        seen = torch.from_numpy(count > 0)
        params[seen, 0:3] = rgb_to_sh0(torch.from_numpy(rgb[count > 0]).float())
        n_colored = int(seen.sum())
    groups = {name: params[:, sl].clone().requires_grad_(True) for name, sl, _ in GROUPS}
    optimizer = torch.optim.Adam([{"params": [groups[name]], "lr": getattr(cfg, lr), "name": name}
                                  for name, _, lr in GROUPS], eps=1e-15)
    keep = [visible_gaussians(texture, verts_t, faces, v) for v in views]
    targets = [v.target(bg) for v in views]

    def mean_rgb_loss(p: torch.Tensor) -> float:
        with torch.no_grad():
            return float(np.mean([float(rgb_loss(render_view(texture, verts_t, faces, v, bg, p, k)["image"], t,
                                                 v.loss_mask)) for v, k, t in zip(views, keep, targets)]))

    before = mean_rgb_loss(params)
    rng = np.random.default_rng(cfg.seed)
    order: list[int] = []
    losses = []
    for it in range(iterations):
        if not order:
            order = list(rng.permutation(len(views)))
        i = order.pop()
        p = torch.cat([groups[name] for name, _, _ in GROUPS], dim=1)
        image = render_view(texture, verts_t, faces, views[i], bg, p, keep[i])["image"]
        loss = rgb_loss(image, targets[i], views[i].loss_mask) + regularizers(p, cfg)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
        if progress is not None:
            progress.step(f"appearance {it + 1}/{iterations}: loss {losses[-1]:.4f}")
    fitted = torch.cat([groups[name] for name, _, _ in GROUPS], dim=1).detach()
    log = {"iterations": iterations, "loss": losses, "background": bg.tolist(), "colored_from_images": n_colored,
           "rgb_loss_before": before, "rgb_loss_after": mean_rgb_loss(fitted),
           "seconds": time.perf_counter() - start, "config": asdict(cfg)}
    return replace(texture, params=fitted), log


def regularizers(params: torch.Tensor, cfg: AppearanceConfig) -> torch.Tensor:
    """w_pos L_pos + w_scale L_scale of raw texture parameters [T, 59]."""
    l_pos = torch.clamp(params[:, tex.OFFSET].abs() - cfg.eps_pos, min=0).norm()
    l_scale = torch.clamp(torch.exp(params[:, tex.LOG_SCALE]) - cfg.eps_scale, min=0).norm()
    return cfg.w_pos * l_pos + cfg.w_scale * l_scale


def downsample_texture(texture: GaussianTexture, verts: np.ndarray, faces: np.ndarray,
                       factor: int = 2) -> GaussianTexture:
    """The texture at 1/factor of its resolution on the same UV atlas: each coarse texel takes the mean raw
    parameters of the fine texels in its factor x factor block, its Gaussians factor times larger.

    Registration needs Gaussians about as dense as the image pixels; stage 1 makes them denser (for appearance),
    and every Gaussian costs time in every iteration."""
    if texture.texels is None or factor <= 1:
        return texture
    res = texture.resolution // factor
    coarse = build_texture(verts, faces, res, uvs=texture.uvs, face_uvs=texture.face_uvs)
    block = torch.from_numpy((texture.texels[:, 0] // factor) * res + texture.texels[:, 1] // factor)
    params = texture.params.detach().to(torch.float32)
    sums = torch.zeros(res * res, params.shape[1]).index_add_(0, block, params)
    counts = torch.zeros(res * res).index_add_(0, block, torch.ones(len(block)))
    index = torch.from_numpy(coarse.texels[:, 0] * res + coarse.texels[:, 1])
    covered = counts[index] > 0
    merged = coarse.params.clone()
    merged[covered] = sums[index[covered]] / counts[index[covered], None]
    merged[covered, tex.LOG_SCALE] += float(np.log(factor))
    return replace(coarse, params=merged)
