"""Which candidates get a refit, and when a refit counts as confirmed."""
from __future__ import annotations

from gg_core.diagnosis.confirm import Trial
from gg_core.diagnosis.pipeline import confirmed, implausible, propose
from gg_core.diagnosis.selection import Selection


def _selection() -> Selection:
    explained = {"wind": 0.3, "mass_damping": 0.0, "air_drag": 0.1, "gravity_offset": 0.2}
    return Selection(1.0, ["air_drag"], explained, {}, {}, inclusion={"air_drag": 0.9, "wind": 0.4,
                                                                       "mass_damping": 0.0, "gravity_offset": 0.1})


def test_selected_candidates_come_first_then_the_others_by_explained_share_even_none():
    assert propose(_selection(), 0.5, 12) == ["air_drag", "wind", "gravity_offset", "mass_damping"]
    assert propose(_selection(), 0.5, 2) == ["air_drag", "wind"]
    assert propose(_selection(), 0.95, 12)[0] == "wind"          # not selected often enough: ranked with the rest


def test_confirmation_needs_the_heldout_gain_and_better_training_rollouts():
    null = Trial([], heldout_l2=0.010, train_loss=1.0, train_l2=0.012)
    assert confirmed(Trial(["a"], 0.0085, 1.0, 0.011), null, 0.10)
    assert not confirmed(Trial(["a"], 0.0095, 1.0, 0.011), null, 0.10)    # held-out gain 5 % < 10 %
    assert not confirmed(Trial(["a"], 0.0080, 1.0, 0.0125), null, 0.10)   # lucky on the held-out sequence only


def test_damping_that_stops_cloth_falling_is_not_air():
    """Terminal speed g / alpha: 1/s (default) falls at 9.8 m/s, 277/s (fitted to registration jitter) at 3.5 cm/s;
    quadratic drag sqrt(rho_area g / coef): 0.2 kg/m^2 at coef 0.6 falls at 1.8 m/s, at coef 100 at 0.14 m/s."""
    def damped(alpha: float) -> Trial:
        return Trial(["mass_damping"], 0.008, 1.0, 0.01, {"material.density": 0.2, "mass_damping.alpha": alpha})

    assert implausible(damped(8.0)) is None                          # Blender air_damping 10 at 24 fps, 0.3 kg
    assert "0.04 m/s" in implausible(damped(277.0))
    assert implausible(Trial(["wind"], 0.008, 1.0, 0.01, {"material.density": 0.2})) is None
    drag = Trial(["air_drag"], 0.008, 1.0, 0.01, {"material.density": 0.2, "air_drag.coef": 0.6})
    assert implausible(drag) is None
    drag.values["air_drag.coef"] = 100.0
    assert "0.14 m/s" in implausible(drag)
    joint = Trial(["wind", "mass_damping"], 0.008, 1.0, 0.01, {"material.density": 0.2, "mass_damping.alpha": 50.0})
    assert implausible(joint) is not None
