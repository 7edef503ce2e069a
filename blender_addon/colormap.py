"""Scalar field → colours for the residual heat map (numpy only; the panel and its tests use it without bpy)."""
from __future__ import annotations

import numpy as np

# Anchor colours of a perceptually ordered dark-blue → teal → yellow → red ramp (sampled from "turbo"-like maps).
_STOPS = np.array([[0.19, 0.07, 0.23], [0.16, 0.47, 0.94], [0.16, 0.85, 0.65], [0.73, 0.97, 0.23],
                   [0.98, 0.62, 0.13], [0.80, 0.16, 0.03]])


def heat_colors(values: np.ndarray, vmax: float | None = None) -> tuple[np.ndarray, float]:
    """Linear RGB [N, 3] for `values` scaled to [0, vmax] (default: the 99th percentile, so one outlier
    vertex does not wash out the map); returns the colours and the vmax used for the legend."""
    values = np.nan_to_num(np.asarray(values, dtype=np.float64), nan=0.0)
    if vmax is None:
        vmax = float(np.percentile(np.abs(values), 99)) if values.size else 1.0
    vmax = vmax if vmax > 0 else 1.0
    t = np.clip(np.abs(values) / vmax, 0.0, 1.0) * (len(_STOPS) - 1)
    low = np.minimum(t.astype(int), len(_STOPS) - 2)
    frac = (t - low)[:, None]
    return (1 - frac) * _STOPS[low] + frac * _STOPS[low + 1], vmax
