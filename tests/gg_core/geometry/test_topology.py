"""Mesh connectivity: edge and hinge counts, hinge orientation, adjacency, lumped areas."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).parents[1] / "physics"))

from physics_helpers import sheet, uv_sphere  # noqa: E402

from gg_core.geometry.topology import build_topology, vertex_areas, vertex_faces  # noqa: E402
from gg_core.physics.energies import dihedral_angles  # noqa: E402


def test_closed_sphere_counts():
    v, f = uv_sphere(1.0, 8, 12)
    topo = build_topology(f, len(v))
    assert len(v) - len(topo.edges) + len(f) == 2                       # Euler characteristic of a sphere
    assert (topo.edge_face_count == 2).all()
    assert len(topo.hinges) == len(topo.edges)
    assert not topo.boundary_vertices.any()
    # face_edges[f, k] joins corners k and k+1
    e = topo.edges[topo.face_edges]
    corners = np.stack([f, np.roll(f, -1, axis=1)], -1)
    np.testing.assert_array_equal(np.sort(e, -1), np.sort(corners, -1))


def test_sheet_boundary_and_hinges():
    v, f = sheet(3, 2, 1.0, 1.0)
    topo = build_topology(f, len(v))
    n_boundary_edges = 2 * (3 + 2)
    assert (topo.edge_face_count == 1).sum() == n_boundary_edges
    assert len(topo.hinges) == len(topo.edges) - n_boundary_edges
    assert topo.boundary_vertices.sum() == 2 * (3 + 2)
    # hinge faces contain their hinge edge, and each opposite vertex belongs to its face
    for (e0, e1, o0, o1), (fa, fb) in zip(topo.hinges, topo.hinge_faces):
        assert {e0, e1, o0} == set(f[fa]) and {e0, e1, o1} == set(f[fb])


def test_hinge_orientation_gives_signed_fold_angles():
    """A flat sheet has zero dihedral angles; folding it gives the same sign on both sides of every hinge's edge
    whichever face was listed first (consistent orientation)."""
    v, f = sheet(4, 1, 1.0, 0.25)
    topo = build_topology(f, len(v))
    hinges = torch.from_numpy(topo.hinges)
    flat = dihedral_angles(torch.from_numpy(v), hinges)
    assert flat.abs().max() < 1e-12
    folded = v.copy()
    folded[:, 1] = 0.3 * np.abs(v[:, 0])                              # a V-shaped valley along x = 0
    angles = dihedral_angles(torch.from_numpy(folded), hinges).numpy()
    on_crease = np.abs(v[topo.hinges[:, 0], 0]) + np.abs(v[topo.hinges[:, 1], 0]) < 1e-9
    assert on_crease.sum() > 0
    expected = 2 * np.arctan(0.3)
    np.testing.assert_allclose(np.abs(angles[on_crease]), expected, rtol=1e-9)
    assert len(set(np.sign(angles[on_crease]))) == 1
    np.testing.assert_allclose(angles[~on_crease], 0.0, atol=1e-12)


def test_adjacency_and_areas():
    v, f = sheet(2, 2, 2.0, 2.0)
    offsets, faces_of = vertex_faces(f, len(v))
    center = 4
    assert offsets[center + 1] - offsets[center] == 6
    assert all(center in f[k] for k in faces_of[offsets[center]:offsets[center + 1]])
    assert vertex_areas(v, f).sum() == pytest.approx(4.0)
