import numpy as np
import pytest
import trimesh

from gg_core.reconstruction.mesh_graph import (adjacency, face_components, genus, smooth, smoothed_normals, vertex_area,
                                               vertex_normals)
from gg_core.reconstruction.surface_cut import border_loops, cut_at_level

from .scenes import sphere_mesh


def test_genus_and_border_loops_of_sphere_tube_and_torus():
    v, f = sphere_mesh(0.3, 2)
    assert genus(f) == 0 and border_loops(f) == 0
    tv, tf = cut_at_level(v, f, 0.2 - np.abs(v[:, 1]), 0.1)        # |y| <= 0.1: a band (tube)
    assert border_loops(tf) == 2 and genus(tf) == 0
    torus = trimesh.creation.torus(major_radius=0.3, minor_radius=0.1)
    assert genus(np.asarray(torus.faces)) == 1


def test_normals_areas_smoothing_and_components():
    v, f = sphere_mesh(0.3, 3)
    n = vertex_normals(v, f)
    assert np.all(np.einsum("ij,ij->i", n, v / 0.3) > 0.99)           # outward unit normals
    assert vertex_area(v, f).sum() == pytest.approx(4 * np.pi * 0.09, rel=0.01)
    adj = adjacency(f, len(v))
    noisy = np.random.default_rng(0).normal(size=len(v))
    assert smooth(noisy, adj, 10).std() < 0.3 * noisy.std()
    assert np.all(face_components(np.concatenate([f, f + len(v)])) == np.repeat([0, 1], len(f)))


def test_smoothed_normals_remove_the_tilt_of_small_wrinkles():
    v, f = sphere_mesh(0.3, 3)
    radial = v / np.linalg.norm(v, axis=1, keepdims=True)
    bumpy = v * (1 + 0.03 * np.random.default_rng(0).normal(size=(len(v), 1)))     # 9 mm rms wrinkles
    n = vertex_normals(bumpy, f)
    adj = adjacency(f, len(v))
    s = smoothed_normals(n, adj, 3)
    assert np.allclose(np.linalg.norm(s, axis=1), 1.0)
    tilt = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, radial), -1, 1))).mean()
    tilt_smoothed = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", s, radial), -1, 1))).mean()
    assert tilt_smoothed < 0.5 * tilt
    assert np.array_equal(smoothed_normals(n, adj, 0), n / np.linalg.norm(n, axis=1, keepdims=True))
