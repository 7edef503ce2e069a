import math

import pytest

from gg_core.errors import InputError
from gg_core.synth.effects import EFFECTS, region_names, resolve_effect
from gg_core.synth.fabrics import FABRICS

CLOTH = FABRICS["cotton"].cloth_settings()


def test_every_effect_resolves_with_defaults():
    assert {"none", "wind", "air_drag", "friction", "shrink", "stiff_patch", "gravity"} <= set(EFFECTS)
    for name in EFFECTS:
        effect = resolve_effect(name, [], CLOTH)
        assert effect.to_json()["params"] == EFFECTS[name].defaults
    assert resolve_effect("none", [], CLOTH).blender == {}


def test_overrides_reach_the_blender_settings():
    wind = resolve_effect("wind", ["strength=40", "azimuth_deg=90"], CLOTH).blender["force_fields"][0]
    assert wind["strength"] == 40.0
    assert wind["direction"] == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)   # azimuth 90 = towards +Z
    assert resolve_effect("air_drag", ["air_damping=7"], CLOTH).blender == {"cloth": {"air_damping": 7.0}}


def test_gravity_is_scaled_and_tilted():
    g = resolve_effect("gravity", ["scale=2", "tilt_deg=30", "azimuth_deg=0"], CLOTH).blender["gravity"]
    assert math.hypot(*g) == pytest.approx(2 * 9.81)
    assert math.degrees(math.atan2(g[0], -g[1])) == pytest.approx(30.0)


def test_stiff_patch_scales_the_base_stiffness_on_a_region():
    effect = resolve_effect("stiff_patch", ["factor=10", "region=hem"], CLOTH)
    assert effect.blender["cloth"]["tension_stiffness_max"] == pytest.approx(10 * CLOTH["tension_stiffness"])
    assert effect.blender["cloth"]["bending_stiffness_max"] == pytest.approx(10 * CLOTH["bending_stiffness"])
    assert region_names(effect) == {"hem"}


@pytest.mark.parametrize("name, params", [("warp", []), ("wind", ["speed=3"]), ("wind", ["strength"]),
                                          ("wind", ["strength=strong"]), ("air_drag", ["air_damping=30"]),
                                          ("friction", ["friction=nan"])])
def test_bad_effect_input_is_an_input_error(name, params):
    with pytest.raises(InputError):
        resolve_effect(name, params, CLOTH)
