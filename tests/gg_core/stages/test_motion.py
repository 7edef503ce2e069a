"""Which garment motion stage 4 and the diagnosis fit to: registered meshes once stage 2 has finished every
sequence, else the synthetic ground truth; a clear error when there is neither."""
from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "diagnosis"))

from diagnosis_helpers import write_sim_capture  # noqa: E402

from gg_core.capture.layout import Capture  # noqa: E402
from gg_core.errors import InputError  # noqa: E402
from gg_core.geometry.meshio import read_mesh, write_ply  # noqa: E402
from gg_core.metrics.surface import point_to_mesh  # noqa: E402
from gg_core.physics.fitting import Observed  # noqa: E402
from gg_core.stages.motion import garment_files, load_sequence, resolve_source, simulation_mesh  # noqa: E402

NAMES = ["a", "b", "c"]


@pytest.fixture(scope="module")
def capture(tmp_path_factory) -> Path:
    return write_sim_capture(tmp_path_factory.mktemp("motion") / "capture", n_frames=4)


def _register(capture: Path, project: Path, names: list[str], shift: float = 0.01) -> None:
    """Stand-in stage-2 output: the ground truth moved by `shift` m, so a test can tell the sources apart."""
    for n in names:
        for path in sorted((capture / n / "gt" / "garment").glob("*.ply")):
            v, f = read_mesh(path)
            write_ply(project / "stage2" / n / "meshes" / path.name, v + shift, f)


def test_auto_takes_the_ground_truth_until_registration_has_finished_every_sequence(capture, tmp_path):
    cap = Capture(capture)
    assert resolve_source("auto", cap, NAMES, tmp_path) == "gt"
    _register(capture, tmp_path, ["a", "b"])
    assert resolve_source("auto", cap, NAMES, tmp_path) == "gt"
    _register(capture, tmp_path, ["c"])
    assert resolve_source("auto", cap, NAMES, tmp_path) == "registered"
    assert resolve_source("gt", cap, NAMES, tmp_path) == "gt"


def test_the_resolved_source_is_what_gets_loaded(capture, tmp_path):
    _register(capture, tmp_path, NAMES, shift=0.01)
    seq = Capture(capture).sequence("a")
    registered, faces, _ = load_sequence(seq, garment_files(seq, "registered", tmp_path), fps=30.0)
    truth, faces_gt, _ = load_sequence(seq, garment_files(seq, "gt", tmp_path), fps=30.0)
    np.testing.assert_allclose(registered.garment - truth.garment, 0.01, atol=1e-6)
    assert registered.garment.shape == (4, 49, 3) and np.array_equal(faces, faces_gt)


def test_neither_source_is_a_clear_input_error(capture, tmp_path):
    real = tmp_path / "real"
    shutil.copytree(capture, real)
    for n in NAMES:
        shutil.rmtree(real / n / "gt")
    with pytest.raises(InputError, match="registration has not finished sequence 'a'"):
        resolve_source("auto", Capture(real), NAMES, tmp_path / "p")
    seq = Capture(real).sequence("a")
    with pytest.raises(InputError, match="no registered garment meshes for sequence 'a'"):
        garment_files(seq, "registered", tmp_path / "p")
    with pytest.raises(InputError, match="unknown source 'mocap'"):
        resolve_source("mocap", Capture(real), NAMES, tmp_path / "p")


def _bending_sheet(n: int, frames: int, phase: float) -> tuple[np.ndarray, np.ndarray]:
    """[T,n*n,3] frames of a 0.5 m square sheet rolling up into an arc, and its faces."""
    u, w = np.meshgrid(np.linspace(-0.25, 0.25, n), np.linspace(0, 0.5, n))
    faces = []
    for r in range(n - 1):
        for c in range(n - 1):
            i = r * n + c
            faces += [[i, i + 1, i + n], [i + 1, i + n + 1, i + n]]
    out = []
    for t in range(frames):
        k = 0.5 + 3.0 * np.sin(phase + 0.3 * t) ** 2           # curvature 1/m
        x, z = np.sin(k * u.ravel()) / k, (1 - np.cos(k * u.ravel())) / k
        out.append(np.stack([x, w.ravel(), z], axis=1))
    return np.array(out), np.array(faces)


def test_fine_meshes_are_simulated_on_a_remeshed_copy_that_follows_every_observed_surface():
    frames_a, faces = _bending_sheet(30, 5, 0.0)
    frames_b, _ = _bending_sheet(30, 4, 1.0)
    seqs = [Observed("a", frames_a.copy(), None, 30.0), Observed("b", frames_b.copy(), None, 30.0)]
    coarse_faces, log = simulation_mesh(seqs, faces, 200)
    assert log["remeshed"] and log["observed_vertices"] == 900
    assert 140 < log["vertices"] < 260 and coarse_faces.max() == log["vertices"] - 1
    for obs, fine in ((seqs[0], frames_a), (seqs[1], frames_b)):
        assert obs.garment.shape == (len(fine), log["vertices"], 3)
        for k in range(len(fine)):
            assert point_to_mesh(obs.garment[k], fine[k], faces).max() < 1e-9      # on the observed surface
    span = np.ptp(seqs[0].garment[0], axis=0)
    assert span[1] > 0.48                                           # the whole sheet, not a shrunken copy


def test_meshes_within_the_limit_are_simulated_as_observed():
    frames, faces = _bending_sheet(10, 3, 0.0)
    for limit in (0, 100, 500):
        obs = Observed("a", frames.copy(), None, 30.0)
        same_faces, log = simulation_mesh([obs], faces, limit)
        assert not log["remeshed"] and same_faces is faces and np.array_equal(obs.garment, frames)
