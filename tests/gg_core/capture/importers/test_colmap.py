"""COLMAP importer on sparse models written with the pycolmap API (binary, and the same model as text)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gg_core.capture.cameras import load_cameras
from gg_core.cli import main


def _import(src: Path, out: Path, *extra: str) -> int:
    return main(["import", "--format", "colmap", str(src), "--out", str(out), "--progress", "none", *extra])


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gg: error: "), err
    return err[0]


def _text_model(model: Path, dest: Path) -> Path:
    import pycolmap

    dest.mkdir(parents=True)
    pycolmap.Reconstruction(str(model)).write_text(str(dest))
    return dest


def _source_projections(text_model: Path, X: np.ndarray) -> dict[str, np.ndarray]:
    """Image name -> pixels of X, from COLMAP's documented text format: images.txt 'ID QW QX QY QZ TX TY TZ
    CAMERA_ID NAME' (world->camera, Hamilton quaternion), cameras.txt 'ID PINHOLE W H fx fy cx cy'."""
    cams = {}
    for line in (text_model / "cameras.txt").read_text().splitlines():
        if line and not line.startswith("#"):
            f = line.split()
            assert f[1] == "PINHOLE"
            cams[f[0]] = [float(v) for v in f[4:8]]
    out = {}
    lines = [l for l in (text_model / "images.txt").read_text().splitlines() if not l.startswith("#")]
    for line in lines[::2]:  # every image has a second line with its 2D points
        f = line.split()
        w, x, y, z = (float(v) for v in f[1:5])
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        cam = X @ R.T + np.array([float(v) for v in f[5:8]])
        fx, fy, cx, cy = cams[f[8]]
        out[f[9]] = np.stack([fx * cam[:, 0] / cam[:, 2] + cx, fy * cam[:, 1] / cam[:, 2] + cy], axis=1)
    return out


@pytest.mark.parametrize("as_text", [False, True])
def test_cameras_project_like_the_source_model(colmap_project: Path, tmp_path: Path, writers,
                                               as_text: bool) -> None:
    text = _text_model(colmap_project / "sparse" / "0", tmp_path / "text")
    src = text if as_text else colmap_project
    extra = ("--images", str(colmap_project / "images")) if as_text else ()
    out = tmp_path / "capture"
    assert _import(src, out, "--sequence", "s", *extra) == 0
    cameras = load_cameras(out / "s" / "cameras.json")
    assert list(cameras) == ["cam00", "cam01", "cam02"]
    expected = _source_projections(text, writers.points)
    assert len(expected) == 6  # 3 cameras x 2 frames, each frame the same fixed camera
    for name, uv_source in expected.items():
        cam = cameras[name.split("/")[0]]
        uv, depth = cam.project(writers.points)
        assert (depth > 0).all() and (cam.width, cam.height) == writers.size
        assert np.abs(uv - uv_source).max() < 1e-6
    assert sorted(p.name for p in (out / "s" / "cam01" / "rgb_images").iterdir()) == ["000000.png", "000001.png"]


def test_project_name_is_the_default_sequence_and_body_is_imported(colmap_project: Path, tmp_path: Path,
                                                                    writers) -> None:
    body = writers.body(tmp_path / "body", ["000000", "000001"])
    assert _import(colmap_project / "sparse" / "0", tmp_path / "out", "--body", str(body)) == 0
    seq = tmp_path / "out" / "project"
    assert sorted(p.name for p in (seq / "body").iterdir()) == ["000000.ply", "000001.ply"]


def test_one_still_per_camera_gives_a_single_frame(tmp_path: Path, writers) -> None:
    project = writers.colmap(tmp_path / "src", n_cams=4, nested=False)
    assert _import(project, tmp_path / "out") == 0
    seq = tmp_path / "out" / "project"
    assert list(load_cameras(seq / "cameras.json")) == ["cam00", "cam01", "cam02", "cam03"]
    assert [p.name for p in (seq / "cam03" / "rgb_images").iterdir()] == ["000000.png"]


def test_distorted_model_is_refused_with_the_undistort_fix(tmp_path: Path, writers, capsys) -> None:
    project = writers.colmap(tmp_path / "src", model="OPENCV", distortion=0.05)
    assert _import(project, tmp_path / "out") == 2
    line = _error_line(capsys)
    assert "uses the OPENCV model with distortion" in line and "pycolmap.undistort_images" in line


def test_zero_distortion_counts_as_pinhole(tmp_path: Path, writers) -> None:
    project = writers.colmap(tmp_path / "src", model="OPENCV", distortion=0.0)
    assert _import(project, tmp_path / "out") == 0


def test_a_camera_that_moves_between_frames_is_refused(tmp_path: Path, writers, capsys) -> None:
    project = writers.colmap(tmp_path / "src", drift=0.01)
    assert _import(project, tmp_path / "out") == 2
    assert "camera 'cam00' moves between frames '000000' and '000001'" in _error_line(capsys)


def test_resized_or_missing_images_are_refused(colmap_project: Path, tmp_path: Path, capsys) -> None:
    path = colmap_project / "images" / "cam01" / "000000.png"
    Image.open(path).resize((20, 30)).save(path)
    assert _import(colmap_project, tmp_path / "out") == 2
    assert "image is 20x30 but the model's camera is 47x64" in _error_line(capsys)
    path.unlink()
    assert _import(colmap_project, tmp_path / "out") == 2
    assert "image 'cam01/000000.png' of the model is missing" in _error_line(capsys)


def test_not_a_model_is_refused(tmp_path: Path, capsys) -> None:
    (tmp_path / "empty").mkdir()
    assert _import(tmp_path / "empty", tmp_path / "out") == 2
    assert "no COLMAP sparse model" in _error_line(capsys)
    (tmp_path / "broken").mkdir()
    for name in ("rigs", "cameras", "frames", "images", "points3D"):
        (tmp_path / "broken" / f"{name}.bin").write_bytes(b"\x01\x02\x03")
    assert _import(tmp_path / "broken", tmp_path / "out") == 2
    assert "COLMAP model cannot be read" in _error_line(capsys)
