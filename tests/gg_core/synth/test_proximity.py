import numpy as np
import trimesh

from gg_core.synth.anchoring import bind
from gg_core.synth.proximity import MeshProximity, closest_on_triangles


def test_closest_on_triangles_matches_dense_sampling():
    rng = np.random.default_rng(1)
    a, b, c = (rng.normal(size=(200, 3)) for _ in range(3))
    p = rng.normal(size=(200, 3)) * 2
    got = closest_on_triangles(p, a, b, c)
    w = rng.dirichlet(np.ones(3), size=20000)                      # dense samples of each triangle
    for i in range(0, 200, 20):
        samples = w @ np.stack([a[i], b[i], c[i]])
        best = np.linalg.norm(samples - p[i], axis=1).min()
        assert np.linalg.norm(got[i] - p[i]) <= best + 1e-9
        assert np.linalg.norm(got[i] - p[i]) > best - 0.02


def test_signed_distance_of_a_sphere():
    sphere = trimesh.creation.icosphere(4)
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(500, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    radius = rng.uniform(0.8, 1.2, 500)
    sd = MeshProximity(sphere.vertices, sphere.faces).signed_distance(dirs * radius[:, None])
    np.testing.assert_allclose(sd, radius - 1, atol=2e-3)   # icosphere facets deviate ~1 mm from the sphere


def test_anchors_reproduce_rest_and_follow_a_rigid_motion():
    sphere = trimesh.creation.icosphere(3)
    pts = sphere.vertices[::7] * 1.05 + 0.003
    anchors = bind(sphere.vertices, sphere.faces, pts)
    np.testing.assert_allclose(anchors.apply(sphere.vertices), pts, atol=1e-9)
    rot = trimesh.transformations.rotation_matrix(0.7, [0.3, 1, 0])[:3, :3]
    moved = anchors.apply(np.stack([sphere.vertices @ rot.T + [0, 1, 0]]))[0]
    np.testing.assert_allclose(moved, pts @ rot.T + [0, 1, 0], atol=1e-9)


def test_mesh_smaller_than_k_neighbours():
    """A single triangle has fewer vertices than the k nearest-vertex candidates asked for."""
    tri = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    prox = MeshProximity(tri, np.array([[0, 1, 2]]))
    np.testing.assert_allclose(prox.signed_distance(np.array([[0.2, 0.2, 0.5], [0.2, 0.2, -0.3]])), [0.5, -0.3])
