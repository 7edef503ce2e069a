"""Confirming trials: friction's coefficient chosen on the training rollouts, which a few-frame refit cannot see."""
from __future__ import annotations

import numpy as np

from gg_core.diagnosis.confirm import rollout_choice
from gg_core.diagnosis.library import BY_NAME, Context
from gg_core.physics.cloth import Cloth
from gg_core.physics.contact import BodyCollider
from gg_core.physics.fitting import Observed, rollout_error
from gg_core.physics.forces import make_terms
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
