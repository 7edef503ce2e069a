import json

import numpy as np
import pytest

from gg_core.geometry.meshio import write_ply
from gg_core.metrics.motion import displacements, effect_field, effect_sizes, reference_divergence, rms


def _motion(frames: int = 6, vertices: int = 5, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(frames, vertices, 3))


def _drift(frames: int, per_frame: tuple[float, float, float]) -> np.ndarray:
    return np.arange(frames, dtype=np.float64)[:, None, None] * np.array(per_frame)


def test_the_same_motion_from_another_start_has_the_same_displacements():
    a = _motion()
    free = np.ones(a.shape[1], bool)
    moved = displacements(a + np.array([0.3, -0.1, 0.2]), free) - displacements(a, free)
    assert rms([moved]) == pytest.approx(0.0, abs=1e-12)


def test_a_steady_drift_is_measured_as_its_rms_over_frames_and_sequences():
    a = _motion()
    free = np.ones(a.shape[1], bool)
    field = displacements(a + _drift(len(a), (0.0, 3e-3, 4e-3)), free) - displacements(a, free)   # 5 mm / frame
    t = np.arange(len(a))
    assert rms([field]) == pytest.approx(5e-3 * np.sqrt((t ** 2).mean()))
    # a second, still sequence of the same size halves the mean square
    assert rms([field, np.zeros_like(field)]) == pytest.approx(rms([field]) / np.sqrt(2))


def _capture(root, sequences: dict[str, np.ndarray], pinned: list[int]):
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    for name, frames in sequences.items():
        (root / name / "gt" / "garment").mkdir(parents=True)
        (root / name / "cameras.json").write_text("{}")
        for k, x in enumerate(frames):
            write_ply(root / name / "gt" / "garment" / f"{k:06d}.ply", x, faces)
    (root / "truth.json").write_text(json.dumps({"garment": {"pinned_vertices": pinned}}))
    return root


def test_an_effect_is_sized_per_sequence_on_free_vertices_and_against_a_finer_step(tmp_path):
    walk, twist = _motion(seed=1), _motion(seed=2)
    drift = _drift(len(walk), (0.0, 0.0, 2e-3))        # the effect: the twist drifts 2 mm per frame, walk matches
    moved = twist + drift
    moved[:, 0] += 1.0                                 # the pinned vertex 0 jumps: ignored
    ref = _capture(tmp_path / "ref", {"00_walk": walk, "01_twist": twist}, [0])
    eff = _capture(tmp_path / "eff", {"00_walk": walk, "01_twist": moved}, [0])
    # at a finer step the reference moves otherwise, and the effect is half as large on top of it
    walk_f, twist_f = walk + _drift(len(walk), (1e-3, 0.0, 0.0)), twist - _drift(len(walk), (0.0, 1e-3, 0.0))
    ref_f = _capture(tmp_path / "ref_f", {"00_walk": walk_f, "01_twist": twist_f}, [0])
    eff_f = _capture(tmp_path / "eff_f", {"00_walk": walk_f, "01_twist": twist_f + 0.5 * drift}, [0])
    field = effect_field(eff, ref)
    assert sorted(field) == ["00_walk", "01_twist"]
    assert rms([field["00_walk"]]) == 0.0 and field["01_twist"].shape == (len(walk), 4, 3)
    signal, step_change = effect_sizes(eff, ref, eff_f, ref_f)
    assert signal == pytest.approx(rms([np.zeros((6, 4, 3)), np.repeat(drift, 4, axis=1)]))
    assert step_change == pytest.approx(signal / 2)
    short = _capture(tmp_path / "short", {"00_walk": walk}, [0])
    with pytest.raises(ValueError, match="different sequences"):
        effect_field(short, ref)
    fewer = _capture(tmp_path / "fewer", {"00_walk": walk[:-1], "01_twist": twist}, [0])
    with pytest.raises(ValueError, match="00_walk"):
        effect_field(fewer, ref)


def test_the_reference_divergence_is_the_mean_distance_over_the_scored_frames_per_sequence(tmp_path):
    walk, twist = _motion(seed=1), _motion(seed=2)
    coarse = _capture(tmp_path / "coarse", {"00_walk": walk, "01_twist": twist}, [0])
    finer_walk = walk + _drift(len(walk), (0.0, 3e-3, 4e-3))       # 5 mm further every frame
    finer_walk[:, 0] += 1.0                                           # the pinned vertex: ignored
    finer = _capture(tmp_path / "finer", {"00_walk": finer_walk, "01_twist": twist + 0.2}, [0])
    divergence = reference_divergence(coarse, finer)
    # frames 2..5 are scored, as in a rollout started from frames 0 and 1: 10, 15, 20, 25 mm
    assert divergence["00_walk"] == pytest.approx(17.5e-3, abs=1e-6)
    assert divergence["01_twist"] == pytest.approx(0.0, abs=1e-6)   # the same motion from another start (float32 files)
