"""Cycles on the CPU: render settings and one view rendered to a multilayer EXR (RGB + object index).

Runs inside the bpy worker only. Persistent data keeps the synced scene between the cameras of a frame,
so only the first view of each frame pays for scene export and BVH build.
"""
from __future__ import annotations

from pathlib import Path

import bpy


def configure(scene: bpy.types.Scene, samples: int, denoise: bool, seed: int, threads: int = 0) -> None:
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = denoise
    scene.cycles.seed = seed
    scene.cycles.max_bounces = 4
    scene.render.use_persistent_data = True
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"   # passes.linear_to_srgb8 applies exactly this
    scene.view_settings.look = "None"
    if threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = threads
    scene.view_layers[0].use_pass_object_index = True
    settings = scene.render.image_settings
    settings.media_type = "MULTI_LAYER_IMAGE"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"


def render_view(scene: bpy.types.Scene, camera: bpy.types.Object, exr_path: Path) -> None:
    scene.camera = camera
    scene.render.filepath = str(exr_path)
    bpy.ops.render.render(write_still=True)
