"""Temporal smoothing of a registered sequence: each vertex's trajectory filtered by a Savitzky-Golay filter.

Why: every frame's stereo step (stereo.py) measures the cloth from that frame's images alone, at about a quarter
of a pixel; part of its error changes from frame to frame while the cloth moves smoothly, so a local quadratic
fit over a few frames of each vertex's trajectory removes that part and keeps the motion (a quadratic follows
constant acceleration exactly). The photometric fits that the frames start from are not touched: this runs on
the finished sequence, over the refined meshes stage 2 keeps per frame.

Measured (2026-11-26, session 12) on session 11's registered demo capture (3 x 30 frames, 12 cameras, 8.8 mm
pixels), CD / p2m (cm) / F@1cm, mean over the frames:
- walk 0.346 / 0.318 / 95.00 % -> window 5 0.338 / 0.309 / 95.24; window 7 0.336 / 0.306 / 95.33 (kept);
  window 9 with a cubic 0.337 / 0.306 / 95.33; window 5 with a line (a moving average) 0.353 / 0.322 / 94.96;
- torso twist 0.362 / 0.327 / 94.46 % -> window 7 0.356 / 0.320 / 94.67;
- arm swing (kept aside while choosing) 0.377 / 0.344 / 93.70 % -> window 7 0.372 / 0.338 / 93.89.
Averaging the stereo step's corrections over 3 / 5 / 9 frames instead (walk) gives 0.310 / 0.311 / 0.318 cm p2m:
no better, so the plain trajectory filter is used.
"""
from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter


def smooth_trajectories(frames: np.ndarray, window: int, order: int) -> np.ndarray:
    """[T, V, 3] vertex positions over T frames filtered along time by a Savitzky-Golay filter of `window` frames
    (odd) and polynomial `order`, the ends fitted by the first / last window's polynomial. A sequence shorter
    than the window uses the longest odd window it holds; one too short for the order is returned unchanged."""
    frames = np.asarray(frames, np.float64)
    if window % 2 == 0 or window < 1 or order < 0:
        raise ValueError(f"the window must be odd and positive and the order non-negative, got {window}, {order}")
    usable = min(window, len(frames) if len(frames) % 2 else len(frames) - 1)
    if usable <= order or usable < 3:
        return frames.copy()
    return savgol_filter(frames, usable, order, axis=0, mode="interp")
