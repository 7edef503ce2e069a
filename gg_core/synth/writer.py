"""Files of a synthetic capture in the product's capture layout (gg_core/capture/layout.py).

Every file is written atomically, so a cancelled run leaves only complete files and resuming can trust
that a file which exists is finished.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..capture.layout import FOREGROUND_MASK, GARMENT_MASK, RGB
from ..geometry.meshio import write_ply
from ..storage import atomic_path
from .passes import Views

GT_GARMENT = Path("gt") / "garment"


def frame_name(index: int) -> str:
    return f"{index:06d}"


def view_paths(seq_dir: Path, camera_id: str, frame: str) -> dict[str, Path]:
    return {kind: seq_dir / camera_id / kind / f"{frame}.png" for kind in (RGB, GARMENT_MASK, FOREGROUND_MASK)}


def views_done(seq_dir: Path, camera_id: str, frame: str) -> bool:
    return all(p.is_file() for p in view_paths(seq_dir, camera_id, frame).values())


def write_views(seq_dir: Path, camera_id: str, frame: str, views: Views) -> None:
    """RGB last: its presence marks the view as complete for resuming (masks are written first)."""
    from PIL import Image  # noqa: PLC0415

    paths = view_paths(seq_dir, camera_id, frame)
    for kind, image in ((GARMENT_MASK, views.garment_mask), (FOREGROUND_MASK, views.foreground_mask),
                        (RGB, views.rgb)):
        with atomic_path(paths[kind]) as tmp:
            Image.fromarray(image).save(tmp, format="PNG")


def gt_path(seq_dir: Path, frame: str) -> Path:
    return seq_dir / GT_GARMENT / f"{frame}.ply"


def write_meshes(folder: Path, frames: list[str], vertices: np.ndarray, faces: np.ndarray) -> None:
    """One PLY per frame: vertices [T,V,3] with a fixed topology."""
    for name, verts in zip(frames, vertices):
        write_ply(folder / f"{name}.ply", verts, faces)
