"""Force library: registry contract, and each effect's physics checked on a falling sheet (terminal velocities,
extra acceleration) where the answer is known in closed form."""
from __future__ import annotations

import numpy as np
import pytest
import torch

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
    with pytest.raises(ValueError, match="bending_damping' parameter tau=-1.0 is not physical"):
        make_terms(["bending_damping"], {"bending_damping": {"tau": -1.0}})
    with pytest.raises(ValueError, match="not physical"):
        make_terms(["wind"], {"wind": {"velocity": (float("nan"), 0.0, 0.0)}})
    assert float(make_terms(["wind"], {"wind": {"velocity": (-2.0, 0.0, 0.0)}})[-1].params["velocity"][0]) == -2.0


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


@pytest.mark.parametrize("term,params", [("strain_rate_damping", {"beta": 1.0}),
                                         ("viscoelastic_damping", {"tau": 0.1}),
                                         ("bending_damping", {"tau": 0.1})])
def test_damping_terms_do_not_act_on_rigid_motion(term, params):
    """Internal damping resists deformation only: a rigidly falling sheet accelerates at g."""
    vel, fps = _fall([term], {term: params}, seconds=1.0)
    accel = np.diff(vel, axis=0).mean(0) * fps
    np.testing.assert_allclose(accel, GRAVITY, atol=1e-3)


def test_viscoelastic_damping_is_tau_times_each_edge_stiffness():
    """k_e = d^2 psi / dl_e^2 at rest (finite differences of the stretching energy with one edge's rest length
    changed: at rest only d q / d L enters, as for d q / d l); the torch and numpy coefficients agree, and scaling
    the material scales the damping with it."""
    from gg_core.physics.energies import Stretching
    from gg_core.physics.forces import ViscoelasticDamping
    v, f = sheet(2, 2, 0.5, 0.5, y=0.0)
    cloth = Cloth(v, f)
    term = ViscoelasticDamping(tau=0.05)
    beta = term._beta(cloth.rest()).detach().numpy()
    np.testing.assert_allclose(term._beta_numeric(cloth.numeric()), beta, rtol=1e-12)
    e, h = 3, 1e-5
    x = torch.from_numpy(v)
    base, energies = cloth.rest_lengths.clone(), []
    for d in (-h, 0.0, h):
        lengths = base.clone()
        lengths[e] = lengths[e] - d                        # x stretched by d relative to rest along edge e
        cloth.rest_lengths = lengths
        energies.append(float(Stretching().energy(x, None, cloth.rest())))
    cloth.rest_lengths = base
    stiffness = (energies[0] - 2 * energies[1] + energies[2]) / h ** 2
    L = float(base[e])
    assert beta[e] == pytest.approx(0.05 * stiffness * L, rel=1e-3)
    cloth.material = type(cloth.material)(**{k: getattr(cloth.material, k) * 3.0 for k in ("density", "mu", "lam",
                                                                                         "bending")})
    np.testing.assert_allclose(term._beta(cloth.rest()).detach().numpy(), 3.0 * beta, rtol=1e-12)


def test_bending_damping_decays_a_flap_at_tau_omega_squared_over_two():
    """One free vertex folding about a hinge (the other three pinned, no gravity) is a single oscillator in its
    bending mode: Kelvin-Voigt damping c = tau k adds tau omega^2 / 2 to its amplitude's decay rate, on top of
    implicit Euler's own numerical damping (measured with tau = 0)."""
    v, f = sheet(1, 1, 0.05, 0.05, y=0.0)

    def decay(tau: float) -> tuple[float, float]:
        """(decay rate 1/s, angular frequency rad/s) of the free vertex's out-of-plane oscillation."""
        terms = make_terms(["stretching", "bending", "bending_damping"], {"bending_damping": {"tau": tau}})
        sim = ImplicitSimulator(Cloth(v, f, pinned=np.array([True, True, True, False])), terms=terms, fps=300.0,
                                substeps=2)
        x = v.copy()
        x[3, 1] = 1e-3
        y = sim.rollout(ClothState(x, np.zeros_like(v)), None, n_frames=601)[:, 3, 1]
        peak = np.flatnonzero((y[1:-1] > y[:-2]) & (y[1:-1] >= y[2:])) + 1
        rate = -np.polyfit(peak / sim.fps, np.log(y[peak]), 1)[0]
        return rate, 2 * np.pi * sim.fps / np.diff(peak).mean()

    numerical, omega = decay(0.0)
    tau = 0.01
    rate, _ = decay(tau)
    assert 5.0 < omega < 50.0 and numerical < 0.3                     # the test's oscillator is what it claims
    assert rate - numerical == pytest.approx(tau * omega ** 2 / 2, rel=0.1)
