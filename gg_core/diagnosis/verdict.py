"""The rules that turn confirming refits into a verdict: what trials must beat, when a gain counts, which
candidates are tried, named first, or left open beside the one named."""
from __future__ import annotations

import numpy as np

from ..physics.cloth import Cloth
from .confirm import INWARD, Trial
from .folds import CrossValidation
from .library import BY_NAME, region_scales
from .selection import Selection

# named_first: the share of bootstrap replicates in which a rival the folds do not separate from the rollouts' first
# must explain more of the residual alone than it, where the selection chose neither (a one-sided paired test).
# Measured (session 33, tilt against wind, 1000 replicates; the diagnosis draws 100): the demo capture's registered
# meshes with a hidden tilt, nothing selected, 0.97 for the tilt (0.96 with the diagnosis's 100; with session 32's
# trial starts, on main since session 34 (confirm.refit_or_scale, starts.lag_start), the rollouts led with wind by half
# a point, the trials before them confirmed neither). Where the selection chose one: for the tilt Blender's s1 / s2
# 0.79 / 1.0, our simulator's s2 at 1.5 mm 0.947, the demo capture's ground truth 0.997; Blender wind s1 0.90 for
# wind, but Blender wind s2 0.87 for the tilt, a wrong pattern: short of 0.95 the residual's preference is no
# evidence.
RESIDUAL_PREFERENCE = 0.95
INWARD_TOLERANCE = 0.05     # stopped_on_ends: a loss this small moving inside the range is no preference for its end


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


def implausible(t: Trial, cloth: Cloth, ends: bool = True) -> str | None:
    """Why the trial's refitted values are not cloth physics (Candidate.implausible, and with `ends`
    stopped_on_ends), or None."""
    return next((why for why in (BY_NAME[n].implausible(t.values, cloth) for n in t.names) if why),
                None) or (stopped_on_ends(t) if ends else None)


def stopped_on_ends(t: Trial) -> str | None:
    """Why a region refit whose every scale stopped on an end of its range has no estimate inside it: moved
    INWARD times inside, its training rollouts lose more than INWARD_TOLERANCE (confirm.inward_rollout); None
    where they lose less (the recordings do not pin those fields there) or a scale lies inside.

    Measured (session 57, Blender's seam shrink s1 with the unloaded garment given): heavy region refitted to
    density x0.1, the range's end, in all three folds, and was reported as a rival the folds could not separate
    from the named rest-length change; refusing every refit with all scales on an end removed it. But Blender's
    stiff patch s2 at 9.81 m/s^2 (session 72) was missed by that rule: its refit without the walk stopped on
    stretch x0.1 and bending x201, the true region's refit too, and the patch's stretch is a field these
    recordings do not pin (identify.py). Moved x2 inside, that refit rolled its training recordings out 8 % worse
    (session 73), so it has no estimate inside; the split's refit (x0.37, x22) and the other fold's had. So the
    rule refuses a candidate where the split's refit, the one delivered models start from, stopped there; a fold
    that held another recording out is reported (Result.fold_stops) and its gain counts as measured."""
    if t.inward_l2 is None or t.inward_l2 <= (1.0 + INWARD_TOLERANCE) * t.train_l2:
        return None
    fields = ", ".join(f"{k} x{v:.3g}" for k, v in region_scales(t.values).items())
    return (f"the region's refit stopped on the ends of this candidate's range ({fields}), and moved x{INWARD:g} "
            f"inside it rolls the training recordings out {100 * (t.inward_l2 / t.train_l2 - 1):.0f} % worse: it "
            f"has no estimate inside, the term stands in for something else")


def selected(sel: Selection, min_inclusion: float) -> list[str]:
    """The candidates the forward selection chose with bootstrap inclusion >= `min_inclusion`; none where the
    bootstrap could not resample (Selection.resampled): a choice whose stability is unknown breaks no tie."""
    return [n for n in sel.order if sel.inclusion[n] >= min_inclusion]


def named_first(cv: CrossValidation, by_rollouts: list[str], sel: Selection, min_inclusion: float,
                min_gain: float) -> list[str]:
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
    ranked = cv.residual_tie_break(by_rollouts, chosen, min_gain)
    if not ranked or ranked[0] != by_rollouts[0] or ranked[0] in chosen:
        return ranked
    lead = ranked[0]
    rivals = [n for n in ranked[1:]
              if not cv.separated(lead, n, min_gain) and sel.preference(n, lead) >= RESIDUAL_PREFERENCE]
    if not rivals:
        return ranked
    first = max(rivals, key=lambda n: sel.preference(n, lead))
    return [first] + [n for n in ranked if n != first]


def unresolved(cv: CrossValidation, passing: list[str], min_gain: float) -> list[str]:
    """The confirmed candidates of other equivalence classes than the first of `passing` that the folds do not
    separate from it (CrossValidation.separated): where neither the rollouts nor the residual chose, the report
    says the recordings leave the class open instead of naming one as if it were certain."""
    if not passing:
        return []
    lead = BY_NAME[passing[0]]
    return [n for n in passing[1:] if BY_NAME[n].equivalence != lead.equivalence
            and not cv.separated(lead.name, n, min_gain)]


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
    refitted and the training rollouts choose (starts.trial_from_starts)."""
    chosen = selected(sel, min_inclusion)
    others = sorted((n for n in sel.explained if n not in chosen), key=lambda n: -sel.explained[n])
    return (chosen + others)[:max_trials]


def closest(cv: CrossValidation, unphysical: dict[str, str], min_gain: float, min_gain_mm: float) -> dict | None:
    """Where nothing was confirmed, the physically plausible candidate that came nearest: the one refitted in every
    fold with the largest mean held-out gain (else the split's best), its gains per fold and the rules it failed
    (CrossValidation.shortfalls). `near_miss`: refitted with each recording held out (more than one fold) and it
    lowered the error there, weak evidence a user should see; a gain on the split alone is none. None where no
    plausible candidate was tried.

    Why: "nothing missing" and "something the recordings could not confirm" are different answers. Measured
    (session 53, Blender's hidden wind on two-recording tiny captures, the unloaded garment given): seed 1 named
    wind at +13.8 / +18.6 % over the two folds, seed 2 answered none at +3.2 / +13.6 %; the second is a near miss a
    user should see, to record more or longer motions, not a clean bill."""
    names = [n for n in cv.folds[0].trials if n not in unphysical]
    if not names:
        return None
    name = max(names, key=lambda n: (cv.complete(n), np.nan_to_num(cv.mean_gains(n)[0], nan=-np.inf)))
    held, train = cv.mean_gains(name)
    folds = [dict(zip(("heldout_gain", "train_rollout_gain"), f.gains(name)), heldout=f.heldout)
             for f in cv.folds if name in f.trials]
    return {"name": name, "class": BY_NAME[name].equivalence, "heldout_gain": held, "train_rollout_gain": train,
            "folds": folds, "near_miss": bool(len(folds) > 1 and held > 0),
            "min_gain": min_gain, "why_not": cv.shortfalls(name, min_gain, min_gain_mm)}
