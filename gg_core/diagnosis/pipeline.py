"""The diagnosis on loaded sequences: baseline, residual, localization, selection, confirmation (the stage,
gg_core/stages/diagnose.py, handles files, resuming and outputs)."""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..jobs import Progress
from ..parallel import Step, run_jobs, worker_count
from ..physics.cloth import Cloth
from ..physics.contact import BodyCollider
from ..physics.fitting import (BehaviorParams, FitConfig, Observed, fit_behavior, free_rollout, rollout_distance,
                               mean_rollout_error)
from ..physics.forces import DEFAULT_TERMS, TERMS, make_terms
from ..physics.simulator import ImplicitSimulator
from ..physics.solver import SolverOptions
from .confirm import Trial, fitted_trial, trial
from .features import FEATURES, state_features
from .folds import CrossValidation, Fold, extra_splits, finalists
from .identify import PROFILE_TOLERANCE, profiles
from .library import BY_NAME, CANDIDATES, Candidate, Context
from .localize import Localization, activity_map, localize
from .residuals import FrameBatch, Pooling, build_frames, make_pooling, nuisance_changes, residual, responses
from .scan import ScanResult, scan_region
from .selection import Design, Selection, fit, gram, select

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
# Measured and not kept (session 8): body friction started at zero (its candidate only adds, and the default mu 0.5
# already holds about as much friction as Blender's hidden one: collider friction 60 is Coulomb mu 0.6 against the
# collision impulse, collision.cc). At noise 0 every detectable bench case was named (7 / 7), friction s2 became
# "none" instead of wind (-26 %, a wrong class) and gains rose (wind -35 / -22 %), but at 1.5 mm noise `none` s1
# became a false alarm: mass damping -13.7 % held-out (mu 0.05: -13.2 %), where mu 0.5 answers "none". The
# friction's dissipation is part of what this baseline needs. Our friction cannot show Blender's anyway: it moves
# the hip band by 0.3-1.7 mm (5-14 mm at the hem is that twist swung out) and refits to mu 0.007 / 0.04.
# named_first: the share of bootstrap replicates in which a rival the folds do not separate from the rollouts' first
# must explain more of the residual alone than it, where the selection chose neither (a one-sided paired test).
# Measured (session 33, tilt against wind, 1000 replicates; the diagnosis draws 100): the demo capture's registered
# meshes with a hidden tilt, nothing selected, 0.97 for the tilt (0.96 with the diagnosis's 100; with session 32's
# trial starts, on main since session 34 (confirm.refit_or_scale, lag_start), the rollouts led with wind by half
# a point, the trials before them confirmed neither). Where the selection chose one: for the tilt Blender's s1 / s2
# 0.79 / 1.0, our simulator's s2 at 1.5 mm 0.947, the demo capture's ground truth 0.997; Blender wind s1 0.90 for
# wind, but Blender wind s2 0.87 for the tilt, a wrong pattern: short of 0.95 the residual's preference is no
# evidence.
RESIDUAL_PREFERENCE = 0.95
# a horizontal candidate's start along the rollout lag is skipped where its other start points within this angle of
# it (lag_start); the regression's direction was 26 degrees off on the registered demo meshes (session 32)
LAG_REDUNDANT_DEG = 10.0
SPLIT_FIT = "the split's fit"   # final_fit's label of the split's trial's fitted values
MARGIN_STARTS = (1.0, 3.0)     # baseline fits start from the collision term's default margin times these
INITIAL_LOSS_FACTOR = 0.1      # internal damping starts at a typical fabric's loss factor at 1 Hz


@dataclass
class Result:
    localization: Localization
    selection: Selection
    trials: dict[str, Trial]
    accepted: list[str]
    null: Trial                        # what trials are judged against (judge_reference)
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
    unseparated: list[str] = field(default_factory=list)   # unresolved rivals of the one accepted (unresolved)
    final: Trial | None = None         # the accepted model refitted on every recording (final_fit) ...
    final_sim: ImplicitSimulator | None = None   # ... and its simulator

    def region_of(self, name: str) -> np.ndarray | None:
        """The region candidate `name` acted on: its scan's, or the localization's."""
        return self.scans[name].region if name in self.scans else self.localization.region

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
        names = sorted(sel.explained, key=lambda n: (order.get(n, len(order)), -sel.inclusion[n], -sel.explained[n]))
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
                "uncertainty": {"inclusion_probability": sel.inclusion[n],
                                "interval_5_95": {c: sel.interval[n][k].tolist()
                                                  for k, c in enumerate(cand.coefficients)},
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
            "selection": {"order": self.selection.order, "rss_after_nuisance": self.selection.rss_nuisance},
            "localization": {"vertex_feature": {"name": loc.vertex_feature[0], "spearman": loc.vertex_feature[1],
                                                "meaning": FEATURES.get(loc.vertex_feature[0], "")},
                             "step_feature": {"name": loc.step_feature[0], "spearman": loc.step_feature[1],
                                              "meaning": FEATURES.get(loc.step_feature[0], "")},
                             "vertex_map_max": float(loc.vertex_map.max()),
                             "vertex_map_median": float(np.median(loc.vertex_map[loc.vertex_map > 0])),
                             "region_vertices": None if loc.region is None else np.flatnonzero(loc.region).tolist(),
                             "region_source": loc.region_source,
                             "activity_z_range": [float(loc.activity_map.min()), float(loc.activity_map.max())],
                             "scanned_regions": {n: {"region_vertices": None if r.region is None
                                                     else np.flatnonzero(r.region).tolist(),
                                                     "patches": r.patches, "explained": r.explained,
                                                     "best_patch_explained": float(r.patch_explained.max())}
                                                 for n, r in self.scans.items()}},
            "train_rollout_l2_before": self.null.train_l2,
            "null_refit": {"heldout_l2": self.null_refit.heldout_l2, "train_rollout_l2": self.null_refit.train_l2},
            "reference_trials": {n: self.trial_summary(t) for n, t in self.reference.items()},
            "joint_trials": {n: self.trial_summary(t) for n, t in self.trials.items() if len(t.names) > 1},
            "cross_validation": {**self.cv.to_json(), "rollouts_first": self.rollouts_first},
            "withheld_candidates": self.withheld,
        }


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


def _baseline(req: DiagnoseRequest, train: list[Observed], faces: np.ndarray, body_faces: np.ndarray,
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
        cloth = Cloth(rest, faces, pinned=attached, flat=not req.rest_mesh)   # stages.diagnose.rest_state
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


def diagnose(req: DiagnoseRequest, train: list[Observed], heldout: list[Observed], faces: np.ndarray,
             body_faces: np.ndarray, attached: np.ndarray, hands: np.ndarray | None,
             reference_region: np.ndarray | None, rest: np.ndarray, progress: Progress) -> Result:
    """Thresholds, iterations, reference candidates and the resolved source (measured_lag) come from `req`;
    `hands` are body vertices that do not collide, `reference_region` the region reference trials of region
    candidates use, `rest` the garment's rest positions (stages.diagnose.rest_state)."""
    timings: dict[str, float] = {}
    candidates, withheld = usable_candidates(bool(req.rest_mesh))
    t0 = time.perf_counter()
    sim, params, starts, train_rollouts, baseline_train_l2 = _baseline(req, train, faces, body_faces, attached,
                                                                       hands, rest, progress.step)
    baseline_l2 = mean_rollout_error(sim, heldout, attached)
    timings["baseline_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    r = _measure(sim, params, train, train_rollouts, attached, req.seed)
    activity = activity_map([obs.garment[1:] for obs in train], train_rollouts, sim.num.edges, sim.num.free > 0)
    loc = localize(sim, r.pooling, r.adjusted, state_features(sim, r.batch, r.pooling), activity)
    progress.step("residual measured and localized")
    timings["residual_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    ctx = Context.build(sim, r.batch, loc.region, r.predicted)
    scans = {c.name: scan_region(c, ctx, r.pooling, r.predicted, r.y, r.nuisance_cols, req.probe_acceleration)
             for c in candidates if c.region_from == "scan"}
    contexts = {c.name: replace(ctx, region=scans[c.name].region) if c.name in scans else ctx for c in candidates}
    progress.step("region scan")
    blocks = _candidate_rows(contexts, r.pooling, r.predicted, req.probe_acceleration)
    progress.step("candidate responses")
    design = Design(r.y, r.nuisance_cols, blocks, r.pooling.groups())
    sel = select(design, BY_NAME, req.min_explained, req.bootstrap, req.seed)
    progress.step("selection with block bootstrap")
    timings["selection_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    # the same refit without any candidate: trials are judged against equal optimization effort, so a gain cannot
    # come from the baseline fit simply running longer; it and the candidates' refits are independent jobs
    refit_config = fit_config(req, req.refit_iterations)
    proposed = propose(sel, req.min_inclusion, req.max_trials)
    jobs = [_TrialJob(n, None if n is None else sel.alone[n], sim, ctx if n is None else contexts[n], train, heldout,
                      attached, refit_config, req.probe_acceleration, baseline_l2, measured_lag(req.source, r))
            for n in [None, *proposed]]
    null_refit, *refits = run_jobs(_run_trial, jobs, worker_count(req.workers, len(jobs)), progress)
    null = judge_reference(Trial([], baseline_l2, float("nan"), baseline_train_l2), null_refit)
    before = null.heldout_l2
    trials = dict(zip(proposed, refits))
    unphysical = {n: why for n in proposed if (why := implausible(trials[n], sim.cloth))}
    first = Fold([o.name for o in train], [o.name for o in heldout], null,
                 {n: t for n, t in trials.items() if n not in unphysical})
    timings["trials_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    final = finalists(first, req.min_gain, req.fold_finalists)
    folds = [first]
    if final or req.reference:   # benchmarks: how much the true effect gains over the folds, named or not
        fold_jobs = [_FoldJob(req, [o for o in train + heldout if o.name in fit_on],
                              [o for o in train + heldout if o.name in held], faces, body_faces, attached, hands, rest,
                              final, {n: contexts[n].region for n in final}, reference_region)
                     for fit_on, held in extra_splits(first.train, first.heldout)]
        folds += run_jobs(_run_fold, fold_jobs, worker_count(req.workers, len(fold_jobs)), progress)
    for fold in folds[1:]:
        for n, t in fold.trials.items():
            if n not in unphysical and (why := implausible(t, sim.cloth)):
                unphysical[n] = f"{why} (refitted without {', '.join(fold.heldout)})"
    cv = CrossValidation(folds)
    by_rollouts = cv.ranked([n for n in first.trials if cv.confirmed(n, req.min_gain, req.min_gain_mm)
                             and n not in unphysical])
    passing = named_first(cv, by_rollouts, sel, req.min_inclusion)
    rollouts_first = by_rollouts[0] if by_rollouts and passing[0] != by_rollouts[0] else None
    timings["folds_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    accepted, after = passing[:1], (trials[passing[0]].heldout_l2 if passing else before)
    model = None if not passing else _trialled_model(passing[0], folds, contexts[passing[0]])
    pair_regions = [contexts[n].region for n in passing[:2] if BY_NAME[n].needs_region]
    one_region = len(pair_regions) < 2 or np.array_equal(*pair_regions)   # one trial holds one region
    if len(passing) > 1 and BY_NAME[passing[0]].equivalence != BY_NAME[passing[1]].equivalence and one_region:
        pair = fit(gram(design), passing[:2], BY_NAME).coefs
        region = pair_regions[0] if pair_regions else None
        chosen = [(in_form(BY_NAME[n], trials[n].form), pair[n]) for n in passing[:2]]
        joint = trial(sim, BASELINE_FIT, chosen, replace(ctx, region=region), region, train, heldout, attached,
                      refit_config)
        joint_name = "+".join(passing[:2])
        trials[joint_name] = joint
        if why := implausible(joint, sim.cloth):
            unphysical[joint_name] = why
        elif confirmed(joint, trials[passing[0]], req.min_gain, req.min_gain_mm):
            accepted, after = passing[:2], joint.heldout_l2
            model = (chosen, replace(ctx, region=region), [(SPLIT_FIT, joint.values)])
    timings["joint_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    recordings_l2 = (baseline_train_l2 * len(train) + baseline_l2 * len(heldout)) / (len(train) + len(heldout))
    delivered, delivered_sim = (None, None) if model is None else final_fit(sim, *model, train + heldout,
                                                                            attached, refit_config, recordings_l2)
    if delivered is not None:
        progress.step(f"final fit of {' + '.join(accepted)} on every recording")
    timings["final_fit_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    reference = _reference_trials(req, sim, r, reference_region, train, heldout, attached, progress.step)
    first.given.update(reference)
    timings["reference_s"] = time.perf_counter() - t0
    baseline = {k: v for k, v in params.global_values().items()}
    baseline.update({f"{t.name}.{k}": float(t.params[k]) for t, k, _ in params.term_refs})
    baseline["heldout_l2_global_fit"] = baseline_l2
    baseline["internal_damping_loss_factor"] = 2.0 * np.pi * baseline["viscoelastic_damping.tau"]   # at 1 Hz
    baseline["held_material"] = list(params.held)
    baseline.update({f"train_rollout_lag_{axis}_mm": 1e3 * float(r.lag[k]) for axis, k in (("x", 0), ("z", 2))})
    baseline.update(starts)
    rivals = unresolved(cv, passing) if len(accepted) == 1 and not rollouts_first else []
    return Result(loc, sel, trials, accepted, null, null_refit, after, baseline,
                  dict(zip(r.labels, r.adjust.tolist())), r.batch, unphysical, progress, cv, reference, timings, scans,
                  withheld, rollouts_first, rivals, delivered, delivered_sim)


def _trialled_model(name: str, folds: list[Fold], ctx: Context
                    ) -> tuple[list[tuple[Candidate, np.ndarray]], Context, list[tuple[str, dict]]]:
    """The candidate `name` in the form and at the start its trial in the split (folds[0]) kept, its context, and
    the fitted values final_fit starts from: the split's trial's, then those of the other folds' trials in the same
    form, labelled by what they held out."""
    t = folds[0].trials[name]
    fits = [(SPLIT_FIT, t.values)]
    fits += [(f"the fit without {', '.join(f.heldout)}", f.trials[name].values) for f in folds[1:]
             if name in f.trials and f.trials[name].form == t.form]
    return [(in_form(BY_NAME[name], t.form), t.start_coefs)], ctx, fits


def final_fit(sim: ImplicitSimulator, chosen: list[tuple[Candidate, np.ndarray]], ctx: Context,
              fits: list[tuple[str, dict]], recordings: list[Observed], attached: np.ndarray, config: FitConfig,
              baseline_l2: float) -> tuple[Trial, ImplicitSimulator]:
    """The accepted model refitted on EVERY recording, held-out ones included, once held-out rollouts have
    confirmed it (confirm.fitted_trial in the accepted trial's form), and that simulator: the model the diagnosis
    delivers (stages.diagnose writes it for `gg simulate --behavior`). It starts from whichever of the labelled
    `fits` (the split's fit, the other folds' fits: _trialled_model) rolls every recording out best, or from the
    central one of three or more that roll them out within PROFILE_TOLERANCE x `baseline_l2` of the best (the
    recordings do not tell those apart: confirm.best_fit), and keeps the refit only where it rolls every
    recording out better still (confirm.refit_or_keep). Every held-out figure of the report stays the split's,
    whose fit never saw those recordings. The delivered effect parameters' profiles over every recording
    (identify.profiles, against `baseline_l2`: the baseline's mean rollout error over `recordings`, measured when it
    was fitted) say how precisely the recordings fix each of them.

    Why: which effect is missing is decided on held-out recordings; the model a user simulates new motions with
    should then have seen every motion recorded (model selection by cross-validation, the selected model fitted on
    all the data). Measured (session 40, Blender's captures at 20 steps per frame, seed 1; `gg bench diagnose`
    scores both fits): it does not make the parameters systematically more accurate: the tilt 13.8 % off with the
    split's fit, 16.9 % with this one (1.80 -> 1.73 m/s^2 against the truth's 2.09; the folds' refits 1.28-2.08),
    air damping's alpha 24.7 -> 20.2 % off (12.5 -> 12.0 /s against 10). It cost 303 s / 134 s of the 67 / 71 min
    diagnoses (one more trial, in this process). Started anew from the trial's start (before session 42) it
    repeated the split's search with few iterations: on the Blender tilt test's capture at 4 refit iterations the
    tilt came out 2.83 m/s^2 (the split's 2.21, the truth about 2.09); from the split's fit 2.23, in 39 s instead
    of 56 s (/work/data/s42/tilt.py)."""
    delivered, delivered_sim, params = fitted_trial(sim, BASELINE_FIT, chosen, ctx, ctx.region, recordings, [],
                                                    attached, config, fits, PROFILE_TOLERANCE * baseline_l2)
    delivered.identified = {p.parameter: p.to_json() for p in profiles(delivered_sim, params, len(BASELINE_FIT),
                                                                       recordings, attached, baseline_l2)}
    return delivered, delivered_sim


def usable_candidates(rest_given: bool) -> tuple[list[Candidate], dict[str, str]]:
    """The candidates these data can tell apart from the model's own rest state, and why the others are withheld.

    A rest-length change is measured against the rest state. Without an unloaded rest mesh that state is the first
    frame, whose edge lengths are off by its load (0.5 % per edge against the unloaded template on captures of our
    own simulator), and a rest-length change on a region is then that error, not physics: refitted scales on
    `none` captures were 0.970-0.984 (Blender's skirt, 8 diagnoses) against 0.936-0.973 with a hidden 15 % seam
    shrink, whose first frame already holds the seam pulled in; on our own simulator's `none` capture (seed 1,
    bending towards flat) the rest-length region gained 18 % held-out (3.9 -> 3.2 mm, scale 0.979): a false
    alarm."""
    usable, withheld = [], {}
    for c in CANDIDATES:
        if rest_given or not c.needs_unloaded_rest:
            usable.append(c)
        else:
            withheld[c.name] = ("not identifiable without an unloaded rest mesh (gg diagnose --rest-mesh): a "
                                "rest-length change against a loaded first frame is that frame's own error")
    return usable, withheld


def judge_reference(baseline: Trial, null_refit: Trial) -> Trial:
    """What trials must beat: the better of the baseline fit and its refit without candidates, on held-out and on
    training rollouts each (so a trial must beat both fits on both).

    Why: the refit minimises a loss a few frames ahead, and now and then it worsens the free rollouts; then any
    trial, whose extra freedom lets its refit end elsewhere, recovers that loss and seems to gain. Measured on the
    benchmark at 1.5 mm noise (hidden rest-length change, seed 2): the refit worsened held-out 6.88 -> 8.41 mm,
    every candidate then gained 10-15 % (wind, mass damping, air drag; the true rest-length term 10.7 % at a
    refitted scale of 1.005, i.e. no change) and quadratic drag was named, a wrong class. Judged against the better
    fit, no candidate passes there. Re-judging the other 24 stored benchmark reports (noise 0 and 1.5 mm) with this
    rule changed no other verdict."""
    return Trial([], min(baseline.heldout_l2, null_refit.heldout_l2), null_refit.train_loss,
                 min(baseline.train_l2, null_refit.train_l2), start="better of the baseline fit and its refit")


def confirmed(t: Trial, reference: Trial, min_gain: float, min_gain_mm: float) -> bool:
    """The trial beats `reference` on held-out rollouts by the share `min_gain` and by `min_gain_mm`, and at all on
    the training rollouts. The absolute floor matters where the baseline already matches: on a capture of our own
    simulator with nothing hidden, a better-converged baseline refit reached 0.22 mm and anisotropy 'gained' 51 %
    (0.11 mm); with its unloaded rest mesh given, `none` seed 2 reached 0.37 mm and body friction 'gained' 10.3 %
    (0.04 mm). The smallest right gain seen is 0.35 mm (-27 %: hidden friction there, rest given, mu refitted to
    1.0 against 1.05), which the former floor of 0.5 mm refused; the default 0.25 mm lies between. Over the 44
    stored benchmark reports at noise 0 (/work/data/s21/floor_scan.py) it changes that verdict and no other: the
    floor only binds where the reference is under 5 mm, and wrong-class gains on `none` captures were either
    under 0.25 mm or under 8 %."""
    needed = min((1.0 - min_gain) * reference.heldout_l2, reference.heldout_l2 - 1e-3 * min_gain_mm)
    return t.heldout_l2 <= needed and t.train_l2 < reference.train_l2


def implausible(t: Trial, cloth: Cloth) -> str | None:
    """Why the trial's refitted values are not cloth physics (Candidate.implausible), or None."""
    return next((why for why in (BY_NAME[n].implausible(t.values, cloth) for n in t.names) if why), None)


def selected(sel: Selection, min_inclusion: float) -> list[str]:
    """The candidates the forward selection chose with bootstrap inclusion >= `min_inclusion`."""
    return [n for n in sel.order if sel.inclusion[n] >= min_inclusion]


def named_first(cv: CrossValidation, by_rollouts: list[str], sel: Selection, min_inclusion: float) -> list[str]:
    """The confirmed candidates `by_rollouts` in the order they are accepted: the residual breaks a tie the folds
    leave (CrossValidation.residual_tie_break), but only with a candidate its forward selection chose with bootstrap
    inclusion >= `min_inclusion`, the bar a candidate's residual evidence must clear to be tried first (propose).

    Why not every candidate in the regression's order: where the selection is unstable its order is a coin toss.
    Measured (session 28, our simulator's hidden gravity tilt, seed 2, 1.5 mm noise): the selection took wind
    (inclusion 0.4, 7.4 % of the residual explained) over the tilt (0.3, 7.1 %); the tilt led the rollouts (mean
    held-out gain 36 % against 25 %, better in 2 folds by 18 and 16 points, worse in the walk-less fold by 10),
    and breaking that tie with the explained share named wind, a wrong class. The case the tie-break was made for
    (Blender's hidden wind, seed 2) had wind selected in 100 % of the bootstrap replicates, the tilt in 5 %.

    Where the selection chose neither the rollouts' first nor a rival the folds do not separate from it, the rival
    still comes first if it explains more of the residual alone in at least RESIDUAL_PREFERENCE of the bootstrap
    replicates (Selection.preference): registration error lowers every candidate's share below the selection's
    bar together, the paired comparison keeps which pattern fits better. See RESIDUAL_PREFERENCE."""
    chosen = selected(sel, min_inclusion)
    ranked = cv.residual_tie_break(by_rollouts, chosen)
    if not ranked or ranked[0] != by_rollouts[0] or ranked[0] in chosen:
        return ranked
    lead = ranked[0]
    rivals = [n for n in ranked[1:] if not cv.separated(lead, n) and sel.preference(n, lead) >= RESIDUAL_PREFERENCE]
    if not rivals:
        return ranked
    first = max(rivals, key=lambda n: sel.preference(n, lead))
    return [first] + [n for n in ranked if n != first]


def unresolved(cv: CrossValidation, passing: list[str]) -> list[str]:
    """The confirmed candidates of other equivalence classes than the first of `passing` that the folds do not
    separate from it (CrossValidation.separated): where neither the rollouts nor the residual chose, the report
    says the recordings leave the class open instead of naming one as if it were certain."""
    if not passing:
        return []
    lead = BY_NAME[passing[0]]
    return [n for n in passing[1:] if BY_NAME[n].equivalence != lead.equivalence and not cv.separated(lead.name, n)]


def propose(sel: Selection, min_inclusion: float, max_trials: int) -> list[str]:
    """At most `max_trials` candidates worth a refit: those the forward selection chose with bootstrap inclusion
    >= `min_inclusion`, then the others by the share of the residual they explain alone.

    The regression on one-frame errors only ranks: against a simulator that differs from the recording's in
    many small ways (Blender's mass-spring cloth vs our StVK on the benchmark), the true effect often explains
    less of the residual than a wrong one (measured: mass damping 0.057 vs strain-rate damping 0.125 on a capture
    with hidden air drag, yet 61 % vs 25 % held-out gain; a horizontal gravity tilt 4th of 6). Held-out
    rollouts decide. With noise even the sign can mislead: on a noisy capture with hidden air damping, mass
    damping explained nothing of the smoothed residual and gained 64 % held-out. Starting such a trial at its probe
    size instead (as reference trials do) named air damping s2 at 1.5 mm noise right (-26 %), but also linear
    damping on `none` captures (bench s2 at 1.5 mm, -18 %; the tiny test captures, -82 %): so both starts are
    refitted and the training rollouts choose (_trial_from_starts)."""
    chosen = selected(sel, min_inclusion)
    others = sorted((n for n in sel.explained if n not in chosen), key=lambda n: -sel.explained[n])
    return (chosen + others)[:max_trials]


@dataclass
class _TrialJob:
    """One confirming refit for a worker process (parallel.run_jobs): the candidate by name (candidates hold
    closures, which do not pickle), None for the refit without candidates.

    The refits are independent and each single-threaded, so they fill the cores. Measured (session 14) on the
    Blender test capture (400 vertices, 3 x 16 frames, 13 refits): the whole diagnosis took 583 s in one process
    (another single-threaded job on the second core); with 2 workers on the 2 idle cores and a halved adjoint
    budget (not kept, physics/fitting.py) 204 s, its trials 451 -> 124 s. The report is the same as in one process
    (the tests' tilted capture, every field but paths and times)."""
    name: str | None
    coefs: np.ndarray | None
    sim: ImplicitSimulator
    ctx: Context
    train: list[Observed]
    heldout: list[Observed]
    attached: np.ndarray
    config: FitConfig
    acceleration: float
    baseline_l2: float            # the global fit's held-out error, for the progress line
    lag: np.ndarray | None        # measured_lag: the baseline's rollout lag on registered meshes


def _run_trial(job: _TrialJob, step: Step) -> Trial:
    if job.name is None:
        out = trial(job.sim, BASELINE_FIT, [], job.ctx, None, job.train, job.heldout, job.attached, job.config)
        label = "baseline refit"
    else:
        out = _trial_from_starts(BY_NAME[job.name], job.coefs, job.sim, job.ctx, job.train, job.heldout,
                                 job.attached, job.config, job.acceleration, job.lag)
        label = f"trial {job.name}"
    step(f"{label}: held-out L2 {job.baseline_l2 * 1e3:.1f} -> {out.heldout_l2 * 1e3:.1f} mm")
    return out


def _trial_from_starts(cand: Candidate, coefs: np.ndarray, sim: ImplicitSimulator, ctx: Context,
                       train: list[Observed], heldout: list[Observed], attached: np.ndarray, config: FitConfig,
                       acceleration: float, lag: np.ndarray | None) -> Trial:
    """The trial of `cand` started from its regression coefficients `coefs`; where the regression put nothing or
    the largest change a region candidate allows (saturated), also from its probe sizes; for a horizontal vector
    (a tilt, a wind) also along the baseline's rollout `lag` (lag_start); keeping the start whose refit rolls the
    TRAINING sequences out best (the held-out error stays unseen until the choice is made, as with the baseline's
    margin starts).

    Why: the refits minimise a loss a few frames ahead, where internal damping and drag look alike, so a refit
    started at zero drag stays there. Measured on the benchmark's hidden air damping (seed 1, noise 0): the
    baseline's internal damping rose to a loss factor of 0.91 and the one-frame regression gave mass damping
    nothing; its trial kept alpha at the default 1 /s and gained 0 %, where the same refit from the probe size
    reached 10.3 /s and gained 24.5 % held-out and training.

    Measured and not kept (session 27): also restarting the baseline's internal damping where it ends at its limit
    (our simulator's hidden moving air, seed 2, fitted without the walk: tau 0.159 s, the truth 0.03 s; the walk held
    out 7.51 mm). The wind trial as moving air from the baseline's damping rolled the training sequences out 5.54 mm
    and the walk 6.97 mm; from tau 0.04 s 5.29 / 7.99 mm, from 0.016 s 5.75 / 6.62 mm: the training rollouts
    would choose the start that is worst held out.

    Why the lag: where the one-frame residual is mostly measurement error, its direction is too. Measured (session
    32) on the demo capture's registered meshes (3 mm off the truth) with a hidden tilt of (2.55, 0) m/s^2: the
    regression's direction was (0.77, 0.38), 26 degrees off, and its trial gained 2.4 % held-out; the recordings'
    mean offset from the baseline's training rollouts lay along (0.99, -0.11), and the baseline with a tilt of
    2 m/s^2 along it, nothing refitted, rolled the held-out sequence out 17 % better."""
    starts = [("regression", coefs)]
    probe = saturated(cand, coefs)
    if not probe and (lag is None or not cand.horizontal):   # no other start: no probe forces needed
        return _best_of_starts(cand, starts, sim, ctx, train, heldout, attached, config)
    sizes = np.array([size for size, _ in cand.probes(ctx, acceleration)])
    if probe and np.all(sizes > 0):
        starts.append(("probe", sizes))
    return _best_of_starts(cand, starts + lag_start(cand, sizes, lag, starts[-1][1]), sim, ctx, train, heldout,
                           attached, config)


def saturated(cand: Candidate, coefs: np.ndarray) -> bool:
    """Whether the regression gave `cand` nothing, or put a coefficient on a bound other than zero (a region
    candidate's largest allowed change, e.g. a region 10x softer): either way the one-frame linearization says
    little about the effect, and its trial also starts from the probe sizes (_trial_from_starts).

    Why the bound: on Blender's hidden stiff patch (seed 1, 20 steps; region 35 of 44 vertices in the true patch),
    the fold that held the walk out regressed region stiffness to both scales' lower bound (x0.1, a softer
    region), where the teacher-forced refit stayed; its training rollouts were 8.2 % worse than the baseline's and
    the fold guard refused the effect. From the probe sizes (stretch x1.02, bending x148) the refit reached
    bending x161, rolling that fold's training sequences out 6.95 mm against 9.19 mm from the bound (+18.2 %
    training, +8.5 % held-out; /work/data/s44/sp_fold.py, session 44)."""
    lo, hi = cand.bounds
    edges = [b for b in (lo, hi) if np.isfinite(b) and b != 0]
    return not np.any(coefs != 0) or any(np.any(np.isclose(coefs, b, rtol=1e-6, atol=0.0)) for b in edges)


def _best_of_starts(cand: Candidate, starts: list[tuple[str, np.ndarray]], sim: ImplicitSimulator, ctx: Context,
                    train: list[Observed], heldout: list[Observed], attached: np.ndarray, config: FitConfig) -> Trial:
    """_trial_in_best_form from each (origin, coefficients) start, the one that rolls the training sequences out
    best (the first on ties), its start labelled with the origin unless that is "regression"."""
    best = None
    for origin, coefs in starts:
        t = _trial_in_best_form(cand, coefs, sim, ctx, train, heldout, attached, config)
        if origin != "regression":
            t.start = origin if t.start == "regression" else f"{origin}, then {t.start}"
        if best is None or t.train_l2 < best.train_l2:
            best = t
    return best


def rollout_lag(rollouts: list[np.ndarray], train: list[Observed], pinned: np.ndarray) -> np.ndarray:
    """[3] the mean horizontal offset (m, y = 0) of the training recordings from the baseline's free rollouts of
    them (fitting.free_rollout), over the frames and free vertices rollout_distance compares: where a steady force
    the model lacks (a tilt, a wind) holds the garment."""
    offsets = np.concatenate([(obs.garment[2:] - traj[1:])[:, ~pinned].reshape(-1, 3)
                              for traj, obs in zip(rollouts, train)])
    return offsets.mean(0) * np.array([1.0, 0.0, 1.0])


def measured_lag(source: str, r: Measured) -> np.ndarray | None:
    """The rollout lag that horizontal trials also start along (lag_start) where the recordings are registered
    meshes; None on ground truth, where that start repeats the other starts' trials.

    Why: it addresses a one-frame residual whose direction is mostly measurement error (session 32: registered
    demo meshes, 3 mm off the truth). On Blender's ground-truth gravity s1 (20 steps, session 34) it and the
    unrefitted start (confirm.refit_or_scale, then for registered meshes only) changed nothing the benchmark
    scores (gravity, -31 % over the folds, tilt 13.8 % off, as before) and made the suite's small Blender tilt
    diagnosis take 17 min."""
    return r.lag if source == "registered" else None


def lag_start(cand: Candidate, sizes: np.ndarray, lag: np.ndarray | None, coefs: np.ndarray
              ) -> list[tuple[str, np.ndarray]]:
    """The start ("rollout lag", coefficients) of a horizontal candidate along `lag` (rollout_lag), at the mean of
    its probe `sizes`; none for other candidates, a zero lag, a probe whose force vanishes, or where the other
    start `coefs` already points within LAG_REDUNDANT_DEG of the lag (refits keep a vector's direction and
    rollout_scale its size, so such a start would repeat that trial)."""
    length = 0.0 if lag is None else float(np.hypot(lag[0], lag[2]))
    if not cand.horizontal or length == 0.0 or not np.all(sizes > 0):
        return []
    along = np.array([lag[0], lag[2]]) / length
    if np.dot(along, coefs) > np.cos(np.radians(LAG_REDUNDANT_DEG)) * np.linalg.norm(coefs):
        return []
    return [("rollout lag", along * float(sizes.mean()))]


def _trial_in_best_form(cand: Candidate, coefs: np.ndarray, sim: ImplicitSimulator, ctx: Context,
                        train: list[Observed], heldout: list[Observed], attached: np.ndarray, config: FitConfig
                        ) -> Trial:
    """The trial of `cand` from `coefs` in its own model and in each of its forms (library.Form), keeping the one
    whose refit rolls the TRAINING sequences out best.

    Why (wind): Blender's wind field pushes cloth faces with a pressure that ignores the cloth's motion; real air
    drags the cloth towards its own velocity, which also damps motion across the wind. Measured on our simulator's
    capture with hidden moving air (skirt, seed 1, 0.7 m/s along x; the stored baseline fit, held-out arm swing
    8.8 mm): a pressure along x rolls out at best 5.2 mm (0.05 Pa), air moving along x 4.4 mm (0.4 m/s)."""
    best = None
    for label in ("", *(f.label for f in cand.forms)):
        t = trial(sim, BASELINE_FIT, [(in_form(cand, label), coefs)], ctx, ctx.region, train, heldout, attached,
                  config)
        t.form = label
        if best is None or t.train_l2 < best.train_l2:
            best = t
    return best


def in_form(cand: Candidate, label: str) -> Candidate:
    """`cand` with the model of its form `label` ("" or a label it lacks: its own model)."""
    form = cand.form(label)
    return cand if form is None else replace(cand, model=form.model)


def _candidate_rows(contexts: dict[str, Context], pooling: Pooling, predicted: np.ndarray, acceleration: float
                    ) -> dict[str, np.ndarray]:
    """Pooled response columns [R,K] of every candidate that acts on these data, each in its own context (region
    candidates need a region; a candidate whose force vanishes here, e.g. friction without contact, is left out)."""
    blocks = {}
    for name, ctx in contexts.items():
        cand = BY_NAME[name]
        if cand.needs_region and ctx.region is None:
            continue
        probes = cand.probes(ctx, acceleration)
        if any(size == 0 for size, _ in probes):
            continue
        rows = pooling.rows(responses(ctx.sim, ctx.batch, predicted, probes)).T
        if np.isfinite(rows).all():         # a probe whose step failed to solve (measured: friction on one
            blocks[cand.name] = rows        # noisy capture) cannot be regressed on; the candidate is not tried
    return blocks


def _reference_trial(cand: Candidate, sim: ImplicitSimulator, r: Measured, region: np.ndarray | None,
                     req: DiagnoseRequest, train: list[Observed], heldout: list[Observed], attached: np.ndarray
                     ) -> Trial:
    """A trial of `cand` whatever the selection said, on the given region (benchmarks: the true effect, on the
    true region), started from its regression coefficients on that region (its probe sizes where those are 0 or
    the probe's step failed)."""
    ctx = Context.build(sim, r.batch, region if cand.needs_region else None, r.predicted)
    probes = cand.probes(ctx, req.probe_acceleration)
    sizes = np.array([size for size, _ in probes])
    coefs = _regressed(cand, ctx, r, probes)
    start, lag = np.where(coefs != 0, coefs, sizes), measured_lag(req.source, r)
    starts = [("regression", start)] + lag_start(cand, sizes, lag, start)
    return _best_of_starts(cand, starts, sim, ctx, train, heldout, attached, fit_config(req, req.refit_iterations))


def _reference_trials(req: DiagnoseRequest, sim: ImplicitSimulator, r: Measured, region: np.ndarray | None,
                      train: list[Observed], heldout: list[Observed], attached: np.ndarray, step: Step,
                      split: str = "") -> dict[str, Trial]:
    """_reference_trial of each of `req.reference`, each reported through `step` (`split` says which fold)."""
    out = {}
    for n in req.reference:
        out[n] = _reference_trial(BY_NAME[n], sim, r, region, req, train, heldout, attached)
        step(f"reference trial {n}{split}: held-out L2 {out[n].heldout_l2 * 1e3:.1f} mm")
    return out


@dataclass
class Measured:
    """The residual of a fitted simulator on training sequences, pooled, with the nuisance columns it is regressed
    beside and the residual left after them."""

    batch: FrameBatch
    predicted: np.ndarray        # [N,V,3] the simulator's one-frame predictions
    pooling: Pooling
    y: np.ndarray                # pooled residual rows
    nuisance_cols: np.ndarray    # [R,K] pooled responses to the nuisance changes (residuals.nuisance_changes)
    labels: list[str]            # the nuisance changes
    adjust: np.ndarray           # [K] their least-squares sizes
    adjusted: np.ndarray         # [N,V,3] the residual after them
    lag: np.ndarray              # [3] rollout_lag: the recordings' mean horizontal offset from the free rollouts


def _measure(sim: ImplicitSimulator, params: BehaviorParams, train: list[Observed], rollouts: list[np.ndarray],
             attached: np.ndarray, seed: int) -> Measured:
    """The residual of `sim` (fitted as `params`) on `train`, whose free rollouts by `sim` are `rollouts`."""
    batch = build_frames(sim, train)
    res = residual(sim, batch)
    predicted = batch.x_next - res
    labels, changes = nuisance_changes(sim, params)
    nuisance = responses(sim, batch, predicted, changes)
    pooling = make_pooling(sim, batch, seed=seed)
    y, n_cols = pooling.rows(res), pooling.rows(nuisance).T
    adjust, *_ = np.linalg.lstsq(n_cols, y, rcond=None)
    return Measured(batch, predicted, pooling, y, n_cols, labels, adjust,
                    res - np.einsum("k,knvc->nvc", adjust, nuisance), rollout_lag(rollouts, train, attached))


def _regressed(cand: Candidate, ctx: Context, r: Measured, probes: list[tuple[float, Callable]]) -> np.ndarray:
    """`cand`'s coefficients regressed alone on the residual beside the nuisance columns (as Selection.alone), from
    its `probes` (Candidate.probes); zero where the regression puts nothing or the probe's step failed."""
    rows = r.pooling.rows(responses(ctx.sim, ctx.batch, r.predicted, probes)).T
    if not np.isfinite(rows).all():
        return np.zeros(len(probes))
    return fit(gram(Design(r.y, r.nuisance_cols, {cand.name: rows}, r.pooling.groups())), [cand.name],
               BY_NAME).coefs[cand.name]


@dataclass
class _FoldJob:
    """One more fold of the cross-validation (folds.py) for a worker process: everything refitted on `train`
    without `heldout`; the finalists tried on the regions fold 0 chose, the `reference` candidates (benchmarks: the
    true effect) on `reference_region`."""
    req: DiagnoseRequest
    train: list[Observed]
    heldout: list[Observed]
    faces: np.ndarray
    body_faces: np.ndarray
    attached: np.ndarray
    hands: np.ndarray | None
    rest: np.ndarray
    names: list[str]
    regions: dict[str, np.ndarray | None]
    reference_region: np.ndarray | None


def _run_fold(job: _FoldJob, step: Step) -> Fold:
    """The baseline, residual and regression of this fold's training sequences, the refit without candidates,
    each finalist's trial (from its regression start, its probe sizes, or along the rollout lag: _trial_from_starts)
    and each reference candidate's (_reference_trial)."""
    req, held = job.req, ", ".join(o.name for o in job.heldout)
    sim, params, _, rollouts, train_l2 = _baseline(req, job.train, job.faces, job.body_faces, job.attached,
                                                   job.hands, job.rest, lambda msg: step(f"{msg}, without {held}"))
    baseline_l2 = mean_rollout_error(sim, job.heldout, job.attached)
    r = _measure(sim, params, job.train, rollouts, job.attached, req.seed)
    config = fit_config(req, req.refit_iterations)
    null_refit = trial(sim, BASELINE_FIT, [], Context.build(sim, r.batch, None, r.predicted), None, job.train,
                       job.heldout, job.attached, config)
    trials = {}
    for n in job.names:
        cand = BY_NAME[n]
        ctx = Context.build(sim, r.batch, job.regions[n], r.predicted)
        coefs = _regressed(cand, ctx, r, cand.probes(ctx, req.probe_acceleration))
        trials[n] = _trial_from_starts(cand, coefs, sim, ctx, job.train, job.heldout, job.attached, config,
                                       req.probe_acceleration, measured_lag(req.source, r))
        step(f"trial {n} without {held}: held-out L2 {baseline_l2 * 1e3:.1f} -> {trials[n].heldout_l2 * 1e3:.1f} mm")
    given = _reference_trials(req, sim, r, job.reference_region, job.train, job.heldout, job.attached, step,
                              f" without {held}")
    return Fold([o.name for o in job.train], [o.name for o in job.heldout],
                judge_reference(Trial([], baseline_l2, float("nan"), train_l2), null_refit), trials, given)
