"""What a diagnosis found (Result) and its report's JSON (Result.summary: P/reports/diagnose.json)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..jobs import Progress
from ..physics.fitting import Observed
from ..physics.simulator import ImplicitSimulator
from .confirm import Trial
from .features import FEATURES
from .folds import CrossValidation
from .library import BY_NAME
from .localize import Localization
from .residuals import FrameBatch
from .scan import ScanResult
from .selection import Selection


ONE_RING, GROWN = "one ring", "grown"   # the activity region's two extents (localize.activity_regions)


@dataclass
class RegionChoice:
    """A map-region candidate refitted on both extents of the activity region: the training rollout error of each
    refit, the one kept and why a refit was refused as not cloth physics (pipeline.choose_regions): the kept one
    need not roll out better."""
    region: np.ndarray
    train_l2: dict[str, float]         # ONE_RING / GROWN -> training rollout error of the refit on that extent
    chosen: str
    refused: dict[str, str] = field(default_factory=dict)   # ONE_RING / GROWN -> verdict.implausible's reason


@dataclass
class Result:
    localization: Localization
    selection: Selection
    trials: dict[str, Trial]
    accepted: list[str]
    null: Trial                        # what trials are judged against (verdict.judge_reference)
    null_refit: Trial                  # the baseline refitted with no candidate, as each trial is
    heldout_after: float
    baseline: dict[str, float]
    nuisance: dict[str, float]
    batch: FrameBatch
    unphysical: dict[str, str]         # trial name -> why its refitted values are not cloth (never accepted)
    progress: Progress
    cv: CrossValidation                # the folds: the user's split, then each training sequence held out
    reference: dict[str, Trial] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    scans: dict[str, ScanResult] = field(default_factory=dict)   # region candidates that found their own region
    withheld: dict[str, str] = field(default_factory=dict)       # candidates not tried on these data, and why
    rollouts_first: str | None = None  # the rollouts' first choice where the residual named another (tie-break)
    unseparated: list[str] = field(default_factory=list)   # unresolved rivals of the one accepted (verdict.unresolved)
    final: Trial | None = None         # the accepted model refitted on every recording (pipeline.final_fit) ...
    final_sim: ImplicitSimulator | None = None   # ... and its simulator
    closest: dict | None = None        # where nothing was accepted, the candidate nearest to it (verdict.closest)
    region_choices: dict[str, RegionChoice] = field(default_factory=dict)   # refitted on both activity extents
    fold_stops: dict[str, str] = field(default_factory=dict)   # a fold's refit stopped on its range's ends, and why

    def region_of(self, name: str) -> np.ndarray | None:
        """The region candidate `name` acted on: its scan's, the extent its training rollouts chose, or the
        localization's."""
        if name in self.scans:
            return self.scans[name].region
        return self.region_choices[name].region if name in self.region_choices else self.localization.region

    @property
    def heldout_before(self) -> float:
        return self.null.heldout_l2

    def gain(self, t: Trial) -> float:
        return 1.0 - t.heldout_l2 / self.heldout_before

    def train_gain(self, t: Trial) -> float:
        return 1.0 - t.train_l2 / self.null.train_l2

    def trial_summary(self, t: Trial) -> dict:
        return {"heldout_l2": t.heldout_l2, "heldout_gain": self.gain(t), "train_rollout_gain": self.train_gain(t),
                "refit": t.values, "form": t.form or None}

    def frame_curve(self, train: list[Observed]) -> dict:
        loc = self.localization
        out = {"unit": "m/s^2", "meaning": "mean over garment patches of the one-frame position error of the "
               "fitted simulator over the frame time squared, after re-adjusting its global parameters",
               "feature": {"name": loc.step_feature[0], "spearman": loc.step_feature[1]}, "sequences": {}}
        for k, obs in enumerate(train):
            idx = self.batch.sequence == k
            out["sequences"][obs.name] = {"frames": (self.batch.frame[idx] + 1).tolist(),
                                          "residual": loc.step_curve[idx].tolist()}
        return out

    def cross_validated(self, name: str) -> dict | None:
        """The candidate's mean gains over the folds that trialled it (folds.py), where there was more than one."""
        n_folds = self.cv.count(name) if name in self.cv.folds[0].trials else 0
        if n_folds < 2:
            return None
        held, train = self.cv.mean_gains(name)
        return {"heldout_gain": held, "train_rollout_gain": train, "folds": n_folds,
                "complete": self.cv.complete(name), "refit_range": self.cv.refit_ranges(name)}

    def effects(self) -> list[dict]:
        sel = self.selection
        order = {n: i for i, n in enumerate(sel.order)}
        names = sorted(sel.explained, key=lambda n: (order.get(n, len(order)), -np.nan_to_num(sel.inclusion[n]),
                                                     -sel.explained[n]))
        out = []
        for n in names:
            cand = BY_NAME[n]
            t = self.trials.get(n)
            form = None if t is None else cand.form(t.form)
            out.append({
                "name": n, "class": cand.equivalence, "description": cand.description if form is None
                else form.description, "form": None if form is None else form.label, "unit": cand.unit,
                "params": cand.params(sel.coefs[n]),
                "refit": None if t is None else t.values,
                "refit_all_recordings": self.final.values if self.final is not None and n in self.accepted else None,
                "uncertainty": {"inclusion_probability": sel.inclusion[n] if sel.resampled else None,
                                "interval_5_95": {c: sel.interval[n][k].tolist()
                                                  for k, c in enumerate(cand.coefficients)} if sel.resampled else None,
                                "delivered_ranges": {k: {"factors": p["range_factors"],
                                                         "grid": [p["factors"][0], p["factors"][-1]],
                                                         "tolerance": p["tolerance"]}
                                                     for k, p in self.final.identified.items()}
                                if self.final is not None and n in self.accepted else None},
                "evidence": {"explained": sel.explained[n], "selected": n in order,
                             "where": self.localization.vertex_feature[0], "when": self.localization.step_feature[0],
                             "region_vertices": int(self.region_of(n).sum())
                             if cand.needs_region and self.region_of(n) is not None else None},
                "refit_start": None if t is None else t.start,
                "heldout_l2": None if t is None else t.heldout_l2,
                "heldout_gain": None if t is None else self.gain(t),
                "train_rollout_gain": None if t is None else self.train_gain(t),
                "cross_validated": self.cross_validated(n),
                "residual_chose_over": self.rollouts_first if self.accepted[:1] == [n] else None,
                "residual_preference": self.selection.preference(n, self.rollouts_first)
                if self.rollouts_first and self.accepted[:1] == [n] else None,
                "not_separated_from": self.unseparated if self.accepted == [n] else [],
                "implausible": self.unphysical.get(n),
                "fold_refit_on_range_ends": self.fold_stops.get(n),
            })
        return out

    def summary(self) -> dict:
        loc = self.localization
        return {
            "verdict": "missing" if self.accepted else "none",
            "accepted": self.accepted,
            "accepted_classes": [BY_NAME[n].equivalence for n in self.accepted],
            "effects": self.effects(),
            "heldout_l2_before": self.heldout_before,
            "heldout_l2_after": self.heldout_after,
            "heldout_gain": 1.0 - self.heldout_after / self.heldout_before,
            "closest": self.closest,
            "heldout_gain_cross_validated": (self.cross_validated(self.accepted[0]) or {}).get("heldout_gain")
            if self.accepted else None,
            "final_fit": None if self.final is None else {
                "meaning": "the accepted model refitted on every recording once held-out rollouts confirmed it: the "
                           "parameters delivered; the held-out errors are the split's, fitted without those recordings",
                "refit": self.final.values, "train_rollout_l2": self.final.train_l2, "start": self.final.start,
                "form": self.final.form or None, "seconds": self.final.seconds,
                "starts_train_rollout_l2": self.final.compared, "identified_ranges": self.final.identified},
            "baseline": self.baseline,
            "nuisance_adjustment": self.nuisance,
            "selection": {"order": self.selection.order, "rss_after_nuisance": self.selection.rss_nuisance,
                          "bootstrap_blocks": self.selection.blocks, "bootstrap_resampled": self.selection.resampled},
            "localization": {"vertex_feature": {"name": loc.vertex_feature[0], "spearman": loc.vertex_feature[1],
                                                "meaning": FEATURES.get(loc.vertex_feature[0], "")},
                             "step_feature": {"name": loc.step_feature[0], "spearman": loc.step_feature[1],
                                              "meaning": FEATURES.get(loc.step_feature[0], "")},
                             "vertex_map_max": float(loc.vertex_map.max()),
                             "vertex_map_median": float(np.median(loc.vertex_map[loc.vertex_map > 0])),
                             "region_vertices": None if loc.region is None else np.flatnonzero(loc.region).tolist(),
                             "region_source": loc.region_source,
                             "activity_z_range": [float(loc.activity_map.min()), float(loc.activity_map.max())],
                             "activity_excess": loc.activity_excess, "activity_blind": loc.activity_blind,
                             "scanned_regions": {n: {"region_vertices": None if r.region is None
                                                     else np.flatnonzero(r.region).tolist(),
                                                     "source": r.source,
                                                     "field_train_rollout_l2": None if np.isnan(r.field_l2)
                                                     else r.field_l2,
                                                     "patches": r.patches, "explained": r.explained,
                                                     "best_patch_explained": float(r.patch_explained.max()),
                                                     "one_frame_patches": r.one_frame_patches,
                                                     "rollouts": None if r.region is None else {
                                                         "train_rollout_l2_before": r.rollout_l2_before,
                                                         "train_rollout_l2": r.rollout_l2,
                                                         "scale": float(np.exp(r.strength))}}
                                                 for n, r in self.scans.items()},
                             "region_choices": {n: {"chosen": c.chosen, "train_rollout_l2": c.train_l2,
                                                    "refused": c.refused,
                                                    "region_vertices": np.flatnonzero(c.region).tolist()}
                                                for n, c in self.region_choices.items()},
                             "grown_region_vertices": None if loc.grown is None
                             else np.flatnonzero(loc.grown).tolist()},
            "train_rollout_l2_before": self.null.train_l2,
            "null_refit": {"heldout_l2": self.null_refit.heldout_l2, "train_rollout_l2": self.null_refit.train_l2},
            "reference_trials": {n: self.trial_summary(t) for n, t in self.reference.items()},
            "joint_trials": {n: self.trial_summary(t) for n, t in self.trials.items() if len(t.names) > 1},
            "cross_validation": {**self.cv.to_json(), "rollouts_first": self.rollouts_first},
            "withheld_candidates": self.withheld,
        }
