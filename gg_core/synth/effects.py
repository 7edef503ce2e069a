"""Hidden physics of a synthetic capture, produced only by Blender's own solver.

Each effect turns its parameters into a patch of Blender settings (cloth, collision, scene gravity,
force fields, vertex groups naming garment regions). The worker applies the patch verbatim and
truth.json records both the parameters and the patch, so metrics know exactly what was hidden and our
simulator never generated any of it. Pure Python: parsed and validated before Blender starts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

from ..errors import InputError

GRAVITY = 9.81
Params = dict[str, float | str]
Patch = dict[str, object]
STIFFNESSES = ("tension_stiffness", "compression_stiffness", "shear_stiffness", "bending_stiffness")


@dataclass(frozen=True)
class Effect:
    name: str
    description: str
    defaults: Params
    patch: Callable[[Params, dict], Patch]  # (params, base cloth settings) -> Blender settings
    limits: dict[str, tuple[float, float]] = field(default_factory=dict)  # Blender's hard ranges (it clamps)


@dataclass(frozen=True)
class ResolvedEffect:
    """An effect with its final parameters and the Blender settings that realise it."""

    name: str
    params: Params
    blender: Patch = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"name": self.name, "description": EFFECTS[self.name].description, "params": dict(self.params),
                "blender": self.blender}


def _horizontal(azimuth_deg: float) -> list[float]:
    """Unit vector in the floor plane (gg +Y up); azimuth 0 points along +X, 90 along +Z (the body's front)."""
    a = math.radians(azimuth_deg)
    return [math.cos(a), 0.0, math.sin(a)]


def _wind(p: Params, cloth: dict) -> Patch:
    return {"force_fields": [{"type": "WIND", "strength": p["strength"], "direction": _horizontal(p["azimuth_deg"]),
                              "noise": p["noise"], "flow": p["flow"]}]}


def _gravity(p: Params, cloth: dict) -> Patch:
    tilt = math.radians(p["tilt_deg"])
    h = _horizontal(p["azimuth_deg"])
    g = GRAVITY * p["scale"]
    return {"gravity": [g * math.sin(tilt) * h[0], -g * math.cos(tilt), g * math.sin(tilt) * h[2]]}


def _stiff_patch(p: Params, cloth: dict) -> Patch:
    region = str(p["region"])
    return {"cloth": {f"{k}_max": cloth[k] * p["factor"] for k in STIFFNESSES},
            "vertex_groups": {"vertex_group_structural_stiffness": region, "vertex_group_shear_stiffness": region,
                              "vertex_group_bending": region}}


EFFECTS: dict[str, Effect] = {e.name: e for e in (
    Effect("none", "no hidden physics: the reference motion", {}, lambda p, c: {}),
    Effect("wind", "steady wind force field blowing horizontally (Blender WIND field, acts on cloth faces)",
           {"strength": 1000.0, "azimuth_deg": 0.0, "noise": 0.0, "flow": 0.0}, _wind,
           {"noise": (0.0, 10.0), "flow": (0.0, 10.0)}),
    Effect("air_drag", "strong air damping of the cloth (velocity-proportional drag; the reference uses 1)",
           {"air_damping": 10.0}, lambda p, c: {"cloth": {"air_damping": p["air_damping"]}},
           {"air_damping": (0.0, 10.0)}),
    Effect("friction", "high friction between garment and body (collider cloth friction; the reference uses 5)",
           {"friction": 60.0}, lambda p, c: {"body_collision": {"cloth_friction": p["friction"]}},
           {"friction": (0.0, 80.0)}),
    Effect("shrink", "rest lengths shortened on one garment region, like a tight seam (factor 0.15 = 15%)",
           {"factor": 0.15, "region": "side_seam"},
           lambda p, c: {"cloth": {"shrink_min": 0.0, "shrink_max": p["factor"]},
                         "vertex_groups": {"vertex_group_shrink": str(p["region"])}},
           {"factor": (-1.0, 0.9)}),
    Effect("stiff_patch", "one garment region much stiffer (stretch, shear and bending), like a glued patch",
           {"factor": 30.0, "region": "patch"}, _stiff_patch, {"factor": (1.0, 200.0)}),
    Effect("gravity", "gravity scaled and tilted away from the vertical",
           {"scale": 1.25, "tilt_deg": 12.0, "azimuth_deg": 0.0}, _gravity,
           {"scale": (0.0, 10.0), "tilt_deg": (0.0, 90.0)}),
)}


def region_names(effect: ResolvedEffect) -> set[str]:
    """Garment regions (vertex groups) the effect refers to; the garment must define them."""
    return {str(v) for v in effect.blender.get("vertex_groups", {}).values()}


def resolve_effect(name: str, assignments: list[str], cloth: dict) -> ResolvedEffect:
    """Effect `name` with `key=value` overrides of its defaults, patched onto the base `cloth` settings.

    Bad names or values raise InputError."""
    if name not in EFFECTS:
        raise InputError(f"unknown effect '{name}'", "--effect", f"choose one of: {', '.join(EFFECTS)}")
    effect = EFFECTS[name]
    params: Params = dict(effect.defaults)
    for item in assignments:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or key not in effect.defaults:
            valid = ", ".join(effect.defaults) or "none"
            raise InputError(f"bad effect parameter '{item}' for effect '{name}'", "--effect-param",
                             f"write key=value with key one of: {valid}")
        if isinstance(effect.defaults[key], str):
            params[key] = value.strip()
            continue
        try:
            params[key] = float(value)
        except ValueError:
            raise InputError(f"effect parameter '{key}' must be a number, got '{value}'", "--effect-param",
                             f"write e.g. {key}={effect.defaults[key]}") from None
        low, high = effect.limits.get(key, (-math.inf, math.inf))
        if not (math.isfinite(params[key]) and low <= params[key] <= high):
            raise InputError(f"effect parameter '{key}'={value} is out of range", "--effect-param",
                             f"use a finite number in [{low}, {high}]")
    return ResolvedEffect(name, params, effect.patch(params, cloth))
