import numpy as np
import pytest

from gg_core.reconstruction.isosurface import extract_surface, signed_volume
from gg_core.reconstruction.visual_hull import Grid


def test_sphere_field_gives_a_closed_outward_sphere():
    grid = Grid.covering(np.full(3, -0.5), np.full(3, 0.5), 0.02)
    field = 0.3 - np.linalg.norm(grid.points(), axis=1).reshape(grid.shape)      # > 0 inside
    verts, faces = extract_surface(grid, field)
    assert np.abs(np.linalg.norm(verts, axis=1) - 0.3).max() < 0.004
    assert signed_volume(verts, faces) == pytest.approx(4 / 3 * np.pi * 0.3 ** 3, rel=0.02)


def test_surface_closes_at_the_grid_border():
    grid = Grid.covering(np.full(3, -0.2), np.full(3, 0.2), 0.05)
    verts, faces = extract_surface(grid, np.ones(grid.shape))       # all inside: a box around the grid
    assert signed_volume(verts, faces) > 0
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)                                      # watertight
    empty_v, empty_f = extract_surface(grid, -np.ones(grid.shape))
    assert len(empty_v) == 0 and len(empty_f) == 0
