"""The candidate library: enough physically named effects with declared equivalence classes, and each
candidate's force per unit coefficient is exactly what its model change does to the simulator."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from physics_helpers import random_cloth, random_step

from gg_core.diagnosis.library import BY_NAME, CANDIDATES, MOVING_AIR, SYNTH_EFFECT_CLASS, Context, applied
from gg_core.diagnosis.residuals import FrameBatch
from gg_core.physics.forces import DEFAULT_TERMS, Wind, WindPressure, make_terms
from gg_core.physics.simulator import ImplicitSimulator
from gg_core.physics.terms import System
from gg_core.synth.effects import EFFECTS


def test_library_names_at_least_eight_effects_with_equivalence_classes():
    assert len(CANDIDATES) >= 8 and len(BY_NAME) == len(CANDIDATES)
    for cand in CANDIDATES:
        assert cand.equivalence and len(cand.description) > 30 and cand.coefficients
        assert cand.bounds[0] < cand.bounds[1]
    classes = {c.equivalence for c in CANDIDATES}
    assert set(SYNTH_EFFECT_CLASS) == set(EFFECTS)             # every hidden effect of gg synth has an answer
    assert set(SYNTH_EFFECT_CLASS.values()) - {"none"} <= classes


@pytest.mark.parametrize("name", [c.name for c in CANDIDATES if c.needs_region])
def test_a_region_candidate_declares_the_log_range_its_plausibility_allows(context, name):
    """The range a rollout search along the region's log-scales may reach (ModelChange.region_range) is exactly the
    one inside whose ends the plausibility check accepts a scale and beyond which it refuses (one field on an end,
    the others unchanged, is accepted; every field on an end is not: test_verdict)."""
    cand = BY_NAME[name]
    change = cand.model(np.zeros(len(cand.coefficients)), context)
    assert set(change.region_range) == set(change.region)
    for key, (lo, hi) in change.region_range.items():
        assert (lo, hi) == pytest.approx((np.log1p(cand.bounds[0]), np.log1p(cand.bounds[1])))
        for log_scale, accepted in ((lo + 0.01, True), (hi - 0.01, True), (lo - 0.01, False), (hi + 0.01, False)):
            values = {f"region.{key}_scale": float(np.exp(log_scale))}
            assert (cand.implausible(values, context.sim.cloth) is None) == accepted


@pytest.fixture
def context() -> Context:
    cloth = random_cloth()
    rng = np.random.default_rng(3)
    x_prev = cloth.template + rng.normal(0, 0.01, cloth.template.shape)
    step = random_step(cloth, x_prev)
    sim = ImplicitSimulator(cloth, terms=make_terms(DEFAULT_TERMS))
    x_next = x_prev + step.dt * step.v_prev + rng.normal(0, 0.003, x_prev.shape)
    batch = FrameBatch([step], [(None, None)], x_next[None], np.zeros(1, int), np.ones(1, int), ["s"], step.dt)
    region = np.zeros(cloth.n_vertices)
    region[: cloth.n_vertices // 3] = 1.0
    return Context.build(sim, batch, region)


@pytest.mark.parametrize("name", [c.name for c in CANDIDATES])
def test_columns_are_the_force_of_the_model_change(context, name):
    """(force with the candidate at coefficient h e_k - force without) / h == column k, for every coefficient."""
    cand = BY_NAME[name]
    sim = context.sim
    base = context.force(sim.terms)
    columns = cand.columns(context)
    assert columns.shape == (len(cand.coefficients),) + base.shape
    h = 1e-5
    for k in range(len(cand.coefficients)):
        with applied(sim, cand.model(np.eye(len(cand.coefficients))[k] * h, context), context.region):
            changed = Context.build(sim, context.batch, context.region).force(sim.terms)
        assert np.abs(columns[k]).max() > 0
        assert (changed - base) / h == pytest.approx(columns[k], rel=1e-3, abs=1e-6 * np.abs(columns[k]).max())
    assert np.allclose(context.force(sim.terms), base)     # applied() restored the simulator


def test_wind_pressure_term_assembles_its_energy_gradient(context):
    """The force-library term the wind candidate adds: the solver's gradient equals the torch energy's."""
    sim, step = context.sim, context.batch.steps[0]
    term = WindPressure(pressure=(3.0, -1.0, 2.0))
    x = context.batch.x_next[0]
    system = System(sim.num)
    energy = term.assemble(x, step, sim.num, system)
    xt = torch.tensor(x, requires_grad=True)
    torch_energy = term.energy(xt, step.to_torch(), context.rest)
    (grad,) = torch.autograd.grad(torch_energy, xt)
    assert energy == pytest.approx(float(torch_energy.detach()))
    assert np.allclose(system.grad, grad.numpy())
    normals = step.normal_prev
    expected = (sim.num.vertex_area * (normals @ np.array([3.0, -1.0, 2.0])))[:, None] * normals
    assert np.allclose(-system.grad, expected)                 # force A (n.w) n


def test_wind_is_horizontal_and_its_moving_air_form_pushes_a_resting_panel_as_the_pressure_does(context):
    """The candidate's pressure has no vertical part; as moving air (library.MOVING_AIR) the same coefficients
    are air at the speed whose drag on a face-on panel at rest is that pressure: coef |w|^2 = |p| along p."""
    wind = BY_NAME["wind"]
    assert wind.coefficients == ("pressure_x", "pressure_z") and wind.form("moving air") is MOVING_AIR
    assert wind.model(np.array([0.3, -0.4]), context).terms == {"wind_pressure": {"pressure": (0.3, 0.0, -0.4)}}
    change = MOVING_AIR.model(np.array([0.3, -0.4]), context)
    assert change.fit == ("wind.velocity",)
    params = change.terms["wind"]
    velocity = np.array(params["velocity"])
    assert velocity[1] == 0.0 and np.allclose(velocity / np.linalg.norm(velocity), [0.6, 0.0, -0.8])
    assert params["coef"] * velocity @ velocity == pytest.approx(0.5)            # |p| = 0.5 Pa
    sim, step = context.sim, context.batch.steps[0]
    system = System(sim.num)
    Wind(**params).assemble(step.x_prev, step, sim.num, system)      # x = x_prev: the cloth at rest
    n = step.normal_prev
    w_n = n @ velocity
    assert np.allclose(-system.grad, (params["coef"] * sim.num.vertex_area * np.abs(w_n) * w_n)[:, None] * n)


def test_a_wind_that_barely_pushes_cloth_at_rest_is_not_wind(context):
    """Session 52, `gg synth --preset tiny --effect air_drag`: wind as air at 1.5-3.4 cm/s (pushes of 0.02-0.06
    m/s^2 per unit mass) was named over mass damping; the tiny capture with hidden wind refitted 0.76-1.76 m/s^2."""
    wind, cloth = BY_NAME["wind"], context.sim.cloth
    calm = {"material.density": 0.0064, "wind.velocity": [0.0131, 0.0, -0.0080]}          # 0.022 m/s^2
    blowing = {"material.density": 0.0567, "wind.velocity": [0.265, 0.0, 0.040]}          # 0.76 m/s^2
    assert "calm air" in wind.implausible(calm, cloth) and wind.implausible(blowing, cloth) is None
    assert wind.implausible({"material.density": 0.15, "wind_pressure.pressure": [0.01, 0.0, 0.0]}, cloth)
    assert wind.implausible({"material.density": 0.15, "wind_pressure.pressure": [0.2, 0.0, 0.1]}, cloth) is None
