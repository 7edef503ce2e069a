"""Calibrated pinhole cameras in the capture's `cameras.json` (OpenCV convention, metres, +Y up world).

Only numpy and the standard library: the Blender add-on reads cameras through this module too.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

ORTHONORMAL_TOL = 1e-4


@dataclass(frozen=True)
class Camera:
    """One calibrated camera: K (3x3), world->camera rotation R and translation t, image size."""

    id: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    index: int = 0

    @property
    def w2c(self) -> np.ndarray:
        m = np.eye(4)
        m[:3, :3] = self.R
        m[:3, 3] = self.t
        return m

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates."""
        return -self.R.T @ self.t

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (x right, y down, pixel centres at +0.5) and camera-space depth."""
        cam = np.asarray(points, dtype=np.float64) @ self.R.T + self.t
        z = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (cam @ self.K.T)[:, :2] / z[:, None]
        return uv, z

    def to_json(self) -> dict:
        return {"intrinsics": self.K.tolist(), "extrinsics": np.hstack([self.R, self.t[:, None]]).tolist(),
                "ids": int(self.index), "width": int(self.width), "height": int(self.height)}


def look_at(cam_id: str, eye: np.ndarray, target: np.ndarray, fov_deg: float, width: int, height: int,
            up: np.ndarray = np.array([0.0, 1.0, 0.0]), index: int = 0) -> Camera:
    """A camera at `eye` looking at `target` with the given horizontal field of view."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    f = 0.5 * width / math.tan(math.radians(fov_deg) / 2)
    K = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1.0]])
    return Camera(cam_id, K, R, -R @ eye, int(width), int(height), index)


def load_cameras(path: str | Path) -> dict[str, Camera]:
    """Read and validate `cameras.json`; every problem is an InputError naming the file and camera."""
    path = Path(path)
    if not path.is_file():
        raise InputError("cameras.json not found", path, "add the calibration file to the sequence folder")
    try:
        raw = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"cameras.json is not valid JSON ({exc.msg if hasattr(exc, 'msg') else exc})", path,
                         "fix or re-export the calibration file") from None
    if not isinstance(raw, dict) or not raw:
        raise InputError("cameras.json holds no cameras", path, "expected {camera_id: {intrinsics, extrinsics, ...}}")
    return {str(cid): _parse_camera(str(cid), entry, path) for cid, entry in sorted(raw.items())}


def save_cameras(path: str | Path, cameras: dict[str, Camera]) -> None:
    from ..storage import write_json

    write_json(path, {cid: cam.to_json() for cid, cam in cameras.items()})


def _parse_camera(cid: str, entry: object, path: Path) -> Camera:
    where = f"{path} camera {cid}"
    if not isinstance(entry, dict):
        raise InputError("camera entry is not an object", where, "expected {intrinsics, extrinsics, width, height}")
    for key in ("intrinsics", "extrinsics", "width", "height"):
        if key not in entry:
            raise InputError(f"camera is missing '{key}'", where, f"add '{key}' to the camera entry")
    K = _matrix(entry["intrinsics"], (3, 3), "intrinsics", where)
    E = _matrix(entry["extrinsics"], (3, 4), "extrinsics", where)
    R, t = E[:, :3], E[:, 3]
    if abs(K[2, 2] - 1) > 1e-9 or abs(K[2, 0]) + abs(K[2, 1]) > 1e-9 or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError("intrinsics are not a pinhole matrix [[fx,s,cx],[0,fy,cy],[0,0,1]] with fx, fy > 0", where,
                         "fix the calibration")
    err = float(np.abs(R @ R.T - np.eye(3)).max())
    if err > ORTHONORMAL_TOL or np.linalg.det(R) < 0:
        raise InputError(f"extrinsic rotation is not orthonormal (|RR^T-I|={err:.2g}, det={np.linalg.det(R):.3f})",
                         where, "re-export the calibration as world->camera [R|t] with a proper rotation")
    width, height = entry["width"], entry["height"]
    if not all(isinstance(v, int) and v > 0 for v in (width, height)):
        raise InputError("width/height must be positive integers", where, "add the image size in pixels")
    index = entry.get("ids", 0)
    return Camera(cid, K, R.copy(), t.copy(), width, height, int(index) if isinstance(index, (int, float)) else 0)


def _matrix(value: object, shape: tuple[int, int], name: str, where: str) -> np.ndarray:
    try:
        m = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name} is not a numeric matrix", where,
                         f"write {name} as a {shape[0]}x{shape[1]} list") from None
    if m.shape != shape:
        raise InputError(f"{name} has shape {m.shape}, expected {shape}", where,
                         f"write {name} as {shape[0]}x{shape[1]}")
    if not np.isfinite(m).all():
        raise InputError(f"{name} contains NaN or infinite values", where, "re-export the calibration")
    return m
