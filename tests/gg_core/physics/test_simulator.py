"""The implicit simulator: free fall, a pinned sheet draping to rest, settling on a static body without
penetration, recovery from a start inside the body."""
from __future__ import annotations

import numpy as np

from gg_core.physics.cloth import GRAVITY, Cloth
from gg_core.physics.contact import BodyCollider
from gg_core.physics.forces import make_terms
from gg_core.physics.simulator import ClothState, ImplicitSimulator
from gg_core.physics.solver import SolverOptions

from physics_helpers import sheet, uv_sphere


def test_free_fall_matches_gravity():
    """No forces but gravity: the discrete acceleration is g and positions follow implicit Euler exactly."""
    v, f = sheet(6, 6, 0.3, 0.3, y=1.0)
    sim = ImplicitSimulator(Cloth(v, f), terms=make_terms(["gravity", "stretching", "bending"]))
    n = 20
    traj = sim.rollout(ClothState(v.copy(), np.zeros_like(v)), None, n_frames=n + 1)
    com = traj.mean(1)
    accel = (com[2:] - 2 * com[1:-1] + com[:-2]) * sim.fps ** 2
    np.testing.assert_allclose(accel, np.broadcast_to(GRAVITY, accel.shape), atol=1e-3)   # 1e-4 g
    k = np.arange(n + 1)
    expected = v.mean(0) + np.outer(k * (k + 1) / 2 / sim.fps ** 2, GRAVITY)
    np.testing.assert_allclose(com, expected, atol=1e-6)
    assert np.abs(traj[-1] - traj[-1].mean(0) - (v - v.mean(0))).max() < 1e-6   # falls rigidly


def test_sheet_pinned_at_two_corners_drapes_and_comes_to_rest():
    v, f = sheet(12, 12, 0.5, 0.5, y=1.0)
    corners = [0, 12]                                     # the two corners of the first row
    pinned = np.zeros(len(v), bool)
    pinned[corners] = True
    sim = ImplicitSimulator(Cloth(v, f, pinned=pinned))
    traj = sim.rollout(ClothState(v.copy(), np.zeros_like(v)), None, n_frames=300)     # 10 s
    assert np.isfinite(traj).all()
    np.testing.assert_allclose(traj[:, corners], np.broadcast_to(v[corners], (300, 2, 3)))
    speed = np.linalg.norm(np.diff(traj, axis=0), axis=2).max(1) * sim.fps
    assert speed.max() > 2.0                             # it swung down...
    assert speed[-30:].max() < 0.02 * speed.max()        # ...and has come to rest (pendulum damped out)
    assert traj[-1][:, 1].min() < 1.0 - 0.35             # hangs down by most of its length
    e = sim.cloth.topology.edges
    strain = np.linalg.norm(traj[-1][e[:, 0]] - traj[-1][e[:, 1]], axis=1) / sim.cloth.rest_lengths.numpy() - 1
    assert strain.max() < 0.25                           # stretched by its weight, not blown up


def _sheet_on_sphere(start_y: float):
    v, f = sheet(24, 24, 0.8, 0.8, y=start_y)
    bv, bf = uv_sphere(0.25, 32, 64)
    collider = BodyCollider(bf, len(bv))
    sim = ImplicitSimulator(Cloth(v, f), collider=collider)
    body = np.repeat(bv[None], 60, 0)
    return sim, collider, body, sim.rollout(ClothState(v.copy(), np.zeros_like(v)), body)


def test_garment_settles_on_static_body_without_penetration():
    sim, collider, body, traj = _sheet_on_sphere(0.27)
    depth = np.array([-collider.query(x, body[0], reach=0.1).distance.min() for x in traj])
    assert depth.max() <= 2e-3
    assert np.linalg.norm(traj[-1] - traj[-2], axis=1).max() * sim.fps < 0.1    # settling, not bouncing
    assert traj[-1][:, 1].min() < 0.0                                           # draped over the sphere


def test_garment_starting_inside_the_body_is_pushed_out():
    sim, collider, body, traj = _sheet_on_sphere(0.245)   # the middle starts 5 mm inside the sphere
    first = collider.query(traj[0], body[0], reach=0.1).distance
    last = collider.query(traj[-1], body[0], reach=0.1).distance
    assert first.min() < -4e-3
    assert last.min() > -2e-3
    assert np.isfinite(traj).all()


def test_friction_takes_the_normal_force_of_the_steps_own_contact_solution():
    """A step that starts deep in the contact margin (an observed state of a simulator whose cloth sits closer to
    the body) must not take friction's normal force from the stiff penalty there: that force never acts, the
    solve pushes the cloth out within the step. With SolverOptions.friction_at_end (the diagnosis), the step
    returned by solve() carries the force at its end."""
    v, f = sheet(24, 24, 0.3, 0.3, y=0.25 + 0.5e-3)            # resting on top of the sphere, 2.5 mm into the margin
    bv, bf = uv_sphere(0.25, 32, 64)
    sim = ImplicitSimulator(Cloth(v, f), collider=BodyCollider(bf, len(bv)))
    start = sim.prepare(v, np.zeros_like(v), bv, bv, sim.dt)
    touching = start.contact_force > 0
    assert touching.sum() >= 5
    weight = sim.num.mass * np.linalg.norm(GRAVITY)
    assert (start.contact_force / weight).max() > 50                 # 95 weights at the top of the sphere
    _, lagged = sim.solve(start, bv)                                  # the default: the start state's force
    np.testing.assert_array_equal(lagged.contact_force, start.contact_force)
    sim.options = SolverOptions(friction_at_end=True)
    _, solved = sim.solve(start, bv)
    assert (solved.contact_force / weight).max() < 10                # 4: the weight and the push out of the margin
