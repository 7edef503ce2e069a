import numpy as np
import pytest
import trimesh

from gg_core.metrics.surface import point_to_mesh, point_triangle_distance, sample_surface, surface_metrics


def _sphere(radius: float, subdivisions: int = 3) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _brute_force(points: np.ndarray, verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    tri = verts[faces]
    p = np.repeat(points, len(faces), axis=0)
    t = np.tile(tri, (len(points), 1, 1))
    return point_triangle_distance(p, t[:, 0], t[:, 1], t[:, 2]).reshape(len(points), len(faces)).min(axis=1)


def test_point_triangle_distance_regions():
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])
    cases = {  # point -> expected distance: face interior, each edge, each vertex region
        (0.2, 0.2, 0.5): 0.5, (0.5, -1.0, 0.0): 1.0, (-2.0, 0.5, 0.0): 2.0,
        (1.0, 1.0, 0.0): np.sqrt(2) / 2,
        (2.0, -1.0, 0.0): np.sqrt(2), (-1.0, -1.0, 1.0): np.sqrt(3), (0.0, 3.0, 0.0): 2.0,
    }
    for p, expected in cases.items():
        got = point_triangle_distance(np.array([p]), a, b, c)[0]
        assert got == pytest.approx(expected, abs=1e-12), p


def test_point_triangle_distance_degenerate_triangle_is_a_segment():
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]), np.array([[2.0, 0, 0]])
    assert point_triangle_distance(np.array([[1.5, 3.0, 4.0]]), a, b, c)[0] == pytest.approx(5.0)


def test_point_to_mesh_matches_brute_force_with_mixed_triangle_sizes():
    rng = np.random.default_rng(1)
    v, f = _sphere(0.3, 2)
    big = np.array([[-2.0, -0.5, -2.0], [2.0, -0.5, -2.0], [0.0, -0.5, 2.0]])  # one large floor triangle
    verts = np.concatenate([v, big])
    faces = np.concatenate([f, [[len(v), len(v) + 1, len(v) + 2]]])
    points = rng.normal(scale=0.6, size=(300, 3))
    np.testing.assert_allclose(point_to_mesh(points, verts, faces), _brute_force(points, verts, faces),
                               rtol=0, atol=1e-12)


def test_sample_surface_is_area_uniform():
    # A unit square at x=0 and a 2x-larger one at x=10 (area 4 vs 1): the big one gets 4/5 of the samples.
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    verts = np.concatenate([sq, sq * 2 + [10, 0, 0]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    pts = sample_surface(verts, faces, 50000, np.random.default_rng(0))
    assert np.mean(pts[:, 0] > 5) == pytest.approx(0.8, abs=0.01)
    small = pts[pts[:, 0] < 5]
    assert np.mean(small[:, 0] < 0.5) == pytest.approx(0.5, abs=0.01)  # uniform within a square, across faces
    assert np.all(point_to_mesh(pts[:100], verts, faces) < 1e-12)


def test_surface_metrics_identical_and_offset_spheres():
    v, f = _sphere(0.3)
    same = surface_metrics(v, f, v, f, n_samples=5000)
    assert same == {"cd_cm": pytest.approx(0, abs=1e-9), "p2m_cm": pytest.approx(0, abs=1e-9),
                    "fscore_1cm": 100.0}
    # Concentric sphere 5 mm larger: every distance ~0.5 cm (faceting changes it by < 0.05 cm).
    m = surface_metrics(v * (0.305 / 0.3), f, v, f, n_samples=5000)
    assert m["cd_cm"] == pytest.approx(0.5, abs=0.05) and m["p2m_cm"] == pytest.approx(0.5, abs=0.05)
    assert m["fscore_1cm"] == 100.0
    far = surface_metrics(v * (0.32 / 0.3), f, v, f, n_samples=5000)
    assert far["cd_cm"] == pytest.approx(2.0, abs=0.1) and far["fscore_1cm"] == 0.0


def test_surface_metrics_partial_prediction_lowers_recall_only():
    v, f = _sphere(0.3)
    upper = f[v[f].mean(axis=1)[:, 1] > 0]        # half the sphere: all its points lie on the gt
    m = surface_metrics(v, upper, v, f, n_samples=8000)
    assert m["p2m_cm"] == pytest.approx(0, abs=1e-9)
    # precision 1, so recall = F / (200 - F) in %: the upper half (~50 %) plus a band within 1 cm of the cut
    assert 50 < 100 * m["fscore_1cm"] / (200 - m["fscore_1cm"]) < 56
    assert m["cd_cm"] > 3.0


def test_point_to_mesh_is_exact_at_the_stages_scale():
    """The pruned search (4 nearest centroids, then radius-grouped balls) against brute force where evaluation runs:
    a 2562-vertex mesh and a noisy copy's surface samples. Its speed is not a test's business (wall clock)."""
    v, f = _sphere(0.3, 4)                          # 2562 vertices, 5120 faces
    rng = np.random.default_rng(0)
    pred = v + rng.normal(scale=0.004, size=v.shape)
    points = sample_surface(pred, f, 400, rng)
    np.testing.assert_allclose(point_to_mesh(points, v, f), _brute_force(points, v, f), rtol=0, atol=1e-12)
