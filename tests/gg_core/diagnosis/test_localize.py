"""Localization: a planted hot patch is found as the standout region, a uniform map has none, the map's
best-correlated feature is reported, and a patch that stretches less than the simulation says is found from the
deformation activity (a more active one is not: that side is left to the residual), in its two extents (one ring,
hysteresis)."""
from __future__ import annotations

import numpy as np
from physics_helpers import sheet

from gg_core.diagnosis.localize import (ACTIVITY_BLIND_EXCESS, _best, activity_map, activity_regions, map_region,
                                        standout_region, strain_activity)
from gg_core.diagnosis.noise import correlated_noise
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


def test_standout_region_grown_by_hysteresis_follows_the_map():
    """A patch whose map stands out strongly only at its centre: one ring around the centre misses most of the
    patch; growing through vertices beyond 2 MADs takes all of it and not the background."""
    v, f = sheet(16, 16, 0.6, 0.6)
    edges = build_topology(f, len(v)).edges
    values = 0.05 * np.random.default_rng(3).normal(size=len(v))
    distance = np.linalg.norm(v[:, [0, 2]] - [0.05, 0.0], axis=1)
    patch, centre = distance < 0.15, distance < 0.05
    values[patch] = 0.15                     # about 3 MADs: under REGION_Z, over the growth threshold
    values[centre] = 1.0
    free = np.ones(len(v), bool)
    ring = standout_region(values, free, edges) > 0
    grown = standout_region(values, free, edges, grow_z=2.0) > 0
    assert (ring & patch).sum() < patch.sum()
    assert (grown & patch).sum() == patch.sum()
    assert (grown & ~patch).sum() <= 0.1 * patch.sum()


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


def _stiffer_patch() -> tuple[np.ndarray, ...]:
    """(vertices, patch, simulated frames, recorded frames, edges, free): a sheet whose recorded patch jiggles 5x less
    than the simulation says, the rest as simulated."""
    v, _ = sheet(16, 16, 0.6, 0.6)
    patch = np.linalg.norm(v[:, [0, 2]] - [-0.1, 0.05], axis=1) < 0.1
    simulated, f = _jiggling_sheet(np.full(len(v), 2e-3), seed=1)
    edges = build_topology(f, len(v)).edges
    free = np.ones(len(v), bool)
    stiffer, _ = _jiggling_sheet(np.where(patch, 4e-4, 2e-3), seed=2)
    return v, patch, simulated, stiffer, edges, free


def test_activity_region_finds_a_stiffer_patch_only():
    v, patch, simulated, stiffer, edges, free = _stiffer_patch()
    z, excess = activity_map([stiffer], [simulated], edges, free)
    assert 0.8 < excess < 1.25                  # the rest of the sheet stretches as simulated
    region, grown = activity_regions(z, free, edges)
    assert region is not None
    found = region > 0
    assert (found & patch).sum() == patch.sum()
    # the map is averaged over one ring and the region grown by one: at most two (diagonal) grid spacings beyond
    assert np.linalg.norm(v[found][:, [0, 2]] - [-0.1, 0.05], axis=1).max() < 0.1 + 2 * np.sqrt(2) * 0.0375
    if grown is not None:                    # the hysteresis extent differs from the ring's, and holds the patch too
        assert not np.array_equal(grown, region) and (grown[patch] > 0).all()
    same, _ = _jiggling_sheet(np.full(len(v), 2e-3), seed=3)
    assert activity_regions(activity_map([same], [simulated], edges, free)[0], free, edges) == (None, None)
    softer, _ = _jiggling_sheet(np.where(patch, 1e-2, 2e-3), seed=4)
    z_soft, _ = activity_map([softer], [simulated], edges, free)
    assert z_soft[patch].mean() > 4 and activity_regions(z_soft, free, edges) == (None, None)


def test_activity_excess_says_when_noise_swamps_the_stretching():
    """Position noise stretches every edge whatever the motion: recorded over simulated activity is then well above
    one over the whole sheet, the stiffer patch no longer stands out, and the excess says so."""
    v, patch, simulated, stiffer, edges, free = _stiffer_patch()
    noisy = stiffer + correlated_noise(v, 0.02, 0.05, len(stiffer), np.random.default_rng(5))
    z, excess = activity_map([noisy], [simulated], edges, free)
    assert excess > ACTIVITY_BLIND_EXCESS
    assert activity_regions(z, free, edges) == (None, None)
    assert activity_map([stiffer], [simulated], edges, free)[1] < ACTIVITY_BLIND_EXCESS


def test_a_blind_activity_map_places_no_region_and_the_residual_map_is_used():
    v, f = sheet(12, 12, 0.6, 0.6)
    edges = build_topology(f, len(v)).edges
    free = np.ones(len(v), bool)
    rng = np.random.default_rng(2)
    low = np.linalg.norm(v[:, [0, 2]] - [-0.15, 0.1], axis=1) < 0.08
    hot = np.linalg.norm(v[:, [0, 2]] - [0.15, -0.1], axis=1) < 0.08
    z = rng.normal(size=len(v)) - 10.0 * low          # the activity map singles out `low`
    residual = 1.0 + 0.05 * rng.normal(size=len(v)) + hot
    region, _, source = map_region(z, 1.0, residual, free, edges)
    assert source == "deformation activity" and (region[low] > 0).all() and not (region[hot] > 0).any()
    region, grown, source = map_region(z, ACTIVITY_BLIND_EXCESS, residual, free, edges)
    assert source == "residual" and (region[hot] > 0).all() and not (region[low] > 0).any() and grown is None
    assert map_region(z, 3.0, np.ones(len(v)), free, edges) == (None, None, "none")
