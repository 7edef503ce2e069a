"""Localization: a planted hot patch is found as the standout region, a uniform map has none, the map's
best-correlated feature is reported, and a patch that stretches less than the simulation says is found from the
deformation activity (a more active one is not: that side is left to the residual)."""
from __future__ import annotations

import numpy as np
from physics_helpers import sheet

from gg_core.diagnosis.localize import _best, activity_map, activity_region, standout_region, strain_activity
from gg_core.geometry.topology import build_topology


def test_standout_region_finds_a_planted_patch():
    v, f = sheet(12, 12, 0.6, 0.6)
    edges = build_topology(f, len(v)).edges
    rng = np.random.default_rng(0)
    values = 1.0 + 0.05 * rng.normal(size=len(v))
    patch = np.linalg.norm(v[:, [0, 2]] - [0.15, 0.1], axis=1) < 0.08
    values[patch] += 1.0
    free = np.ones(len(v), bool)
    region = standout_region(values, free, edges)
    assert region is not None
    found = region > 0
    assert (found & patch).sum() == patch.sum()             # the whole patch
    assert found.sum() <= patch.sum() + 3 * np.sqrt(patch.sum()) * 4   # plus about one ring
    assert standout_region(1.0 + 0.05 * rng.normal(size=len(v)), free, edges) is None


def test_best_feature_is_the_most_correlated_one():
    rng = np.random.default_rng(1)
    target = rng.random(100)
    name, rho = _best(target, {"noise": rng.random(100), "speed": target ** 2 + 0.01 * rng.random(100)})
    assert name == "speed" and rho > 0.95


def _jiggling_sheet(amplitude: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Frames [T,V,3] of a sheet whose vertices oscillate with per-vertex `amplitude` (m, 10 % noise drawn from
    `seed`) in fixed random directions."""
    v, f = sheet(16, 16, 0.6, 0.6)
    rng = np.random.default_rng(seed)
    direction = np.random.default_rng(0).normal(size=v.shape)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    t = np.sin(np.linspace(0, 4 * np.pi, 24))[:, None, None]
    return v + t * (amplitude * (1 + 0.1 * rng.normal(size=len(v))))[None, :, None] * direction, f


def test_strain_activity_follows_the_local_stretching():
    v, _ = sheet(16, 16, 0.6, 0.6)
    quiet = np.linalg.norm(v[:, [0, 2]] - [0.05, -0.05], axis=1) < 0.12
    frames, f = _jiggling_sheet(np.where(quiet, 0.0, 2e-3), seed=0)
    activity = strain_activity(frames, build_topology(f, len(v)).edges)
    inner = np.linalg.norm(v[:, [0, 2]] - [0.05, -0.05], axis=1) < 0.05
    assert activity[inner].max() < 0.2 * np.median(activity[~quiet])


def test_activity_region_finds_a_stiffer_patch_only():
    v, _ = sheet(16, 16, 0.6, 0.6)
    patch = np.linalg.norm(v[:, [0, 2]] - [-0.1, 0.05], axis=1) < 0.1
    simulated, f = _jiggling_sheet(np.full(len(v), 2e-3), seed=1)
    edges = build_topology(f, len(v)).edges
    free = np.ones(len(v), bool)
    stiffer, _ = _jiggling_sheet(np.where(patch, 4e-4, 2e-3), seed=2)
    z = activity_map([stiffer], [simulated], edges, free)
    region = activity_region(z, free, edges)
    assert region is not None
    found = region > 0
    assert (found & patch).sum() == patch.sum()
    # the map is averaged over one ring and the region grown by one: at most two (diagonal) grid spacings beyond
    assert np.linalg.norm(v[found][:, [0, 2]] - [-0.1, 0.05], axis=1).max() < 0.1 + 2 * np.sqrt(2) * 0.0375
    same, _ = _jiggling_sheet(np.full(len(v), 2e-3), seed=3)
    assert activity_region(activity_map([same], [simulated], edges, free), free, edges) is None
    softer, _ = _jiggling_sheet(np.where(patch, 1e-2, 2e-3), seed=4)
    z_soft = activity_map([softer], [simulated], edges, free)
    assert z_soft[patch].mean() > 4 and activity_region(z_soft, free, edges) is None
