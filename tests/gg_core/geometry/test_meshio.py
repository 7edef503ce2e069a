from __future__ import annotations

import numpy as np
import pytest
import trimesh

from gg_core.errors import InputError
from gg_core.geometry.meshio import read_mesh, read_obj, write_obj, write_ply


def test_ply_round_trip_keeps_order_and_matches_trimesh(tmp_path) -> None:
    mesh = trimesh.creation.icosphere(2)
    write_ply(tmp_path / "m.ply", mesh.vertices, mesh.faces)
    v, f = read_mesh(tmp_path / "m.ply")
    assert np.allclose(v, mesh.vertices, atol=1e-6) and (f == mesh.faces).all()
    other = trimesh.load(tmp_path / "m.ply", process=False)
    assert np.allclose(other.vertices, v, atol=1e-6)


def test_ascii_ply_and_quads(tmp_path) -> None:
    (tmp_path / "q.ply").write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                                    "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                    "end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    v, f = read_mesh(tmp_path / "q.ply")
    assert v.shape == (4, 3) and f.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_obj_with_uvs_round_trip(tmp_path) -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    f = np.array([[0, 1, 2]])
    uv = np.array([[0, 0], [1, 0], [0, 1.0]])
    write_obj(tmp_path / "t.obj", v, f, uv, f)
    v2, f2, uv2, fu2 = read_obj(tmp_path / "t.obj")
    assert np.allclose(v2, v) and (f2 == f).all() and np.allclose(uv2, uv) and (fu2 == f).all()


def test_nan_and_bad_index_are_input_errors(tmp_path) -> None:
    write_ply(tmp_path / "nan.ply", np.array([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    with pytest.raises(InputError, match="NaN"):
        read_mesh(tmp_path / "nan.ply")
    write_ply(tmp_path / "idx.ply", np.zeros((3, 3)), np.array([[0, 1, 5]]))
    with pytest.raises(InputError, match="do not exist"):
        read_mesh(tmp_path / "idx.ply")
