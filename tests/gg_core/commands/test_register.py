"""`gg register` from the command line: help, and bad input -> exit 2 with one `gg: error:` line."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gg_core.gaussians import face_texture
from gg_core.geometry.meshio import write_obj
from gg_core.storage import write_npz

ROOT = Path(__file__).resolve().parents[3]


def gg(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gg_core", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


def write_stage1(project: Path, bad_topology: bool = False) -> None:
    """A small sheet around the fixture's octahedron body as the template, one Gaussian per face."""
    u, v = np.meshgrid(np.linspace(-0.4, 0.4, 4), np.linspace(0.8, 1.2, 4), indexing="ij")
    verts = np.stack((u.ravel(), v.ravel(), np.full(16, 0.4)), 1)
    faces = np.array([[i * 4 + j, i * 4 + j + 4, i * 4 + j + 5] for i in range(3) for j in range(3)] +
                     [[i * 4 + j, i * 4 + j + 5, i * 4 + j + 1] for i in range(3) for j in range(3)])
    uvs = verts[:, :2] - verts[:, :2].min(0)
    write_obj(project / "stage1" / "template.obj", verts, faces, uvs / uvs.max(), faces)
    texture = face_texture(verts, faces)
    state = texture.state()
    if bad_topology:
        state["face_ids"] = state["face_ids"] + 5
    write_npz(project / "stage1" / "gaussians.npz", **state)


def test_help_lists_the_options():
    out = gg("register", "--help")
    assert out.returncode == 0
    for option in ("--project", "--sequences", "--ablation", "--iterations", "--frames", "--align", "--texture-factor",
                   "--progress"):
        assert option in out.stdout
    for ablation in ("only-rgb", "no-body", "body-always", "full"):
        assert ablation in out.stdout


@pytest.mark.parametrize("case, expected", [
    ("no_stage1", "stage 1 output missing"),
    ("topology", "template topology mismatch"),
    ("no_body", "body mesh missing for frame '000001'"),
    ("empty_masks", "garment masks of frame '000000' are empty in every camera"),
    ("sequence", "sequence 'nope' not found"),
    ("workers", "--workers must be at least 1, got 0"),
])
def test_bad_input_exits_2_with_one_line(capture_writer, tmp_path, case, expected):
    capture = capture_writer(tmp_path / "capture")
    project = tmp_path / "project"
    if case != "no_stage1":
        write_stage1(project, bad_topology=case == "topology")
    args = ["register", str(capture), "--project", str(project), "--progress", "none", "--iterations", "2"]
    if case == "no_body":
        (capture / "seq0" / "body" / "000001.ply").unlink()
    elif case == "empty_masks":
        for cam in ("cam00", "cam01", "cam02"):
            Image.fromarray(np.zeros((30, 40), np.uint8)).save(capture / "seq0" / cam / "garment_masks" / "000000.png")
    elif case == "sequence":
        args += ["--sequences", "nope"]
    elif case == "workers":
        args += ["--workers", "0"]
    out = gg(*args)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gg: error: ") and expected in lines[0], lines
    if case == "no_stage1":
        assert "run gg template first" in lines[0]
    assert not (project / "stage2").exists() or not list((project / "stage2").rglob("*.ply"))


def test_registers_the_small_capture_end_to_end(capture_writer, tmp_path):
    capture = capture_writer(tmp_path / "capture")
    project = tmp_path / "project"
    write_stage1(project)
    out = gg("register", str(capture), "--project", str(project), "--progress", "jsonl", "--iterations", "3",
             "--renders", "1")
    assert out.returncode == 0, out.stderr
    lines = [line for line in out.stdout.splitlines() if line.startswith("{")]
    assert '"done": true' in lines[-1]
    meshes = sorted((project / "stage2" / "seq0" / "meshes").glob("*.ply"))
    assert [p.stem for p in meshes] == ["000000", "000001", "000002"]
    assert (project / "reports" / "register.json").is_file()
    assert len(list((project / "stage2" / "seq0" / "renders").glob("*.png"))) == 1
