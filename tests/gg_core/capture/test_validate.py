"""`gg inspect`: a clean capture passes; each kind of bad input gives exit 2 and one line naming the file."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gg_core.capture.validate import validate_capture
from gg_core.cli import main


def test_clean_capture_has_no_problems(small_capture: Path, capsys) -> None:
    report = validate_capture(small_capture)
    assert report.problems == []
    seq = report.sequences[0]
    assert seq.cameras == ["cam00", "cam01", "cam02"] and len(seq.frames) == 3 and seq.body_files == 3
    assert main(["inspect", str(small_capture), "--json", "--progress", "none"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["sequences"][0]["resolutions"] == [[40, 30]]


def _break_missing_camera(root: Path) -> str:
    import shutil

    shutil.rmtree(root / "seq0" / "cam01")
    return "camera folder 'cam01' is missing"


def _break_camera_frames(root: Path) -> str:
    rgb = root / "seq0" / "cam02" / "rgb_images"
    (rgb / "000002.png").rename(rgb / "00002.png")
    return "frame names of camera 'cam02' differ"


def _break_body_names(root: Path) -> str:
    body = root / "seq0" / "body"
    for p in body.iterdir():
        p.rename(body / f"{int(p.stem):05d}.ply")
    return "body mesh names do not match"


def _break_png(root: Path) -> str:
    path = root / "seq0" / "cam01" / "rgb_images" / "000001.png"
    path.write_bytes(path.read_bytes()[:60])
    return "cannot be decoded"


def _break_nan(root: Path) -> str:
    path = root / "seq0" / "cameras.json"
    cams = json.loads(path.read_text())
    cams["cam01"]["extrinsics"][0][0] = float("nan")
    path.write_text(json.dumps(cams).replace("NaN", "NaN"))
    return "NaN"


def _break_rotation(root: Path) -> str:
    path = root / "seq0" / "cameras.json"
    cams = json.loads(path.read_text())
    cams["cam02"]["extrinsics"][0][:3] = [2.0, 0.0, 0.0]
    path.write_text(json.dumps(cams))
    return "not orthonormal"


def _break_mask_size(root: Path) -> str:
    Image.fromarray(np.zeros((31, 40), np.uint8)).save(root / "seq0" / "cam00" / "garment_masks" / "000000.png")
    return "mask is 40x31 but the camera is 40x30"


BREAKS = {
    "missing_camera": (_break_missing_camera, "cam01"),
    "camera_frame_names": (_break_camera_frames, "cam02/rgb_images"),
    "body_frame_names": (_break_body_names, "seq0/body"),
    "corrupt_png": (_break_png, "cam01/rgb_images/000001.png"),
    "nan_extrinsics": (_break_nan, "cameras.json camera cam01"),
    "non_orthonormal_rotation": (_break_rotation, "cameras.json camera cam02"),
    "mask_wrong_size": (_break_mask_size, "cam00/garment_masks/000000.png"),
}


@pytest.mark.parametrize("name", sorted(BREAKS))
def test_bad_input_exit_2_one_line(small_capture: Path, name: str) -> None:
    breaker, where = BREAKS[name]
    what = breaker(small_capture)
    proc = subprocess.run([sys.executable, "-m", "gg_core", "inspect", str(small_capture), "--progress", "none"],
                          capture_output=True, text=True)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("gg: error: ") and "Traceback" not in proc.stderr
    assert what in lines[0] and where in lines[0], lines[0]
