"""Fabric physics (Blender cloth settings) and fabric looks (procedural shader parameters).

Physics uses Blender's own units, in the proportions of Blender's cloth presets (vertex mass in kg per
vertex next to spring stiffnesses): Blender's solver is tuned for them, and a physically small vertex mass
makes every fabric behave like cardboard (gravity and wind barely bend it). Looks are seeded: colours
and pattern scale vary with the seed, the pattern kind is chosen by the user.
"""
from __future__ import annotations

import colorsys
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import InputError


@dataclass(frozen=True)
class Fabric:
    name: str
    vertex_mass: float          # kg per vertex, as in Blender's presets
    tension_stiffness: float    # Blender cloth stiffness units
    compression_stiffness: float
    shear_stiffness: float
    bending_stiffness: float
    tension_damping: float
    compression_damping: float
    shear_damping: float
    bending_damping: float
    air_damping: float

    def cloth_settings(self) -> dict:
        """Blender ClothSettings attributes."""
        settings = {k: v for k, v in asdict(self).items() if k not in ("name", "vertex_mass")}
        settings["mass"] = self.vertex_mass
        settings["bending_model"] = "ANGULAR"
        return settings


FABRICS: dict[str, Fabric] = {f.name: f for f in (
    Fabric("cotton", 0.3, 15.0, 15.0, 5.0, 0.5, 5.0, 5.0, 5.0, 0.5, 1.0),
    Fabric("jersey", 0.25, 8.0, 8.0, 3.0, 0.2, 4.0, 4.0, 4.0, 0.3, 1.0),
    Fabric("silk", 0.15, 5.0, 5.0, 2.0, 0.05, 2.0, 2.0, 2.0, 0.1, 1.0),
    Fabric("denim", 1.0, 40.0, 40.0, 15.0, 10.0, 25.0, 25.0, 25.0, 1.0, 1.0),
)}

PATTERNS = ("print", "weave", "fuzzy")


@dataclass(frozen=True)
class Look:
    """Procedural fabric shader: a high-frequency pattern in UV space (UVs are in metres / uv_scale)."""

    pattern: str
    base_color: tuple[float, float, float]
    accent_color: tuple[float, float, float]
    repeats_per_metre: float
    roughness: float
    sheen: float

    def to_json(self) -> dict:
        return asdict(self)


def random_look(rng: np.random.Generator, pattern: str) -> Look:
    """Saturated, seed-chosen colours (never the grey studio background) with a contrasting accent."""
    if pattern not in PATTERNS:
        raise InputError(f"unknown texture pattern '{pattern}'", "--texture", f"choose one of: {', '.join(PATTERNS)}")
    hue = float(rng.uniform(0, 1))
    base = colorsys.hsv_to_rgb(hue, float(rng.uniform(0.55, 0.85)), float(rng.uniform(0.45, 0.75)))
    accent = colorsys.hsv_to_rgb((hue + rng.uniform(0.3, 0.7)) % 1.0, float(rng.uniform(0.2, 0.6)),
                                 float(rng.uniform(0.8, 0.95)))
    repeats = {"print": 18.0, "weave": 60.0, "fuzzy": 40.0}[pattern] * float(rng.uniform(0.85, 1.15))
    return Look(pattern, tuple(round(c, 4) for c in base), tuple(round(c, 4) for c in accent), round(repeats, 3),
                roughness=0.9 if pattern == "fuzzy" else 0.55, sheen=1.0 if pattern == "fuzzy" else 0.2)
