"""Profiles of the delivered effect parameters: how precisely every recording's rollouts fix each of them."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from gg_core.diagnosis.confirm import CandidateParams
from gg_core.diagnosis.identify import Profile, profiles
from gg_core.physics.fitting import mean_rollout_error

from diagnosis_helpers import fall, hanging, stiff_half


def test_a_profile_range_is_where_the_rollouts_cross_the_tolerance_in_log_factor():
    grid = [0.25, 0.5, 1.0, 2.0, 4.0]
    p = Profile("wind.pressure", grid, [2.0, 1.04, 1.0, 1.02, 1.07], [], baseline_l2=1.0)   # crossing at 1.05
    low, high = p.range()
    assert low == pytest.approx(0.5 * 0.5 ** (0.01 / 0.96))      # 1.04 -> 2.0 crosses 1.05 just below x0.5
    assert high == pytest.approx(2.0 * 2.0 ** (0.03 / 0.05))      # 1.02 -> 1.07 crosses 1.05 at 60 % of the way
    assert Profile("a", grid, [1.01, 1.0, 1.0, 0.9, 1.04], [], 1.0).range() == (None, None)   # open at both ends
    # the tolerance is the baseline's: a delivered model that rolls out exactly still has a range
    assert Profile("b", grid, [0.5, 0.2, 0.0, 0.01, 0.1], [], 1.0).range()[1] == pytest.approx(2.0 * 2 ** (4 / 9))
    assert p.to_json()["range_factors"] == [low, high]


def test_a_tilt_delivered_at_its_truth_is_fixed_to_a_range_around_it():
    observed, pinned = fall(hanging(2.0))
    sim = hanging(2.0)
    params = CandidateParams(sim.cloth, sim, ("collision.margin", "gravity_offset.delta_g"), None, {})
    before = params.snapshot()
    baseline = mean_rollout_error(hanging(0.0), [observed], pinned)
    (tilt,) = profiles(sim, params, 1, [observed], pinned, baseline)
    assert tilt.parameter == "gravity_offset.delta_g" and tilt.traded_against == []
    errors = dict(zip(tilt.factors, tilt.rollout_l2))
    assert errors[1.0] < 1e-9 and min(errors.values()) == errors[1.0]
    low, high = tilt.range()
    assert 0.71 < low < 1.0 < high < 1.41 and tilt.baseline_l2 == baseline
    # the delivered model is left as it was
    assert all(torch.equal(before[k], v) for k, v in params.snapshot().items())
    assert next(t for t in sim.terms if t.name == "gravity_offset").params["delta_g"].tolist() == [2.0, 0.0, 0.0]
    assert mean_rollout_error(sim, [observed], pinned) == pytest.approx(errors[1.0], abs=1e-12)


def test_a_region_scale_is_profiled_as_a_ratio_to_the_garment_own_field():
    """Each point is the better of the rest held and the region's own value held: a region covering the whole
    garment leaves its ratio to the garment's bending free (the product is what moves it), a half does not."""
    observed, pinned = fall(stiff_half(np.log(30.0))[0])
    sim, params = stiff_half(np.log(30.0))
    (half,) = profiles(sim, params, 1, [observed], pinned, mean_rollout_error(stiff_half(0.0)[0], [observed], pinned))
    assert half.parameter == "region.bending_scale" and half.traded_against == ["material.bending"]
    assert dict(zip(half.factors, half.rollout_l2))[1.0] < 1e-9
    low, high = half.range()
    assert 0.5 < low < 1.0 < high < 2.0                             # the half's ratio shows in the rollouts
    whole = hanging(0.0)
    region = np.ones(whole.cloth.n_vertices)
    truth_bending = float(whole.cloth.material.bending[0]) * 30.0
    params = CandidateParams(whole.cloth, whole, ("collision.margin",), region, {"bending": np.log(30.0)})
    params.apply(whole.cloth)
    whole.refresh()
    assert float(whole.cloth.material.bending[0]) == pytest.approx(truth_bending)
    whole_fall, _ = fall(whole)
    (ratio,) = profiles(whole, params, 1, [whole_fall], pinned, 1e-3)
    assert max(ratio.rollout_l2) < 1e-6 and ratio.range() == (None, None)
