"""Proof on held-out sequences: add candidate effects to the simulator, refit, compare held-out rollouts.

A trial copies the baseline simulator, switches the candidates' force-library terms on (or scales the region's
material fields), and refits the global material together with the candidates' coefficients on the training
sequences (teacher-forced prediction a few frames ahead of observed states, L-BFGS, warm-started from the baseline
and the regression's coefficients, or from probe sizes: starts.trial_from_starts). Its held-out rollout error
decides: an effect is accepted only if it lowers the error by at least `min_gain` relative to the baseline, and
also lowers the free-rollout error of the training sequences (a real effect helps every recording; a term that
only helps the held-out one got lucky among the many tried). The regression only proposes; rollouts decide,
which also protects against effects that fit single frames but drift in free rollouts.

Friction's coefficient is also chosen on the training rollouts from a grid (Candidate.rollout_values,
rollout_choice): its stick-slip force is invisible a few frames ahead. Every other single candidate's refitted
coefficients (a region candidate's log-scales: its scales raised to a power) are then scaled by the factor that
rolls the training sequences out best (rollout_scale): slow, quasi-static forces (a gravity tilt) and a region's
bending barely show a few frames ahead either; and the candidate is also tried on the unrefitted baseline, scaled
the same way, and refitted again from there where that rolls out better (refit_or_scale): a refit can spoil the
material where the one-frame residual is mostly measurement error.

Vector coefficients (a wind's pressure, a gravity tilt) are refitted as one log-scale of the start's vector, so
the refit keeps its direction; the direction comes from the regression or from the baseline's rollout lag
(starts.lag_start), whichever start the training rollouts prefer. Measured and not kept (session 6): refitting
each component freely (offsets in units of the start's length), so that a wrong regression direction can be
corrected. Benchmark, noise 0: gravity s1 / s2 unchanged (-28 % / -40 %), wind s1 -24 -> -27 %, wind s2 -10.4 ->
-6.7 % (below the 10 % needed: a case lost), `none` s1 still none. Registered demo meshes with a hidden gravity
tilt: the tilt's refit turned from the regression's (-0.15, 0.78) to (0.59, 1.08) m/s^2 (truth (2.55, 0)) and
lost 11 % held-out; wind gained 11.5 % and was named (the verdict had been none; both wrong classes).
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import torch

from ..physics.cloth import Cloth
from ..physics.fitting import (BehaviorParams, FitConfig, Observed, TeacherForced, mean_rollout_error, minimize_lbfgs)
from ..physics.material import MATERIAL_NAMES, Material
from ..physics.simulator import ImplicitSimulator
from .library import PINNED_LOG, Candidate, Context, ModelChange, apply_region, region_value, with_terms

SCALE_RANGE = (0.25, 8.0)   # factors on a candidate's refitted coefficients tried on training rollouts
SCALE_EVALUATIONS = 11      # golden-section steps: the factor to within 3 %
INWARD = 2.0                # inward_rollout: the factor by which region scales on their range's ends move inside


class CandidateParams(BehaviorParams):
    """Global behaviour latents plus region log-scales of material fields (library.apply_region), with each
    scale's declared log range (ModelChange.region_range; unbounded where not given)."""

    def __init__(self, cloth: Cloth, sim: ImplicitSimulator, term_params: tuple[str, ...],
                 region: np.ndarray | None, region_init: dict[str, float], held: tuple[str, ...] = (),
                 region_range: dict[str, tuple[float, float]] | None = None) -> None:
        super().__init__(cloth, {n: float(getattr(cloth.material, n).mean()) for n in MATERIAL_NAMES}, sim.terms,
                         term_params, held)
        self.region = region
        self.region_keys = tuple(region_init)
        self.region_s = torch.tensor([region_init[k] for k in self.region_keys], dtype=torch.float64)
        ranges = [(region_range or {}).get(k, (-np.inf, np.inf)) for k in self.region_keys]
        self.region_lo, self.region_hi = (torch.tensor([r[i] for r in ranges], dtype=torch.float64) for i in (0, 1))

    def tensors(self) -> dict[str, torch.Tensor]:
        return {**super().tensors(), "region_s": self.region_s}

    def apply(self, cloth: Cloth) -> None:
        super().apply(cloth)
        if self.region_keys:
            apply_region(cloth, self.region, dict(zip(self.region_keys, self.region_s)))

    def trainable(self) -> list[torch.Tensor]:
        """What a trial refits: the global material, the term parameters, the region's scales."""
        return [self.global_z, self.term_s, self.region_s]

    def snapshot(self) -> dict[str, torch.Tensor]:
        return {name: t.detach().clone() for name, t in self.tensors().items()}

    def restore(self, sim: ImplicitSimulator, values: dict[str, torch.Tensor]) -> None:
        """Set the parameters to a snapshot() and apply them to `sim` (whose cloth they fit)."""
        with torch.no_grad():
            for name, t in self.tensors().items():
                t.copy_(values[name])
        self.apply(sim.cloth)
        sim.refresh()

    def values(self) -> dict[str, object]:
        """Physical values of everything fitted: material, term parameters, region scale factors."""
        out: dict[str, object] = {f"material.{k}": v for k, v in self.global_values().items()}
        for term, key, _ in self.term_refs:
            out[f"{term.name}.{key}"] = term.params[key].detach().tolist()
        out.update({region_value(k): float(np.exp(float(s))) for k, s in zip(self.region_keys, self.region_s)})
        return out


@dataclass
class Trial:
    names: list[str]
    heldout_l2: float
    train_loss: float
    train_l2: float             # free-rollout error on the training sequences (the fit saw them only one frame ahead)
    values: dict[str, object] = field(default_factory=dict)
    seconds: float = 0.0
    start: str = "regression"   # where the refit started: the regression's coefficients, or the probe sizes
    form: str = ""              # the candidate's Form (library.py) the trial refitted; "" its own model
    start_coefs: np.ndarray | None = None   # a single candidate's coefficients at that start (final_fit reuses them)
    compared: dict[str, float] = field(default_factory=dict)   # final fit: each earlier fit's rollout error (best_fit)
    identified: dict[str, dict] = field(default_factory=dict)  # final fit: its effect parameters' profiles (identify)
    region: np.ndarray | None = None   # [V] where the change's region fields act (None: no region)
    # every region scale refitted onto an end of its range: the training rollout error with each moved INWARD
    # times inside it (inward_rollout; verdict.stopped_on_ends); None otherwise
    inward_l2: float | None = None


def merge(changes: list[ModelChange]) -> ModelChange:
    out = ModelChange()
    for c in changes:
        out.terms.update(c.terms)
        out.fit += tuple(p for p in c.fit if p not in out.fit)
        out.region.update(c.region)
        out.region_range.update(c.region_range)
    return out


def refit(sim: ImplicitSimulator, params: BehaviorParams, train: list[Observed], trainable: list[torch.Tensor],
          config: FitConfig) -> float:
    """L-BFGS on the teacher-forced loss (config: global_iterations, max_samples, seed, horizon) over `trainable`;
    leaves the best parameters applied, returns its loss."""
    problem = TeacherForced(sim, train, config.max_samples, config.seed, horizon=config.horizon)
    if config.global_iterations <= 0:
        return problem.evaluate(params, [])[0]     # evaluating applies the parameters

    def evaluate() -> tuple[float, list[torch.Tensor]]:
        loss, _, grads = problem.evaluate(params, trainable)
        return loss, grads

    return minimize_lbfgs(sim, params, trainable, evaluate, config.global_iterations)


def trial(base: ImplicitSimulator, base_fit: tuple[str, ...], chosen: list[tuple[Candidate, np.ndarray]],
          ctx: Context, region: np.ndarray | None, train: list[Observed], heldout: list[Observed],
          pinned: np.ndarray, config: FitConfig) -> Trial:
    """Refit the baseline with the chosen candidates (initial coefficients given) and roll out the held-out
    sequences (none: heldout_l2 is NaN). `base_fit` are the term parameters the baseline fitted; the baseline
    simulator is left unchanged. A single candidate is also tried on the unrefitted baseline (refit_or_scale)."""
    return fitted_trial(base, base_fit, chosen, ctx, region, train, heldout, pinned, config)[0]


def fitted_trial(base: ImplicitSimulator, base_fit: tuple[str, ...], chosen: list[tuple[Candidate, np.ndarray]],
                 ctx: Context, region: np.ndarray | None, train: list[Observed], heldout: list[Observed],
                 pinned: np.ndarray, config: FitConfig, warm: list[tuple[str, dict[str, object]]] | None = None,
                 tie: float = 0.0) -> tuple[Trial, ImplicitSimulator, CandidateParams]:
    """trial, and the refitted simulator itself (what the diagnosis delivers of its final fit) with its
    parameters. `warm`: labelled values (Trial.values) of earlier trials of the same candidates to start from
    instead of the candidates' coefficients on the baseline: the one that rolls `train` out best, or the central
    one of those within `tie` (m) of it (best_fit), refitted where that helps (refit_or_keep)."""
    start = time.perf_counter()
    change = merge([cand.model(coefs, ctx) for cand, coefs in chosen])
    compared: dict[str, float] = {}
    if warm:
        (sim, params), kept_error, origin, compared = best_fit(
            [(label, _at_start(base, base_fit, change, region, config, values)) for label, values in warm],
            train, pinned, change.fit + tuple(map(region_value, change.region)), tie)
        loss, train_error, start_label = refit_or_keep(sim, params, train, pinned, config, kept_error, origin)
    else:
        sim, params = _at_start(base, base_fit, change, region, config, None)
        if len(chosen) == 1 and not chosen[0][0].rollout_values:
            loss, train_error, start_label = refit_or_scale(sim, params, len(base_fit), train, pinned, config)
        else:
            loss = refit(sim, params, train, params.trainable(), config)
            train_error, start_label = mean_rollout_error(sim, train, pinned), "regression"
            if len(chosen) == 1:
                train_error, start_label = rollout_choice(sim, chosen[0][0], ctx, train, pinned, train_error)
    inward = inward_rollout(sim, params, train, pinned)
    error = mean_rollout_error(sim, heldout, pinned) if heldout else float("nan")
    return Trial([c.name for c, _ in chosen], error, loss, train_error, params.values(), time.perf_counter() - start,
                 start_label, start_coefs=chosen[0][1] if len(chosen) == 1 else None, compared=compared,
                 region=region, inward_l2=inward), sim, params


def inward_rollout(sim: ImplicitSimulator, params: CandidateParams, train: list[Observed], pinned: np.ndarray
                   ) -> float | None:
    """Where the refit stopped every region scale on an end of its declared range (within PINNED_LOG): the
    training rollout error with each moved INWARD times inside it, the parameters then restored; else None.

    Why: a fit held inside its range stops on an end either because the recordings want it beyond (no estimate
    inside: the term stands in for something else) or because they do not pin that field at all, and then a value
    inside rolls out as well. Blender's stiff patch s2 at 9.81 m/s^2 (session 72): refitted without the walk, the
    region's stretch stopped on x0.1 and its bending on x201, and the true region's refit did the same; the
    patch's stretch rolls out alike from x0.07 to x1.1 (identify.py, session 46)."""
    if not params.region_keys:
        return None
    s = params.region_s
    low, high = (s - params.region_lo).abs() <= PINNED_LOG, (params.region_hi - s).abs() <= PINNED_LOG
    if not bool((low | high).all()):
        return None
    kept = params.snapshot()
    with torch.no_grad():
        params.region_s += float(np.log(INWARD)) * (low.double() - high.double())
    params.apply(sim.cloth)
    sim.refresh()
    out = mean_rollout_error(sim, train, pinned)
    params.restore(sim, kept)
    return out


def _at_start(base: ImplicitSimulator, base_fit: tuple[str, ...], change: ModelChange, region: np.ndarray | None,
              config: FitConfig, values: dict[str, object] | None) -> tuple[ImplicitSimulator, CandidateParams]:
    """A copy of `base` with `change` switched on, at the change's start or, given, at an earlier trial's fitted
    `values` (at_values), and the parameters a refit of it trains."""
    cloth = copy.deepcopy(base.cloth)
    sim = ImplicitSimulator(cloth, terms=with_terms(copy.deepcopy(base.terms), change.terms), collider=base.collider,
                            fps=base.fps, substeps=base.substeps, options=base.options,
                            contact_reach=base.contact_reach)
    region_logs = change.region if values is None else at_values(cloth, sim, change.region, values)
    params = CandidateParams(cloth, sim, base_fit + change.fit, region, region_logs, config.held, change.region_range)
    params.apply(cloth)
    sim.refresh()
    return sim, params


def best_fit(fits: list[tuple[str, tuple[ImplicitSimulator, CandidateParams]]], train: list[Observed],
             pinned: np.ndarray, effect: tuple[str, ...], tie: float
             ) -> tuple[tuple[ImplicitSimulator, CandidateParams], float, str, dict[str, float]]:
    """Of labelled simulators at earlier fits, the one that rolls `train` out best or, where three or more roll
    it out within `tie` (m) of the best, the central one of those by their `effect` parameters (central_fit); its
    rollout error, its label (saying which choice it was) and every fit's rollout error.

    Why the best (pipeline.final_fit): the split's fit and the other folds' fits of the same model each saw most of
    the recordings, and their parameters spread where the recordings barely identify them; the delivered model
    should roll every recording out well. Measured (session 44, /work/data/s44/final_fit.py re-running the final
    fit of session 43's `gg bench diagnose` reports, Blender, seed 1, 20 steps): hidden air damping, the folds'
    alpha 10.46 (the split's), 9.93 and 11.64 /s against a true 10; every recording rolled out 5.38, 5.05, 5.37 mm;
    the fit without the walk was kept: alpha 0.7 % off, where the split's fit refitted (before this) rolled out
    5.13 mm at 8.1 % off.

    Why the central one within `tie` (session 47): rollout differences smaller than what the diagnosis could call
    an effect (pipeline.final_fit passes the profiles' tolerance, identify.PROFILE_TOLERANCE of the baseline's
    error) do not tell the fits apart, and the smallest of several nearly equal errors picks whichever fit's
    parameters strayed furthest along the direction the recordings barely see. Measured by re-running the final
    fits of stored Blender diagnoses (sessions 43-46, 20 steps, noise 0; /work/data/s46/final_ranges.py): air
    damping s2, the fits' alpha 10.29 (the split's), 15.42, 9.48 /s rolled out 5.73, 5.60, 5.73 mm (tie 0.47 mm):
    delivered 15.4 /s (54 % off, the truth outside its profile's range) before, 10.29 (2.9 %, range 7.5-16.3) now;
    tilt s1, 1.55, 2.32, 2.12 m/s^2 at 8.08, 8.61, 8.43 mm (tie 0.69): the tilt 26 % off before, 3.3 % now (the
    tilt vector's error, as `gg bench diagnose` scores it; end to end the same); tilt s2, 2.27, 2.28, 2.56 at 8.57,
    8.65, 8.47 mm (tie 0.77): 22.7 % before, 11.3 % now; but air damping s1, 10.46 (the split's), 9.93, 11.64 at
    5.38, 5.05, 5.37 mm (tie 0.44): 0.7 % before, 8.1 % now (the split's, refitted: 10.81). The stiff patches are
    unchanged (s1: one fit outside the tie; s2: the same fit is central). Chosen after seeing these truths, on
    seven cases. On seeds nobody had looked at (session 48: gravity and air damping s3, s4) it never chose
    differently from the plain best: two had two fits in the tie, in two the central fit was also the best."""
    by_label = dict(fits)
    errors = {label: mean_rollout_error(sim, train, pinned) for label, (sim, _) in fits}
    label = min(errors, key=errors.get)
    close = [k for k in errors if errors[k] <= errors[label] + tie]
    if len(close) < 3:
        return by_label[label], errors[label], label, errors
    label = central_fit({k: by_label[k][1].values() for k in close}, effect, errors)
    read = f"{label} (the central one of {len(close)} fits rolling out within {1e3 * tie:.2f} mm)"
    return by_label[label], errors[label], read, errors


def central_fit(values: dict[str, dict[str, object]], effect: tuple[str, ...], errors: dict[str, float]) -> str:
    """The label of the fit whose `effect` parameters (Trial.values keys) lie closest to the others' in total
    (the medoid; the lower rollout error on ties): positive scalars compared in log, vectors in units of the fits'
    mean length, so a scale and a direction weigh alike whatever their units."""
    labels = list(values)
    columns = []
    for key in effect:
        v = np.array([np.atleast_1d(np.asarray(values[k][key], np.float64)) for k in labels])
        if v.shape[1] == 1 and np.all(v > 0):
            columns.append(np.log(v))
        else:
            length = float(np.linalg.norm(v, axis=1).mean())
            columns.append(v / length if length > 0 else v)
    x = np.concatenate(columns, axis=1)
    total = dict(zip(labels, np.linalg.norm(x[:, None] - x[None], axis=2).sum(1)))
    return min(labels, key=lambda k: (round(float(total[k]), 12), errors[k]))


def at_values(cloth: Cloth, sim: ImplicitSimulator, region_logs: dict[str, float], values: dict[str, object]
              ) -> dict[str, float]:
    """Set `cloth`'s global material and `sim`'s term parameters to a trial's fitted `values` (Trial.values), so
    CandidateParams built next starts at them; returns the region's log-scales at those values (its region_init)."""
    cloth.material = Material.uniform(cloth.n_vertices, **{n: float(values[f"material.{n}"]) for n in MATERIAL_NAMES})
    for term in sim.terms:
        for key in term.params:
            if (value := values.get(f"{term.name}.{key}")) is not None:
                term.params[key] = torch.tensor(value, dtype=torch.float64)
    return {k: float(np.log(values[region_value(k)])) for k in region_logs}


def refit_or_keep(sim: ImplicitSimulator, params: CandidateParams, train: list[Observed], pinned: np.ndarray,
                  config: FitConfig, kept_error: float, origin: str) -> tuple[float, float, str]:
    """From an earlier trial's fit (at_values; labelled `origin`, rolling `train` out with `kept_error`): refit on
    `train`, and keep that refit only where it rolls `train` out better than the earlier fit did; leaves the better
    applied, returns its loss, training rollout error and which it was.

    Why (pipeline.final_fit): the split's fit already holds what the rollouts chose (its scale, its start, a
    friction grid value); a refit on every recording started anew from the baseline repeats that search with the
    same few iterations and can end further off. Measured (session 41, the Blender tilt test at 4 iterations):
    the split's tilt 2.21 m/s^2, the final fit from the kept start 2.83 (truth about 2.09)."""
    kept = params.snapshot()
    loss = refit(sim, params, train, params.trainable(), config)
    error = mean_rollout_error(sim, train, pinned)
    if error < kept_error:
        return loss, error, f"{origin}, refitted"
    params.restore(sim, kept)
    return refit(sim, params, train, [], replace(config, global_iterations=0)), kept_error, origin


def refit_or_scale(sim: ImplicitSimulator, params: CandidateParams, first: int, train: list[Observed],
                   pinned: np.ndarray, config: FitConfig) -> tuple[float, float, str]:
    """A single candidate's coefficients (params.term_s from index `first` on), chosen on the training rollouts
    among: (a) the candidate added to the UNREFITTED baseline at its start, scaled by rollout_scale; (b) its refit
    with the material from that start, scaled the same way; (c) where (a) rolls out better than (b), the refit
    started from (a), scaled again where scaling moved it (unscaled, (a) is the start and (c) would repeat (b)).
    Leaves the best applied; returns its teacher-forced loss, its training rollout error and where its value came
    from. A region candidate's coefficients are its region's log-scales (rollout_scale scales those).
    Only (b) where the start is the baseline itself (no coefficient, no region scale).

    Why (a): the refit predicts observed states a few frames ahead, and where the one-frame residual is mostly
    measurement error it can move the material so that free rollouts get worse than with no refit at all.
    Measured (session 32) on the demo capture's registered meshes (3 mm off the truth) with a hidden gravity tilt:
    the tilt's refit moved density 0.084 -> 0.149 kg/m^2 and the loss factor 0.13 -> 0.97 and gained 2.4 %
    held-out, where the baseline with the tilt added and nothing refitted gains 14-17 %. Why (c): (a) alone keeps
    the baseline's material, which the effect's absence biased; on Blender's hidden tilt (seed 1) choosing (a)
    where it won left the tilt 26 % off, against 14 % with the refit (session 33). On ground truth too (session
    38, Blender's hidden air damping at 20 steps, seeds 1 / 2): the refit alone had left alpha 25 / 40 % off
    (seed 1: 12.5 /s against 10; the internal damping it moves trades against it), with (a)-(c) 4.6 / 2.9 %, and the
    gains over the folds rose from -35 / -31 % to -38 / -33 %. Why (a) for regions too: on Blender's hidden stiff
    patch (seed 1, 20 steps, session 41) the region stiffness refit from the regression's start (stretch x1.27,
    bending x4.8 on the localized region, 35 of its 44 vertices in the true patch) ended, in the fold that held the
    walk out, at both scales' lower bound (x0.1) and rolled the training sequences out 8.2 % worse than the
    baseline, so the fold guard refused the effect (held-out +14 % over the folds)."""
    if not _starts_off_baseline(params, first):
        loss = refit(sim, params, train, params.trainable(), config)
        error, factor = rollout_scale(sim, params, first, train, pinned, mean_rollout_error(sim, train, pinned))
        return loss, error, f"regression{scale_label(factor)}"
    start = params.snapshot()
    error, factor = rollout_scale(sim, params, first, train, pinned, mean_rollout_error(sim, train, pinned))
    unrefitted = (error, params.snapshot(), None, f"without refit{scale_label(factor)}")
    options = [unrefitted]
    restarts = [(start, "regression")]
    if factor != 1.0:   # unscaled, (a) is the start itself, and (c) would repeat (b)
        restarts.append((unrefitted[1], f"without refit{scale_label(factor)}, then refit"))
    for values, origin in restarts:
        params.restore(sim, values)
        loss = refit(sim, params, train, params.trainable(), config)
        error, factor = rollout_scale(sim, params, first, train, pinned, mean_rollout_error(sim, train, pinned))
        options.append((error, params.snapshot(), loss, f"{origin}{scale_label(factor)}"))
        if error <= unrefitted[0]:
            break       # the refit rolls out at least as well as the unrefitted start: no restart from it
    error, values, loss, label = min(options, key=lambda o: o[0])
    params.restore(sim, values)
    if loss is None:    # the unrefitted start: its loss, evaluated without an iteration
        loss = refit(sim, params, train, [], replace(config, global_iterations=0))
    return loss, error, label


def _starts_off_baseline(params: CandidateParams, first: int) -> bool:
    """Whether the candidate's start changes the baseline: a nonzero term coefficient (params.term_s from index
    `first` on) or a region scale other than 1."""
    terms = any(np.any(np.asarray(term.params[key].detach()) != 0) for term, key, _ in params.term_refs[first:])
    return terms or bool(torch.any(params.region_s != 0))


def scale_label(factor: float) -> str:
    """How a rollout_scale factor reads in a trial's start label ("" where it left the coefficients alone)."""
    return "" if factor == 1.0 else f", rollout scale x{factor:.3g}"


def rollout_scale(sim: ImplicitSimulator, params: CandidateParams, first: int, train: list[Observed],
                  pinned: np.ndarray, refit_error: float) -> tuple[float, float]:
    """Scale the candidate's current change by the factor in SCALE_RANGE that rolls the training sequences out
    best (golden section on its logarithm, SCALE_EVALUATIONS rollouts of each), where that beats `refit_error`
    (unscaled); leaves it applied, returns that error and the factor (1.0: left alone). The change is its term
    coefficients (params.term_s from index `first` on), or, without any, its region's log-scales (params.region_s:
    the region's scales raised to the factor's power, within their declared range).

    Why: the refit predicts observed states a few frames ahead, where a slow force barely shows against the
    material, which the refit moves too. Measured offline on stored benchmark trials (our simulator, hidden
    gravity tilt of 2.55 m/s^2, seed 1): the refit reached a tilt of 0.79 (held-out 11.6 -> 6.4 mm), scaled by
    2.55 on the training rollouts 2.02 (held-out 3.8 mm, -67 %); hidden air damping (alpha 10 /s): mass damping
    5.3 -> 12.5 /s, held-out -13 % -> -24 %. On the trials of four `none` captures (seeds 1-2, both simulators)
    the search moved held-out gains by -4 to +6 points, none above 9 % (mass damping, Blender seed 1, 9 % before
    the search too; 10 % is needed). Regions too: a stiffer patch's bending barely shows a few frames ahead
    either. Measured offline (session 44, each fold of Blender's hidden stiff patch alone, bending x30, 20 steps):
    seed 2's region stiffness gained +21 / -1 / +20 % held out over the folds (mean 13 %, named; unscaled +17 / -5
    / +10 %, mean 7 %, missed), its bending x15 / x16 / x9 (unscaled x5 / x3 / x5); seed 1 +24 / +5 / +28 %
    (unscaled, in the benchmark, +14 / +9 / +19 %); the `none` capture (seed 2) +1.3 % held out. The benchmark
    on this code (session 45) reproduced those figures and named the stiff patch on both seeds (-19 / -13 % over
    the folds, 123 / 103 % of the true region's gain); `none` s2 stayed none."""
    if first < len(params.term_s):
        changed, moved = params.term_s, params.term_s.detach().clone()

        def scaled(log_factor: float) -> torch.Tensor:
            out = moved.clone()
            out[first:] += log_factor
            return out
    elif params.region_keys:
        changed, moved = params.region_s, params.region_s.detach().clone()

        def scaled(log_factor: float) -> torch.Tensor:
            return torch.clamp(moved * np.exp(log_factor), params.region_lo, params.region_hi)
    else:
        return refit_error, 1.0

    def scale(log_factor: float) -> None:
        with torch.no_grad():
            changed.copy_(scaled(log_factor) if log_factor else moved)   # unscaled: the refit as it was, unclamped
        params.apply(sim.cloth)
        sim.refresh()

    def error(log_factor: float) -> float:
        scale(log_factor)
        return mean_rollout_error(sim, train, pinned)

    log_factor, best = golden_section(error, *np.log(SCALE_RANGE), SCALE_EVALUATIONS)
    if best >= refit_error:
        log_factor, best = 0.0, refit_error
    scale(log_factor)
    return best, float(np.exp(log_factor))


def golden_section(f: Callable[[float], float], lo: float, hi: float, evaluations: int) -> tuple[float, float]:
    """(argmin, min) of `f` on [lo, hi] by golden-section search with `evaluations` calls (f unimodal there)."""
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = lo, hi
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(evaluations - 2):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = f(d)
    return (c, fc) if fc < fd else (d, fd)


def rollout_choice(sim: ImplicitSimulator, cand: Candidate, ctx: Context, train: list[Observed], pinned: np.ndarray,
                   refit_error: float) -> tuple[float, str]:
    """The refitted simulator's coefficient of `cand`, or the one of `cand.rollout_values` that rolls the
    training sequences out best, whichever is better there (set on `sim`'s terms); returns that error and where
    the value came from.

    Why: friction is stick-slip. Where the cloth sticks, the force is the sticking spring's and the coefficient
    only bounds it, so a fit a few frames ahead of observed states barely sees it, while free rollouts do.
    Measured on the t-shirt with hidden friction (Blender friction 60, seeds 1 / 2): the refit kept mu at
    0.50 (from 0.50), where mu 1.0 rolls the training sequences out 10.9 / 13.8 % better and the held-out one
    21.7 / 14.3 %. Searched this way for every candidate (a log-scale of the refitted coefficients, 1/4 to
    64), smooth terms lost: on 17 stored benchmark reports the verdicts changed to a false alarm on `none` s2
    (anisotropy scaled 16x, -17.5 %) and a miss of wind s2 (the training rollouts chose half the wind)."""
    (term, key), = ((name, k) for name, ps in cand.model(np.zeros(1), ctx).terms.items() for k in ps)
    grid = [(added, cand.model(np.array([added]), ctx).terms[term][key]) for added in cand.rollout_values]
    target = next(t for t in sim.terms if t.name == term)
    best, value, label = refit_error, target.params[key].detach().clone(), "regression"
    for added, coefficient in grid:
        target.params[key] = torch.tensor(coefficient, dtype=torch.float64)
        error = mean_rollout_error(sim, train, pinned)
        if error < best:
            best, value, label = error, target.params[key], f"rollout grid ({key} + {added:g})"
    target.params[key] = value
    return best, label
