"""Heat-map colours: ordered, robust to one outlier, NaN-safe."""
from __future__ import annotations

import importlib

import numpy as np


def test_heat_colors_are_ordered_and_clip_outliers(extension_package):
    colormap = importlib.import_module(f"{extension_package.__name__}.blender_addon.colormap")
    values = np.concatenate([np.linspace(0.0, 1.0, 199), [1000.0]])
    colors, vmax = colormap.heat_colors(values)
    assert vmax < 2.0  # the 99th percentile, not the outlier
    assert colors.shape == (200, 3) and (colors >= 0).all() and (colors <= 1).all()
    np.testing.assert_allclose(colors[-1], colors[-2], atol=0.02)  # outlier saturates at the top colour
    assert not np.allclose(colors[0], colors[-1])
    nan_colors, _ = colormap.heat_colors(np.array([np.nan, 0.0, 1.0]), vmax=1.0)
    np.testing.assert_allclose(nan_colors[0], nan_colors[1])
