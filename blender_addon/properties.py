"""Add-on data: per-scene paths (saved in the .blend) and the job state shown in the panel (not saved)."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, FloatProperty, PointerProperty, StringProperty
from bpy.types import PropertyGroup


class GG_SceneSettings(PropertyGroup):
    capture_path: StringProperty(name="Capture", subtype="DIR_PATH",
                                 description="Capture folder (one sub-folder per sequence with cameras.json)")
    project_path: StringProperty(name="Project", subtype="DIR_PATH",
                                 description="Project folder where the stages write their results")
    behavior: StringProperty(name="Behaviour", description="Held-out rollout error of the last loaded behaviour fit")
    diagnosis: StringProperty(name="Diagnosis", description="Verdict of the last loaded physics diagnosis")


class GG_JobProperties(PropertyGroup):
    running: BoolProperty(name="Running", default=False)
    stage: StringProperty(name="Stage")
    progress: FloatProperty(name="Progress", min=0.0, max=1.0, subtype="FACTOR")
    status: StringProperty(name="Status", description="Stage, step, message and ETA of the running job")
    result: StringProperty(name="Result", description="Outcome of the last job")
    failed: BoolProperty(name="Failed", description="The last job ended with an error")


CLASSES = (GG_SceneSettings, GG_JobProperties)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.gg = PointerProperty(type=GG_SceneSettings)
    bpy.types.WindowManager.gg_job = PointerProperty(type=GG_JobProperties)


def unregister() -> None:
    del bpy.types.WindowManager.gg_job
    del bpy.types.Scene.gg
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
