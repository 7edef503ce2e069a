"""4D-Dress importer on a take written exactly as the dataset ships it (pickled cameras.pkl, PNGs, SMPLX ply)."""
from __future__ import annotations

import json
import os
import pickle
import shutil
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from gg_core.capture.cameras import load_cameras
from gg_core.capture.validate import validate_capture
from gg_core.cli import main
from gg_core.geometry.meshio import read_mesh


def _import(take: Path, out: Path, *extra: str) -> int:
    return main(["import", "--format", "4d-dress", str(take), "--out", str(out), "--progress", "none", *extra])


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gg: error: "), err
    return err[0]


def test_cameras_project_like_the_source_calibration(dress_take: Path, tmp_path: Path, writers) -> None:
    out = tmp_path / "capture"
    assert _import(dress_take, out) == 0
    with open(dress_take / "Capture" / "cameras.pkl", "rb") as fh:
        source = pickle.load(fh)
    cameras = load_cameras(out / "Take9" / "cameras.json")
    assert list(cameras) == ["0004", "0028", "0076"]
    X = writers.points
    for cid, cam in cameras.items():
        K = np.asarray(source[cid]["intrinsics"], np.float64)
        E = np.asarray(source[cid]["extrinsics"], np.float64)
        p = (K @ (E[:, :3] @ X.T + E[:, 3:4])).T  # 4D-Dress: x_img ~ K [R|t] X, OpenCV world->camera
        uv_source = p[:, :2] / p[:, 2:3]
        uv, depth = cam.project(X)
        assert (depth > 0).all()
        assert np.abs(uv - uv_source).max() < 1e-6
        assert (cam.width, cam.height) == writers.size  # read from the image files
    assert validate_capture(out).problems == []


def test_frames_masks_and_body_are_renamed_and_converted(dress_take: Path, tmp_path: Path) -> None:
    out = tmp_path / "capture"
    assert _import(dress_take, out) == 0
    seq = out / "Take9"
    assert sorted(p.name for p in (seq / "0028" / "rgb_images").iterdir()) == ["00011.png", "00012.png", "00013.png"]
    src_cam = dress_take / "Capture" / "0028"
    assert (seq / "0028" / "foreground_masks" / "00012.png").read_bytes() == \
        (src_cam / "masks" / "mask-f00012.png").read_bytes()
    label = np.asarray(Image.open(src_cam / "labels" / "label-f00012.png"))
    garment = np.asarray(Image.open(seq / "0028" / "garment_masks" / "00012.png"))
    expected = (label == (0, 128, 255)).all(-1)  # the 'outer' colour, default for Outer takes
    assert expected.sum() > 100 and np.array_equal(garment > 0, expected) and set(np.unique(garment)) == {0, 255}
    verts, faces = read_mesh(seq / "body" / "00013.ply")
    source = trimesh.load(dress_take / "SMPLX" / "mesh-f00013_smplx.ply", process=False)
    assert np.allclose(verts, source.vertices, atol=1e-6) and np.array_equal(faces, source.faces)
    assert (seq / "body" / "00013.pkl").read_bytes() == (dress_take / "SMPLX" / "mesh-f00013_smplx.pkl").read_bytes()
    record = json.loads((seq / "import.json").read_text())
    assert record["complete"] and record["options"] == {"garment": "outer"} and record["frames"] == 3


def test_link_uses_hard_links_and_a_rerun_skips_everything(dress_take: Path, tmp_path: Path) -> None:
    out = tmp_path / "capture"
    assert _import(dress_take, out, "--link") == 0
    src = dress_take / "Capture" / "0004" / "images" / "capture-f00011.png"
    assert os.path.samefile(src, out / "Take9" / "0004" / "rgb_images" / "00011.png")
    first = json.loads((out / "Take9" / "import.json").read_text())
    assert first["files_written"] == 3 * 3 * 3 + 3 + 3 and first["files_skipped"] == 0
    assert _import(dress_take, out, "--link") == 0
    again = json.loads((out / "Take9" / "import.json").read_text())
    assert again["files_written"] == 0 and again["files_skipped"] == first["files_written"]


def test_inner_outfit_needs_the_garment_label(tmp_path: Path, writers, capsys) -> None:
    take = writers.dress_take(tmp_path / "src", outfit="Inner")
    assert _import(take, tmp_path / "out") == 2
    assert "choose which labelled garment" in _error_line(capsys)
    assert _import(take, tmp_path / "out", "--garment", "upper,lower") == 0
    label = np.asarray(Image.open(take / "Capture" / "0004" / "labels" / "label-f00011.png"))
    mask = np.asarray(Image.open(tmp_path / "out" / "Take9" / "0004" / "garment_masks" / "00011.png")) > 0
    assert np.array_equal(mask, (label == (50, 180, 50)).all(-1) | (label == (180, 50, 50)).all(-1))


def test_take_without_labels_imports_with_a_garment_mask_warning(tmp_path: Path, writers, capsys) -> None:
    take = writers.dress_take(tmp_path / "src", labels=False)
    assert _import(take, tmp_path / "out") == 0
    err = capsys.readouterr().err
    assert "gg: warning: the 4d-dress source has no garment masks" in err
    assert not (tmp_path / "out" / "Take9" / "0004" / "garment_masks").exists()
    problems = validate_capture(tmp_path / "out").problems
    assert problems and all("no garment masks" in p.what for p in problems)
    assert _import(take, tmp_path / "out2", "--garment", "outer") == 2
    assert "--garment needs rendered labels" in _error_line(capsys)


def test_labels_of_only_some_cameras_are_refused(dress_take: Path, tmp_path: Path, capsys) -> None:
    shutil.rmtree(dress_take / "Capture" / "0028" / "labels")
    assert _import(dress_take, tmp_path / "out") == 2
    assert "garment_masks: camera(s) 0028 have none" in _error_line(capsys)


def test_a_frame_missing_in_one_camera_is_refused_naming_the_source(dress_take: Path, tmp_path: Path,
                                                                     capsys) -> None:
    (dress_take / "Capture" / "0076" / "images" / "capture-f00012.png").unlink()
    assert _import(dress_take, tmp_path / "out") == 2
    line = _error_line(capsys)
    assert "lacks frames 00012" in line and str(dress_take / "Capture") in line
    assert not (tmp_path / "out").exists()


def test_camera_missing_from_cameras_pkl_is_refused(dress_take: Path, tmp_path: Path, capsys) -> None:
    shutil.copytree(dress_take / "Capture" / "0004", dress_take / "Capture" / "0100")
    assert _import(dress_take, tmp_path / "out") == 2
    assert "cameras.pkl has no entry for camera(s) 0100" in _error_line(capsys)


class _Exploit:
    def __reduce__(self):
        return (os.system, ("touch pwned",))


def test_a_cameras_pkl_that_would_run_code_is_refused(dress_take: Path, tmp_path: Path, capsys,
                                                      monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with open(dress_take / "Capture" / "cameras.pkl", "wb") as fh:
        pickle.dump({"0004": _Exploit()}, fh)
    assert _import(dress_take, tmp_path / "out") == 2
    assert "refusing to load posix.system" in _error_line(capsys)
    assert not (tmp_path / "pwned").exists()


def test_reimport_with_other_options_is_refused(dress_take: Path, tmp_path: Path, capsys) -> None:
    assert _import(dress_take, tmp_path / "out") == 0
    capsys.readouterr()
    assert _import(dress_take, tmp_path / "out", "--garment", "skin") == 2
    assert "holds an earlier import" in _error_line(capsys)


def test_take_without_body_meshes_is_refused(dress_take: Path, tmp_path: Path, capsys) -> None:
    for ply in (dress_take / "SMPLX").glob("*.ply"):
        ply.unlink()
    assert _import(dress_take, tmp_path / "out") == 2
    assert "no SMPL-X body meshes (mesh-f#####_smplx.ply), only parameter .pkl files" in _error_line(capsys)
