from __future__ import annotations

import json

import numpy as np
import pytest

from gg_core.capture.cameras import load_cameras, look_at, save_cameras
from gg_core.errors import InputError


def test_look_at_projects_target_to_principal_point_and_up_is_image_up() -> None:
    cam = look_at("c", np.array([0.0, 1.0, 3.0]), np.array([0.0, 1.0, 0.0]), 60, 200, 100)
    uv, z = cam.project(np.array([[0.0, 1.0, 0.0], [0.0, 1.5, 0.0], [0.5, 1.0, 0.0]]))
    assert np.allclose(uv[0], [100, 50]) and np.isclose(z[0], 3.0)
    assert uv[1, 1] < 50  # world up is image up (OpenCV y down)
    assert uv[2, 0] > 100  # +x is to the right seen from +z
    assert np.allclose(cam.center, [0, 1, 3])
    assert np.allclose(cam.R @ cam.R.T, np.eye(3)) and np.isclose(np.linalg.det(cam.R), 1)


def test_cameras_json_round_trip(tmp_path) -> None:
    cams = {f"c{i}": look_at(f"c{i}", np.array([np.sin(i), 0.5, np.cos(i)]) * 3, np.zeros(3), 40, 64, 48, index=i)
            for i in range(3)}
    save_cameras(tmp_path / "cameras.json", cams)
    back = load_cameras(tmp_path / "cameras.json")
    for cid, cam in cams.items():
        assert np.allclose(back[cid].K, cam.K) and np.allclose(back[cid].w2c, cam.w2c)
        assert (back[cid].width, back[cid].height, back[cid].index) == (64, 48, cam.index)


@pytest.mark.parametrize("mutate, message", [
    (lambda c: c["c0"].pop("width"), "missing 'width'"),
    (lambda c: c["c0"].__setitem__("intrinsics", [[1, 0], [0, 1]]), "intrinsics has shape"),
    (lambda c: c["c0"]["extrinsics"][0].__setitem__(0, -1.0), "not orthonormal"),
])
def test_bad_camera_entries_are_input_errors(tmp_path, mutate, message) -> None:
    save_cameras(tmp_path / "cameras.json", {"c0": look_at("c0", np.array([0, 0, 3.0]), np.zeros(3), 40, 8, 8)})
    raw = json.loads((tmp_path / "cameras.json").read_text())
    mutate(raw)
    (tmp_path / "cameras.json").write_text(json.dumps(raw))
    with pytest.raises(InputError, match=message):
        load_cameras(tmp_path / "cameras.json")
