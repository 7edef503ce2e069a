"""The one place where gg coordinates (+Y up, OpenCV cameras) meet Blender's (+Z up, -Z looking cameras).

Numpy only, so the conversion can be tested without Blender and shared by the worker and the tests.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..capture.cameras import Camera

# (x, y, z)_gg -> (x, -z, y)_blender
GG_TO_BLENDER = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
# OpenCV camera axes (x right, y down, z forward) -> Blender camera axes (x right, y up, z backward)
CV_TO_BLENDER_CAMERA = np.diag([1.0, -1.0, -1.0])
SENSOR_WIDTH_MM = 36.0
# Blender's cloth solver accelerates by the scene's gravity x 0.001 per frame^2, not per s^2
# (tests/gg_core/diagnosis/test_blender_units.py measures it: 8.83 m/s^2 for 9.81 at 30 fps)
CLOTH_GRAVITY_PER_FRAME2 = 0.001


def to_blender(points: np.ndarray) -> np.ndarray:
    """Points [..., 3] from gg world to Blender world."""
    return np.asarray(points) @ GG_TO_BLENDER.T


def from_blender(points: np.ndarray) -> np.ndarray:
    """Points [..., 3] from Blender world to gg world."""
    return np.asarray(points) @ GG_TO_BLENDER


def scene_gravity(gravity: list[float], fps: int) -> list[float]:
    """Blender's scene gravity setting under which the cloth falls at `gravity` (gg coordinates, m/s^2).

    Set uncompensated, every capture would fall at 0.001 fps^2 of the intended gravity (0.9 g at 30 fps) while its
    truth.json said 9.81.
    """
    return (to_blender(np.asarray(gravity, np.float64)) / (CLOTH_GRAVITY_PER_FRAME2 * fps ** 2)).tolist()


@dataclass(frozen=True)
class BlenderCamera:
    """Settings of a Blender camera object that renders exactly what `Camera.project` predicts."""

    matrix_world: np.ndarray  # 4x4, Blender world
    lens_mm: float
    sensor_width_mm: float
    shift_x: float
    shift_y: float
    width: int
    height: int


def blender_camera(cam: Camera) -> BlenderCamera:
    """Pinhole K,R,t -> Blender camera (horizontal sensor fit, square pixels, principal point as lens shift)."""
    fx, fy = cam.K[0, 0], cam.K[1, 1]
    if abs(fx - fy) > 1e-9 * fx or abs(cam.K[0, 1]) > 1e-12:
        raise ValueError(f"camera {cam.id}: Blender renders square, unskewed pixels only (fx={fx}, fy={fy})")
    m = np.eye(4)
    m[:3, :3] = GG_TO_BLENDER @ cam.R.T @ CV_TO_BLENDER_CAMERA
    m[:3, 3] = GG_TO_BLENDER @ cam.center
    # Blender measures lens shift in units of the fitted (horizontal) sensor side; +x shifts the view right.
    return BlenderCamera(matrix_world=m, lens_mm=fx * SENSOR_WIDTH_MM / cam.width, sensor_width_mm=SENSOR_WIDTH_MM,
                         shift_x=(cam.width / 2 - cam.K[0, 2]) / cam.width,
                         shift_y=(cam.K[1, 2] - cam.height / 2) / cam.width, width=cam.width, height=cam.height)
