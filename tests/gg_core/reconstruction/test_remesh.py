import numpy as np
import pytest

from gg_core.reconstruction.remesh import edge_length_for, edge_lengths, isotropic_remesh, triangle_quality

from .scenes import sphere_mesh


def test_remesh_reaches_the_target_vertex_count_with_even_triangles():
    verts, faces = sphere_mesh(0.3, 4)
    area = 4 * np.pi * 0.3 ** 2
    h = edge_length_for(area, 1500)
    v, f = isotropic_remesh(verts, faces, h)
    assert len(v) == pytest.approx(1500, rel=0.15)
    assert np.median(edge_lengths(v, f)) == pytest.approx(h, rel=0.15)
    assert np.percentile(triangle_quality(v, f), 5) > 0.7
    assert np.abs(np.linalg.norm(v, axis=1) - 0.3).max() < 0.005      # stays on the surface


def test_triangle_quality_is_one_for_equilateral_and_zero_for_degenerate():
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0], [2, 0, 0]], float)
    q = triangle_quality(v, np.array([[0, 1, 2], [0, 1, 3]]))
    assert q[0] == pytest.approx(1.0) and q[1] == pytest.approx(0.0)
