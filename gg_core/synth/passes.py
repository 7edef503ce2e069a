"""Decode one Cycles multilayer EXR into the capture's RGB image, garment mask and foreground mask.

The masks come from the object-index pass (body and garment objects carry their own pass index), so
they are exactly what Blender rendered rather than a re-projection of our own geometry.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

BODY_INDEX, GARMENT_INDEX = 1, 2


@dataclass(frozen=True)
class Views:
    rgb: np.ndarray             # uint8 HxWx3, sRGB
    garment_mask: np.ndarray    # uint8 HxW, 255 = garment
    foreground_mask: np.ndarray  # uint8 HxW, 255 = body or garment


def linear_to_srgb8(linear: np.ndarray) -> np.ndarray:
    """Blender's 'Standard' view transform: the sRGB transfer function, clipped, rounded to 8 bits."""
    c = np.clip(linear, 0.0, 1.0)
    srgb = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.round(srgb * 255).astype(np.uint8)


def read_views(path: str | os.PathLike) -> Views:
    """RGB and masks from a multilayer EXR with the Combined and Object Index passes."""
    import OpenEXR  # noqa: PLC0415 - only needed where renders are decoded

    with OpenEXR.File(str(path)) as exr:
        channels = {name: ch.pixels for part in exr.parts for name, ch in part.channels.items()}
    combined = next(v for k, v in channels.items() if k.endswith("Combined"))
    index = np.rint(next(v for k, v in channels.items() if k.endswith("Object Index.X"))).astype(np.int32)
    garment = index == GARMENT_INDEX
    foreground = garment | (index == BODY_INDEX)
    return Views(linear_to_srgb8(combined[..., :3]), garment.astype(np.uint8) * 255,
                 foreground.astype(np.uint8) * 255)
