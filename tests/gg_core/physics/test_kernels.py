"""Numba kernels that replace numpy expressions on the simulator's hot path give the same bits."""
from __future__ import annotations

import numpy as np

from gg_core.physics import kernels


def test_edge_lengths_are_numpys_row_norms_to_the_bit():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(50, 3)) * 0.3
    edges = rng.integers(0, 50, size=(200, 2))
    d = x[edges[:, 0]] - x[edges[:, 1]]
    np.testing.assert_array_equal(kernels.edge_lengths(x, edges), (d * d).sum(-1) ** 0.5)
