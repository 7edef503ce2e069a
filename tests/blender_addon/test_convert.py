"""Y-up -> Z-up and OpenCV -> Blender camera conversion, checked without Blender (the projection itself is
checked through Blender in tests/operators/test_import_capture.py)."""
from __future__ import annotations

import importlib

import numpy as np
import pytest

from gg_core.capture.cameras import look_at


@pytest.fixture
def convert(extension_package):
    return importlib.import_module(f"{extension_package.__name__}.blender_addon.convert")


def test_points_go_to_z_up(convert):
    pts = np.array([[1.0, 2.0, 3.0], [-4.0, 5.0, -6.0]])
    np.testing.assert_array_equal(convert.to_blender_points(pts), [[1.0, -3.0, 2.0], [-4.0, 6.0, 5.0]])


def test_camera_pose_and_intrinsics(convert):
    cam = look_at("c", np.array([2.0, 1.5, 2.5]), np.array([0.0, 1.0, 0.0]), 50, 160, 90)
    K = cam.K.copy()
    K[0, 0], K[1, 1], K[0, 2], K[1, 2] = 150.0, 120.0, 90.0, 40.0
    b = convert.blender_camera(K, cam.R, cam.t, 160, 90)
    M = b.matrix_world
    np.testing.assert_allclose(M[:3, :3] @ M[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(M[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_allclose(M[:3, 3], [2.0, -2.5, 1.5], atol=1e-12)  # eye (2, 1.5, 2.5) in Z-up
    # Blender cameras look down their local -Z: that axis must be the OpenCV optical axis, in Z-up world.
    forward = -M[:3, 2]
    np.testing.assert_allclose(forward, convert.to_blender_points(cam.R[2][None])[0], atol=1e-12)
    # and their local +Y (up in the image) must be OpenCV's -y (image rows grow downwards).
    np.testing.assert_allclose(M[:3, 1], -convert.to_blender_points(cam.R[1][None])[0], atol=1e-12)
    assert b.lens == pytest.approx(150.0 * 36.0 / 160)
    assert b.shift_x == pytest.approx((80 - 90) / 160)
    assert b.pixel_aspect_y / b.pixel_aspect_x == pytest.approx(150.0 / 120.0)
    assert min(b.pixel_aspect_x, b.pixel_aspect_y) == 1.0
