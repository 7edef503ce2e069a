"""ActorsHQ importer on a sequence written in the dataset's layout (calibration.csv, rgbs/, masks/)."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gg_core.capture.cameras import load_cameras
from gg_core.capture.importers.actorshq import rotation_from_axis_angle
from gg_core.capture.validate import validate_capture
from gg_core.cli import main


def _import(src: Path, out: Path, *extra: str) -> int:
    return main(["import", "--format", "actorshq", str(src), "--out", str(out), "--progress", "none", *extra])


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gg: error: "), err
    return err[0]


def _source_projection(row: dict[str, str], width: int, height: int, X: np.ndarray) -> np.ndarray:
    """HumanRF CameraData: world = R_c2w cam + t; K from fx, fy, px, py times the (downscaled) image size."""
    R_c2w = Rotation.from_rotvec([float(row[k]) for k in ("rx", "ry", "rz")]).as_matrix()
    cam = (X - np.array([float(row[k]) for k in ("tx", "ty", "tz")])) @ R_c2w  # R_c2w^T (X - t), row vectors
    K = np.array([[float(row["fx"]) * width, 0, float(row["px"]) * width],
                  [0, float(row["fy"]) * height, float(row["py"]) * height], [0, 0, 1]])
    p = cam @ K.T
    return p[:, :2] / p[:, 2:3]


def test_cameras_project_like_the_source_calibration(actorshq_sequence: Path, tmp_path: Path, writers) -> None:
    body = writers.body(tmp_path / "body", ["000000", "000001", "000002"])
    out = tmp_path / "capture"
    assert _import(actorshq_sequence, out, "--body", str(body)) == 0
    cameras = load_cameras(out / "Sequence1" / "cameras.json")  # "2x" folder -> the sequence's name
    with open(actorshq_sequence / "calibration.csv", newline="") as fh:
        rows = {r["name"]: r for r in csv.DictReader(fh)}
    assert list(cameras) == ["Cam001", "Cam002", "Cam003"]
    w, h = writers.size
    for cid, cam in cameras.items():
        assert (cam.width, cam.height) == (w, h) and int(rows[cid]["w"]) == 2 * w  # CSV at full resolution
        uv, depth = cam.project(writers.points)
        assert (depth > 0).all()
        assert np.abs(uv - _source_projection(rows[cid], w, h, writers.points)).max() < 1e-6
    seq = out / "Sequence1"
    assert sorted(p.name for p in (seq / "Cam002" / "rgb_images").iterdir()) == ["000000.jpg", "000001.jpg",
                                                                              "000002.jpg"]
    assert (seq / "Cam002" / "foreground_masks" / "000001.png").read_bytes() == \
        (actorshq_sequence / "masks" / "Cam002" / "Cam002_mask000001.png").read_bytes()
    problems = validate_capture(out).problems
    assert problems and all(p.what == "no garment masks" for p in problems)  # ActorsHQ has none: warned


def test_body_named_with_other_zero_padding_is_refused(actorshq_sequence: Path, tmp_path: Path, writers,
                                                       capsys) -> None:
    body = writers.body(tmp_path / "body", ["00000", "00001", "00002"])
    assert _import(actorshq_sequence, tmp_path / "out", "--body", str(body)) == 2
    line = _error_line(capsys)
    assert "same frame numbers, but the body files use 5 digits (e.g. '00000') and the frames 6 digits" in line
    assert str(body) in line and not (tmp_path / "out").exists()


def test_missing_body_frames_are_refused(actorshq_sequence: Path, tmp_path: Path, writers, capsys) -> None:
    body = writers.body(tmp_path / "body", ["000000", "000002", "000007"])
    assert _import(actorshq_sequence, tmp_path / "out", "--body", str(body)) == 2
    assert "the body lacks frames 000001 and has extra frames 000007" in _error_line(capsys)


def test_without_body_and_garment_masks_the_import_warns(actorshq_sequence: Path, tmp_path: Path, capsys) -> None:
    assert _import(actorshq_sequence, tmp_path / "out") == 0
    err = capsys.readouterr().err
    assert "gg: warning: the actorshq source has no body meshes" in err
    assert "gg: warning: the actorshq source has no garment masks" in err


def test_images_that_are_no_integer_downscale_are_refused(tmp_path: Path, writers, capsys) -> None:
    src = writers.actorshq(tmp_path / "src", downscale=3)
    rows = list(csv.DictReader(open(src / "calibration.csv", newline="")))
    rows[1]["w"] = str(int(rows[1]["w"]) + 7)
    with open(src / "calibration.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    assert _import(src, tmp_path / "out") == 2
    assert "camera 'Cam002' images are 47x64 but calibration.csv says 148x192" in _error_line(capsys)


def test_image_folder_without_calibration_row_is_refused(actorshq_sequence: Path, tmp_path: Path, capsys) -> None:
    rows = (actorshq_sequence / "calibration.csv").read_text().splitlines()
    (actorshq_sequence / "calibration.csv").write_text("\n".join(rows[:-1]) + "\n")
    assert _import(actorshq_sequence, tmp_path / "out") == 2
    assert "no calibration for camera(s) Cam003" in _error_line(capsys)


def test_missing_columns_and_bad_numbers_are_refused(actorshq_sequence: Path, tmp_path: Path, capsys) -> None:
    path = actorshq_sequence / "calibration.csv"
    text = path.read_text()
    path.write_text(text.replace(",py\n", ",pyy\n", 1))
    assert _import(actorshq_sequence, tmp_path / "out") == 2
    assert "calibration.csv lacks column(s) py" in _error_line(capsys)
    lines = text.splitlines()
    lines[2] = lines[2].replace(",", ",x", 4)
    path.write_text("\n".join(lines) + "\n")
    assert _import(actorshq_sequence, tmp_path / "out") == 2
    assert "calibration.csv line 3 has a non-numeric value" in _error_line(capsys)


def test_rodrigues_matches_scipy() -> None:
    rng = np.random.default_rng(5)
    for r in [np.zeros(3), np.array([0, 0, np.pi]), *rng.normal(0, 1.5, (20, 3))]:
        assert np.abs(rotation_from_axis_angle(r) - Rotation.from_rotvec(r).as_matrix()).max() < 1e-12
