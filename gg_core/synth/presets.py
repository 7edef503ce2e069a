"""Size presets of the synthetic capture: how many cameras, pixels, sequences, frames and vertices.

`tiny` is what CI generates (must stay under ~2 minutes on 2 cores including the cloth settle),
`demo` feeds `make demo` (under 15 minutes on 2 cores: few samples, no denoiser, which alone costs more
per view than 10 samples), `bench` is large enough for timing measurements.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

from ..errors import InputError


@dataclass(frozen=True)
class Preset:
    name: str
    camera_rows: tuple[tuple[int, float], ...]  # (cameras in the ring, elevation in degrees) per ring of the dome
    height: int                    # image height in pixels; width is 3/4 of it (a standing person)
    n_sequences: int
    n_frames: int                  # recorded frames per sequence
    settle_frames: int             # simulated before recording while the body blends from rest into the motion
    garment_vertices: int          # target vertex count of the garment template
    samples: int                   # Cycles samples per pixel
    denoise: bool                  # OpenImageDenoise after sampling (costs ~0.2 s per view)
    cloth_quality: int             # cloth solver steps per frame
    collision_quality: int
    self_collision: bool
    motions: tuple[str, ...]       # default motion per sequence (cycled when more sequences are asked)
    fps: int = 30

    @property
    def width(self) -> int:
        return self.height * 3 // 4

    @property
    def n_cameras(self) -> int:
        return sum(n for n, _ in self.camera_rows)

    def to_json(self) -> dict:
        out = asdict(self)
        out.update(width=self.width, n_cameras=self.n_cameras)
        return out


PRESETS: dict[str, Preset] = {
    "tiny": Preset("tiny", camera_rows=((6, 8.0),), height=96, n_sequences=2, n_frames=8, settle_frames=14,
                   garment_vertices=1000, samples=16, denoise=False, cloth_quality=5, collision_quality=2,
                   self_collision=False, motions=("walk", "arm_swing")),
    "demo": Preset("demo", camera_rows=((8, 5.0), (4, 30.0)), height=256, n_sequences=3, n_frames=30,
                   settle_frames=20, garment_vertices=3000, samples=8, denoise=False, cloth_quality=6,
                   collision_quality=2, self_collision=True, motions=("walk", "arm_swing", "torso_twist")),
    "bench": Preset("bench", camera_rows=((12, 5.0), (8, 30.0), (4, 60.0)), height=512, n_sequences=5,
                    n_frames=60, settle_frames=24, garment_vertices=6000, samples=32, denoise=True, cloth_quality=8,
                    collision_quality=3, self_collision=True,
                    motions=("walk", "arm_swing", "torso_twist", "squat", "jump")),
}


def get_preset(name: str) -> Preset:
    if name not in PRESETS:
        raise InputError(f"unknown preset '{name}'", "--preset", f"choose one of: {', '.join(PRESETS)}")
    return PRESETS[name]


def resized(preset: Preset, n_sequences: int | None = None, n_frames: int | None = None) -> Preset:
    """`preset` with fewer or more sequences / frames (cameras, pixels and quality unchanged)."""
    for value, option in ((n_sequences, "--sequences"), (n_frames, "--frames")):
        if value is not None and value < 1:
            raise InputError(f"{option} must be at least 1, got {value}", option, "pass a positive count")
    return replace(preset, n_sequences=n_sequences or preset.n_sequences, n_frames=n_frames or preset.n_frames)
