"""Conversions at the Blender boundary: +Y-up world -> Blender +Z-up, OpenCV pinhole -> Blender camera.

Numpy only (no bpy) so the maths is testable on its own. Derivation, for a camera with K, R, t:
a world point P (Y-up) has OpenCV camera coordinates X = R P + t (x right, y down, z forward).
Blender camera axes are x right, y up, -z forward, i.e. X_blender = F X with F = diag(1, -1, -1), and Blender
world points are A P with A the Y-up -> Z-up rotation. Hence the camera's matrix_world is
[A R^T F | A C] with C = -R^T t the camera centre.

Blender's view plane (sensor_fit HORIZONTAL, sensor width S, lens L, render size W x H, pixel aspect
ratio ycor = aspect_y / aspect_x) maps camera coordinates to pixels as
u = fx_b x/z + W/2 - shift_x W and v = fx_b/ycor y/z + H/2 + shift_y W / ycor with fx_b = L W / S
(v measured from the top). Matching u = fx x/z + cx, v = fy y/z + cy gives the formulas below.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# (x, y, z) in the Y-up world -> (x, -z, y) in Blender's Z-up world.
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
# OpenCV camera axes (x right, y down, z forward) -> Blender camera axes (x right, y up, -z forward).
OPENCV_TO_BLENDER_CAMERA = np.diag([1.0, -1.0, -1.0])
SENSOR_WIDTH_MM = 36.0


def to_blender_points(points: np.ndarray) -> np.ndarray:
    """Y-up world points [..., 3] -> Blender Z-up points [..., 3] (any leading shape: one mesh or its frames)."""
    return np.asarray(points, dtype=np.float64) @ Y_UP_TO_Z_UP.T


@dataclass(frozen=True)
class BlenderCamera:
    """Everything a Blender camera object + scene render settings need to reproduce one pinhole camera."""

    matrix_world: np.ndarray  # 4x4, Blender Z-up world
    lens: float  # mm, with sensor_fit HORIZONTAL
    sensor_width: float  # mm
    shift_x: float
    shift_y: float
    resolution_x: int
    resolution_y: int
    pixel_aspect_x: float  # Blender keeps both aspects >= 1
    pixel_aspect_y: float
    skew: float  # K[0, 1]; Blender cameras cannot represent it


def blender_camera(K: np.ndarray, R: np.ndarray, t: np.ndarray, width: int, height: int,
                   sensor_width: float = SENSOR_WIDTH_MM) -> BlenderCamera:
    """Blender camera parameters reproducing the OpenCV camera (K, world->camera R, t) of a Y-up world."""
    K, R, t = (np.asarray(a, dtype=np.float64) for a in (K, R, t))
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    matrix = np.eye(4)
    matrix[:3, :3] = Y_UP_TO_Z_UP @ R.T @ OPENCV_TO_BLENDER_CAMERA
    matrix[:3, 3] = Y_UP_TO_Z_UP @ (-R.T @ t)
    ycor = fx / fy  # = pixel_aspect_y / pixel_aspect_x
    aspect_x, aspect_y = (1.0, ycor) if ycor >= 1.0 else (1.0 / ycor, 1.0)
    return BlenderCamera(
        matrix_world=matrix,
        lens=fx * sensor_width / width,
        sensor_width=sensor_width,
        shift_x=(width / 2 - cx) / width,
        shift_y=(cy - height / 2) * ycor / width,
        resolution_x=int(width),
        resolution_y=int(height),
        pixel_aspect_x=aspect_x,
        pixel_aspect_y=aspect_y,
        skew=float(K[0, 1]),
    )
