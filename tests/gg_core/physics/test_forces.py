"""Force library: registry contract, and each effect's physics checked on a falling sheet (terminal velocities,
extra acceleration) where the answer is known in closed form."""
from __future__ import annotations

import numpy as np
import pytest

from gg_core.physics.cloth import GRAVITY, Cloth
from gg_core.physics.forces import DEFAULT_TERMS, LIBRARY, TERMS, make_terms
from gg_core.physics.material import MATERIAL_SPEC
from gg_core.physics.simulator import ClothState, ImplicitSimulator

from physics_helpers import sheet

DENSITY = MATERIAL_SPEC["density"][0]


def test_registry_contract():
    assert set(DEFAULT_TERMS) <= set(TERMS)
    for name, cls in TERMS.items():
        assert cls.name == name
        assert len(cls.meaning()) > 40, f"{name} must document its physical meaning"
    assert {c.name for c in LIBRARY} >= {"air_drag", "wind", "mass_damping", "strain_rate_damping",
                                        "body_friction", "anisotropic_stretch"}
    terms = make_terms(["gravity", "air_drag"], {"air_drag": {"coef": 1.0}})
    assert terms[0].name == "inertia" and float(terms[-1].params["coef"]) == 1.0
    with pytest.raises(ValueError, match="unknown force terms"):
        make_terms(["lift_off"])
    with pytest.raises(ValueError, match="not switched on"):
        make_terms(["gravity"], {"wind": {"coef": 1.0}})
    with pytest.raises(ValueError, match="has no parameters"):
        make_terms(["air_drag"], {"air_drag": {"cd": 1.0}})


def _fall(extra: list[str], params: dict, seconds: float = 4.0) -> tuple[np.ndarray, float]:
    """Centre-of-mass velocity history of a horizontal sheet falling with the given extra terms."""
    v, f = sheet(4, 4, 0.5, 0.5, y=0.0)
    sim = ImplicitSimulator(Cloth(v, f), terms=make_terms(["gravity", "stretching", "bending"] + extra, params))
    traj = sim.rollout(ClothState(v.copy(), np.zeros_like(v)), None, n_frames=int(seconds * 30) + 1)
    return np.diff(traj.mean(1), axis=0) * sim.fps, sim.fps


def test_quadratic_air_drag_terminal_velocity():
    coef = 0.6
    vel, _ = _fall(["air_drag"], {"air_drag": {"coef": coef}})
    terminal = np.sqrt(DENSITY * 9.81 / coef)                       # m g = coef A v^2 per unit area
    assert vel[-1, 1] == pytest.approx(-terminal, rel=0.01)


def test_mass_damping_terminal_velocity():
    alpha = 2.0
    vel, _ = _fall(["mass_damping"], {"mass_damping": {"alpha": alpha}})
    assert vel[-1, 1] == pytest.approx(-9.81 / alpha, rel=0.01)


def test_wind_pushes_a_falling_sheet_towards_its_velocity():
    """A horizontal sheet falling in an updraft of the terminal speed stops falling."""
    coef = 0.6
    terminal = np.sqrt(DENSITY * 9.81 / coef)
    vel, _ = _fall(["wind"], {"wind": {"coef": coef, "velocity": (0.0, terminal, 0.0)}})
    assert abs(vel[-1, 1]) < 0.02 * terminal


def test_gravity_offset_adds_acceleration():
    vel, fps = _fall(["gravity_offset"], {"gravity_offset": {"delta_g": (1.0, 0.0, 0.0)}}, seconds=1.0)
    accel = np.diff(vel, axis=0).mean(0) * fps
    np.testing.assert_allclose(accel, np.array(GRAVITY) + [1.0, 0.0, 0.0], atol=1e-3)


def test_damping_terms_do_not_act_on_rigid_motion():
    """Strain-rate damping resists deformation only: a rigidly falling sheet accelerates at g."""
    vel, fps = _fall(["strain_rate_damping"], {"strain_rate_damping": {"beta": 1.0}}, seconds=1.0)
    accel = np.diff(vel, axis=0).mean(0) * fps
    np.testing.assert_allclose(accel, GRAVITY, atol=1e-3)
