"""Where confirming refits start (regression, probe sizes, rollout lag) and which start and form are kept."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gg_core.diagnosis import starts
from gg_core.diagnosis.confirm import Trial
from gg_core.diagnosis.library import BY_NAME, MOVING_AIR
from gg_core.physics.fitting import Observed


def test_a_candidate_is_refitted_in_each_of_its_forms_and_the_training_rollouts_choose(monkeypatch):
    """starts.trial_in_best_form: the wind's pressure and its moving-air form are both refitted; the one that
    rolls the TRAINING sequences out better is kept, whatever the held-out rollouts say."""
    wind, ctx = BY_NAME["wind"], SimpleNamespace(region=None)

    def fake_trial(base, base_fit, chosen, *args):
        moving = chosen[0][0].model is MOVING_AIR.model
        return Trial(["wind"], heldout_l2=0.009 if moving else 0.005, train_loss=1.0,
                     train_l2=train_l2["moving air" if moving else "pressure"])

    monkeypatch.setattr(starts, "trial", fake_trial)
    train_l2 = {"pressure": 0.008, "moving air": 0.007}
    best = starts.trial_in_best_form(wind, np.array([0.1, 0.0]), None, ctx, [], [], None, None)
    assert best.form == "moving air" and best.heldout_l2 == 0.009
    train_l2 = {"pressure": 0.006, "moving air": 0.007}
    assert starts.trial_in_best_form(wind, np.array([0.1, 0.0]), None, ctx, [], [], None, None).form == ""
    mass = starts.trial_in_best_form(BY_NAME["mass_damping"], np.array([1.0]), None, ctx, [], [], None, None)
    assert mass.form == ""                                       # no forms: its own model only
    assert starts.in_form(wind, "moving air").model is MOVING_AIR.model and starts.in_form(wind, "") is wind


def test_the_rollout_lag_is_the_recordings_mean_horizontal_offset_from_the_free_rollouts_on_free_vertices():
    rng = np.random.default_rng(0)
    pinned = np.array([True, False, False, False])
    observed = [Observed(name, rng.normal(size=(frames, 4, 3)), None, 30.0) for name, frames in (("a", 6), ("b", 4))]
    offsets = {"a": np.array([0.004, 0.05, -0.003]), "b": np.array([0.001, -0.02, 0.006])}
    rollouts = []
    for obs in observed:
        traj = obs.garment[1:] - offsets[obs.name]
        traj[:, pinned] = obs.garment[1:, pinned] + 1.0       # pinned vertices follow their pins, never compared
        traj[0] += 5.0                                         # the first rolled-out frame is the observed start
        rollouts.append(traj)
    lag = starts.rollout_lag(rollouts, observed, pinned)
    # rollout_distance's frames: 4 of sequence a, 2 of b, each with 3 free vertices
    assert lag == pytest.approx((4 * offsets["a"] + 2 * offsets["b"]) / 6 * np.array([1.0, 0.0, 1.0]))
    assert lag[1] == 0.0


def test_horizontal_candidates_also_start_along_the_rollout_lag():
    lag, tilt, wind = np.array([0.003, 0.0, -0.004]), BY_NAME["gravity_offset"], BY_NAME["wind"]
    across = np.array([0.8, 0.6])                                     # the regression's direction, 90 degrees off
    (origin, coefs), = starts.lag_start(tilt, np.array([2.0, 2.0]), lag, across)
    assert origin == "rollout lag" and coefs == pytest.approx([1.2, -1.6])     # (0.6, -0.8) at the probe size
    (_, pressure), = starts.lag_start(wind, np.array([0.1, 0.3]), lag, np.zeros(2))
    assert pressure == pytest.approx([0.12, -0.16])                             # the mean of its probe sizes
    assert starts.lag_start(BY_NAME["mass_damping"], np.array([2.0]), lag, np.ones(1)) == []   # not horizontal
    assert starts.lag_start(tilt, np.array([2.0, 2.0]), np.zeros(3), across) == []
    assert starts.lag_start(wind, np.array([0.1, 0.0]), lag, across) == []   # a force that vanishes here
    # a start already along the lag (within LAG_REDUNDANT_DEG) would repeat its trial; 12 degrees off would not
    turn = np.radians(8.0)
    near = 0.3 * np.array([0.6 * np.cos(turn) + 0.8 * np.sin(turn), -0.8 * np.cos(turn) + 0.6 * np.sin(turn)])
    assert starts.LAG_REDUNDANT_DEG == 10.0 and starts.lag_start(tilt, np.array([2.0, 2.0]), lag, near) == []
    turn = np.radians(12.0)
    off = np.array([0.6 * np.cos(turn) + 0.8 * np.sin(turn), -0.8 * np.cos(turn) + 0.6 * np.sin(turn)])
    assert len(starts.lag_start(tilt, np.array([2.0, 2.0]), lag, off)) == 1


def test_the_start_whose_refit_rolls_the_training_sequences_out_best_is_kept(monkeypatch):
    """starts.trial_from_starts: a tilt the regression found along the wrong direction is also started along the
    rollout lag, and the training rollouts (never the held-out ones) choose; the start is labelled."""
    tilt, ctx = BY_NAME["gravity_offset"], SimpleNamespace(region=None)
    monkeypatch.setattr(type(tilt), "probes", lambda self, ctx, acceleration: [(acceleration, None)] * 2)
    seen = []

    def fake_best_form(cand, coefs, *args):
        seen.append(coefs.tolist())
        along_x = coefs[0] > 0.9 * np.hypot(*coefs)
        return Trial([cand.name], heldout_l2=0.009 if along_x else 0.004, train_loss=1.0,
                     train_l2=0.005 if along_x else 0.006 if np.any(coefs) else 0.007,
                     start="without refit, rollout scale x2")

    monkeypatch.setattr(starts, "trial_in_best_form", fake_best_form)
    lag = np.array([0.004, 0.0, 0.0])
    best = starts.trial_from_starts(tilt, np.array([0.5, 0.5]), None, ctx, [], [], None, None, 1.5, lag)
    assert seen == [[0.5, 0.5], [1.5, 0.0]]
    assert best.start == "rollout lag, then without refit, rollout scale x2" and best.heldout_l2 == 0.009
    seen.clear()
    best = starts.trial_from_starts(tilt, np.array([0.0, 0.0]), None, ctx, [], [], None, None, 1.5, np.zeros(3))
    assert seen == [[0.0, 0.0], [1.5, 1.5]]                 # nothing regressed: the probe sizes, no lag
    assert best.start == "probe, then without refit, rollout scale x2"


def test_a_region_regressed_to_its_largest_change_also_starts_from_the_probe_sizes(monkeypatch):
    """starts.saturated: a region candidate on a bound away from zero (x0.1 softer) is also started from its probe
    sizes; within its bounds, or a term on its zero bound beside a nonzero coefficient, it is not."""
    stiff = BY_NAME["region_stiffness"]
    assert stiff.bounds[0] == -0.9
    assert starts.saturated(stiff, np.array([-0.9, -0.9])) and starts.saturated(stiff, np.array([0.3, 200.0]))
    assert starts.saturated(stiff, np.zeros(2)) and not starts.saturated(stiff, np.array([0.27, 3.8]))
    assert not starts.saturated(BY_NAME["anisotropic_stretch"], np.array([1e4, 0.0]))
    assert starts.saturated(BY_NAME["mass_damping"], np.zeros(1))
    monkeypatch.setattr(type(stiff), "probes", lambda self, ctx, acceleration: [(0.02, None), (150.0, None)])
    seen = []

    def fake_best_form(cand, coefs, *args):
        seen.append(coefs.tolist())
        return Trial([cand.name], 0.004, 1.0, 0.009 if coefs[0] < 0 else 0.007, start="regression")

    monkeypatch.setattr(starts, "trial_in_best_form", fake_best_form)
    best = starts.trial_from_starts(stiff, np.array([-0.9, -0.9]), None, SimpleNamespace(region=None), [], [],
                                       None, None, 0.5, None)
    assert seen == [[-0.9, -0.9], [0.02, 150.0]] and best.start == "probe" and best.train_l2 == 0.007
    seen.clear()
    starts.trial_from_starts(stiff, np.array([0.27, 3.8]), None, SimpleNamespace(region=None), [], [], None, None,
                                0.5, None)
    assert seen == [[0.27, 3.8]]


def test_the_lag_start_is_for_registered_meshes_only():
    measured = SimpleNamespace(lag=np.array([0.004, 0.0, 0.0]))
    assert starts.measured_lag("registered", measured) is measured.lag
    assert starts.measured_lag("gt", measured) is None
    assert starts.lag_start(BY_NAME["gravity_offset"], np.array([2.0, 2.0]), None, np.zeros(2)) == []


def test_a_regressed_start_with_no_other_start_needs_no_probe_forces(monkeypatch):
    def no_probes(self, ctx, acceleration):
        raise AssertionError("probe forces computed for nothing")

    monkeypatch.setattr(type(BY_NAME["mass_damping"]), "probes", no_probes)
    monkeypatch.setattr(starts, "trial_in_best_form",
                        lambda cand, coefs, *args: Trial([cand.name], 0.004, 1.0, 0.005, start="regression"))
    ctx, lag = SimpleNamespace(region=None), np.array([0.004, 0.0, 0.0])
    damping = starts.trial_from_starts(BY_NAME["mass_damping"], np.array([2.0]), None, ctx, [], [], None, None,
                                          0.5, lag)
    tilt = starts.trial_from_starts(BY_NAME["gravity_offset"], np.array([0.5, 0.0]), None, ctx, [], [], None,
                                       None, 0.5, None)          # ground truth: no lag start either
    assert damping.start == tilt.start == "regression"
