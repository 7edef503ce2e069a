"""Confirming trials: coefficients chosen on the training rollouts, which a few-frame refit barely sees (friction's
grid, every other candidate's scale)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from gg_core.diagnosis import confirm
from gg_core.diagnosis.confirm import (INWARD, CandidateParams, at_values, central_fit, fitted_trial, golden_section,
                                      inward_rollout, refit_or_scale, rollout_choice, rollout_scale, scale_label)
from gg_core.diagnosis.library import BY_NAME, Context
from gg_core.physics.cloth import Cloth
from gg_core.physics.contact import BodyCollider
from gg_core.physics.fitting import FitConfig, Observed, rollout_error
from gg_core.physics.forces import DEFAULT_TERMS, make_terms
from gg_core.physics.material import MATERIAL_NAMES, Material, to_latent
from gg_core.physics.simulator import ClothState, ImplicitSimulator

from diagnosis_helpers import fall, hanging, stiff_half
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
    truth = hanging(2.0)
    observed, pinned = fall(truth)
    sim = hanging(0.5)
    params = CandidateParams(sim.cloth, sim, ("collision.margin", "gravity_offset.delta_g"), None, {})
    before = rollout_error(sim, observed, pinned)
    error, factor = rollout_scale(sim, params, 1, [observed], pinned, before)
    tilt = next(t for t in sim.terms if t.name == "gravity_offset").params["delta_g"].tolist()
    assert tilt[0] == pytest.approx(2.0, rel=0.05) and tilt[1:] == [0.0, 0.0]
    assert factor == pytest.approx(4.0, rel=0.05)
    assert scale_label(factor).startswith(", rollout scale x4")
    assert error == pytest.approx(rollout_error(sim, observed, pinned)) and error < 0.1 * before
    assert next(t for t in sim.terms if t.name == "collision").params["margin"] == pytest.approx(
        next(t for t in truth.terms if t.name == "collision").params["margin"])     # only the candidate's scaled
    # at the truth no factor rolls out better: the refit's value stays
    params = CandidateParams(truth.cloth, truth, ("collision.margin", "gravity_offset.delta_g"), None, {})
    exact = rollout_error(truth, observed, pinned)
    assert rollout_scale(truth, params, 1, [observed], pinned, exact) == (exact, 1.0)
    assert truth.terms[-1].params["delta_g"].tolist() == [2.0, 0.0, 0.0]
    assert rollout_scale(truth, params, 2, [observed], pinned, exact) == (exact, 1.0)   # nothing to scale
    assert scale_label(1.0) == ""


def _refit_to(monkeypatch: pytest.MonkeyPatch, densities: list[float]) -> list[float]:
    """Replace the trials' refit by one that sets the garment's density to the next of `densities` (what an
    L-BFGS refit that moves the material would do); returns the tilt each call started from."""
    starts = []

    def fake(sim, params, train, trainable, config):
        if trainable:
            starts.append(float(params.term_refs[-1][0].params["delta_g"][0]))
            with torch.no_grad():
                params.global_z[MATERIAL_NAMES.index("density")] = to_latent("density", densities[len(starts) - 1])
        params.apply(sim.cloth)
        sim.refresh()
        return float(len(starts))

    monkeypatch.setattr(confirm, "refit", fake)
    return starts


def _start(density: float) -> tuple[ImplicitSimulator, CandidateParams]:
    """The tilt's trial from a quarter of the truth's 2 m/s^2 on a garment of the given density."""
    sim = hanging(0.5)
    sim.cloth.material = Material.uniform(sim.cloth.n_vertices, density=density)
    params = CandidateParams(sim.cloth, sim, ("collision.margin", "gravity_offset.delta_g"), None, {})
    params.apply(sim.cloth)
    sim.refresh()
    return sim, params


def test_a_refit_that_spoils_the_rollouts_loses_to_the_unrefitted_start_and_is_restarted_from_it(monkeypatch):
    observed, pinned = fall(hanging(2.0))
    true_density = float(hanging(2.0).cloth.material.density[0])
    # the refit from the regression's start moves the density 4x off; restarted from the scaled start, to the truth
    starts = _refit_to(monkeypatch, [4.0 * true_density, true_density])
    sim, params = _start(1.3 * true_density)
    loss, error, label = refit_or_scale(sim, params, 1, [observed], pinned, FitConfig())
    assert starts[0] == pytest.approx(0.5) and starts[1] == pytest.approx(2.0, rel=0.1)   # the scaled start
    assert label.startswith("without refit, rollout scale x") and ", then refit" in label
    assert float(sim.cloth.material.density[0]) == pytest.approx(true_density)
    assert params.values()["gravity_offset.delta_g"][0] == pytest.approx(2.0, rel=0.05)
    assert error == pytest.approx(rollout_error(sim, observed, pinned)) and error < 0.05 * rollout_error(
        _start(1.3 * true_density)[0], observed, pinned)
    assert loss == 2.0                                    # the loss of the refit that was kept


def test_the_unrefitted_start_is_kept_where_every_refit_spoils_the_rollouts(monkeypatch):
    observed, pinned = fall(hanging(2.0))
    true_density = float(hanging(2.0).cloth.material.density[0])
    starts = _refit_to(monkeypatch, [4.0 * true_density, 4.0 * true_density])
    sim, params = _start(true_density)
    loss, error, label = refit_or_scale(sim, params, 1, [observed], pinned, FitConfig())
    assert len(starts) == 2 and label.startswith("without refit, rollout scale x4") and "then refit" not in label
    assert float(sim.cloth.material.density[0]) == pytest.approx(true_density)     # the material left alone
    assert params.values()["gravity_offset.delta_g"][0] == pytest.approx(2.0, rel=0.05)
    assert error == pytest.approx(rollout_error(sim, observed, pinned))
    assert loss == 2.0        # evaluated at the kept parameters (the fake counts its calls: no iteration, no start)


def test_a_refit_that_rolls_out_as_well_is_kept_without_a_restart(monkeypatch):
    observed, pinned = fall(hanging(2.0))
    true_density = float(hanging(2.0).cloth.material.density[0])
    starts = _refit_to(monkeypatch, [true_density])
    sim, params = _start(3.0 * true_density)
    _, error, label = refit_or_scale(sim, params, 1, [observed], pinned, FitConfig())
    assert len(starts) == 1 and label.startswith("regression, rollout scale x4")
    assert float(sim.cloth.material.density[0]) == pytest.approx(true_density)
    assert error == pytest.approx(rollout_error(sim, observed, pinned))


def test_a_zero_coefficient_is_only_refitted(monkeypatch):
    """Without a coefficient the unrefitted start is the baseline itself: nothing to scale, no restart."""
    observed, pinned = fall(hanging(2.0))
    true_density = float(hanging(2.0).cloth.material.density[0])
    starts = _refit_to(monkeypatch, [4.0 * true_density])
    sim = hanging(0.0)
    params = CandidateParams(sim.cloth, sim, ("collision.margin", "gravity_offset.delta_g"), None, {})
    loss, error, label = refit_or_scale(sim, params, 1, [observed], pinned, FitConfig())
    assert starts == [0.0] and label == "regression" and loss == 1.0
    assert float(sim.cloth.material.density[0]) == pytest.approx(4.0 * true_density)
    assert error == pytest.approx(rollout_error(sim, observed, pinned))


def test_a_region_start_the_refit_spoils_is_kept_without_a_repeated_refit(monkeypatch):
    """A region candidate's start (its regression scales) is the unrefitted option too; with nothing to scale,
    the refit is not repeated from it."""
    observed, pinned = fall(stiff_half(np.log(30.0))[0])
    calls = []

    def spoiling_refit(sim, params, train, trainable, config):
        if trainable:
            calls.append(float(params.region_s[0]))
            with torch.no_grad():
                params.region_s[0] = np.log(0.1)     # what the stiff patch's walk-less fold did (session 41)
        params.apply(sim.cloth)
        sim.refresh()
        return float(len(calls))

    monkeypatch.setattr(confirm, "refit", spoiling_refit)
    sim, params = stiff_half(np.log(30.0))
    loss, error, label = refit_or_scale(sim, params, 1, [observed], pinned, FitConfig())
    assert calls == [pytest.approx(np.log(30.0))] and label == "without refit"
    assert params.values()["region.bending_scale"] == pytest.approx(30.0)
    assert error == pytest.approx(rollout_error(sim, observed, pinned)) and error < 1e-9
    # without a region scale the start is the baseline: only the refit, its softer region scaled as close to the
    # truth as a power of it gets (x0.1 ** 0.25)
    calls.clear()
    sim, params = stiff_half(0.0)
    _, _, label = refit_or_scale(sim, params, 1, [observed], pinned, FitConfig())
    assert calls == [0.0] and label.startswith("regression, rollout scale x0.25")
    assert params.values()["region.bending_scale"] == pytest.approx(0.1 ** 0.25, rel=0.03)


def test_a_region_the_refit_left_too_soft_is_scaled_on_training_rollouts_within_its_range():
    """A refit that reached bending x3 on a region whose truth is x30: raised to the power that rolls the training
    sequences out best, x30 where its range allows it, its range's end where not."""
    observed, pinned = fall(stiff_half(np.log(30.0))[0])
    for top, expected, gain in ((200.0, 30.0, 0.1), (10.0, 11.0, 0.7)):
        sim, params = stiff_half(np.log(3.0), {"bending": (np.log(0.1), np.log1p(top))})
        before = rollout_error(sim, observed, pinned)
        error, factor = rollout_scale(sim, params, 1, [observed], pinned, before)
        assert params.values()["region.bending_scale"] == pytest.approx(expected, rel=0.1)
        assert error == pytest.approx(rollout_error(sim, observed, pinned)) and error < gain * before
        assert factor > 2.0 and params.values()["material.bending"] == pytest.approx(
            float(hanging(0.0).cloth.material.bending.mean()))   # only the region's scale moved


def test_a_region_refit_stopped_on_its_ranges_end_is_rolled_out_inside_it():
    """confirm.inward_rollout: every region scale on an end of its range is moved INWARD times inside and the
    training recordings rolled out there, the refit's values then restored; a scale inside the range: no rollout."""
    observed, pinned = fall(stiff_half(np.log(30.0))[0])
    sim, params = stiff_half(np.log(30.0), {"bending": (np.log(0.1), np.log(30.0))})   # the truth, on the top end
    at_end = rollout_error(sim, observed, pinned)
    inward = inward_rollout(sim, params, [observed], pinned)
    assert params.values()["region.bending_scale"] == pytest.approx(30.0)
    assert rollout_error(sim, observed, pinned) == pytest.approx(at_end)          # restored, applied
    inside, _ = stiff_half(np.log(30.0 / INWARD))
    assert inward == pytest.approx(rollout_error(inside, observed, pinned)) and inward > at_end
    sim, params = stiff_half(np.log(0.1), {"bending": (np.log(0.1), np.log(30.0))})     # the bottom end: moved up
    inside, _ = stiff_half(np.log(0.1 * INWARD))
    assert inward_rollout(sim, params, [observed], pinned) == pytest.approx(rollout_error(inside, observed, pinned))
    sim, params = stiff_half(np.log(3.0), {"bending": (np.log(0.1), np.log(30.0))})
    assert inward_rollout(sim, params, [observed], pinned) is None


def _split_fit(density: float, tilt: float = 2.0) -> dict[str, object]:
    """Trial.values of a tilt trial that found `tilt` m/s^2 (the truth's 2) on a garment of the given density."""
    sim = hanging(tilt)
    sim.cloth.material = Material.uniform(sim.cloth.n_vertices, density=density)
    return CandidateParams(sim.cloth, sim, ("collision.margin", "gravity_offset.delta_g"), None, {}).values()


def _final_fit(*warm: dict[str, object], tie: float = 0.0):
    """fitted_trial of the tilt on a baseline without one, from its coefficients (0.5, 0) and the earlier fits
    `warm` (the split's first), those rolling out within `tie` (m) of the best tied."""
    v, f = sheet(6, 6, 0.3, 0.3)
    base = ImplicitSimulator(Cloth(v, f, pinned=np.abs(v[:, 2] + 0.15) < 1e-9), terms=make_terms(DEFAULT_TERMS))
    observed, pinned = fall(hanging(2.0))
    return fitted_trial(base, ("collision.margin",), [(BY_NAME["gravity_offset"], np.array([0.5, 0.0]))], None,
                        None, [observed], [], pinned, FitConfig(),
                        [(f"fit {i}", values) for i, values in enumerate(warm)], tie)


def test_a_warm_start_keeps_the_split_fit_where_its_refit_rolls_out_worse(monkeypatch):
    """pipeline.final_fit starts from the split's fitted values (at_values), not the candidate's start: a refit
    that spoils the material loses to them."""
    true_density = float(hanging(2.0).cloth.material.density[0])
    starts = _refit_to(monkeypatch, [4.0 * true_density])
    trial, sim, params = _final_fit(_split_fit(true_density))
    assert starts == [pytest.approx(2.0)]                       # the refit started at the split's tilt, not at 0.5
    assert trial.start == "fit 0" and trial.values["gravity_offset.delta_g"] == [2.0, 0.0, 0.0]
    assert float(sim.cloth.material.density[0]) == pytest.approx(true_density)
    assert trial.train_l2 < 1e-6 and trial.train_loss == 1.0      # evaluated without an iteration at the kept fit
    assert params.values() == trial.values                      # the delivered parameters (identify profiles them)


def test_a_warm_start_keeps_the_refit_where_it_rolls_out_better(monkeypatch):
    true_density = float(hanging(2.0).cloth.material.density[0])
    _refit_to(monkeypatch, [true_density])
    trial, sim, params = _final_fit(_split_fit(1.5 * true_density))
    assert trial.start == "fit 0, refitted"
    assert trial.values["material.density"] == pytest.approx(true_density)
    assert float(sim.cloth.material.density[0]) == pytest.approx(true_density) and trial.train_l2 < 1e-6
    assert params.values() == trial.values


def test_the_final_fit_starts_from_the_earlier_fit_that_rolls_out_best(monkeypatch):
    """pipeline.final_fit also starts from the other folds' fits (confirm.best_fit): where the split's tilt is half
    the truth's and a fold found it, the fold's fit is delivered, and the refit that spoils the material is not."""
    true_density = float(hanging(2.0).cloth.material.density[0])
    starts = _refit_to(monkeypatch, [4.0 * true_density])
    trial, sim, _ = _final_fit(_split_fit(true_density, 1.0), _split_fit(true_density, 3.0),
                            _split_fit(true_density))
    assert trial.start == "fit 2" and starts == [pytest.approx(2.0)]   # refitted once, from the best fit only
    assert trial.values["gravity_offset.delta_g"] == [2.0, 0.0, 0.0] and trial.train_l2 < 1e-6
    assert set(trial.compared) == {"fit 0", "fit 1", "fit 2"} and min(trial.compared.values()) == trial.train_l2
    assert trial.compared["fit 0"] > 1e-4 and trial.compared["fit 1"] > 1e-4
    assert float(sim.cloth.material.density[0]) == pytest.approx(true_density)


def test_among_fits_the_recordings_do_not_tell_apart_the_final_fit_starts_from_the_central_one(monkeypatch):
    """confirm.best_fit: where three fits roll out within the tie, the one between the others is delivered, not
    the one that rolls out a hair better (the truth's 2 here, so the tie is far wider than a real one)."""
    true_density = float(hanging(2.0).cloth.material.density[0])
    fits = (_split_fit(true_density, 1.0), _split_fit(true_density, 2.0), _split_fit(true_density, 1.4))
    _refit_to(monkeypatch, [4.0 * true_density])
    best, _, _ = _final_fit(*fits)
    assert best.start == "fit 1" and best.values["gravity_offset.delta_g"] == [2.0, 0.0, 0.0]
    _refit_to(monkeypatch, [4.0 * true_density])
    tied, _, _ = _final_fit(*fits, tie=1.0)
    assert tied.start == "fit 2 (the central one of 3 fits rolling out within 1000.00 mm)"
    assert tied.values["gravity_offset.delta_g"] == pytest.approx([1.4, 0.0, 0.0])
    assert tied.train_l2 == tied.compared["fit 2"] > best.train_l2   # kept: the refit spoils the material
    _refit_to(monkeypatch, [4.0 * true_density])
    narrow = max(best.compared.values()) - best.train_l2   # the worst fit outside: at most two tie, the best wins
    assert _final_fit(*fits, tie=0.5 * narrow)[0].start == "fit 1"


def test_the_central_fit_weighs_scales_in_log_and_vectors_by_their_length():
    errors = {"a": 3.0, "b": 1.0, "c": 2.0}
    alpha = {"a": {"mass_damping.alpha": 10.3}, "b": {"mass_damping.alpha": 15.4}, "c": {"mass_damping.alpha": 9.5}}
    assert central_fit(alpha, ("mass_damping.alpha",), errors) == "a"
    tilt = {k: {"gravity_offset.delta_g": v} for k, v in
            (("a", [1.55, 0.0, -0.06]), ("b", [2.32, 0.0, -0.05]), ("c", [2.12, 0.0, 0.06]))}
    assert central_fit(tilt, ("gravity_offset.delta_g",), errors) == "c"
    # bending x4 .. x160 in log: x19 is between; the stretch scales alone would pick b
    region = {k: {"region.stretch_scale": s, "region.bending_scale": b} for k, s, b in
              (("a", 1.01, 4.3), ("b", 1.01, 160.0), ("c", 0.37, 19.0))}
    assert central_fit(region, ("region.stretch_scale", "region.bending_scale"), errors) == "c"
    assert central_fit(region, ("region.stretch_scale",), errors) == "b"   # a and b tie: the lower error


def test_at_values_sets_the_material_the_terms_and_the_region_scales():
    sim = hanging(0.5)
    values = {**_split_fit(0.3), "region.stretch_scale": 0.5, "region.bending_scale": 4.0}
    logs = at_values(sim.cloth, sim, {"stretch": 0.0, "bending": 0.0}, values)
    assert logs == {"stretch": pytest.approx(np.log(0.5)), "bending": pytest.approx(np.log(4.0))}
    assert torch.allclose(sim.cloth.material.density, torch.full((sim.cloth.n_vertices,), 0.3, dtype=torch.float64))
    assert next(t for t in sim.terms if t.name == "gravity_offset").params["delta_g"].tolist() == [2.0, 0.0, 0.0]
