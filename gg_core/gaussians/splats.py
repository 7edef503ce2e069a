"""`Gaussians`: the renderable set of 3D Gaussians in world space (what every backend draws)."""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

import torch


@dataclass(frozen=True)
class Gaussians:
    """N world-space Gaussians. Activated values: opacities in [0, 1], linear scales.

    Colour is either `colors` [N, 3] (view-independent RGB) or `sh` [N, K, 3] (K = 1, 4, 9, 16
    spherical-harmonic coefficients, evaluated per camera). Quaternions are (w, x, y, z) and need
    not be unit length.
    """

    means: torch.Tensor          # [N, 3]
    quats: torch.Tensor          # [N, 4]
    scales: torch.Tensor         # [N, 3]
    opacities: torch.Tensor      # [N]
    colors: torch.Tensor | None = None   # [N, 3]
    sh: torch.Tensor | None = None       # [N, K, 3]

    def __post_init__(self) -> None:
        n = self.means.shape[0]
        if (self.colors is None) == (self.sh is None):
            raise ValueError("Gaussians need exactly one of colors [N,3] or sh [N,K,3]")
        expected = {"means": (n, 3), "quats": (n, 4), "scales": (n, 3), "opacities": (n,)}
        for name, shape in expected.items():
            if tuple(getattr(self, name).shape) != shape:
                raise ValueError(f"Gaussians.{name} has shape {tuple(getattr(self, name).shape)}, expected {shape}")
        if self.colors is not None and tuple(self.colors.shape) != (n, 3):
            raise ValueError(f"Gaussians.colors has shape {tuple(self.colors.shape)}, expected ({n}, 3)")
        if self.sh is not None and (self.sh.ndim != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3):
            raise ValueError(f"Gaussians.sh has shape {tuple(self.sh.shape)}, expected ({n}, K, 3)")

    def __len__(self) -> int:
        return self.means.shape[0]

    def __getitem__(self, index: torch.Tensor | slice) -> "Gaussians":
        """A subset (boolean mask, indices or slice); gradients flow back to this set."""
        return replace(self, **{f.name: getattr(self, f.name)[index] for f in fields(self)
                                if getattr(self, f.name) is not None})

    @property
    def dtype(self) -> torch.dtype:
        return self.means.dtype

    @property
    def device(self) -> torch.device:
        return self.means.device
