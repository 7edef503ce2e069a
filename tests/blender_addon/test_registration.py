"""register()/unregister() of the whole extension: panel, properties, preferences, operators."""
from __future__ import annotations

import importlib

import pytest

pytestmark = pytest.mark.bpy


def test_register_and_unregister(blender, extension_package):
    bpy = blender
    panel = bpy.types.GG_PT_garments
    assert (panel.bl_space_type, panel.bl_region_type, panel.bl_category) == ("VIEW_3D", "UI", "Garments")
    assert bpy.types.GG_PT_job.bl_parent_id == "GG_PT_garments"
    preferences = importlib.import_module(f"{extension_package.__name__}.blender_addon.preferences")
    assert preferences.GG_AddonPreferences.is_registered
    assert preferences.GG_AddonPreferences.bl_idname == extension_package.__name__
    scene = bpy.context.scene
    scene.gg.capture_path = "/data/capture"
    assert scene.gg.capture_path == "/data/capture"
    assert bpy.context.window_manager.gg_job.running is False
    assert bpy.types.GG_PT_stages.bl_parent_id == "GG_PT_garments"
    for op in ("import_capture", "run_job", "cancel_job", "use_capture_camera", "reconstruct_template",
               "register_sequences", "fit_behavior", "diagnose_physics", "load_template", "load_registration",
               "show_behavior", "show_residuals"):
        assert hasattr(bpy.ops.gg, op)
    assert not bpy.ops.gg.cancel_job.poll()  # nothing is running
    extension_package.unregister()
    try:
        assert not hasattr(bpy.types, "GG_PT_garments")
        assert not hasattr(bpy.types.Scene, "gg")
    finally:
        extension_package.register()  # the fixture unregisters after the test
