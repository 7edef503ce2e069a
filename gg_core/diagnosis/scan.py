"""Region scan: where a change of one region field explains the residual, for region effects no deformation map
shows.

A rest-length change on a region (a tight seam, an elastic band) leaves no trace in the recorded shape or in how
much the cloth stretches: the rest shape is an observed frame, which already holds the seam pulled in. Measured on
the benchmark's hidden seam shrink (15 % on a 36-vertex side seam, noise 0): per-vertex log ratio of recorded over
simulated mean edge length AUC 0.44 / 0.45 (seeds 1 / 2), deformation activity AUC 0.35 / 0.42. What does show is
the tension it keeps: the one-frame residual is explained by a rest-length change on the seam's pooling patches
more than on any other patch (offline, the k-means partition of seed 0: explained shares 11 % and 9 % vs at most
1.2 % off the seam, seed 1; 19 % and 16 % vs 5 %, seed 2; the seam's patches ranked 1-4 of 50 in both).

So the scan fits the candidate's field change on each pooling patch alone (the same weak-form rows and nuisance
re-adjustment as the selection), starts from the patch it explains best, and grows the region patch by
neighbouring patch while one common change on the union explains at least GROWTH_SHARE more of the residual. A
region that explains less than MIN_SHARE, or covers more than REGION_MAX_FRACTION of the garment, is no region.
The scan proposes; held-out rollouts still decide (verdict.confirmed). A candidate that fits its own field vertex
by vertex (Candidate.field_fit: rest lengths, rest_field.py) has that field's region (field_region) tried on the
training rollouts too, at its best strength (fitted_field), and it replaces the patches' region where it rolls the
training recordings out better than it and than the baseline.

Measured in the benchmark (noise 0, the pipeline's pooling): seed 1 found 19 vertices along the waist from the
seam's top towards the back (4 on the seam; the seam pulls on the attached waistband there), and the trial gained
18 % held-out, where the true region lost 5 %; seed 2 found 27 vertices on the seam's upper half (10 on the seam),
the trial gained 15 % on the training rollouts but lost 6 % held-out (the true region gains 14 %). The signal
sits at the seam's top: the rest of it is free to shrink, which the rest shape absorbs. The scan is no evidence by
itself: on the `none` captures the grown region explained 15 % and 24 % of the residual (its trials gained 2 % and
-1 %). Which patches win depends on the k-means partition (offline, shrink seed 2: 12-vertex patches from two
seeds gave 10 / 27 and 12 / 32 vertices on the seam; 6-vertex patches stopped at one patch, 6 / 11 and 5 / 9).

The one-frame share is a poor guide to which patches of a seam matter: a uniform tension along a line cancels
inside it and shows at its ends, so patches in a seam's middle regress with the opposite sign and the union of the
seam's patches explains less than its best patch (Blender's seam shrink s3 with the unloaded garment given: the
best patch 6.1 %, all five seam patches together 2.0 %). So the region the one-frame scan proposes is then chosen
on the training rollouts (rollout_region): it, and each of the ROLLOUT_SEEDS patches that explain most alone, at
the strength that rolls the training recordings out best, the best grown patch by neighbouring patch while that
lowers the training rollout error by ROLLOUT_GROWTH. Measured offline (session 55, /work/data/s55/evalscan.py:
this scan on the stored baselines, the unrefitted baseline changed on the chosen region, held-out rollouts never
seen by the choice): s3 the one-frame region 31 vertices (17 on the seam) rolls out 11.5 mm on training at its
best scale (held-out 13.8 mm at x0.85), the baseline 12.2 / 15.5 mm; the rollouts' region 42 vertices (19 on the
seam) at x0.885, 9.1 / 8.7 mm (the true seam at x0.85: 8.2 / 6.1 mm); s1 kept the one-frame region (39
vertices, 21 on the seam, x0.86: 15.0 -> 9.7 mm training, 15.3 -> 8.9 mm held out); on `none` s1 no change
rolled the training recordings out better (7.8 mm), so its one-frame region stood, unscaled; on `none` s2 another
patch at x0.972 rolled the training recordings out 8 % better and the held-out one no better (5.84 mm both).
End to end (`gg bench diagnose --rest-given`, 20 steps): s3, missed before, named (-29.9 % over the folds, each
fold scanning its own recordings; the true seam -46.4 %), s2 -42.6 % (was -44.6 %), `none` s1 none.

Finer than patches, tried offline and not adopted (session 57, /work/data/s56/{border,strip,layer,peel}.py on
session 55's stored baselines of the seam shrinks s1-s3, the region's best scale each time): the seam's exact
vertices matter as much as the whole scan gains (s2: the true 36 vertices roll the training recordings out 7.98
mm, without the 6 where the seam is three vertices wide 9.28, the scan's region 9.22); no single vertex added at
the region's border (24, 5 on the seam) or removed (23) lowers it by more than 2.3 %; straight strips along the
region's axis reach 8.95; peeling the vertices the gradient of the teacher-forced loss w.r.t. per-edge rest
lengths points out (AUC 0.85 for the seam, 1 s) lowers the training rollouts on s1 / s2 / s3 by 13.5 / 5.2 / 2.6 %,
held out by 9.6 / 3.5 % on s1 / s2 but raises it by 8.3 % on s3; on `none` s1 two vertices added at x1.018 lower
held-out by 8 %. Changes of a few vertices are within the rollouts' sensitivity, so the patches stay the unit.

Measured and not kept (session 58, 432aace, reverted): the rollouts also starting from the 4 patches the fits' own
teacher-forced training loss is most sensitive to (one adjoint gradient in every patch's rest log-scale, 10-15 s;
checked against central differences within 0.1-3 %). Offline on six folds of the seam shrinks s1 / s3 with the
unloaded garment given (/work/data/s58/{probe,evalv,gradrank}.py), patches with 3 or more seam vertices ranked at
AUC 0.79-0.97 by it against 0.58-0.83 by the one-frame share, and s3's fold holding out the twist, where no share
seed rolled the training recordings out better, found the seam (held out -20.1 %, the true seam -36.9 %); but s1's
twist fold lost (-20.2 -> -15.8 %) and the six-fold mean moved only -26.8 -> -29.4 %. End to end (gg bench diagnose
--rest-given, 20 steps) s3 fell from -29.9 % over the folds (session 55) to -24.6 % (-41.6 / -26.3 / -5.9 %, the
true seam -42.0 %; a one-patch region of 12 vertices, 5 on the seam) and `none` s1 chose a sensitive patch that
rolled the training recordings out 7.9 % better and the held-out one 1.9 % worse (verdict none). Choosing the region
by the worst per-recording training ratio or the geometric mean instead of the mean changed no region.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..physics.fitting import Observed, mean_rollout_error
from .confirm import golden_section
from .library import Candidate, Context, applied
from .localize import REGION_MAX_FRACTION
from .residuals import Pooling, responses
from .selection import Design, explained_share, fit, gram

GROWTH_SHARE = 0.01     # share of the residual a neighbouring patch must add to join the region
# share the best patch must explain for the scan to propose a region at all: as little as a patch must add to
# grow one, since held-out rollouts decide and other candidates are tried whatever share they explain. With the
# selection's 5 % instead, our own simulator's hidden seam shrink (seed 1, unloaded rest mesh given) was never
# tried: its best patch, on the seam, explained 4.8 % (offline, /work/data/s21/scan_probe.py; the true region
# gains 36 % held-out)
MIN_SHARE = GROWTH_SHARE
ROLLOUT_SEEDS = 4          # single patches, those explaining most alone, tried on the rollouts beside the region
ROLLOUT_GROWTH = 0.01      # relative drop of the training rollout error a neighbouring patch must bring to join
STRENGTH_EVALUATIONS = 8   # rollouts of a golden-section search for a region's strength
GROWTH_EVALUATIONS = 5     # and for a grown region's, between none and the strength before it grew
FIELD_CORE = 0.5           # share of a fitted field's extreme a vertex's value must reach to be in its region


@dataclass
class ScanResult:
    region: np.ndarray | None    # [V] 1.0 on the chosen patches, None if nothing stood out
    patches: list[int]           # chosen patches, in order of entry
    explained: float             # share of the nuisance-only residual the region's one change explains
    patch_explained: np.ndarray  # [P] share each patch explains alone
    one_frame_patches: list[int]   # the region the one-frame residual grew, before the rollouts chose
    rollout_l2_before: float     # training rollout error of the baseline (m), NaN where nothing was rolled out
    rollout_l2: float            # of the baseline with the chosen region changed, at its best strength
    strength: float              # that change as a log-scale of the candidate's fields
    source: str = "patches"      # "patches": grown patch by patch; "field": the candidate's fitted field (field_fit)
    field_l2: float = float("nan")   # training rollout error of the fitted field's region at its best strength


def patch_adjacency(patch: np.ndarray, edges: np.ndarray) -> list[set[int]]:
    """Neighbouring patches of every patch (an edge joins their vertices); pinned vertices (-1) belong to none."""
    n = int(patch.max()) + 1
    a, b = patch[edges[:, 0]], patch[edges[:, 1]]
    keep = (a >= 0) & (b >= 0) & (a != b)
    out: list[set[int]] = [set() for _ in range(n)]
    for i, j in zip(a[keep], b[keep]):
        out[i].add(int(j))
        out[j].add(int(i))
    return out


def _share(cand: Candidate, y: np.ndarray, nuisance: np.ndarray, columns: np.ndarray, groups: np.ndarray,
           base: float) -> float:
    """Share of the nuisance-only residual sum of squares `base` that `columns` remove next to the nuisance."""
    g = gram(Design(y, nuisance, {cand.name: columns}, groups))
    return 0.0 if base <= 0 else explained_share(fit(g, [cand.name], {cand.name: cand}).rss, base)


def nuisance_rss(y: np.ndarray, nuisance: np.ndarray, groups: np.ndarray) -> float:
    """Residual sum of squares of the pooled residual rows `y` with only the nuisance columns fitted: what the
    shares of grow and _share are shares of."""
    return fit(gram(Design(y, nuisance, {}, groups)), [], {}).rss


def grow(cand: Candidate, y: np.ndarray, nuisance: np.ndarray, columns: np.ndarray, groups: np.ndarray, base: float,
         neighbours: list[set[int]], max_patches: int, min_share: float) -> tuple[list[int], float, np.ndarray]:
    """Patches of the region and its explained share of `base` (nuisance_rss) from per-patch response rows
    `columns` [P,R,K] (a change on a union of patches responds as the sum of their rows: the responses are linear
    in the change)."""
    alone = np.array([_share(cand, y, nuisance, c, groups, base) for c in columns])
    best = int(np.argmax(alone))
    chosen, share = [best], float(alone[best])
    if share < min_share:
        return [], share, alone
    total = columns[best].copy()
    while len(chosen) < max_patches:
        border = set().union(*(neighbours[p] for p in chosen)) - set(chosen)
        if not border:
            break
        tries = {q: _share(cand, y, nuisance, total + columns[q], groups, base) for q in border}
        q = max(tries, key=tries.get)
        if tries[q] < share + GROWTH_SHARE:
            break
        chosen.append(q)
        share = tries[q]
        total += columns[q]
    return chosen, share, alone


def _rows(cand: Candidate, ctx: Context, pooling: Pooling, predicted: np.ndarray, region: np.ndarray,
          acceleration: float, n_rows: int) -> np.ndarray:
    """[n_rows,K] pooled one-frame response rows of `cand`'s change on `region` (zero where the change does nothing
    there or its probe step failed to solve: it explains nothing)."""
    probes = cand.probes(replace(ctx, region=region), acceleration)
    if all(size > 0 for size, _ in probes):
        rows = pooling.rows(responses(ctx.sim, ctx.batch, predicted, probes)).T
        if np.isfinite(rows).all():
            return rows
    return np.zeros((n_rows, len(cand.coefficients)))


def field_region(u: np.ndarray) -> np.ndarray | None:
    """Region of a fitted per-vertex log-scale field `u`: 1.0 where it reaches FIELD_CORE of its extreme on the
    extreme's side, else 0 (None where the field is flat). A region, not the graded field: the effects it stands
    for (a shrunk seam, an elastic band) change a region uniformly, and the candidate's one strength then measures
    that change (a graded region's strength would be its extreme's, which no vertex group of the garment has).

    Why half (FIELD_CORE), cross-validated offline (session 63, /work/data/s63/core/corecv.py: session 61's stored
    fields cut at 0.2 / 0.3 / 0.4 / 0.5 / 0.65, each region's strength searched on the training rollouts, held out
    against the fold's baseline): on three seam-shrink folds the mean held-out gain is 33.5 / 43.7 / 43.8 / 43.9 /
    40.0 % (all but one vertex on the seam from 0.3 up, 26-28 of its 36 at 0.3, 13-22 at half), on two `none` folds
    7.0 / 7.6 / 5.8 / 4.2 / 5.7 % (at 0.3 one fold's region gains 11.2 %, past the 10 % a finalist needs): from 0.3
    to half the seams gain alike, and half gives a `none` least."""
    k = int(np.argmax(np.abs(u)))
    if abs(u[k]) < 1e-6:
        return None
    return (u / u[k] >= FIELD_CORE).astype(np.float64)


def scan_region(cand: Candidate, ctx: Context, pooling: Pooling, predicted: np.ndarray, y: np.ndarray,
                nuisance: np.ndarray, acceleration: float, train: list[Observed], pinned: np.ndarray,
                train_l2: float, seed: int) -> ScanResult:
    """The region of `cand` (a region candidate) from its response on each pooling patch, chosen on the rollouts
    of the training recordings `train` (rollout_region), which the unchanged simulator rolls out `train_l2` (m) off
    (the baseline fit measured it); `y` and `nuisance` are the pooled residual rows and nuisance columns of the
    selection, `predicted` the unchanged one-frame prediction. A candidate that fits its own field
    (Candidate.field_fit, sampled with `seed`) has that field's region tried on the same rollouts, and the
    region that rolls them out better is taken."""
    columns_arr = np.stack([_rows(cand, ctx, pooling, predicted, (pooling.patch == p).astype(np.float64),
                                  acceleration, len(y)) for p in range(pooling.n_patches)])
    free = pooling.patch >= 0
    sizes = np.bincount(pooling.patch[free], minlength=pooling.n_patches)
    max_patches = max(1, int(REGION_MAX_FRACTION * free.sum() / max(sizes.mean(), 1.0)))
    neighbours = patch_adjacency(pooling.patch, ctx.sim.num.edges)
    groups = pooling.groups()
    base = nuisance_rss(y, nuisance, groups)
    chosen, share, alone = grow(cand, y, nuisance, columns_arr, groups, base, neighbours, max_patches, MIN_SHARE)
    rolled = None
    if chosen:
        seeds = [[int(p)] for p in np.argsort(-alone)[:ROLLOUT_SEEDS] if [int(p)] != chosen]
        rolled = rollout_region(cand, ctx, pooling.patch, [chosen, *seeds], neighbours, max_patches, train, pinned,
                                train_l2)
    fitted = None if cand.field_fit is None else fitted_field(cand, ctx, train, pinned, seed)
    field_l2 = float("nan") if fitted is None else fitted.error
    # rollout_region's error is at most the baseline's (train_l2): where no start beats it, it reports that
    if fitted is not None and fitted.error < (train_l2 if rolled is None else rolled.error):
        explained = _share(cand, y, nuisance, _rows(cand, ctx, pooling, predicted, fitted.region, acceleration,
                                                     len(y)), groups, base)
        return ScanResult(fitted.region, [], explained, alone, chosen, train_l2, fitted.error, fitted.strength,
                          "field", field_l2)
    if rolled is None:
        return ScanResult(None, [], share, alone, [], float("nan"), float("nan"), 0.0, field_l2=field_l2)
    explained = _share(cand, y, nuisance, columns_arr[rolled.patches].sum(0), groups, base)
    return ScanResult(np.isin(pooling.patch, rolled.patches).astype(np.float64), rolled.patches, explained, alone,
                      chosen, rolled.before, rolled.error, rolled.strength, field_l2=field_l2)


def region_error(cand: Candidate, ctx: Context, region: np.ndarray, strength: float, train: list[Observed],
                 pinned: np.ndarray) -> float:
    """Training rollout error (m) of the simulator with `cand`'s fields changed by the log-scale `strength` on
    `region` (infinite where a rollout fails)."""
    change = cand.model(np.full(len(cand.coefficients), np.expm1(strength)), replace(ctx, region=region))
    with applied(ctx.sim, change, region) as sim:
        return float(np.nan_to_num(mean_rollout_error(sim, train, pinned), nan=np.inf))


@dataclass
class FittedField:
    """The region of a candidate's fitted field (field_region), at the strength that rolls the training
    recordings out best."""

    region: np.ndarray
    strength: float
    error: float


def fitted_field(cand: Candidate, ctx: Context, train: list[Observed], pinned: np.ndarray,
                 seed: int) -> FittedField | None:
    """`cand`'s own field fitted on the `train` recordings (Candidate.field_fit) as a region, its strength searched
    on their rollouts between none and twice the fitted extreme (the fit's teacher-forced loss looks a few frames
    ahead; the rollouts, like rollout_region's, look at the whole motion); None where the fit left the field flat."""
    u = cand.field_fit(ctx.sim, train, seed)
    region = field_region(u)
    if region is None:
        return None
    lo, hi = np.log1p(cand.bounds)
    extreme = float(u[np.argmax(np.abs(u))])
    strength, error = golden_section(lambda c: region_error(cand, ctx, region, float(np.clip(c * extreme, lo, hi)),
                                                            train, pinned), 0.0, 2.0, STRENGTH_EVALUATIONS)
    return FittedField(region, float(np.clip(strength * extreme, lo, hi)), error)


@dataclass
class RolledRegion:
    """A region tried on the training rollouts, at its best strength."""

    patches: list[int]
    strength: float     # log-scale of the candidate's fields on the region
    error: float        # training rollout error there (m)
    before: float       # the baseline's


def rollout_region(cand: Candidate, ctx: Context, patch: np.ndarray, starts: list[list[int]],
                   neighbours: list[set[int]], max_patches: int, train: list[Observed], pinned: np.ndarray,
                   before: float) -> RolledRegion:
    """The region, of the `starts` (patch lists, the one-frame region first) and what grows from the best of them,
    whose change at its best strength rolls the `train` recordings out best (`before`: the unchanged simulator's
    error). Each start's strength is searched over the candidate's declared range (golden section); a neighbouring
    patch joins where the union, at its best strength between none and the current one (a larger region needs
    less), lowers the error by ROLLOUT_GROWTH.
    Where no start beats the unchanged baseline, the one-frame region stands (the trial refits its strength)."""
    lo, hi = np.log1p(cand.bounds)

    def error(patches: list[int], strength: float) -> float:
        return region_error(cand, ctx, np.isin(patch, patches).astype(np.float64), strength, train, pinned)

    searched = [RolledRegion(p, *golden_section(lambda s, p=p: error(p, s), lo, hi, STRENGTH_EVALUATIONS), before)
                for p in starts]
    best = min(searched, key=lambda r: r.error)
    if best.error >= before:
        return replace(searched[0], error=before, strength=0.0)
    while len(best.patches) < max_patches:
        border = set().union(*(neighbours[p] for p in best.patches)) - set(best.patches)
        bracket = sorted((0.0, best.strength))
        tries = [RolledRegion(best.patches + [q], *golden_section(lambda s, q=q: error(best.patches + [q], s),
                                                                  *bracket, GROWTH_EVALUATIONS), before)
                 for q in sorted(border)]
        grown = min(tries, key=lambda r: r.error, default=None)
        if grown is None or grown.error > (1.0 - ROLLOUT_GROWTH) * best.error:
            break
        best = grown
    return best
