"""`gg template` from the command line: help, and bad input -> exit 2 with one `gg: error:` line."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[3]


def gg(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gg_core", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


def _blank_garment(capture: Path, cameras: list[str]) -> None:
    for cam in cameras:
        for path in (capture / "seq0" / cam / "garment_masks").glob("*.png"):
            Image.fromarray(np.zeros((30, 40), np.uint8)).save(path)


def test_help_lists_the_options():
    out = gg("template", "--help")
    assert out.returncode == 0
    for option in ("--project", "--sequence", "--frame", "--vertices", "--resolution", "--free-border-trim",
                   "--progress"):
        assert option in out.stdout


@pytest.mark.parametrize("case, expected", [
    ("sequence", "sequence 'nope' not found"),
    ("frame", "frame '999999' not found"),
    ("no_cameras", "cameras.json holds no cameras"),
    ("empty_masks", "garment masks of frame '000000' are empty in every camera"),
    ("few_cameras", "visible in only 2 camera(s)"),
    ("negative_trim", "--free-border-trim must not be negative"),
])
def test_bad_input_exits_2_with_one_line(capture_writer, tmp_path, case, expected):
    capture = capture_writer(tmp_path / "capture")
    args = ["template", str(capture), "--project", str(tmp_path / "project"), "--progress", "none"]
    if case == "sequence":
        args += ["--sequence", "nope"]
    elif case == "frame":
        args += ["--frame", "999999"]
    elif case == "no_cameras":
        (capture / "seq0" / "cameras.json").write_text("{}")
    elif case == "empty_masks":
        _blank_garment(capture, ["cam00", "cam01", "cam02"])
    elif case == "few_cameras":
        _blank_garment(capture, ["cam00"])
    elif case == "negative_trim":
        args += ["--free-border-trim", "-1"]
    out = gg(*args)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gg: error: ") and expected in lines[0]
    assert not (tmp_path / "project" / "stage1" / "template.obj").exists()
