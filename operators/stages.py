"""Panel buttons for the pipeline stages: each runs its `gg` command as a job on the scene's capture and
project folders, then loads the result into the scene (gg.run_job's `then`)."""
from __future__ import annotations

import shlex
from pathlib import Path

import bpy
from bpy.types import Context, Operator

from ..gg_core.errors import InputError
from .results import project_dir


def stage_arguments(context: Context) -> list[str]:
    """`<capture> --project <project>` from the panel's folders; InputError when one is missing."""
    settings = context.scene.gg
    if not settings.capture_path:
        raise InputError("no capture folder set", "Garments panel > Capture", "choose the capture folder")
    if not settings.project_path:
        raise InputError("no project folder set", "Garments panel > Project", "choose a folder for the results")
    capture = Path(bpy.path.abspath(settings.capture_path))
    project = Path(bpy.path.abspath(settings.project_path))
    return [str(capture), "--project", str(project)]


class _StageJob(Operator):
    stage = ""
    then = ""

    def arguments(self, context: Context) -> list[str]:
        return stage_arguments(context)

    def execute(self, context: Context) -> set[str]:
        try:
            arguments = self.arguments(context)
        except InputError as exc:
            self.report({"ERROR"}, exc.line())
            return {"CANCELLED"}
        return bpy.ops.gg.run_job(stage=self.stage, arguments=shlex.join(arguments), then=self.then)


class GG_OT_reconstruct_template(_StageJob):
    """Stage 1: template mesh with a UV atlas and initial Gaussians from one multi-view frame"""

    bl_idname = "gg.reconstruct_template"
    bl_label = "Reconstruct Template"
    stage, then = "template", "load_template"


class GG_OT_register_sequences(_StageJob):
    """Stage 2: fit the template to every frame of every sequence (runs in the background; Cancel keeps
    finished frames)"""

    bl_idname = "gg.register_sequences"
    bl_label = "Register Sequences"
    stage, then = "register", "load_registration"


class GG_OT_fit_behavior(_StageJob):
    """Stage 4: fit the simulator's material and rest lengths to the registered motion (the synthetic ground truth
    until registration has finished) and measure it on held-out sequences"""

    bl_idname = "gg.fit_behavior"
    bl_label = "Fit Behaviour"
    stage, then = "behavior", "show_behavior"


def diagnose_arguments(context: Context) -> list[str]:
    """`gg diagnose` arguments: the folders and the panel's mass spread."""
    return [*stage_arguments(context), "--vertex-mass", context.scene.gg.diagnose_vertex_mass]


class GG_OT_diagnose_physics(_StageJob):
    """Find where and when simulation and recording differ, name the missing physics, refit, and colour the
    garment by the residual"""

    bl_idname = "gg.diagnose_physics"
    bl_label = "Diagnose Physics"
    stage, then = "diagnose", "show_residuals"

    def arguments(self, context: Context) -> list[str]:
        return diagnose_arguments(context)


# properties.SIMULATION_MODEL_ITEMS key -> (model file in the project, how to make it)
SIMULATION_MODELS = {
    "diagnosed": ("diagnose/model.npz", "run Diagnose Physics first (it writes a model only when it finds missing "
                                        "physics; otherwise simulate the Fitted Behaviour)"),
    "behaviour": ("stage4/behavior.npz", "run Fit Behaviour first"),
}


def simulate_arguments(context: Context) -> list[str]:
    """`gg simulate` arguments for the panel's model, motion and frames; InputError when the model is missing. The
    output folder is simulate/<model>_<motion> in the project, replaced by a rerun."""
    settings = context.scene.gg
    project = project_dir(context.scene)
    relative, how = SIMULATION_MODELS[settings.simulation_model]
    model = project / relative
    if not model.is_file():
        raise InputError(f"no {relative} in the project", model, how)
    out = project / "simulate" / f"{settings.simulation_model}_{settings.simulation_motion}"
    return ["--behavior", str(model), "--motion", settings.simulation_motion,
            "--frames", str(settings.simulation_frames), "--out", str(out)]


class GG_OT_simulate_garment(_StageJob):
    """Simulate the fitted garment model (with the missing physics the diagnosis found, or the fitted behaviour) on
    a built-in motion of the default body, then play it back with the body"""

    bl_idname = "gg.simulate_garment"
    bl_label = "Simulate Garment"
    stage, then = "simulate", "load_simulations"

    def arguments(self, context: Context) -> list[str]:
        return simulate_arguments(context)


CLASSES = (GG_OT_reconstruct_template, GG_OT_register_sequences, GG_OT_fit_behavior, GG_OT_diagnose_physics,
           GG_OT_simulate_garment)
