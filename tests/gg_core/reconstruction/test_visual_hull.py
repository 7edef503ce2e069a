import numpy as np
import pytest

from gg_core.reconstruction.isosurface import extract_surface
from gg_core.reconstruction.visual_hull import Grid, Silhouette, bilinear, camera_bounds, hull_bounds, hull_field, \
    silhouette_sdf

from .scenes import ring_cameras, sphere_mask


def test_silhouette_sdf_of_a_disc_is_the_distance_to_its_outline():
    yy, xx = np.mgrid[0:101, 0:101] + 0.5
    r = np.hypot(xx - 50.5, yy - 50.5)
    sdf = silhouette_sdf(r <= 30)
    assert sdf[50, 50] == pytest.approx(30, abs=1.0)        # centre: 30 px inside
    assert sdf[50, 90] == pytest.approx(-10, abs=1.0)       # 40 px from the centre: 10 px outside
    assert np.all(sdf[r <= 29] > 0) and np.all(sdf[r > 31] < 0)


def test_bilinear_interpolates_between_pixel_centres():
    image = np.array([[0.0, 1.0], [2.0, 3.0]])
    assert bilinear(image, np.array([1.0]), np.array([1.0]))[0] == pytest.approx(1.5)
    assert bilinear(image, np.array([0.5]), np.array([1.5]))[0] == pytest.approx(2.0)
    rgb = np.stack([image, 2 * image, 3 * image], axis=-1)
    np.testing.assert_allclose(bilinear(rgb, np.array([1.0]), np.array([1.0]))[0], [1.5, 3.0, 4.5])


def test_hull_of_a_sphere_contains_it_and_is_tight():
    centre, radius = np.array([0.1, 0.05, -0.05]), 0.3
    cams = ring_cameras(8, size=(96, 96))
    sils = [Silhouette.from_mask(c, sphere_mask(c, centre, radius)) for c in cams]
    lo, hi = camera_bounds(cams)
    assert np.all(lo < centre - radius) and np.all(hi > centre + radius)
    lo, hi = hull_bounds(sils, 0.02)
    assert np.all(lo <= centre - radius) and np.all(hi >= centre + radius)
    assert np.all(lo > centre - radius - 0.15) and np.all(hi < centre + radius + 0.15)
    inner = centre + radius * 0.9 * np.eye(3)
    outer = centre + radius * 1.6 * np.eye(3)
    assert np.all(hull_field(inner, sils) > 0) and np.all(hull_field(outer, sils) < 0)
    grid = Grid.covering(lo, hi, 0.01)
    verts, faces = extract_surface(grid, grid.sample(sils))
    dist = np.linalg.norm(verts - centre, axis=1)
    # sphere inside the hull (up to a pixel); 8 views over-estimate the sphere by a few centimetres at most
    assert dist.min() > radius - 0.01 and dist.max() < radius * 1.12 and np.median(dist) < radius * 1.04


def test_narrow_band_sampling_matches_dense_sampling_in_sign():
    cams = ring_cameras(6, size=(64, 64))
    sils = [Silhouette.from_mask(c, sphere_mask(c, np.zeros(3), 0.3)) for c in cams]
    grid = Grid.covering(np.full(3, -0.45), np.full(3, 0.45), 0.015)
    fast, dense = grid.sample(sils), grid.sample(sils, coarse=1)
    assert np.array_equal(fast > 0, dense > 0)
    near = np.abs(dense) < 0.02
    np.testing.assert_allclose(fast[near], dense[near])
