"""Residuals and responses on data from our own simulator: zero when the model is the truth, and a hidden force is
recovered by regressing the residual on the responses to the candidate changes."""
from __future__ import annotations

import numpy as np
import pytest

from diagnosis_helpers import MATERIAL, hanging_sheet

from gg_core.diagnosis.library import BY_NAME, Context
from gg_core.diagnosis.residuals import build_frames, make_pooling, residual, responses
from gg_core.diagnosis.selection import Design, gram, fit
from gg_core.physics.cloth import Cloth
from gg_core.physics.fitting import Observed
from gg_core.physics.forces import make_terms
from gg_core.physics.material import Material
from gg_core.physics.simulator import ClothState, ImplicitSimulator

BASE = ["gravity", "stretching", "bending"]


def observe(extra: dict[str, dict], n_frames: int = 14) -> tuple[ImplicitSimulator, list[Observed]]:
    """Two swaying sequences simulated with `extra` on; returns a simulator without it (the model) and them."""
    v, f, pinned = hanging_sheet()
    material = Material.uniform(len(v), **MATERIAL)
    truth = ImplicitSimulator(Cloth(v, f, pinned=pinned, material=material),
                              terms=make_terms(BASE + list(extra), extra))
    sequences = []
    for k, amp in enumerate((0.08, 0.12)):
        shift = np.zeros((n_frames, 3))
        shift[:, 0] = amp * np.sin(2 * np.pi * 1.2 * np.arange(n_frames) / 30)
        traj = truth.rollout(ClothState(v.copy(), np.zeros_like(v)), None, n_frames=n_frames,
                             pin_frames=v[None] + shift[:, None])
        sequences.append(Observed(f"s{k}", traj, None, 30.0))
    model = ImplicitSimulator(Cloth(v, f, pinned=pinned, material=Material.uniform(len(v), **MATERIAL)),
                              terms=make_terms(BASE))
    return model, sequences


def test_residual_vanishes_when_the_model_is_the_truth():
    sim, seqs = observe({})
    batch = build_frames(sim, seqs)
    assert batch.x_next.shape == (2 * 12, 49, 3)
    assert np.abs(residual(sim, batch)).max() < 1e-9


@pytest.mark.parametrize("name, term, coefs", [
    ("gravity_offset", {"gravity_offset": {"delta_g": (1.5, 0.0, -0.8)}}, [1.5, -0.8]),
    ("mass_damping", {"mass_damping": {"alpha": 1.5}}, [1.5]),
])
def test_hidden_force_is_recovered_from_the_responses(name, term, coefs):
    sim, seqs = observe(term)
    batch = build_frames(sim, seqs)
    res = residual(sim, batch)
    assert np.sqrt((res ** 2).mean()) > 1e-5                  # the hidden force shows
    predicted = batch.x_next - res
    cand = BY_NAME[name]
    ctx = Context.build(sim, batch)
    probes = cand.probes(ctx, 0.5)
    cols = responses(sim, batch, predicted, probes)
    free = sim.num.free > 0
    rms = [np.sqrt(((c / sim.num.mass[None, :, None])[:, free] ** 2).mean()) for c in cand.columns(ctx)]
    assert [size * r for (size, _), r in zip(probes, rms)] == pytest.approx([0.5] * len(coefs), rel=1e-6)
    pooling = make_pooling(sim, batch, patch_vertices=6, window=4)
    assert np.allclose(pooling.windows.sum(1), 1.0)
    design = Design(pooling.rows(res), np.zeros((len(pooling.rows(res)), 0)), {name: pooling.rows(cols).T},
                    pooling.groups())
    result = fit(gram(design), [name], BY_NAME)
    assert result.coefs[name] == pytest.approx(coefs, rel=0.1, abs=0.05)
    assert result.rss < 0.05 * design.y @ design.y           # it explains (nearly) everything
