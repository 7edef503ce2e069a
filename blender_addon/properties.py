"""Add-on data: per-scene paths (saved in the .blend) and the job state shown in the panel (not saved)."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty
from bpy.types import PropertyGroup

from ..gg_core.body.motions import MOTIONS

# which fitted model Simulate rolls out: (key, label, description); operators.stages.SIMULATION_MODELS says where
# each lives in the project
SIMULATION_MODEL_ITEMS = [
    ("diagnosed", "Diagnosed Model", "diagnose/model.npz: the fitted simulator with the missing physics the diagnosis "
                                     "found and confirmed"),
    ("behaviour", "Fitted Behaviour", "stage4/behavior.npz: the material and rest lengths of Fit Behaviour"),
]


class GG_SceneSettings(PropertyGroup):
    capture_path: StringProperty(name="Capture", subtype="DIR_PATH",
                                 description="Capture folder (one sub-folder per sequence with cameras.json)")
    project_path: StringProperty(name="Project", subtype="DIR_PATH",
                                 description="Project folder where the stages write their results")
    diagnose_vertex_mass: EnumProperty(
        name="Mass", default="area", description="How Diagnose Physics spreads the garment's mass (--vertex-mass)",
        items=[("area", "By Area", "each vertex carries its share of the surface: a real fabric"),
               ("uniform", "Per Vertex", "every vertex weighs the same, as Blender's cloth does: for captures "
                                         "Blender simulated")])
    behavior: StringProperty(name="Behaviour", description="Held-out rollout error of the last loaded behaviour fit")
    diagnosis: StringProperty(name="Diagnosis", description="Verdict of the last loaded physics diagnosis")
    simulation_model: EnumProperty(name="Model", items=SIMULATION_MODEL_ITEMS, default="diagnosed",
                                   description="Fitted garment model to simulate")
    simulation_motion: EnumProperty(name="Motion", items=[(m, m.replace("_", " ").title(), f"built-in {m} motion")
                                                          for m in MOTIONS], default="walk",
                                    description="Built-in motion of the default body to simulate the garment on")
    simulation_frames: IntProperty(name="Frames", default=60, min=1, max=2000,
                                   description="Frames of the motion (after 15 frames blending in from the rest pose)")


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
