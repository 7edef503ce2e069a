"""Point Cache 2 files: per-frame vertex positions that Blender's Mesh Cache modifier plays back."""
from __future__ import annotations

import os
import struct

import numpy as np

_HEADER = struct.Struct("<12siiffi")  # signature, version, points, start frame, sample rate, samples


def write_pc2(path: str | os.PathLike, frames: np.ndarray, start: float = 0.0) -> None:
    """Write frames [T,V,3] (already in the target's coordinate frame) as a PC2 file."""
    frames = np.ascontiguousarray(frames, dtype="<f4")
    with open(path, "wb") as fh:
        fh.write(_HEADER.pack(b"POINTCACHE2\0", 1, frames.shape[1], start, 1.0, frames.shape[0]))
        fh.write(frames.tobytes())

