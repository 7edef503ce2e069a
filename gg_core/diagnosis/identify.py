"""How precisely the recordings fix the delivered model's effect parameters: a profile of every recording's
free-rollout error over each parameter scaled by PROFILE_FACTORS around the delivered value, and the range of
factors whose rollouts lose less than PROFILE_TOLERANCE of the baseline's error (the model without the effect)
against the delivered model's: changes a diagnosis could not call an effect either.

Why: the selection's bootstrap interval is the one-frame regression's (the coefficient that explains the
residual), not the delivered value's, which the refit and the rollout scale moved, often far outside it (Blender's
stiff patch, seed 1: bending change interval 1.6-7.1, delivered x17.4). A user needs to know which delivered
numbers the recordings pin down and which they barely constrain (session 46, /work/data/s46/profile_probe*.py on
that diagnosis: the region's stretch scale x0.07-x1.1 rolls out within 1 %; its bending x12-x24 within 5.3 %
with the garment's own bending held, but x17-x69 within 4.8 % with the patch's absolute bending held, because
the recordings barely fix the rest of the garment's bending).

A region scale is a ratio to the garment's own material field, so each of its profile points is the better of
two rollouts: the rest of the garment held, and the region's absolute value held (the garment's field divided
by the factor). Term coefficients are profiled with everything else held. Neither re-optimizes the other
parameters, so the ranges are lower bounds on what the recordings leave open: a profile that refitted them at
each point could only roll out better and widen the range.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from ..physics.fitting import Observed, mean_rollout_error
from ..physics.material import MATERIAL_NAMES, from_latent, to_latent
from ..physics.simulator import ImplicitSimulator
from .confirm import CandidateParams
from .library import region_value

PROFILE_FACTORS = (0.25, 0.5, 0.71, 1.41, 2.0, 4.0)   # multiples of the delivered value (1 is the delivered model)
PROFILE_TOLERANCE = 0.05   # of the baseline's error: half the smallest gain the diagnosis accepts (min_gain 10 %)
REGION_FIELDS = {"density": ("density",), "stretch": ("mu", "lam"), "bending": ("bending",), "rest": ()}


@dataclass
class Profile:
    parameter: str               # "region.bending_scale", "mass_damping.alpha", ...
    factors: list[float]         # multiples of the delivered value, ascending, 1 included
    rollout_l2: list[float]      # every recording's mean free-rollout error at each factor (m)
    traded_against: list[str]    # global material fields held at the region's absolute value in the second rollouts
    baseline_l2: float           # the same recordings' rollout error without the effect
    tolerance: float = PROFILE_TOLERANCE

    def range(self) -> tuple[float | None, float | None]:
        """The factors, either side of 1, where the rollout error crosses the delivered model's plus tolerance x
        the baseline's, interpolated in log factor; None where it stays below to the end of the grid (open)."""
        f, e = np.log(self.factors), np.asarray(self.rollout_l2)
        at = int(np.flatnonzero(f == 0.0)[0])
        limit = e[at] + self.tolerance * self.baseline_l2

        def crossing(order: range) -> float | None:
            prev = at
            for k in order:
                if e[k] > limit:
                    t = (limit - e[prev]) / (e[k] - e[prev])
                    return float(np.exp(f[prev] + t * (f[k] - f[prev])))
                prev = k
            return None

        return crossing(range(at - 1, -1, -1)), crossing(range(at + 1, len(f)))

    def to_json(self) -> dict:
        low, high = self.range()
        return {"factors": self.factors, "rollout_l2": self.rollout_l2, "baseline_l2": self.baseline_l2,
                "tolerance": self.tolerance, "range_factors": [low, high], "traded_against": self.traded_against,
                "meaning": "multiples of the delivered value whose rollouts of every recording lose less than the "
                           "tolerance x the baseline's error against the delivered model's (null: still less at the "
                           "grid's end); the other parameters held, so the recordings leave at least this range open"}


def profiles(sim: ImplicitSimulator, params: CandidateParams, first: int, recordings: list[Observed],
             pinned: np.ndarray, baseline_l2: float, factors: tuple[float, ...] = PROFILE_FACTORS) -> list[Profile]:
    """A Profile of each effect parameter of `params` (applied to `sim`): its term coefficients from index `first`
    on and its region's log-scales; `baseline_l2`: the recordings' rollout error without the effect. Leaves
    `params` as it found them."""
    delivered = params.snapshot()
    grid = sorted({1.0, *factors})
    base = mean_rollout_error(sim, recordings, pinned)
    out = []

    def rollout(change: Callable[..., None], *args: object) -> float:
        params.restore(sim, delivered)
        with torch.no_grad():
            change(params, *args)
        params.apply(sim.cloth)
        sim.refresh()
        return mean_rollout_error(sim, recordings, pinned)

    for i in range(first, len(params.term_refs)):
        term, key, _ = params.term_refs[i]
        errors = [base if f == 1.0 else rollout(_scale_term, i, f) for f in grid]
        out.append(Profile(f"{term.name}.{key}", grid, errors, [], baseline_l2))
    for j, key in enumerate(params.region_keys):
        fields = [n for n in REGION_FIELDS[key] if n not in params.held]
        errors = []
        for f in grid:
            if f == 1.0:
                errors.append(base)
                continue
            ratio = rollout(_scale_region, j, f, [])
            absolute = rollout(_scale_region, j, f, fields) if fields else ratio
            errors.append(min(ratio, absolute))
        out.append(Profile(region_value(key), grid, errors, [f"material.{n}" for n in fields], baseline_l2))
    params.restore(sim, delivered)
    return out


def _scale_term(params: CandidateParams, i: int, factor: float) -> None:
    params.term_s[i] += np.log(factor)


def _scale_region(params: CandidateParams, j: int, factor: float, fields: list[str]) -> None:
    """Region scale j times `factor`, and the garment's material `fields` divided by it (the region's own values
    of those fields unchanged)."""
    params.region_s[j] += np.log(factor)
    for n in fields:
        k = MATERIAL_NAMES.index(n)
        params.global_z[k] = to_latent(n, from_latent(n, params.global_z[k]) / factor)
