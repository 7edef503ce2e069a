"""ActorsHQ sequences (synthesiaresearch/humanrf, actorshq/dataset) -> product capture layout.

Source layout of one sequence at one resolution (`<Actor>/<Sequence>/<1x|2x|4x>/`):
```
calibration.csv                      name, w, h, rx, ry, rz, tx, ty, tz, fx, fy, px, py
rgbs/<cam>/<cam>_rgb######.jpg
masks/<cam>/<cam>_mask######.png     (person mask, optional)
```
Conventions (HumanRF `CameraData`): cameras are right-down-forward like OpenCV; (rx, ry, rz) is an
axis-angle rotation and (tx, ty, tz) a translation, both camera->world (`world = R c + t`), metres,
world +Y up; fx, fy, px, py are normalized by the image width/height. HumanRF exports these values to
COLMAP as `fx*w, fy*h, px*w, py*h` unchanged, so the pixel origin is the top-left pixel's corner, the
product's convention. The CSV's w, h may be the full-resolution size while the images are a 2x/4x
downscale (HumanRF keeps the normalized values and integer-divides the size); K uses the actual image size.

Frames keep the dataset's 6-digit names (`Cam001_rgb000012.jpg` -> `000012`). ActorsHQ ships no body
meshes: pass `body` (a folder of per-frame meshes named exactly like the frames); names that differ, for
example 5-digit `00012.ply` against 6-digit frames, are refused instead of silently dropping the body.
ActorsHQ has no garment masks: the import warns and leaves `garment_masks/` to the user.
"""
from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from ...errors import InputError
from ..images import image_size
from ..layout import FOREGROUND_MASK, RGB
from .source import SourceSequence, body_from_folder, numbered_files, pinhole_camera

FORMAT = "actorshq"
COLUMNS = ("name", "w", "h", "rx", "ry", "rz", "tx", "ty", "tz", "fx", "fy", "px", "py")
DISTORTION_COLUMNS = ("k1", "k2", "k3", "p1", "p2")


def read(src: str | Path, body: str | Path | None = None) -> SourceSequence:
    """The sequence folder `src` (the one holding calibration.csv, rgbs/ and masks/) as a SourceSequence."""
    src = Path(src)
    if src.is_file() and src.name == "calibration.csv":
        src = src.parent
    rows = _read_calibration(src / "calibration.csv")
    rgbs = src / "rgbs"
    if not rgbs.is_dir():
        raise InputError("no rgbs/ folder", src, "pass the folder that holds calibration.csv and rgbs/")
    files: dict[str, dict[str, dict[str, Path]]] = {RGB: {}, FOREGROUND_MASK: {}}
    cameras = {}
    for index, cam_dir in enumerate(sorted(p for p in rgbs.iterdir() if p.is_dir())):
        cid = cam_dir.name
        files[RGB][cid] = numbered_files(cam_dir, rf"{re.escape(cid)}_rgb(\d+)\.jpg")
        if not files[RGB][cid]:
            raise InputError(f"no {cid}_rgb######.jpg images", cam_dir, "download the camera's images")
        masks = numbered_files(src / "masks" / cid, rf"{re.escape(cid)}_mask(\d+)\.png")
        if masks:
            files[FOREGROUND_MASK][cid] = masks
        if cid in rows:
            size = image_size(next(iter(files[RGB][cid].values())))
            cameras[cid] = _camera(cid, rows[cid], index, size, src / "calibration.csv")
    files = {kind: per_cam for kind, per_cam in files.items() if per_cam}
    meshes, params = body_from_folder(Path(body)) if body is not None else ({}, {})
    name = src.parent.name if re.fullmatch(r"\d+x", src.name) else src.name
    return SourceSequence(FORMAT, src, name, cameras, files, body=meshes, body_params=params,
                          options={"body": None if body is None else str(Path(body).resolve())})


def rotation_from_axis_angle(r: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: the rotation by |r| radians about r/|r|."""
    angle = float(np.linalg.norm(r))
    if angle < 1e-12:
        return np.eye(3)
    k = np.asarray(r, np.float64) / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def _read_calibration(path: Path) -> dict[str, dict[str, float]]:
    if not path.is_file():
        raise InputError("calibration.csv not found", path, "pass the ActorsHQ folder that holds calibration.csv")
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        missing = [c for c in COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise InputError(f"calibration.csv lacks column(s) {', '.join(missing)}", path,
                             f"expected the header {','.join(COLUMNS)}")
        rows = {}
        for line, row in enumerate(reader, start=2):
            try:
                values = {c: float(row[c]) for c in COLUMNS[1:]}
                distortion = [float(row[c] or 0) for c in DISTORTION_COLUMNS if c in row]
            except (TypeError, ValueError):
                raise InputError(f"calibration.csv line {line} has a non-numeric value", path,
                                 "fix or re-download the calibration") from None
            if any(distortion):
                raise InputError(f"camera '{row['name']}' has non-zero distortion", path,
                                 "undistort the images first and write zero distortion")
            rows[row["name"]] = values
    if not rows:
        raise InputError("calibration.csv holds no cameras", path, "re-download the calibration")
    return rows


def _camera(cid: str, row: dict[str, float], index: int, size: tuple[int, int], where: Path):
    name_w, name_h = int(row["w"]), int(row["h"])
    width, height = size
    if (width, height) != (name_w, name_h):
        factor = round(name_w / width) if width else 0
        if factor < 1 or (name_w // factor, name_h // factor) != (width, height):
            raise InputError(f"camera '{cid}' images are {width}x{height} but calibration.csv says {name_w}x{name_h} "
                             "(not an integer downscale)", where, "use the calibration.csv of the same resolution")
    c2w = rotation_from_axis_angle(np.array([row["rx"], row["ry"], row["rz"]]))
    R = c2w.T
    t = -R @ np.array([row["tx"], row["ty"], row["tz"]])
    K = np.array([[row["fx"] * width, 0.0, row["px"] * width], [0.0, row["fy"] * height, row["py"] * height],
                  [0.0, 0.0, 1.0]])
    return pinhole_camera(cid, K, np.hstack([R, t[:, None]]), width, height, index, where)
