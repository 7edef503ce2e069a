"""The diagnosis's baseline: the default model plus internal damping, fitted with global parameters only, and the
fit settings every later refit of the diagnosis shares (trials, folds, the final fit).

Why global parameters only: per-vertex parameters can silently absorb a missing effect (REFERENCE.md section 6);
they come after the diagnosis."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..parallel import Step
from ..physics.cloth import Cloth
from ..physics.contact import BodyCollider
from ..physics.fitting import BehaviorParams, FitConfig, Observed, fit_behavior, free_rollout, rollout_distance
from ..physics.forces import DEFAULT_TERMS, TERMS, make_terms
from ..physics.simulator import ImplicitSimulator
from ..physics.solver import SolverOptions

if TYPE_CHECKING:
    from ..stages.diagnose import DiagnoseRequest

# the baseline: the default model plus internal damping (fabrics are viscoelastic; so is Blender's reference cloth,
# whose springs are damped), fitted with the material and the contact margin
BASELINE_TERMS = DEFAULT_TERMS + ("viscoelastic_damping",)
# Measured and not kept (session 6, with a per-component fit of vector term parameters that was then removed): the
# vertical gravity fitted with the baseline as a nuisance (the rest shape is a loaded frame,
# residuals.nuisance_changes). On the benchmark's `none` s1 it fell to 3.5 m/s^2 and held-out
# improved 8.4 -> 7.9 mm; on gravity s1 it fell to 2.3 m/s^2 and held-out worsened 10.2 -> 15.4 mm (the loss a
# few frames ahead prefers a weak gravity that free rollouts do not).
BASELINE_FIT = ("collision.margin", "viscoelastic_damping.tau")
# Measured and not kept (session 64, /work/data/s64/floorbd.py): bending damping (forces.BendingDamping, Blender
# damps its bending springs too) in the baseline, fitted with it from 0.15 s (the fits a few frames ahead leave it at
# its start; 0.15 rolled out best of 0.01 / 0.05 / 0.15 / 0.45 s). On Blender's `none` skirt s1 / s3 (20 steps, first
# frame as rest, each recording held out once) the training rollouts improved in all six folds (mean -8.6 %), the
# held-out ones did not: s1 arm swing / walk / twist 7.53 / 7.99 / 8.87 -> 5.94 / 6.70 / 10.41 mm, s3 walk / arm
# swing / twist 9.10 / 6.92 / 9.08 -> 10.02 / 7.29 / 8.84 mm (mean 8.25 -> 8.20 mm); with the unloaded garment given
# (s1, arm swing held out) 6.15 -> 5.07 mm. The floor the 30 % target runs into does not move.
# Measured and not kept (session 8): body friction started at zero (its candidate only adds, and the default mu 0.5
# already holds about as much friction as Blender's hidden one: collider friction 60 is Coulomb mu 0.6 against the
# collision impulse, collision.cc). At noise 0 every detectable bench case was named (7 / 7), friction s2 became
# "none" instead of wind (-26 %, a wrong class) and gains rose (wind -35 / -22 %), but at 1.5 mm noise `none` s1
# became a false alarm: mass damping -13.7 % held-out (mu 0.05: -13.2 %), where mu 0.5 answers "none". The
# friction's dissipation is part of what this baseline needs. Our friction cannot show Blender's anyway: it moves
# the hip band by 0.3-1.7 mm (5-14 mm at the hem is that twist swung out) and refits to mu 0.007 / 0.04.
MARGIN_STARTS = (1.0, 3.0)     # baseline fits start from the collision term's default margin times these
INITIAL_LOSS_FACTOR = 0.1      # internal damping starts at a typical fabric's loss factor at 1 Hz


def fit_config(req: DiagnoseRequest, iterations: int) -> FitConfig:
    """Global-parameter fits of the diagnosis (baseline and trials): `iterations` L-BFGS iterations on
    `req.max_samples` observed states, each predicted `req.fit_horizon` frames ahead.

    Why several frames: trials are judged on free rollouts, and a one-frame loss is a poor stand-in for them. On the
    small Blender test capture with nothing hidden, one-frame refits moved the baseline's held-out error from 6.0
    to 6.8 mm and strain stiffening then 'gained' 17 % (a false alarm); predicting 3 frames ahead, the refit kept
    6.0 mm and no candidate gained more than 3 %, while the gravity tilt was still named (19 %). 12 states x 3
    frames cost 1.5x the former 24 x 1."""
    return FitConfig(global_iterations=iterations, local_iterations=0, max_samples=req.max_samples, seed=req.seed,
                     term_params=BASELINE_FIT, horizon=req.fit_horizon, held=held_material(req.source))


def held_material(source: str) -> tuple[str, ...]:
    """Global material values every fit of the diagnosis leaves at the simulator's default: the density, where the
    recordings are registered meshes; none on ground truth.

    Why: weight and inertia both scale with the density, so a motion fixes it only through the few forces that do
    not (contact, wind): it is nearly a free scale of the material, and a flat direction for L-BFGS. On the demo
    capture's registered meshes with a hidden gravity tilt (session 36) the free fit ended at 0.0087 kg/m^2 (its
    bound is 0.0043), a worse minimum than the default's 0.2 held: training rollouts 12.26 vs 12.11 mm, held-out
    9.53 vs 9.67 mm. From the free fit the tilt along the rollout lag, added with nothing refitted, gained 7.6 %
    held-out and pointed 51 degrees off the truth; from the held one it gained 20.5 % and pointed 32 degrees off.
    On Blender's ground-truth gravity s1 (20 steps per frame) holding it fitted a better baseline too (training
    rollouts 13.98 -> 13.52 mm, held-out 14.39 -> 13.30 mm; the tilt added unrefitted reached 6.68 / 6.61 mm).
    Ground truth keeps the free density: with it held (session 37; Blender's captures at 20 steps, fold-mean gain,
    the user's split in brackets, then the figures with it fitted) gravity s1 gained more, -35 % [-54 %] against
    -30 % [-54 %], and air damping s1 -39 % against -35 %, wind s1 about as much (-29 % against -28 %) and `none`
    s1 stayed none, but the parameters came out further off (tilt 19.8 % against 13.8 %, alpha 42 % against 25 %)
    and the stiff patch s1 was missed (none: the localized region's stiffness gained 8.7 % over the folds and
    rolled the walk-less fold's training sequences out worse; fitted, it is named, -15 %)."""
    return ("density",) if source == "registered" else ()


def fit_baseline(req: DiagnoseRequest, train: list[Observed], faces: np.ndarray, body_faces: np.ndarray,
                 attached: np.ndarray, hands: np.ndarray | None, rest: np.ndarray, step: Step
                 ) -> tuple[ImplicitSimulator, BehaviorParams, dict[str, float], list[np.ndarray], float]:
    """The global-parameter fit from each of MARGIN_STARTS, kept by the training sequences' free-rollout error;
    also returns the kept fit's free rollouts of the training sequences (the activity map compares them) and
    their error.

    The teacher-forced loss starts every step from an observed state, so with noisy positions near the body the
    contact margin has several local minima (measured on a capture with 1.5 mm noise: the fit stayed at the 3 mm
    start, held-out 14.8 mm, where from other starts it reaches 12-13 mm, held-out 12.6 mm, as on clean data).
    Free rollouts average the noise out, so they choose between the starts.

    Internal damping is Kelvin-Voigt (forces.ViscoelasticDamping). Measured and not kept: strain-rate damping
    with a fixed coefficient in N s fitted here with the material. On Blender captures with
    nothing hidden it lowered held-out errors by 30 % (11.2 -> 7.8 mm clean, 15.0 -> 10.0 mm at 1.5 mm noise) and
    ended the false alarms there, but its strength is absolute while the material's scale is free: the fit drifts
    along that scale (density to its lower bound) to loss factors of 2-15 and absorbed a gravity tilt (small
    Blender test capture: the tilt trial gained 1 %); hidden air damping was missed on 3 of 4 bench captures
    (the true effect would have gained 24-27 %). Kelvin-Voigt damping scales with the stiffness, so the material's
    scale changes nothing, and its loss factor is limited."""
    collider = BodyCollider(body_faces, train[0].body.shape[1], exclude=hands)
    best, starts = None, {}
    for scale in MARGIN_STARTS:
        cloth = Cloth(rest, faces, pinned=attached, flat=not req.rest_mesh,   # stages.diagnose.rest_state
                      uniform_mass=req.vertex_mass == "uniform")
        terms = make_terms(BASELINE_TERMS, {
            "collision": {"margin": scale * TERMS["collision"].defaults["margin"]},
            "viscoelastic_damping": {"tau": INITIAL_LOSS_FACTOR / (2.0 * np.pi)}})
        sim = ImplicitSimulator(cloth, terms=terms, collider=collider, fps=req.fps, substeps=req.substeps,
                                options=SolverOptions(friction_at_end=True))
        params, _ = fit_behavior(sim, train, fit_config(req, req.baseline_iterations))
        rollouts = [free_rollout(sim, obs) for obs in train]
        error = float(np.mean([rollout_distance(r, obs, attached) for r, obs in zip(rollouts, train)]))
        starts[f"margin_start_{scale:g}x_train_rollout_l2"] = error
        if best is None or error < best[2]:
            best = (sim, params, error, rollouts)
    step("baseline fitted (global parameters only)")
    return best[0], best[1], starts, best[3], best[2]
