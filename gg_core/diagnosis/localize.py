"""Where and when the model fails: a per-vertex residual map, a per-step residual curve, the state feature each
correlates with most, and the garment region that stands out (region candidates act there).

Both are computed from the compliance-weighted residual (residuals.py) after the global parameters have been
re-adjusted to it (nuisance fit), so they show what no global material can explain. Units: acceleration (m/s^2,
the one-frame position error over the step length squared), comparable across mesh resolutions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.stats import spearmanr

from ..physics.simulator import ImplicitSimulator
from .residuals import Pooling

REGION_Z = 4.0              # robust z-score a vertex must exceed to belong to the standout region
REGION_MAX_FRACTION = 0.25  # larger "regions" are global effects, not a patch


@dataclass
class Localization:
    vertex_map: np.ndarray             # [V] m/s^2, RMS over time windows of the window-averaged residual
    step_curve: np.ndarray             # [N] m/s^2, mean over patches of the patch residual per step
    region: np.ndarray | None          # [V] 1.0 on the standout region
    vertex_feature: tuple[str, float]  # best-correlated feature of the map (name, Spearman rho)
    step_feature: tuple[str, float]


def _smooth(field: np.ndarray, edges: np.ndarray, passes: int = 2) -> np.ndarray:
    """Average each vertex with its one-ring ([..., V, 3]): internal-force noise alternates sign between
    neighbours and cancels, a missing external force does not."""
    n = field.shape[-2]
    adj = coo_matrix((np.ones(2 * len(edges)), (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                     shape=(n, n)).tocsr()
    adj = adj + coo_matrix((np.ones(n), (np.arange(n), np.arange(n))), shape=(n, n)).tocsr()
    deg = np.asarray(adj.sum(1)).ravel()
    by_vertex = np.moveaxis(field, -2, 0)
    flat = by_vertex.reshape(n, -1)
    for _ in range(passes):
        flat = adj @ flat / deg[:, None]
    return np.moveaxis(flat.reshape(by_vertex.shape), 0, -2)


def _best(target: np.ndarray, features: dict[str, np.ndarray]) -> tuple[str, float]:
    scores = {}
    for name, values in features.items():
        if np.ptp(values) > 0 and np.ptp(target) > 0:
            scores[name] = float(spearmanr(target, values).statistic)
    if not scores:
        return "none", 0.0
    name = max(scores, key=lambda k: abs(scores[k]))
    return name, scores[name]


def standout_region(vertex_map: np.ndarray, free: np.ndarray, edges: np.ndarray) -> np.ndarray | None:
    """Largest connected set of free vertices whose map value is a robust outlier (median + REGION_Z MADs), grown
    by one ring; None when nothing stands out or the set covers too much of the garment to be a region."""
    values = vertex_map[free]
    mad = 1.4826 * np.median(np.abs(values - np.median(values)))
    hot = free & (vertex_map > np.median(values) + REGION_Z * max(mad, 1e-12))
    if hot.sum() < 3:
        return None
    keep = hot[edges[:, 0]] & hot[edges[:, 1]]
    n = len(vertex_map)
    graph = coo_matrix((np.ones(int(keep.sum())), (edges[keep, 0], edges[keep, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    sizes = np.bincount(label[hot], minlength=label.max() + 1)
    region = hot & (label == np.argmax(sizes))
    if region.sum() < 3:
        return None
    grown = region.copy()
    touch = region[edges[:, 0]] | region[edges[:, 1]]
    grown[edges[touch].ravel()] = True
    grown &= free
    if grown.sum() > REGION_MAX_FRACTION * free.sum():
        return None
    return grown.astype(np.float64)


def localize(sim: ImplicitSimulator, pooling: Pooling, adjusted: np.ndarray, features: dict[str, np.ndarray]
             ) -> Localization:
    """`adjusted`: [N,V,3] compliance-weighted residual (m) after the nuisance fit."""
    num = sim.num
    free = num.free > 0
    timed = _smooth(pooling.over_time(adjusted), num.edges) / pooling.dt ** 2
    vertex_map = np.sqrt((np.linalg.norm(timed, axis=-1) ** 2).mean(0)) * free
    step_curve = np.linalg.norm(pooling.patch_means(adjusted), axis=-1).mean(1)
    vertex_feature = _best(vertex_map[free], {k: f.mean(0)[free] for k, f in features.items()})
    step_feature = _best(step_curve, {k: f[:, free].mean(1) for k, f in features.items()})
    return Localization(vertex_map, step_curve, standout_region(vertex_map, free, num.edges), vertex_feature,
                        step_feature)
