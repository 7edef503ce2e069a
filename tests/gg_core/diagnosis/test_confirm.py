"""Confirming trials: coefficients chosen on the training rollouts, which a few-frame refit barely sees (friction's
grid, every other candidate's scale)."""
from __future__ import annotations

import numpy as np
import pytest

from gg_core.diagnosis.confirm import CandidateParams, golden_section, rollout_choice, rollout_scale
from gg_core.diagnosis.library import BY_NAME, Context
from gg_core.physics.cloth import Cloth
from gg_core.physics.contact import BodyCollider
from gg_core.physics.fitting import Observed, rollout_error
from gg_core.physics.forces import DEFAULT_TERMS, make_terms
from gg_core.physics.simulator import ClothState, ImplicitSimulator

from physics_helpers import sheet, uv_sphere


def _sim(mu: float) -> ImplicitSimulator:
    v, f = sheet(10, 10, 0.3, 0.3, y=0.253)
    bv, bf = uv_sphere(0.25, 16, 32)
    terms = make_terms(params={"body_friction": {"mu": mu}})
    return ImplicitSimulator(Cloth(v, f), terms=terms, collider=BodyCollider(bf, len(bv)))


def _sliding_body(frames: int = 14) -> np.ndarray:
    """The sphere, with the sheet lying on its top, pulled sideways ever faster: friction drags the sheet along."""
    bv = uv_sphere(0.25, 16, 32)[0]
    t = np.arange(frames) / 30.0
    return bv[None] + (1.5 * t * t)[:, None, None] * np.array([1.0, 0.0, 0.0])


def test_friction_is_chosen_on_training_rollouts():
    body = _sliding_body()
    truth = _sim(1.5)
    rest = truth.cloth.template
    observed = Observed("pull", truth.rollout(ClothState(rest.copy(), np.zeros_like(rest)), body), body, 30.0)
    pinned = np.zeros(len(rest), bool)
    sim = _sim(0.5)
    before = rollout_error(sim, observed, pinned)
    error, label = rollout_choice(sim, BY_NAME["body_friction"], Context(sim, None, None, None), [observed], pinned,
                                  before)
    friction = next(t for t in sim.terms if t.name == "body_friction")
    assert float(friction.params["mu"]) == 1.5                   # 0.5 + 1.0 of the grid: the truth
    assert label == "rollout grid (mu + 1)"
    assert error == rollout_error(sim, observed, pinned) < 0.2 * before
    # with the truth already there the grid finds nothing better and leaves the coefficient alone
    error, label = rollout_choice(truth, BY_NAME["body_friction"], Context(truth, None, None, None), [observed],
                                  pinned, rollout_error(truth, observed, pinned))
    assert label == "regression"
    assert float(next(t for t in truth.terms if t.name == "body_friction").params["mu"]) == 1.5


def _hanging(tilt: float) -> ImplicitSimulator:
    """A sheet pinned along one edge, falling under gravity tilted sideways by `tilt` m/s^2."""
    v, f = sheet(6, 6, 0.3, 0.3)
    pinned = np.abs(v[:, 2] + 0.15) < 1e-9
    terms = make_terms([*DEFAULT_TERMS, "gravity_offset"], {"gravity_offset": {"delta_g": (tilt, 0.0, 0.0)}})
    return ImplicitSimulator(Cloth(v, f, pinned=pinned), terms=terms)


def test_golden_section_finds_the_minimum_of_a_unimodal_function():
    calls = []

    def f(x: float) -> float:
        calls.append(x)
        return (x - 0.7) ** 2 + 1.0

    x, fx = golden_section(f, -1.0, 2.0, 12)
    assert len(calls) == 12
    assert x == pytest.approx(0.7, abs=0.02) and fx == pytest.approx(1.0, abs=1e-3)
    assert min(calls) >= -1.0 and max(calls) <= 2.0


def test_a_tilt_the_refit_underestimates_is_scaled_on_training_rollouts():
    truth = _hanging(2.0)
    rest = truth.cloth.template
    observed = Observed("fall", truth.rollout(ClothState(rest.copy(), np.zeros_like(rest)), None, 12),
                        None, 30.0)
    pinned = truth.cloth.pinned
    sim = _hanging(0.5)
    params = CandidateParams(sim.cloth, sim, ("collision.margin", "gravity_offset.delta_g"), None, {})
    before = rollout_error(sim, observed, pinned)
    error, label = rollout_scale(sim, params, 1, [observed], pinned, before)
    tilt = next(t for t in sim.terms if t.name == "gravity_offset").params["delta_g"].tolist()
    assert tilt[0] == pytest.approx(2.0, rel=0.05) and tilt[1:] == [0.0, 0.0]
    assert label.startswith("regression, rollout scale x4")
    assert error == pytest.approx(rollout_error(sim, observed, pinned)) and error < 0.1 * before
    assert next(t for t in sim.terms if t.name == "collision").params["margin"] == pytest.approx(
        next(t for t in truth.terms if t.name == "collision").params["margin"])     # only the candidate's scaled
    # at the truth no factor rolls out better: the refit's value stays
    params = CandidateParams(truth.cloth, truth, ("collision.margin", "gravity_offset.delta_g"), None, {})
    exact = rollout_error(truth, observed, pinned)
    assert rollout_scale(truth, params, 1, [observed], pinned, exact) == (exact, "regression")
    assert truth.terms[-1].params["delta_g"].tolist() == [2.0, 0.0, 0.0]
    assert rollout_scale(truth, params, 2, [observed], pinned, exact) == (exact, "regression")   # nothing to scale
