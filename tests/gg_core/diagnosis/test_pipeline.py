"""The candidates a diagnosis may try, and the accepted model's final fit on every recording."""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from gg_core.diagnosis import pipeline
from gg_core.diagnosis.confirm import Trial
from gg_core.diagnosis.folds import Fold
from gg_core.diagnosis.identify import Profile
from gg_core.diagnosis.library import CANDIDATES, MOVING_AIR
from gg_core.diagnosis.pipeline import usable_candidates
from gg_core.physics.fitting import Observed


def test_rest_length_changes_are_withheld_without_an_unloaded_rest_mesh():
    loaded, why = usable_candidates(rest_given=False)
    unloaded, none_withheld = usable_candidates(rest_given=True)
    assert [c.name for c in unloaded] == [c.name for c in CANDIDATES] and none_withheld == {}
    assert set(why) == {"rest_length_region"} and "--rest-mesh" in why["rest_length_region"]
    assert [c.name for c in loaded] == [c.name for c in CANDIDATES if c.name != "rest_length_region"]
    assert len(loaded) >= 8                      # the library the issue asks for, still without rest lengths


def test_the_accepted_model_is_refitted_on_every_recording_from_its_trials_fits(monkeypatch):
    """pipeline.final_fit: once held-out rollouts have confirmed a candidate, it is refitted on the training AND
    the held-out recordings, in the form its trial kept, from the split's fitted values and the other folds' fits
    in that form, with nothing left to hold out."""
    ctx = SimpleNamespace(region=np.ones(3, bool))
    kept = Trial(["wind"], 0.004, 1.0, 0.005, {"wind.pressure": [0.3, 0.0, 0.1]}, start="without refit",
                 form="moving air", start_coefs=np.array([0.2, 0.1]), region=np.ones(3))
    fold_a = Trial(["wind"], 0.004, 1.0, 0.005, {"wind.pressure": [0.4, 0.0, 0.1]}, form="moving air",
                   region=np.ones(3))
    fold_b = Trial(["wind"], 0.004, 1.0, 0.005, {"wind.pressure": [0.5, 0.0, 0.1]},     # another form: not a start
                   region=np.ones(3))
    fold_c = Trial(["wind"], 0.004, 1.0, 0.005, {"wind.pressure": [0.6, 0.0, 0.1]}, form="moving air",
                   region=np.array([1.0, 0.0, 0.0]))    # fitted on another region (its own scan): not a start
    fold_d = Trial(["wind"], 0.004, 1.0, 0.005, {"wind.pressure": [0.7, 0.0, 0.1]}, form="moving air")  # none
    folds = [Fold(["a", "b"], ["c"], kept, {"wind": kept}), Fold(["b", "c"], ["a"], kept, {"wind": fold_a}),
             Fold(["a", "c"], ["b"], kept, {"wind": fold_b}), Fold(["a"], ["b", "c"], kept, {}),
             Fold(["b"], ["a", "c"], kept, {"wind": fold_c}), Fold(["c"], ["a", "b"], kept, {"wind": fold_d})]
    chosen, model_ctx, fits = pipeline._trialled_model("wind", folds, ctx)
    ((cand, coefs),) = chosen
    assert cand.model is MOVING_AIR.model and coefs.tolist() == [0.2, 0.1] and model_ctx is ctx
    assert fits == [("the split's fit", kept.values), ("the fit without a", fold_a.values)]   # where it starts
    calls = []

    def fake_trial(base, base_fit, chosen, ctx, region, train, heldout, pinned, config, warm, tie):
        calls.append((chosen, region, [o.name for o in train], heldout, warm, tie))
        return Trial([c.name for c, _ in chosen], float("nan"), 1.0, 0.003), "the refitted simulator", "its params"

    def fake_profiles(sim, params, first, recordings, pinned, baseline_l2):
        calls.append((sim, params, first, [o.name for o in recordings], baseline_l2))
        return [Profile("wind.velocity", [0.5, 1.0, 2.0], [0.004, 0.003, 0.0032], [], baseline_l2)]

    monkeypatch.setattr(pipeline, "fitted_trial", fake_trial)
    monkeypatch.setattr(pipeline, "profiles", fake_profiles)
    recordings = [Observed(n, np.zeros((3, 2, 3)), None, 30.0) for n in ("a", "b", "c")]
    final, simulator = pipeline.final_fit(None, chosen, ctx, fits, recordings, None, None, 0.005)   # the baseline's
    assert calls == [(chosen, ctx.region, ["a", "b", "c"], [], fits, pytest.approx(0.05 * 0.005)),
                     ("the refitted simulator", "its params", len(pipeline.BASELINE_FIT), ["a", "b", "c"], 0.005)]
    assert final.train_l2 == 0.003 and simulator == "the refitted simulator"   # what stages.diagnose writes
    assert final.identified["wind.velocity"]["range_factors"] == [pytest.approx(0.5 ** 0.25), None]


@dataclass
class _Region:
    region: np.ndarray | None


def test_a_fold_scans_its_own_training_recordings_for_a_scanned_region(monkeypatch):
    """pipeline._run_fold: a candidate that scans for its region (scan.py) is tried on the region this fold's
    scan of its own training recordings chooses, not fold 0's (chosen on rollouts of recordings this fold holds
    out), and not at all where that scan finds none; a localized region candidate keeps fold 0's region."""
    train = [Observed(n, np.zeros((3, 2, 3)), None, 30.0) for n in ("a", "b")]
    heldout = [Observed("c", np.zeros((3, 2, 3)), None, 30.0)]
    r = SimpleNamespace(batch=None, predicted=None, pooling="the fold's pooling", y="y", nuisance_cols="n")
    base = Trial([], 0.005, float("nan"), 0.004)
    monkeypatch.setattr(pipeline, "fit_baseline", lambda *a: ("sim", "params", {}, [], 0.004))
    monkeypatch.setattr(pipeline, "mean_rollout_error", lambda *a: 0.005)
    monkeypatch.setattr(pipeline, "measure", lambda *a: r)
    monkeypatch.setattr(pipeline, "trial", lambda *a: base)
    monkeypatch.setattr(pipeline, "regressed", lambda *a: np.zeros(1))
    monkeypatch.setattr(pipeline.Candidate, "probes", lambda *a: [])
    monkeypatch.setattr(pipeline, "reference_trials", lambda *a: {})
    monkeypatch.setattr(pipeline.Context, "build", lambda sim, batch, region, predicted: _Region(region))
    tried, scanned = {}, []

    def fake_trial(cand, coefs, sim, ctx, fit_on, held, attached, config, acceleration, lag):
        tried[cand.name] = ctx.region
        return Trial([cand.name], 0.004, 1.0, 0.003)

    def fake_scan(cand, ctx, pooling, predicted, y, nuisance, acceleration, fit_on, attached, train_l2, seed):
        scanned.append((cand.name, pooling, [o.name for o in fit_on], ctx.region, train_l2))
        return SimpleNamespace(region=found)

    monkeypatch.setattr(pipeline, "trial_from_starts", fake_trial)
    monkeypatch.setattr(pipeline, "scan_region", fake_scan)
    req = SimpleNamespace(seed=0, refit_iterations=1, probe_acceleration=0.5, source="ground truth")
    monkeypatch.setattr(pipeline, "fit_config", lambda *a: None)
    split_region, found = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    job = pipeline._FoldJob(req, train, heldout, None, None, None, None, None,
                            ["rest_length_region", "heavy_region"],
                            {"heavy_region": split_region}, None)
    fold = pipeline._run_fold(job, lambda msg: None)
    assert scanned == [("rest_length_region", "the fold's pooling", ["a", "b"], None, 0.004)]   # its baseline's
    assert tried["rest_length_region"] is found and tried["heavy_region"] is split_region
    assert set(fold.trials) == {"rest_length_region", "heavy_region"} and fold.heldout == ["c"]
    found = None                                    # this fold's scan finds no region: the candidate is not tried
    assert set(pipeline._run_fold(job, lambda msg: None).trials) == {"heavy_region"}


def test_a_map_region_candidate_keeps_the_extent_its_training_rollouts_prefer():
    """pipeline.choose_regions: refitted on the activity region's one-ring and grown extents, a region candidate
    keeps the refit that rolls the training recordings out better, unless its values are not cloth (the bounds of
    its range); the context the folds and the final fit use follows. Held-out errors play no part."""
    ring, grown = np.array([1.0, 1.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0, 0.0])
    inside = {"region.stretch_scale": 2.0, "region.bending_scale": 20.0}

    def refits(ring_train: float, grown_train: float, grown_values: dict, grown_inward: float | None = None
               ) -> tuple[dict, dict, dict]:
        trials = {"region_stiffness": Trial(["region_stiffness"], 0.001, 1.0, ring_train, inside, region=ring)}
        other = {"region_stiffness": Trial(["region_stiffness"], 0.009, 1.0, grown_train, grown_values,
                                           region=grown, inward_l2=grown_inward)}
        return trials, other, {"region_stiffness": _Region(ring)}

    sim = SimpleNamespace(cloth=None)
    trials, other, contexts = refits(0.0087, 0.0084, inside)
    choice = pipeline.choose_regions(trials, other, contexts, sim)["region_stiffness"]
    assert choice.chosen == "grown" and choice.train_l2 == {"one ring": 0.0087, "grown": 0.0084}
    assert choice.refused == {}
    assert trials["region_stiffness"] is other["region_stiffness"]          # its held-out error is worse: unseen
    assert np.array_equal(contexts["region_stiffness"].region, grown) and np.array_equal(choice.region, grown)
    trials, other, contexts = refits(0.0087, 0.0090, inside)
    assert pipeline.choose_regions(trials, other, contexts, sim)["region_stiffness"].chosen == "one ring"
    assert np.array_equal(contexts["region_stiffness"].region, ring)
    on_ends = {"region.stretch_scale": 0.1, "region.bending_scale": 201.0}   # both fields on the range's ends ...
    trials, other, contexts = refits(0.0087, 0.0050, on_ends, 0.0060)       # ... and inside rolls out worse
    choice = pipeline.choose_regions(trials, other, contexts, sim)["region_stiffness"]
    assert choice.chosen == "one ring" and list(choice.refused) == ["grown"]    # said why, though it rolled out better
    assert choice.refused["grown"].startswith("the region's refit stopped on the ends of this candidate's range "
                                              "(stretch x0.1, bending x201)")
