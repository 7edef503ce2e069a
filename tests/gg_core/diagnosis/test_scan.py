"""Region scan: growing a region over neighbouring patches finds the patches the residual came from and nothing in
noise; on our own simulator, a hidden rest-length change on a strip of a hanging sheet is found on that strip, by
the fitted field and by the patches, and the training rollouts choose the start on the strip over one off it, and
nothing where nothing is hidden."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from diagnosis_helpers import shrunk_strip, swaying

from gg_core.diagnosis.library import BY_NAME, Context
from gg_core.diagnosis.residuals import build_frames, make_pooling, residual
from gg_core.diagnosis.scan import MIN_SHARE, grow, nuisance_rss, patch_adjacency, rollout_region, scan_region
from gg_core.physics.fitting import mean_rollout_error

REST = BY_NAME["rest_length_region"]


def test_patch_adjacency_joins_patches_that_share_an_edge():
    patch = np.array([0, 0, 1, 1, 2, -1])
    edges = np.array([[0, 1], [1, 2], [3, 4], [4, 5], [0, 5]])
    assert patch_adjacency(patch, edges) == [{1}, {0, 2}, {1}]


def _chain(n: int) -> list[set[int]]:
    return [{k - 1, k + 1} & set(range(n)) for k in range(n)]


def test_grow_takes_the_neighbouring_patches_the_residual_came_from():
    rng = np.random.default_rng(0)
    columns = rng.normal(size=(10, 600, 1))
    groups = np.repeat(np.arange(10), 60)
    nuisance = rng.normal(size=(600, 2))       # unrelated global re-adjustment columns
    y = -0.5 * (columns[4] + columns[5] + columns[6])[:, 0] + 0.3 * rng.normal(size=600)
    base = nuisance_rss(y, nuisance, groups)
    chosen, share, alone = grow(REST, y, nuisance, columns, groups, base, _chain(10), 5, 0.05)
    assert sorted(chosen) == [4, 5, 6]
    assert share > 0.85 and share > alone.max() + 0.3         # signal 0.75 of 0.84 in all
    chosen, share, _ = grow(REST, y, nuisance, columns, groups, base, _chain(10), 2, 0.05)
    assert len(chosen) == 2                                 # the size cap holds
    noise = rng.normal(size=600)
    chosen, share, alone = grow(REST, noise, nuisance, columns, groups, nuisance_rss(noise, nuisance, groups),
                                _chain(10), 5, 0.05)
    assert chosen == [] and alone.max() < 0.05              # noise: no region
    noise = rng.normal(size=600)
    assert grow(REST, noise, nuisance, columns, groups, nuisance_rss(noise, nuisance, groups), _chain(10), 5,
                MIN_SHARE)[0] == []


def test_hidden_rest_length_change_on_a_strip_is_found_there():
    v, pinned, strip, sequences, model = shrunk_strip(0.95)
    batch = build_frames(model, sequences)
    res = residual(model, batch)
    pooling = make_pooling(model, batch, patch_vertices=5, window=4)
    y = pooling.rows(res)
    ctx = Context.build(model, batch)
    before = mean_rollout_error(model, sequences, pinned)
    result = scan_region(REST, ctx, pooling, batch.x_next - res, y, np.ones((len(y), 1)), 0.5, sequences, pinned,
                         before, 0)
    assert result.region is not None and result.explained > 0.5
    found = result.region > 0
    on_strip = strip & (model.num.free > 0)
    assert result.patch_explained.argmax() in set(pooling.patch[on_strip])
    assert result.rollout_l2_before == before
    assert result.rollout_l2 < 0.5 * before and result.strength < 0     # a shrink rolls out better
    # the fitted field's region (rest_field.py) rolls out better than the patches' and is taken, at the hidden scale
    assert result.source == "field" and result.field_l2 == result.rollout_l2 < 0.05 * before
    assert result.strength == pytest.approx(np.log(0.95), rel=0.1)
    assert (found == strip).all()
    patches = scan_region(replace(REST, field_fit=None), ctx, pooling, batch.x_next - res, y, np.ones((len(y), 1)),
                          0.5, sequences, pinned, before, 0)
    found = patches.region > 0                                          # without a field: the patches
    assert patches.source == "patches" and np.isnan(patches.field_l2)
    assert (found & on_strip).sum() >= 0.7 * on_strip.sum() and (found & ~strip).sum() <= (found & strip).sum()
    assert patches.rollout_l2 < 0.5 * before and patches.strength < 0

    off = [int(p) for p in set(pooling.patch[~strip & (model.num.free > 0)]) - set(pooling.patch[strip])]
    neighbours = patch_adjacency(pooling.patch, model.num.edges)
    on = int(pooling.patch[on_strip][0])
    rolled = rollout_region(REST, ctx, pooling.patch, [[off[0]], [on]], neighbours, 4, sequences, pinned, before)
    assert set(rolled.patches) == set(pooling.patch[on_strip])      # grown from the strip over all of it
    assert rolled.strength == pytest.approx(np.log(0.95), rel=0.2) and rolled.error < 0.3 * rolled.before

    still = swaying(model, v)                  # nothing hidden: no change rolls out better, the first start stands
    calm = mean_rollout_error(model, still, pinned)
    rolled = rollout_region(REST, ctx, pooling.patch, [[off[0]], [on]], neighbours, 4, still, pinned, calm)
    assert rolled.patches == [off[0]] and rolled.strength == 0.0 and rolled.error == rolled.before == calm
