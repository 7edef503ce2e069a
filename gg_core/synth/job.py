"""What the parent process hands the bpy worker for one sequence: settings (JSON) and arrays (npz).

Its JSON form doubles as the resume key: a sequence whose saved job equals the new one keeps its
finished simulation and renders; any change makes the worker start that sequence afresh.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

ARRAY_NAMES = ("body_frames", "body_faces", "collider_faces", "garment_rest", "garment_faces", "garment_uvs",
               "garment_face_uvs", "garment_targets")
GROUP_PREFIX = "group__"  # npz arrays named group__<region> hold per-vertex weights of garment regions


@dataclass
class SequenceJob:
    sequence: str
    seq_dir: str
    arrays: str                       # npz: ARRAY_NAMES (gg coordinates) + GROUP_PREFIX weights
    arrays_digest: str                # sha256 of the arrays, so a changed body or garment invalidates results
    settle_frames: int                # simulated frames before the first recorded one
    frame_names: list[str]            # recorded frames
    fps: int
    cloth: dict                       # Blender ClothSettings attributes (effect included)
    cloth_collision: dict             # ClothCollisionSettings attributes
    body_collision: dict              # CollisionSettings of the body collider
    scene_gravity: list[float]        # Blender's scene setting (Blender coordinates): blender_frame.scene_gravity
    force_fields: list[dict] = field(default_factory=list)
    cloth_vertex_groups: dict[str, str] = field(default_factory=dict)   # ClothSettings attribute -> region
    cameras: dict = field(default_factory=dict)     # cameras.json content: part of the resume key
    lights: list[dict] = field(default_factory=list)
    look: dict = field(default_factory=dict)
    uv_scale: float = 1.0
    render: dict = field(default_factory=dict)                          # samples, denoise, seed, threads

    @property
    def n_sim_frames(self) -> int:
        return self.settle_frames + len(self.frame_names)

    def to_json(self) -> dict:
        return asdict(self)

    def save(self, path: Path) -> None:
        from ..storage import write_json  # noqa: PLC0415

        write_json(path, self.to_json())

    @classmethod
    def load(cls, path: Path) -> "SequenceJob":
        return cls(**json.loads(Path(path).read_text()))
