"""How differently recordings of one garment move, without any simulator of ours in the loop.

The diagnosis benchmark asks two things of a hidden effect with it: how much it changes the recorded motion (its
capture against the same seed's capture with nothing hidden), and whether that change is physics or the
reference solver's numerics (the same change when Blender takes twice the steps per frame). An effect whose
change moves by as much as the change itself when the step is halved is not defined by the reference: no
simulator that is not Blender at the same step size can be expected to reproduce it. The same twin at twice the
steps also measures the floor under every rollout error (reference_divergence): how far the reference's own motion
moves with its step, effect or not.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..capture.layout import Capture
from ..synth.quality import gt_frames


def displacements(frames: np.ndarray, free: np.ndarray) -> np.ndarray:
    """[T,F,3] displacements of the `free` vertices of `frames` [T,V,3] from the first frame.

    Displacements, not positions: the diagnosis starts every rollout from a recorded state, so a garment that
    hangs differently from the first frame on is given to it; what it must explain is how the motion goes on."""
    return frames[:, free] - frames[:1, free]


def rms(fields: list[np.ndarray]) -> float:
    """Root mean square vector length over every frame and vertex of the [T,F,3] `fields` (one per sequence,
    each weighted by its size)."""
    squares = np.concatenate([(f * f).sum(-1).ravel() for f in fields])
    return float(np.sqrt(squares.mean()))


def effect_field(effect: Path, reference: Path) -> dict[str, np.ndarray]:
    """Per sequence name, [T,F,3] how the displacements of the synthetic capture `effect` differ from those of
    `reference` (same garment and motions), on the vertices neither pins (truth.json)."""
    cap_e, cap_r = Capture(effect), Capture(reference)
    if sorted(cap_e.sequences) != sorted(cap_r.sequences):
        raise ValueError(f"captures hold different sequences: {sorted(cap_e.sequences)} vs {sorted(cap_r.sequences)}")
    pinned = {i for c in (cap_e, cap_r) for i in c.truth["garment"]["pinned_vertices"]}
    out = {}
    for name in sorted(cap_e.sequences):
        e, r = gt_frames(cap_e.sequence(name)), gt_frames(cap_r.sequence(name))
        if e.shape != r.shape:
            raise ValueError(f"sequence '{name}' differs in shape: {e.shape} vs {r.shape}")
        free = np.array([i not in pinned for i in range(e.shape[1])])
        out[name] = displacements(e, free) - displacements(r, free)
    return out


def reference_divergence(capture: Path, finer: Path) -> dict[str, float]:
    """Per sequence, in metres: the mean distance between the displacements of `capture` and of the same capture
    simulated at a finer step (`finer`), over the frames a rollout is scored on (from the third) and the free
    vertices. How far the reference solver's own numerics move its motion: a simulator that is not the reference
    at its step starts about this far from the recordings, whatever physics it gets right."""
    return {name: float(np.linalg.norm(field[2:], axis=-1).mean())
            for name, field in effect_field(capture, finer).items()}


def effect_sizes(effect: Path, reference: Path, effect_finer: Path, reference_finer: Path) -> tuple[float, float]:
    """(signal, step change) in metres: the RMS of effect_field(effect, reference), and the RMS of how that field
    changes when both captures are simulated at a finer step (`effect_finer`, `reference_finer`)."""
    coarse, fine = effect_field(effect, reference), effect_field(effect_finer, reference_finer)
    return rms(list(coarse.values())), rms([coarse[name] - fine[name] for name in coarse])
