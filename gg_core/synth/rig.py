"""Camera dome and lights of the synthetic studio, in gg coordinates (+Y up, metres, body facing +Z)."""
from __future__ import annotations

import math

import numpy as np

from ..capture.cameras import Camera, look_at
from .presets import Preset

BODY_HEIGHT = 1.75          # framing assumes a standing adult (feet on y=0)
FRAME_MARGIN = 1.25         # extra room around the body for arm swings, jumps and skirt flare


def camera_dome(preset: Preset, rng: np.random.Generator, target_y: float = 0.95,
                distance: float = 3.2) -> dict[str, Camera]:
    """Rings of cameras around the body, each looking at its centre, framing it with margin.

    Each ring is rotated by half a step against the previous one so the rings interleave; a small
    seeded jitter of azimuth and distance keeps cameras from being perfectly symmetric (like a real rig).
    """
    fov_v = 2 * math.degrees(math.atan(FRAME_MARGIN * BODY_HEIGHT / 2 / distance))
    fov_h = 2 * math.degrees(math.atan(math.tan(math.radians(fov_v) / 2) * preset.width / preset.height))
    cams: dict[str, Camera] = {}
    for row, (count, elevation) in enumerate(preset.camera_rows):
        for k in range(count):
            azimuth = 2 * math.pi * (k + 0.5 * row) / count + rng.uniform(-0.05, 0.05)
            d = distance * (1 + rng.uniform(-0.03, 0.03))
            el = math.radians(elevation)
            eye = np.array([d * math.cos(el) * math.sin(azimuth), target_y + d * math.sin(el),
                            d * math.cos(el) * math.cos(azimuth)])
            index = len(cams)
            cid = f"cam{index:02d}"
            cams[cid] = look_at(cid, eye, np.array([0.0, target_y, 0.0]), fov_h, preset.width, preset.height,
                                index=index)
    return cams


def held_out_cameras(camera_ids: list[str], every: int = 6) -> list[str]:
    """Every `every`-th camera (at least one) for appearance evaluation on views never trained on."""
    return camera_ids[every // 2::every] or camera_ids[-1:]


def lights(rng: np.random.Generator) -> list[dict]:
    """A warm key sun with soft shadows, a cool area fill and a rim light; positions jittered by seed."""
    key_az = math.radians(35 + rng.uniform(-15, 15))
    return [
        {"type": "SUN", "direction": [-math.sin(key_az) * 0.6, -0.75, -math.cos(key_az) * 0.6],
         "strength": 2.2, "color": [1.0, 0.96, 0.9], "angle_deg": 4.0},
        {"type": "AREA", "location": [-2.2, 1.8, 1.6], "target": [0.0, 1.0, 0.0], "strength": 90.0,
         "size": 1.5, "color": [0.85, 0.9, 1.0]},
        {"type": "AREA", "location": [0.8, 2.4, -2.4], "target": [0.0, 1.2, 0.0], "strength": 60.0,
         "size": 1.0, "color": [1.0, 1.0, 1.0]},
    ]
