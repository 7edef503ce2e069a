import numpy as np
import pytest
import trimesh

from gg_core.reconstruction.mesh_graph import adjacency, face_components, genus, smooth, vertex_area, vertex_normals
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
