"""The "Garments" tab of the 3D View sidebar: capture and project, import, the running job.

Later stages add their own sub-panels with bl_parent_id = GG_PT_garments.bl_idname.
"""
from __future__ import annotations

import shlex

import bpy
from bpy.types import Context, Panel


class _Sidebar:
    """Where every panel of the add-on lives: the 3D View sidebar's "Garments" tab."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Garments"


class GG_PT_garments(_Sidebar, Panel):
    bl_idname = "GG_PT_garments"
    bl_label = "Gaussian Garments"

    def draw(self, context: Context) -> None:
        settings = context.scene.gg
        layout = self.layout
        col = layout.column(align=True)
        col.prop(settings, "capture_path")
        col.prop(settings, "project_path")
        row = layout.row(align=True)
        op = row.operator("gg.import_capture", icon="IMPORT")
        op.directory = settings.capture_path
        inspect = row.operator("gg.run_job", text="Inspect", icon="VIEWZOOM")
        inspect.stage = "inspect"
        inspect.arguments = shlex.join([bpy.path.abspath(settings.capture_path)])
        row.enabled = bool(settings.capture_path)
        obj = context.active_object
        if obj is not None and "gg_camera_id" in obj:
            layout.operator("gg.use_capture_camera", icon="VIEW_CAMERA")


class GG_PT_stages(_Sidebar, Panel):
    bl_idname = "GG_PT_stages"
    bl_label = "Pipeline"
    bl_parent_id = GG_PT_garments.bl_idname

    def draw(self, context: Context) -> None:
        settings = context.scene.gg
        layout = self.layout
        ready = bool(settings.capture_path and settings.project_path)
        for run, load, icon in (("gg.reconstruct_template", "gg.load_template", "MESH_ICOSPHERE"),
                                ("gg.register_sequences", "gg.load_registration", "ANIM"),
                                ("gg.fit_behavior", "gg.show_behavior", "PHYSICS"),
                                ("gg.diagnose_physics", "gg.show_residuals", "FORCE_WIND")):
            row = layout.row(align=True)
            row.enabled = ready
            row.operator(run, icon=icon)
            row.operator(load, text="", icon="FILE_REFRESH")
        layout.prop(settings, "diagnose_vertex_mass")
        if settings.behavior:
            layout.label(text=settings.behavior, icon="INFO")
        if settings.diagnosis:
            layout.label(text=settings.diagnosis, icon="INFO")


class GG_PT_simulate(_Sidebar, Panel):
    """Use the fitted asset: the diagnosed model (or the fitted behaviour) on a built-in motion, with its body."""

    bl_idname = "GG_PT_simulate"
    bl_label = "Simulate"
    bl_parent_id = GG_PT_garments.bl_idname

    def draw(self, context: Context) -> None:
        settings = context.scene.gg
        layout = self.layout
        col = layout.column(align=True)
        col.prop(settings, "simulation_model")
        col.prop(settings, "simulation_motion")
        col.prop(settings, "simulation_frames")
        row = layout.row(align=True)
        row.enabled = bool(settings.project_path)
        row.operator("gg.simulate_garment", icon="PLAY")
        row.operator("gg.load_simulations", text="", icon="FILE_REFRESH")


class GG_PT_job(_Sidebar, Panel):
    bl_idname = "GG_PT_job"
    bl_label = "Job"
    bl_parent_id = GG_PT_garments.bl_idname

    def draw(self, context: Context) -> None:
        job = context.window_manager.gg_job
        layout = self.layout
        if job.running:
            layout.progress(factor=job.progress, type="BAR", text=job.status)
            layout.operator("gg.cancel_job", icon="CANCEL")
        elif job.result:
            layout.label(text=job.result, icon="ERROR" if job.failed else "CHECKMARK")
        else:
            layout.label(text="No job has run yet")


CLASSES = (GG_PT_garments, GG_PT_stages, GG_PT_simulate, GG_PT_job)
register, unregister = bpy.utils.register_classes_factory(CLASSES)
