"""Sparse selection on designs with a known answer: the right candidates enter, bounds hold, the bootstrap
resamples blocks, and pure noise selects nothing."""
from __future__ import annotations

import numpy as np
import pytest

from gg_core.diagnosis.library import BY_NAME
from gg_core.diagnosis.selection import MIN_BOOTSTRAP_BLOCKS, Design, Selection, fit, forward, gram, select
from gg_core.diagnosis.verdict import selected


def design(effects: dict[str, np.ndarray], rows: int = 1200, noise: float = 1.0, seed: int = 0) -> Design:
    rng = np.random.default_rng(seed)
    nuisance = rng.normal(size=(rows, 4))
    blocks = {n: rng.normal(size=(rows, len(c.coefficients))) for n, c in BY_NAME.items()}
    y = nuisance @ rng.normal(size=4) * 5 + rng.normal(0, noise, rows)
    for name, coefs in effects.items():
        y += blocks[name] @ coefs
    return Design(y, nuisance, blocks, np.repeat(np.arange(12), rows // 12))


def test_selection_names_the_hidden_terms_with_their_coefficients():
    sel = select(design({"mass_damping": np.array([0.8]), "wind": np.array([0.5, -0.4])}), BY_NAME,
                 min_gain=0.05, n_boot=40)
    assert sel.order[:2] == ["mass_damping", "wind"] and len(sel.order) == 2
    assert sel.inclusion["mass_damping"] == 1.0 and sel.inclusion["wind"] == 1.0
    assert sel.inclusion["air_drag"] < 0.2
    assert sel.coefs["mass_damping"] == pytest.approx([0.8], abs=0.1)
    lo, hi = sel.interval["mass_damping"][0]
    se = (hi - lo) / 3.29                                      # the 5-95 % interval spans 3.29 standard errors
    assert lo < sel.coefs["mass_damping"][0] < hi and 0.005 < se < 0.1
    assert abs(sel.coefs["mass_damping"][0] - 0.8) < 4 * se   # the interval's width matches the actual error


def test_noise_alone_selects_nothing():
    sel = select(design({}), BY_NAME, min_gain=0.05, n_boot=40)
    assert sel.order == []
    assert max(sel.inclusion.values()) < 0.2
    assert max(sel.explained.values()) < 0.05


def test_one_sided_coefficients_stay_on_their_side():
    d = design({"mass_damping": np.array([-0.8])})           # "negative damping" is not a candidate effect
    result = fit(gram(d), ["mass_damping"], BY_NAME)
    assert result.coefs["mass_damping"][0] == 0.0
    chosen, _ = forward(gram(d), {n: BY_NAME[n] for n in ("mass_damping", "air_drag")}, 0.05)
    assert chosen == []


def test_gram_of_blocks_sums_to_the_full_gram():
    d = design({"wind": np.array([0.5, 0.0])})
    full = gram(d)
    parts = [gram(d, d.groups == b, full.scale) for b in np.unique(d.groups)]
    summed = full.reweighted(parts, np.ones(len(parts)))
    assert np.allclose(summed.xx, full.xx) and np.allclose(summed.xy, full.xy) and summed.yy == pytest.approx(full.yy)


def test_paired_bootstrap_prefers_the_true_pattern_where_neither_share_clears_the_bar():
    # registered meshes: every share falls below min_gain together; the rival's columns only half match the truth's
    d = design({}, seed=2)
    tilt = d.blocks["gravity_offset"]
    d.blocks["wind"] = tilt + np.random.default_rng(102).normal(size=tilt.shape)
    d.y += tilt @ np.array([0.15, 0.1])
    sel = select(d, BY_NAME, min_gain=0.05, n_boot=100)
    assert sel.order == [] and sel.explained["wind"] < sel.explained["gravity_offset"] < 0.05
    assert len(sel.shares["wind"]) == 100
    assert sel.preference("gravity_offset", "wind") >= 0.95 and sel.preference("wind", "gravity_offset") <= 0.05
    assert sel.preference("air_drag", "wind") < 0.5                  # explains nothing: never ahead
    assert Selection(1.0, [], {}, {}, {}).preference("wind", "air_drag") == 0.5   # no replicates, no preference


def test_too_few_blocks_leave_the_uncertainty_unknown_not_certain():
    # one training recording of 8 frames is one block: every replicate would be the data itself
    d = design({"mass_damping": np.array([0.8])})
    few = Design(d.y, d.nuisance, d.blocks, np.repeat(np.arange(MIN_BOOTSTRAP_BLOCKS - 1), 400))
    sel = select(few, BY_NAME, min_gain=0.05, n_boot=40)
    assert sel.order == ["mass_damping"] and sel.coefs["mass_damping"] == pytest.approx([0.8], abs=0.1)
    assert not sel.resampled and sel.blocks == MIN_BOOTSTRAP_BLOCKS - 1
    assert np.isnan(sel.inclusion["mass_damping"]) and np.isnan(sel.interval["mass_damping"]).all()
    assert sel.preference("mass_damping", "wind") == 0.5
    assert selected(sel, 0.5) == []                    # an unknown stability breaks no tie
    enough = select(design({"mass_damping": np.array([0.8])}), BY_NAME, min_gain=0.05, n_boot=40)
    assert enough.resampled and enough.blocks == 12 and selected(enough, 0.5) == ["mass_damping"]
