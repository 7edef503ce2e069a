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
from gg_core.stages.motion import garment_files, load_sequence, resolve_source  # noqa: E402

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
