"""Which candidate forces explain the pooled residual: sparse regression with one-sided coefficients and a block
bootstrap for inclusion probabilities and intervals.

Model: y = N d + sum_k C_k c_k + e, with y the pooled residual rows, N the nuisance columns (global material
re-adjustment, free) and C_k each candidate's columns with its bounds. Forward selection adds the candidate that
lowers the residual sum of squares most, while the drop is at least `min_gain` of the nuisance-only RSS (an
effect must explain a visible share of what the model misses; the bounded coefficients make this a one-sided
test, where a plain F or chi^2 test would be wrong on the boundary). Rows are correlated within a time window and
with neighbouring windows, so the uncertainty comes from resampling whole blocks of consecutive windows within a
sequence (moving-block bootstrap), never single rows.

Everything works on Gram matrices: a fit needs only X^T X, X^T y and y^T y, which are sums over blocks, so a
bootstrap replicate costs a weighted sum of per-block Grams instead of a pass over the rows.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import lsq_linear

from .library import Candidate

# The fewest resampling blocks a bootstrap replicate is drawn from. With one block every replicate is the data
# itself: each selected candidate is "included" in 100 % of them, intervals have zero width and one candidate
# "explains more than another" in 100 % (measured, session 53: the two-recording tiny captures of `gg synth --preset
# tiny` train on one recording of 8 frames: 6 steps, one 6-frame window, one block; session 52 named wind over mass
# damping on such a capture by a residual preference of 1.0). With three blocks the replicates take at most 10
# distinct values. Four is what the suite's smallest diagnosed captures have (2 training recordings x 16 frames);
# the benchmark's (2 x 24) have eight.
MIN_BOOTSTRAP_BLOCKS = 4


@dataclass
class Design:
    y: np.ndarray                       # [R] pooled residual (m/s^2)
    nuisance: np.ndarray                # [R,Kn]
    blocks: dict[str, np.ndarray]       # candidate name -> [R,K] columns
    groups: np.ndarray                  # [R] resampling block of each row (consecutive windows of one sequence)


@dataclass
class Gram:
    """X^T X, X^T y, y^T y of all columns (nuisance first, then each candidate's), columns scaled to unit norm
    on the full data, plus the column range of every candidate."""

    xx: np.ndarray
    xy: np.ndarray
    yy: float
    scale: np.ndarray
    n_nuisance: int
    columns: dict[str, slice]

    def reweighted(self, parts: list["Gram"], counts: np.ndarray) -> "Gram":
        xx = sum(c * p.xx for c, p in zip(counts, parts))
        xy = sum(c * p.xy for c, p in zip(counts, parts))
        yy = float(sum(c * p.yy for c, p in zip(counts, parts)))
        return Gram(xx, xy, yy, self.scale, self.n_nuisance, self.columns)


def gram(design: Design, rows: np.ndarray | None = None, scale: np.ndarray | None = None) -> Gram:
    x = np.concatenate([design.nuisance] + list(design.blocks.values()), axis=1)
    if scale is None:
        scale = np.linalg.norm(x, axis=0)
        scale[scale == 0] = 1.0
    columns, start = {}, design.nuisance.shape[1]
    for name, block in design.blocks.items():
        columns[name] = slice(start, start + block.shape[1])
        start += block.shape[1]
    x, y = x / scale, design.y
    if rows is not None:
        x, y = x[rows], y[rows]
    return Gram(x.T @ x, x.T @ y, float(y @ y), scale, design.nuisance.shape[1], columns)


@dataclass
class Fit:
    coefs: dict[str, np.ndarray]    # physical units
    rss: float


def fit(g: Gram, names: list[str], candidates: dict[str, Candidate]) -> Fit:
    """Bounded least squares of y on the nuisance columns (free) and the named candidates' columns, solved on the
    Cholesky factor of the Gram matrix."""
    idx = np.concatenate([np.arange(g.n_nuisance)] + [np.arange(g.columns[n].start, g.columns[n].stop)
                                                      for n in names]).astype(int)
    xx = g.xx[np.ix_(idx, idx)] + 1e-10 * np.eye(len(idx))
    r = np.linalg.cholesky(xx).T
    q = np.linalg.solve(r.T, g.xy[idx])
    lo = [np.full(g.n_nuisance, -np.inf)] + [np.full(g.columns[n].stop - g.columns[n].start,
                                                      candidates[n].bounds[0]) for n in names]
    hi = [np.full(g.n_nuisance, np.inf)] + [np.full(g.columns[n].stop - g.columns[n].start,
                                                     candidates[n].bounds[1]) for n in names]
    scale = g.scale[idx]
    result = lsq_linear(r, q, bounds=(np.concatenate(lo) * scale, np.concatenate(hi) * scale), method="bvls")
    rss = max(g.yy - q @ q + float(np.sum((r @ result.x - q) ** 2)), 0.0)
    x = result.x / scale
    coefs, offset = {}, g.n_nuisance
    for n in names:
        k = g.columns[n].stop - g.columns[n].start
        coefs[n] = x[offset:offset + k]
        offset += k
    return Fit(coefs, rss)


def forward(g: Gram, candidates: dict[str, Candidate], min_gain: float, max_terms: int = 3
            ) -> tuple[list[str], float]:
    """Greedy forward selection; returns the chosen names and the nuisance-only RSS."""
    base = fit(g, [], candidates).rss
    chosen: list[str] = []
    current = base
    while len(chosen) < max_terms:
        trials = {n: fit(g, chosen + [n], candidates).rss for n in g.columns if n in candidates and n not in chosen}
        if not trials:
            break
        best = min(trials, key=trials.get)
        if current - trials[best] < min_gain * base:
            break
        chosen.append(best)
        current = trials[best]
    return chosen, base


@dataclass
class Selection:
    rss_nuisance: float
    order: list[str]                                     # selected, in order of entry
    explained: dict[str, float]                          # each candidate alone: share of nuisance-only RSS removed
    coefs: dict[str, np.ndarray]                         # each candidate next to the selected ones, full data
    alone: dict[str, np.ndarray]                         # each candidate alone (a single-candidate trial's start)
    inclusion: dict[str, float] = field(default_factory=dict)
    interval: dict[str, np.ndarray] = field(default_factory=dict)   # [K,2] 5th / 95th bootstrap percentiles
    shares: dict[str, np.ndarray] = field(default_factory=dict)     # [B] `explained` in each bootstrap replicate
    blocks: int = 0                                      # resampling blocks the replicates were drawn from
    replicates: int = 0                                  # bootstrap replicates drawn

    @property
    def resampled(self) -> bool:
        """Whether the bootstrap ran: with fewer than MIN_BOOTSTRAP_BLOCKS blocks (or no replicates asked for) the
        inclusion probabilities and intervals are unknown (NaN), not certain."""
        return self.replicates > 0

    def preference(self, first: str, other: str) -> float:
        """Share of the bootstrap replicates in which `first` alone explains more of the residual than `other`
        alone: a paired comparison, so what moves both (how much of the residual is registration error in the
        resampled blocks) cancels, where each share's own interval does not. 0.5 without replicates."""
        a, b = self.shares.get(first), self.shares.get(other)
        if a is None or b is None or not len(a):
            return 0.5
        return float(np.mean(a > b))


def explained_share(rss: float, nuisance_rss: float) -> float:
    """Share of the nuisance-only residual sum of squares a fit removes (0 where there is none to remove)."""
    return 1.0 - rss / nuisance_rss if nuisance_rss > 0 else 0.0


def select(design: Design, candidates: dict[str, Candidate], min_gain: float, n_boot: int = 100,
           seed: int = 0) -> Selection:
    full = gram(design)
    order, base = forward(full, candidates, min_gain)
    alone = {n: fit(full, [n], candidates) for n in design.blocks}
    # coefficients (and their intervals) next to the selected terms, so they are not biased by an omitted effect
    context = {n: [m for m in order if m != n] + [n] for n in design.blocks}
    sel = Selection(base, order, {n: explained_share(f.rss, base) for n, f in alone.items()},
                    {n: fit(full, context[n], candidates).coefs[n] for n in design.blocks},
                    {n: f.coefs[n] for n, f in alone.items()})
    blocks = np.unique(design.groups)
    sel.blocks = len(blocks)
    if len(blocks) < MIN_BOOTSTRAP_BLOCKS or n_boot <= 0:
        sel.inclusion = {n: float("nan") for n in design.blocks}
        sel.interval = {n: np.full((len(sel.coefs[n]), 2), np.nan) for n in design.blocks}
        return sel
    parts = [gram(design, design.groups == b, full.scale) for b in blocks]
    rng = np.random.default_rng(seed)
    hits = {n: 0 for n in design.blocks}
    draws: dict[str, list[np.ndarray]] = {n: [] for n in design.blocks}
    shares: dict[str, list[float]] = {n: [] for n in design.blocks}
    for _ in range(n_boot):
        counts = np.bincount(rng.integers(0, len(blocks), len(blocks)), minlength=len(blocks))
        sample = full.reweighted(parts, counts)
        chosen, nuisance_rss = forward(sample, candidates, min_gain)
        for n in chosen:
            hits[n] += 1
        for n in design.blocks:
            beside = fit(sample, context[n], candidates)
            draws[n].append(beside.coefs[n])
            own = beside if context[n] == [n] else fit(sample, [n], candidates)
            shares[n].append(explained_share(own.rss, nuisance_rss))
    sel.replicates = n_boot
    sel.shares = {n: np.array(v) for n, v in shares.items()}
    sel.inclusion = {n: hits[n] / n_boot for n in design.blocks}
    sel.interval = {n: np.percentile(np.stack(d), [5, 95], axis=0).T for n, d in draws.items()}
    return sel
