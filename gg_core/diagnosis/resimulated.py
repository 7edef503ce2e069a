"""Captures whose garment motion comes from our own simulator instead of Blender's cloth: the well-specified
reference of `gg bench diagnose --truth-simulator ours`.

Why: on Blender captures the diagnosis cannot gain more than our simulator given the true effect, and that ceiling
is set by how Blender's cloth differs from ours: with nothing hidden our baseline rolls out 8-11 mm from the skirt
captures, about what Blender's own motion changes between 5 and 10 steps per frame (6.8-11.2 mm, session 18). Here
the same garment, bodies and pins of a Blender capture with nothing hidden are simulated again by our simulator,
with a material and damping the diagnosis does not start from, twice its substeps, and the hidden effect as one
of our force terms or region fields. What the diagnosis's baseline then lacks is the effect alone, so this measures
the diagnosis itself: does it name what is missing, and gain what the simulator given the effect gains.

Each Blender effect (gg_core/synth/effects.py) is translated into our parameters as the benchmark's parameter
errors compare them (blender_units.truth_parameters), where that is defined:
air damping -> mass damping alpha = 0.01 air_damping fps / mass; gravity -> the same gravity vector as an offset
from -9.81 y; friction -> Blender's added Coulomb coefficient 0.01 (friction - reference friction) added to our
default 0.5; shrink and stiff patch -> the same scale on the same region (rest lengths; stretch and bending
stiffness); wind -> quadratic drag against air moving at WIND_SPEED_PER_STRENGTH x strength along the field
(Blender's field strength has no unit of ours: chosen so its pressure on a face-on panel at rest, 0.3 Pa, is what
the diagnosis fitted on Blender's wind captures, 0.03-0.09 Pa at a 3-5x lighter fitted density).
"""
from __future__ import annotations

import json
import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from ..capture.layout import Capture
from ..errors import InputError
from ..geometry.meshio import read_mesh, write_ply
from ..physics.cloth import Cloth
from ..physics.contact import BodyCollider
from ..physics.forces import TERMS, make_terms
from ..physics.material import Material
from ..physics.simulator import ClothState, ImplicitSimulator
from ..physics.solver import SolverOptions
from ..storage import write_json
from ..synth.effects import GRAVITY, resolve_effect
from .baseline import BASELINE_TERMS
from .blender_units import truth_parameters, wind_push
from .library import apply_region

# the re-simulated garment's material and damping: none is a start of the diagnosis's fits (material defaults,
# margin starts 1x / 3x the default, loss factor 0.1); the proportions are those its baseline fitted on the
# Blender skirt with nothing hidden (density 0.06-0.34 kg/m^2, mu 4.6e4-2.2e5 Pa)
TRUE_MATERIAL = {"density": 0.15, "mu": 6.0e4, "lam": 5.0e4, "bending": 1.0e-4}
TRUE_TERMS = {"collision": {"margin": 0.012}, "viscoelastic_damping": {"tau": 0.03}}
WIND_SPEED_PER_STRENGTH = 0.7e-3    # m/s of air per unit of Blender's wind field strength (module docstring)
SETTLE_FRAMES = 30                  # the first recorded pose held still before each sequence


@dataclass
class OurEffect:
    """A Blender effect in our simulator: terms replaced or added (name -> parameters), region material
    log-scales (library.apply_region) on a named garment region, and the comparable true parameters."""

    terms: dict[str, dict] = field(default_factory=dict)
    region: str | None = None
    region_logs: dict[str, float] = field(default_factory=dict)
    parameters: dict[str, float | list[float]] = field(default_factory=dict)


def our_effect(name: str, assignments: list[str], reference_truth: dict) -> tuple[dict, OurEffect]:
    """(the resolved Blender effect as truth.json records it, the same effect in our simulator's terms) for
    effect `name` with `key=value` parameter overrides; `reference_truth` is the truth.json of the Blender capture
    with nothing hidden whose garment is re-simulated (its cloth settings and frame rate)."""
    material = reference_truth["material"]
    resolved = resolve_effect(name, assignments, material["blender_cloth"])
    p = resolved.params
    gravity = np.asarray(resolved.blender.get("gravity", material["gravity"]), np.float64)
    comparable = truth_parameters({"effect": resolved.to_json(), "preset": reference_truth["preset"],
                                   "material": {**material, "gravity": gravity.tolist()}})
    if name == "air_drag":
        ours = OurEffect({"mass_damping": {"alpha": comparable["mass_damping.alpha"]}}, parameters=comparable)
    elif name == "gravity":
        offset = gravity - np.array([0.0, -GRAVITY, 0.0])
        ours = OurEffect({"gravity_offset": {"delta_g": tuple(offset)}}, parameters=comparable)
    elif name == "friction":
        # Blender's added Coulomb coefficient added to ours (truth_parameters scores Blender's total)
        added = 0.01 * (float(p["friction"]) - float(material["blender_body_collision"]["cloth_friction"]))
        mu = TERMS["body_friction"].defaults["mu"] + added
        ours = OurEffect({"body_friction": {"mu": mu}}, parameters={"body_friction.mu": mu})
    elif name == "shrink":
        ours = OurEffect(region=str(p["region"]), region_logs={"rest": math.log(comparable["region.rest_scale"])},
                         parameters=comparable)
    elif name == "stiff_patch":
        log_factor = math.log(comparable["region.stretch_scale"])
        ours = OurEffect(region=str(p["region"]), region_logs={"stretch": log_factor, "bending": log_factor},
                         parameters=comparable)
    elif name == "wind":
        field_ = resolved.blender["force_fields"][0]
        velocity = np.asarray(field_["direction"], np.float64) * WIND_SPEED_PER_STRENGTH * float(p["strength"])
        ours = OurEffect({"wind": {"velocity": tuple(velocity)}}, parameters={"wind.push": wind_push(
            {"wind.velocity": velocity, "material.density": TRUE_MATERIAL["density"]})})
    elif name == "none":
        ours = OurEffect()
    else:
        raise InputError(f"effect '{name}' has no counterpart in our simulator", "--effects",
                         "choose one of: none, wind, air_drag, friction, shrink, stiff_patch, gravity")
    return resolved.to_json(), ours


def recorded_effect(truth: dict) -> OurEffect:
    """The hidden effect a re-simulated capture's truth.json records (resimulate)."""
    ours = truth["effect"]["ours"]
    return OurEffect(ours["terms"], ours["region"], ours["region_log_scales"], truth.get("true_parameters", {}))


def true_simulator(template: np.ndarray, faces: np.ndarray, pinned: np.ndarray, body_faces: np.ndarray,
                   n_body: int, hands: np.ndarray | None, effect: OurEffect, regions: dict[str, np.ndarray],
                   fps: float, substeps: int, flat: bool = False) -> ImplicitSimulator:
    """Our simulator with TRUE_MATERIAL, the diagnosis's baseline terms at TRUE_TERMS and the effect; the rest
    shape is `template`: the garment unloaded, as Blender's is, bending towards its own angles (or towards flat)."""
    cloth = Cloth(template, faces, pinned=pinned, material=Material.uniform(len(template), **TRUE_MATERIAL),
                  flat=flat)
    if effect.region is not None:
        with torch.no_grad():
            apply_region(cloth, (regions[effect.region] > 0).astype(np.float64), effect.region_logs)
    params = {**TRUE_TERMS, **effect.terms}
    names = list(BASELINE_TERMS) + [n for n in effect.terms if n not in BASELINE_TERMS]
    return ImplicitSimulator(cloth, terms=make_terms(names, params),
                             collider=BodyCollider(body_faces, n_body, exclude=hands), fps=fps, substeps=substeps,
                             options=SolverOptions(friction_at_end=True))


def simulate_sequence(sim: ImplicitSimulator, garment: np.ndarray, body: np.ndarray) -> np.ndarray:
    """[T,V,3]: the recorded first garment frame held with the body still for SETTLE_FRAMES, then every frame
    of the body motion, the pinned vertices following their recorded positions."""
    state = ClothState(garment[0].copy(), np.zeros_like(garment[0]))
    for _ in range(SETTLE_FRAMES):
        state = sim.step(state, body[0], body[0], garment[0])
    frames = [state.x]
    for t in range(1, len(garment)):
        state = sim.step(state, body[t - 1], body[t], garment[t])
        frames.append(state.x)
    out = np.stack(frames)
    if not np.isfinite(out).all():
        raise FloatingPointError("the re-simulated garment left the finite numbers; lower the effect's strength")
    return out


def _stacked(paths: list[Path]) -> tuple[np.ndarray, np.ndarray]:
    """([T,V,3] vertices, faces of the first) of meshes sharing one topology."""
    meshes = [read_mesh(p) for p in paths]
    return np.stack([m[0] for m in meshes]), meshes[0][1]


def resimulate(reference: Path, out: Path, effect: str, assignments: list[str],
               hands_of: Callable[[int], np.ndarray | None], substeps: int) -> Path:
    """Write capture `out`: the Blender capture `reference` (nothing hidden) with its garment simulated again by
    our simulator with hidden `effect` (module docstring), `substeps` per frame. `hands_of(n_body_vertices)` gives
    the body vertices that do not collide. Written to a temporary folder renamed at the end, so an interrupted run
    leaves no capture."""
    ref = Capture(reference)
    truth = json.loads((reference / "truth.json").read_text())
    effect_json, ours = our_effect(effect, assignments, truth)
    template, _ = read_mesh(reference / "gt" / "template.obj")
    with np.load(reference / "gt" / "regions.npz") as z:
        regions = {k: z[k] for k in z.files}
    pinned = np.zeros(len(template), bool)
    pinned[np.asarray(truth["garment"]["pinned_vertices"], np.int64)] = True
    fps = float(truth["preset"]["fps"])
    tmp = out.with_name(out.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    sim = None
    for name, seq in ref.sequences.items():
        frames = sorted(seq.gt_garment_files)
        garment, faces = _stacked([seq.gt_garment_files[f] for f in frames])
        body, body_faces = _stacked([seq.body_path(f) for f in frames])
        if sim is None:
            sim = true_simulator(template, faces, pinned, body_faces, body.shape[1], hands_of(body.shape[1]), ours,
                                 regions, fps, substeps)
        for frame, x in zip(frames, simulate_sequence(sim, garment, body)):
            write_ply(tmp / name / "gt" / "garment" / f"{frame}.ply", x, faces)
        shutil.copytree(seq.root / "body", tmp / name / "body")
        shutil.copy2(seq.root / "cameras.json", tmp / name / "cameras.json")
    shutil.copytree(reference / "gt", tmp / "gt")
    write_json(tmp / "truth.json", {
        **truth, "generator": f"gg bench diagnose: our simulator (gg_core.physics) on the garment, bodies and pins "
                              f"of {reference.name}",
        "effect": {**effect_json, "ours": {"terms": ours.terms, "region": ours.region,
                                            "region_log_scales": ours.region_logs}},
        "material": {**truth["material"], "ours": {"material": TRUE_MATERIAL, "terms": TRUE_TERMS,
                                                   "substeps": substeps, "settle_frames": SETTLE_FRAMES}},
        "true_parameters": ours.parameters})
    shutil.rmtree(out, ignore_errors=True)
    tmp.rename(out)
    return out
