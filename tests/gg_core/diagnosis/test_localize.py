"""Localization: a planted hot patch is found as the standout region, a uniform map has none, and the map's
best-correlated feature is reported."""
from __future__ import annotations

import numpy as np
from physics_helpers import sheet

from gg_core.diagnosis.localize import _best, standout_region
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
