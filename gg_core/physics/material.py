"""Cloth material per vertex: HOOD/ContourCraft's four values, their defaults and ranges.

Fitting works in an unconstrained space: z = logit((log v - log lo) / (log hi - log lo)) per value, so every
parameter stays inside its bounds and steps are relative (a stiffness 10x off is as far as one 10x too soft).
HOOD normalizes mu and bending in log space; log space for all four keeps one rule. The bounds are HOOD's ranges
widened by FIT_RANGE_FACTOR on each side: HOOD chose soft ranges its network trains well on, while fits to
Blender's cloth presets were measured to press against them (lighter and stiffer than HOOD allows).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

# name -> (default, low, high) in SI units: HOOD's / ContourCraft's defaults (also the paper's) and ranges.
MATERIAL_SPEC: dict[str, tuple[float, float, float]] = {
    "density": (0.20022, 0.043, 0.7),        # kg/m^2 (areal)
    "mu": (23600.0, 15909.0, 63636.0),       # Pa, Lame mu (times thickness gives N/m)
    "lam": (44400.0, 3535.0, 93334.0),       # Pa, Lame lambda
    "bending": (3.96e-5, 6.4e-8, 1.3e-3),    # N m, dihedral bending coefficient
}
MATERIAL_NAMES = tuple(MATERIAL_SPEC)
THICKNESS = 4.7e-4  # m, HOOD's fabric thickness (scales the stretching energy)
FIT_RANGE_FACTOR = 10.0


def _bounds(name: str) -> tuple[float, float]:
    _, lo, hi = MATERIAL_SPEC[name]
    return math.log(lo / FIT_RANGE_FACTOR), math.log(hi * FIT_RANGE_FACTOR)


def to_latent(name: str, value: torch.Tensor | float) -> torch.Tensor:
    """Physical value -> unconstrained latent (clamped just inside the range)."""
    lo, hi = _bounds(name)
    t = (torch.log(torch.as_tensor(value, dtype=torch.float64)) - lo) / (hi - lo)
    t = t.clamp(1e-6, 1 - 1e-6)
    return torch.log(t) - torch.log1p(-t)


def from_latent(name: str, z: torch.Tensor) -> torch.Tensor:
    lo, hi = _bounds(name)
    return torch.exp(lo + (hi - lo) * torch.sigmoid(z))


@dataclass
class Material:
    """Per-vertex material values [V] (float64 tensors, physical units)."""

    density: torch.Tensor
    mu: torch.Tensor
    lam: torch.Tensor
    bending: torch.Tensor

    @classmethod
    def uniform(cls, n_vertices: int, **values: float) -> "Material":
        unknown = set(values) - set(MATERIAL_NAMES)
        if unknown:
            raise ValueError(f"unknown material values {sorted(unknown)}; known: {MATERIAL_NAMES}")
        return cls(**{n: torch.full((n_vertices,), float(values.get(n, MATERIAL_SPEC[n][0])), dtype=torch.float64)
                      for n in MATERIAL_NAMES})

    def as_dict(self) -> dict[str, torch.Tensor]:
        return {n: getattr(self, n) for n in MATERIAL_NAMES}

    def summary(self) -> dict[str, dict[str, float]]:
        """Mean / min / max per value, for reports."""
        return {n: {"mean": float(v.mean()), "min": float(v.min()), "max": float(v.max())}
                for n, v in self.as_dict().items()}
