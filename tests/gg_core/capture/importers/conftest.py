"""Small captures written in the real on-disk formats of 4D-Dress, ActorsHQ and COLMAP.

Calibrations are non-trivial on purpose: off-centre principal points, fx != fy, non-square images,
cameras all around the subject, so that a transposed rotation or a swapped axis cannot pass.
"""
from __future__ import annotations

import csv
import pickle
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from PIL import Image
from scipy.spatial.transform import Rotation

SIZE = (47, 64)  # W x H, portrait like 4D-Dress (940 x 1280) but tiny
OCTA_V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float) * 0.3
OCTA_F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
# World points around a standing person (metres, +Y up) used to compare projections.
TEST_POINTS = np.array([[0.0, 1.0, 0.0], [0.21, 1.43, -0.12], [-0.3, 0.35, 0.17], [0.05, 1.72, 0.2]])


def ring_calibration(n_cams: int, size: tuple[int, int] = SIZE, seed: int = 0) -> list[dict]:
    """Per camera: K (3x3), world->camera R, t (OpenCV) and the camera->world rotation and centre."""
    rng = np.random.default_rng(seed)
    w, h = size
    out = []
    for i in range(n_cams):
        a = 2 * np.pi * i / n_cams + 0.3
        eye = np.array([2.6 * np.sin(a), 0.9 + 0.3 * i, 2.6 * np.cos(a)])
        z = np.array([0.0, 1.0, 0.0]) - eye
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, -1.0, 0.0])
        x /= np.linalg.norm(x)
        c2w = np.stack([x, np.cross(z, x), z], axis=1) @ Rotation.from_rotvec(rng.normal(0, 0.05, 3)).as_matrix()
        R = c2w.T
        f = rng.uniform(0.9, 1.3) * w
        K = np.array([[f, 0, w / 2 + rng.uniform(-3, 3)], [0, f * rng.uniform(0.97, 1.03), h / 2 + rng.uniform(-3, 3)],
                      [0, 0, 1.0]])
        out.append({"K": K, "R": R, "t": -R @ eye, "c2w": c2w, "center": eye})
    return out


def _rgb(rng: np.random.Generator, size: tuple[int, int]) -> Image.Image:
    return Image.fromarray(rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8))


def _block_mask(size: tuple[int, int], k: int) -> Image.Image:
    w, h = size
    m = np.zeros((h, w), np.uint8)
    m[h // 4 + k: 3 * h // 4, w // 4: 3 * w // 4 - k] = 255
    return Image.fromarray(m)


def write_4d_dress_take(root: Path, outfit: str = "Outer", cams: tuple[str, ...] = ("0004", "0028", "0076"),
                        frames: tuple[int, ...] = (11, 12, 13), labels: bool = True) -> Path:
    """`<root>/00122/<outfit>/Take9` as the dataset ships it (cameras.pkl pickled numpy arrays)."""
    rng = np.random.default_rng(1)
    take = root / "00122" / outfit / "Take9"
    capture = take / "Capture"
    calib = ring_calibration(len(cams))
    capture.mkdir(parents=True)
    pkl = {cid: {"intrinsics": c["K"].astype(np.float32), "extrinsics": np.hstack([c["R"], c["t"][:, None]])}
           for cid, c in zip(cams, calib)}
    with open(capture / "cameras.pkl", "wb") as fh:
        pickle.dump(pkl, fh)
    with open(take / "basic_info.pkl", "wb") as fh:
        pickle.dump({"scan_frames": [f"{f:05d}" for f in frames], "rotation": None, "offset": np.zeros(3)}, fh)
    for cid in cams:
        for sub in ("images", "masks") + (("labels",) if labels else ()):
            (capture / cid / sub).mkdir(parents=True)
        for k, f in enumerate(frames):
            _rgb(rng, SIZE).save(capture / cid / "images" / f"capture-f{f:05d}.png")
            _block_mask(SIZE, k).save(capture / cid / "masks" / f"mask-f{f:05d}.png")
            if labels:
                lab = np.full((SIZE[1], SIZE[0], 3), 255, np.uint8)
                lab[10 + k:30, 8:40] = (0, 128, 255)   # outer
                lab[30:50, 8:40] = (128, 128, 128)     # skin
                lab[50:60, 8:20] = (50, 180, 50)       # lower
                Image.fromarray(lab).save(capture / cid / "labels" / f"label-f{f:05d}.png")
                Image.fromarray(lab // 2).save(capture / cid / "labels" / f"overlap-f{f:05d}.png")
    smplx = take / "SMPLX"
    smplx.mkdir()
    for k, f in enumerate(frames):
        trimesh.Trimesh(OCTA_V + [0, 1.0 + 0.01 * k, 0], OCTA_F, process=False).export(
            smplx / f"mesh-f{f:05d}_smplx.ply")
        with open(smplx / f"mesh-f{f:05d}_smplx.pkl", "wb") as fh:
            pickle.dump({"betas": np.zeros((1, 10), np.float32), "transl": np.array([[0, 0.01 * k, 0]])}, fh)
    return take


ACTORSHQ_COLUMNS = ["name", "w", "h", "rx", "ry", "rz", "tx", "ty", "tz", "fx", "fy", "px", "py"]


def write_actorshq_sequence(root: Path, n_cams: int = 3, frames: tuple[int, ...] = (0, 1, 2),
                            downscale: int = 2) -> Path:
    """`<root>/Actor01/Sequence1/<downscale>x/` with calibration.csv at full resolution, images downscaled."""
    rng = np.random.default_rng(2)
    folder = root / "Actor01" / "Sequence1" / f"{downscale}x"
    folder.mkdir(parents=True)
    calib = ring_calibration(n_cams)
    full = (SIZE[0] * downscale, SIZE[1] * downscale)
    with open(folder / "calibration.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=ACTORSHQ_COLUMNS)
        writer.writeheader()
        for i, c in enumerate(calib):
            rot = Rotation.from_matrix(c["c2w"]).as_rotvec()
            K = c["K"]
            writer.writerow({"name": f"Cam{i + 1:03d}", "w": full[0], "h": full[1], "rx": rot[0], "ry": rot[1],
                             "rz": rot[2], "tx": c["center"][0], "ty": c["center"][1], "tz": c["center"][2],
                             "fx": K[0, 0] / SIZE[0], "fy": K[1, 1] / SIZE[1], "px": K[0, 2] / SIZE[0],
                             "py": K[1, 2] / SIZE[1]})
    for i in range(n_cams):
        cam = f"Cam{i + 1:03d}"
        (folder / "rgbs" / cam).mkdir(parents=True)
        (folder / "masks" / cam).mkdir(parents=True)
        for k, f in enumerate(frames):
            _rgb(rng, SIZE).save(folder / "rgbs" / cam / f"{cam}_rgb{f:06d}.jpg", quality=90)
            _block_mask(SIZE, k).save(folder / "masks" / cam / f"{cam}_mask{f:06d}.png")
    return folder


def write_body_folder(folder: Path, names: list[str]) -> Path:
    folder.mkdir(parents=True)
    for k, name in enumerate(names):
        trimesh.Trimesh(OCTA_V + [0, 1.0 + 0.01 * k, 0], OCTA_F, process=False).export(folder / f"{name}.ply")
    return folder


def write_colmap_project(root: Path, n_cams: int = 3, frames: tuple[str, ...] = ("000000", "000001"),
                         model: str = "PINHOLE", distortion: float = 0.0, nested: bool = True,
                         drift: float = 0.0) -> Path:
    """`<root>/project/{images,sparse/0}`: a binary sparse model written with pycolmap plus its images.

    `nested`: image names `<camera>/<frame>.png` (a video per camera); otherwise `<camera>.png` stills.
    `drift`: metres each camera moves per frame (a moving camera the importer must refuse)."""
    import pycolmap

    rng = np.random.default_rng(3)
    project = root / "project"
    rec = pycolmap.Reconstruction()
    image_id = 1
    for i, c in enumerate(ring_calibration(n_cams)):
        K = c["K"]
        cam = pycolmap.Camera.create_from_model_name(i + 1, model, float(K[0, 0]), SIZE[0], SIZE[1])
        if model == "PINHOLE":
            cam.params = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
        elif model == "OPENCV":
            cam.params = [K[0, 0], K[1, 1], K[0, 2], K[1, 2], distortion, 0, 0, 0]
        rec.add_camera_with_trivial_rig(cam)
        for k, frame in enumerate(frames if nested else (None,)):
            pose = pycolmap.Rigid3d(pycolmap.Rotation3d(c["R"]), c["t"] + [drift * k, 0, 0])
            name = f"cam{i:02d}/{frame}.png" if nested else f"cam{i:02d}.png"
            rec.add_image_with_trivial_frame(pycolmap.Image(name=name, camera_id=i + 1, image_id=image_id), pose)
            image_id += 1
            (project / "images" / name).parent.mkdir(parents=True, exist_ok=True)
            _rgb(rng, SIZE).save(project / "images" / name)
    (project / "sparse" / "0").mkdir(parents=True)
    rec.write(str(project / "sparse" / "0"))
    return project


@pytest.fixture
def writers() -> SimpleNamespace:
    """The fixture writers and constants above, for tests that need variants (importlib mode: no imports)."""
    return SimpleNamespace(size=SIZE, points=TEST_POINTS, dress_take=write_4d_dress_take,
                           actorshq=write_actorshq_sequence, body=write_body_folder, colmap=write_colmap_project)


@pytest.fixture
def dress_take(tmp_path: Path) -> Path:
    return write_4d_dress_take(tmp_path / "4D-DRESS")


@pytest.fixture
def actorshq_sequence(tmp_path: Path) -> Path:
    return write_actorshq_sequence(tmp_path / "ActorsHQ")


@pytest.fixture
def colmap_project(tmp_path: Path) -> Path:
    return write_colmap_project(tmp_path / "colmap")
