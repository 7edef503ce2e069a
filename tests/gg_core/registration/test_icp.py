"""First-frame alignment: ICP recovers known similarities, the body alignment a known rigid motion."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from gg_core.registration.icp import Similarity, body_alignment, icp, umeyama


def skirt_points(n: int = 1500, seed: int = 0) -> np.ndarray:
    """A flared, wavy tube with a slit (no symmetry ICP could slide along)."""
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0.2, 2 * np.pi - 0.2, n)
    v = rng.uniform(0, 1, n)
    r = (0.15 + 0.1 * v) * (1 + 0.08 * np.sin(5 * theta))
    return np.stack((r * np.cos(theta), 0.9 - 0.5 * v, r * np.sin(theta)), 1)


def test_umeyama_is_exact_for_a_similarity():
    p = skirt_points()
    truth = Similarity(Rotation.from_rotvec([0.1, 0.4, -0.2]).as_matrix(), np.array([0.1, -0.2, 0.3]), 1.1)
    est = umeyama(p, truth.apply(p), scale=True)
    assert np.allclose(est.R, truth.R, atol=1e-10) and np.allclose(est.t, truth.t) and abs(est.s - 1.1) < 1e-10


def test_icp_recovers_a_rigid_motion_from_the_centroid_start():
    p = skirt_points()
    truth = Similarity(Rotation.from_rotvec([0.0, 0.25, 0.05]).as_matrix(), np.array([0.05, 0.02, -0.04]))
    target = truth.apply(skirt_points(2000, seed=1))        # other samples of the same surface
    start = Similarity(t=target.mean(0) - p.mean(0))
    est, log = icp(p, target, init=start)
    err = np.linalg.norm(est.apply(p) - truth.apply(p), axis=1).max()
    assert err < 4e-3, err                                   # sample spacing ~1 cm: a few mm
    assert log["rms"][-1] < log["rms"][0]


def test_icp_with_scale_recovers_the_scale():
    p = skirt_points()
    truth = Similarity(np.eye(3), np.array([0.0, 0.01, 0.0]), 1.08)
    est, _ = icp(p, truth.apply(p), scale=True, keep=1.0)
    assert abs(est.s - 1.08) < 1e-6


def test_body_alignment_follows_the_body_part_near_the_garment():
    rng = np.random.default_rng(2)
    hips = rng.uniform(-0.2, 0.2, (500, 3))
    head = rng.uniform(-0.1, 0.1, (300, 3)) + [0, 1.0, 0]
    body = np.concatenate((hips, head))
    garment = hips[:100] + 0.01                              # worn on the hips only
    motion = Similarity(Rotation.from_rotvec([0, 0.3, 0]).as_matrix(), np.array([0.1, 0, 0.2]))
    moved = motion.apply(body)
    moved[500:] += [0.3, 0, 0]                               # the head moves differently: it must not count
    est = body_alignment(garment, body, moved, radius=0.05)
    assert np.allclose(est.apply(garment), motion.apply(garment), atol=1e-9)
    far = body_alignment(garment + 10.0, body, moved)        # nothing within reach: identity
    assert far.s == 1.0 and np.allclose(far.R, np.eye(3)) and np.allclose(far.t, 0)
