"""Rest-length field: the total variation's gradient is its derivative; on our own simulator a hidden rest-length
change on a strip of a hanging sheet is fitted on that strip at its size and nowhere else, the simulator is left
as it was, and nothing hidden leaves the field flat."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from diagnosis_helpers import shrunk_strip, swaying

from gg_core.diagnosis.rest_field import fit_rest_field, total_variation
from gg_core.diagnosis.scan import field_region


def test_total_variation_gradient_is_its_derivative():
    rng = np.random.default_rng(0)
    edges = np.array([[0, 1], [1, 2], [2, 3], [0, 3], [1, 3]])
    u = rng.normal(scale=0.01, size=4)
    value, grad = total_variation(u, edges)
    assert value == pytest.approx(np.mean(np.sqrt(np.diff(u[edges], axis=1) ** 2 + 1e-6)))
    h = 1e-7
    numeric = [(total_variation(u + h * e, edges)[0] - total_variation(u - h * e, edges)[0]) / (2 * h)
               for e in np.eye(4)]
    assert grad == pytest.approx(numeric, rel=1e-5, abs=1e-9)


def test_a_hidden_rest_length_change_on_a_strip_is_fitted_on_the_strip_and_nothing_hidden_leaves_it_flat():
    v, _, strip, recordings, model = shrunk_strip(0.95)
    rest = model.cloth.rest_lengths.clone()
    u = fit_rest_field(model, recordings, 0)
    assert torch.equal(model.cloth.rest_lengths, rest)           # the simulator is left as it was
    assert u[strip] == pytest.approx(np.log(0.95), rel=0.15)     # the strip, at the hidden size
    assert np.abs(u[~strip]).max() < 0.1 * np.abs(np.log(0.95))  # and nowhere else
    assert (field_region(u) == strip).all()
    assert field_region(fit_rest_field(model, swaying(model, v), 0)) is None


def test_field_region_is_where_the_field_reaches_half_its_extreme_on_its_side():
    u = np.array([-0.2, -0.1, -0.09, 0.15, 0.0])
    assert list(field_region(u)) == [1.0, 1.0, 0.0, 0.0, 0.0]
    assert list(field_region(-u)) == [1.0, 1.0, 0.0, 0.0, 0.0]
    assert field_region(np.zeros(3)) is None
