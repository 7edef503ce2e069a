"""Rigid alignment of the template to a sequence's first frame: from the body, then (optionally scaled) ICP.

The body meshes of all frames share one topology, so the rigid motion of the body part under the garment
between the template frame and the new sequence's first frame (body_alignment) is a robust start: a worn
garment moves with the hips and shoulders it hangs from.

Point-to-point ICP with trimmed correspondences (the worst `1 - keep` fraction of nearest-neighbour pairs is
dropped each iteration, since the target cloud holds more or less than the garment) and the closed-form
similarity of Umeyama (1991) per iteration. Correspondences run both ways (template -> cloud and cloud ->
template) so that a partial cloud cannot pull the template into itself.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class Similarity:
    """x -> s R x + t."""

    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    s: float = 1.0

    def apply(self, points: np.ndarray) -> np.ndarray:
        return self.s * np.asarray(points, np.float64) @ self.R.T + self.t

    def then(self, other: "Similarity") -> "Similarity":
        """The similarity that applies self first, then other."""
        return Similarity(other.R @ self.R, other.s * other.R @ self.t + other.t, other.s * self.s)


def umeyama(src: np.ndarray, dst: np.ndarray, scale: bool = False) -> Similarity:
    """Least-squares similarity (or rigid motion) mapping src [N,3] onto dst [N,3]."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    cov = b.T @ a / len(src)
    U, S, Vt = np.linalg.svd(cov)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / max((a * a).sum() / len(src), 1e-30)) if scale else 1.0
    return Similarity(R, mu_d - s * R @ mu_s, s)


def body_alignment(garment: np.ndarray, body_from: np.ndarray, body_to: np.ndarray,
                   radius: float = 0.05) -> Similarity:
    """Rigid motion of the body vertices within `radius` of the garment, from `body_from` to `body_to` (same
    topology); the identity when no body vertex is that close."""
    near = np.isfinite(cKDTree(np.asarray(garment, np.float64)).query(body_from, distance_upper_bound=radius)[0])
    if near.sum() < 3:
        return Similarity()
    return umeyama(np.asarray(body_from, np.float64)[near], np.asarray(body_to, np.float64)[near])


def icp(source: np.ndarray, target: np.ndarray, init: Similarity | None = None, scale: bool = False,
        iterations: int = 50, keep: float = 0.9, tol: float = 1e-7) -> tuple[Similarity, dict]:
    """Similarity aligning `source` points onto `target` points; returns it with a log (rms per iteration)."""
    source, target = np.asarray(source, np.float64), np.asarray(target, np.float64)
    current = init or Similarity()
    tree_t = cKDTree(target)
    rms: list[float] = []
    for _ in range(iterations):
        moved = current.apply(source)
        tree_s = cKDTree(moved)
        d_st, j = tree_t.query(moved)
        d_ts, i = tree_s.query(target)
        src = np.concatenate((moved, moved[i]))
        dst = np.concatenate((target[j], target))
        dist = np.concatenate((d_st, d_ts))
        good = dist <= np.quantile(dist, keep)
        step = umeyama(src[good], dst[good], scale)
        current = current.then(step)
        rms.append(float(np.sqrt(np.mean(dist[good] ** 2))))
        if len(rms) > 1 and abs(rms[-2] - rms[-1]) < tol:
            break
    return current, {"rms": rms, "iterations": len(rms)}
