"""Body proximity: exact distances to a sphere, signs, reach, excluded parts, contact transport, penetration."""
from __future__ import annotations

import numpy as np
import pytest

from gg_core.physics.contact import BodyCollider, penetration_stats

from physics_helpers import uv_sphere

R = 0.3


@pytest.fixture(scope="module")
def sphere():
    v, f = uv_sphere(R, 48, 96)
    return v, f, BodyCollider(f, len(v))


def test_signed_distance_matches_the_sphere(sphere):
    v, f, collider = sphere
    rng = np.random.default_rng(0)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    radius = rng.uniform(R - 0.03, R + 0.04, 500)
    prox = collider.query(d * radius[:, None], v, reach=0.05)
    assert prox.found.all()
    sagitta = R * (1 - np.cos(np.pi / 48))                          # polygonal sphere lies inside the true one
    np.testing.assert_allclose(prox.distance, radius - R, atol=sagitta + 1e-6)
    assert (np.sign(prox.distance) == np.sign(radius - R))[np.abs(radius - R) > 2 * sagitta].all()


def test_reach_and_excluded_parts(sphere):
    v, f, _ = sphere
    far = np.array([[0.0, R + 0.08, 0.0]])
    assert not BodyCollider(f, len(v)).query(far, v, reach=0.05).found.any()
    top = v[:, 1] > R * 0.5                                         # exclude the top cap ("hands")
    collider = BodyCollider(f, len(v), exclude=top)
    prox = collider.query(np.array([[0.0, R + 0.01, 0.0]]), v, reach=0.2)
    hit = f[prox.face[0]]
    assert not top[hit].any()
    assert prox.distance[0] > 0.05


def test_contact_point_follows_the_body(sphere):
    v, f, collider = sphere
    points = np.array([[0.0, R + 0.005, 0.0], [R + 0.002, 0.0, 0.0]])
    prox = collider.query(points, v, reach=0.05)
    shift = np.array([0.1, -0.2, 0.05])
    point0, normal0 = collider.surface_point(prox, v)
    point1, normal1 = collider.surface_point(prox, v + shift)
    np.testing.assert_allclose(point1 - point0, np.broadcast_to(shift, point0.shape), atol=1e-12)
    np.testing.assert_allclose(normal1, normal0, atol=1e-12)
    np.testing.assert_allclose(normal0, points / np.linalg.norm(points, axis=1, keepdims=True), atol=1e-3)


def test_penetration_stats(sphere):
    v, f, collider = sphere
    d = np.random.default_rng(1).normal(size=(100, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    outside = d * (R + 0.01)
    inside = outside.copy()
    inside[:5] = d[:5] * (R - 0.005)                                # 5 % of the vertices 5 mm deep
    stats = penetration_stats(np.stack([outside, inside]), np.stack([v, v]), collider)
    assert stats["max_fraction_deeper"] == pytest.approx(0.05)
    assert stats["mean_fraction_deeper"] == pytest.approx(0.025)
    assert stats["max_depth_m"] == pytest.approx(0.005, abs=R * (1 - np.cos(np.pi / 48)) + 1e-6)
