"""Binding: texture Gaussians (face-local) -> world Gaussians on the current mesh (torch, differentiable).

Face frame R_f (columns): a0 = normalized (v1 - v0); a1 = normalized (a0 x (v2 - v0)), the face normal;
a2 = a0 x a1. Face scale k_f = (B + H) / 2 with base B = |v1 - v0| and height H over that base.
World Gaussian: rotation R_f r, mean k_f R_f mu + tau (tau = barycentric surface point), scale k_f s.
A rigid motion moves every frame with the mesh and keeps k_f; a uniform scale c scales k_f by c, so
Gaussians follow both exactly. Gradients reach the vertex positions through tau, R_f and k_f.
"""
from __future__ import annotations

import numpy as np
import torch

from . import texture as tex
from .rotations import quat_multiply, rotmat_to_quat
from .splats import Gaussians


def face_frames(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """[F, 3, 3] rotation matrices whose columns are (edge direction, normal, in-plane third axis)."""
    v0, v1, v2 = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    a0 = _normalize(v1 - v0)
    a1 = _normalize(torch.cross(a0, v2 - v0, dim=-1))
    a2 = torch.cross(a0, a1, dim=-1)
    return torch.stack((a0, a1, a2), dim=-1)


def face_scale(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """[F] k_f = (base + height) / 2 of each triangle, base = |v1 - v0|."""
    v0, v1, v2 = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    base = (v1 - v0).norm(dim=-1)
    height = torch.cross(v1 - v0, v2 - v0, dim=-1).norm(dim=-1) / base
    return 0.5 * (base + height)


def surface_points(texture: tex.GaussianTexture, verts: torch.Tensor,
                   faces: torch.Tensor | np.ndarray) -> torch.Tensor:
    """[T, 3] the barycentric surface point tau of every texture Gaussian."""
    faces = _faces_tensor(faces, verts.device)
    corners = verts[faces[torch.from_numpy(texture.face_ids).to(verts.device)]]      # [T, 3, 3]
    bary = torch.as_tensor(texture.barycentrics, dtype=verts.dtype, device=verts.device)
    return (bary[:, :, None] * corners).sum(dim=1)


def bind(texture: tex.GaussianTexture, verts: torch.Tensor, faces: torch.Tensor | np.ndarray,
         params: torch.Tensor | None = None) -> Gaussians:
    """World Gaussians of `texture` on the mesh (verts [V, 3], faces [F, 3]).

    `params` [T, 59] replaces texture.params, e.g. with network offsets added (stage 3). The result
    is differentiable w.r.t. verts and params.
    """
    faces = _faces_tensor(faces, verts.device)
    params = (texture.params if params is None else params).to(dtype=verts.dtype, device=verts.device)
    fid = torch.from_numpy(texture.face_ids).to(verts.device)
    frames = face_frames(verts, faces)[fid]
    k = face_scale(verts, faces)[fid]
    offsets = (frames @ params[:, tex.OFFSET, None]).squeeze(-1)
    means = surface_points(texture, verts, faces) + k[:, None] * offsets
    quats = quat_multiply(rotmat_to_quat(frames), _normalize(params[:, tex.ROTATION]))
    return Gaussians(means=means, quats=quats, scales=k[:, None] * torch.exp(params[:, tex.LOG_SCALE]),
                     opacities=torch.sigmoid(params[:, tex.OPACITY]),
                     sh=params[:, tex.SH].reshape(-1, 16, 3))


def _faces_tensor(faces: torch.Tensor | np.ndarray, device: torch.device) -> torch.Tensor:
    if isinstance(faces, torch.Tensor):
        return faces.to(device=device, dtype=torch.long)
    return torch.as_tensor(np.asarray(faces, np.int64), device=device)


def _normalize(v: torch.Tensor) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True)
