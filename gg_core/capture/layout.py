"""The product's capture layout (REFERENCE.md §1): where every file of a capture lives.

```
<capture>/truth.json                                 (synthetic only; metrics only)
<capture>/<sequence>/cameras.json
<capture>/<sequence>/<camera_id>/rgb_images/<frame>.png|jpg
<capture>/<sequence>/<camera_id>/garment_masks/<frame>.png
<capture>/<sequence>/<camera_id>/foreground_masks/<frame>.png
<capture>/<sequence>/body/<frame>.ply|obj
<capture>/<sequence>/gt/garment/<frame>.ply          (synthetic only; metrics only)
```
Only the standard library and numpy: the Blender add-on uses this module too.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

from ..errors import InputError
from .cameras import Camera, load_cameras

IMAGE_EXTS = (".png", ".jpg", ".jpeg")
MESH_EXTS = (".ply", ".obj")
RGB, GARMENT_MASK, FOREGROUND_MASK = "rgb_images", "garment_masks", "foreground_masks"
IMAGE_KINDS = (RGB, GARMENT_MASK, FOREGROUND_MASK)


def _stems(folder: Path, exts: tuple[str, ...]) -> dict[str, Path]:
    if not folder.is_dir():
        return {}
    return {p.stem: p for p in sorted(folder.iterdir()) if p.suffix.lower() in exts and not p.name.startswith(".")}


@dataclass
class Sequence:
    """One synchronized multi-view sequence of a capture."""

    root: Path
    name: str = field(init=False)

    def __post_init__(self) -> None:
        self.root = Path(self.root)
        self.name = self.root.name

    @cached_property
    def cameras(self) -> dict[str, Camera]:
        return load_cameras(self.root / "cameras.json")

    @property
    def camera_ids(self) -> list[str]:
        return list(self.cameras)

    def files(self, camera_id: str, kind: str = RGB) -> dict[str, Path]:
        """Frame name -> file for one camera and image kind."""
        return _stems(self.root / camera_id / kind, IMAGE_EXTS)

    @cached_property
    def frames(self) -> list[str]:
        """Frame names of the sequence: those of the first camera (validation checks the rest agree)."""
        if not self.camera_ids:
            return []
        return sorted(self.files(self.camera_ids[0]))

    def image_path(self, camera_id: str, frame: str, kind: str = RGB) -> Path:
        path = self.files(camera_id, kind).get(frame)
        if path is None:
            raise InputError(f"no {kind} file for frame '{frame}'", self.root / camera_id / kind,
                             "make every camera hold the same frame names")
        return path

    @cached_property
    def body_files(self) -> dict[str, Path]:
        return _stems(self.root / "body", MESH_EXTS)

    def body_path(self, frame: str) -> Path:
        path = self.body_files.get(frame)
        if path is None:
            raise InputError(f"no body mesh for frame '{frame}'", self.root / "body",
                             "name body meshes exactly like the image frames (e.g. 000012.ply)")
        return path

    @cached_property
    def gt_garment_files(self) -> dict[str, Path]:
        """Ground-truth garment meshes (synthetic captures only). Stages must never read these."""
        return _stems(self.root / "gt" / "garment", MESH_EXTS)


@dataclass
class Capture:
    """A capture folder: one or more sequences, optional synthetic ground truth."""

    root: Path

    def __post_init__(self) -> None:
        self.root = Path(self.root)
        if not self.root.is_dir():
            raise InputError("capture folder not found", self.root, "pass the folder that holds the sequences")

    @cached_property
    def sequences(self) -> dict[str, Sequence]:
        seqs = {p.name: Sequence(p) for p in sorted(self.root.iterdir())
                if p.is_dir() and (p / "cameras.json").exists()}
        if not seqs:
            raise InputError("no sequence found (no <sequence>/cameras.json)", self.root,
                             "point to a capture folder in the layout of REFERENCE.md §1, "
                             "or import one with `gg import`")
        return seqs

    def sequence(self, name: str) -> Sequence:
        if name not in self.sequences:
            raise InputError(f"sequence '{name}' not found", self.root,
                             f"choose one of: {', '.join(self.sequences)}")
        return self.sequences[name]

    @cached_property
    def truth(self) -> dict | None:
        """Synthetic ground truth (materials, hidden effects, splits). Metrics only."""
        path = self.root / "truth.json"
        if not path.is_file():
            return None
        try:
            return json.loads(path.read_text())
        except json.JSONDecodeError:
            raise InputError("truth.json is not valid JSON", path, "regenerate the synthetic capture") from None
