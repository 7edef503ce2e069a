"""Gaussian Garments headless core: capture I/O, Gaussian texture and rasterizer, cloth physics, stages.

Never imports bpy (except the bake and synth workers, which run inside the bpy module) so the
core runs anywhere. Modules reached by the Blender add-on (capture/) use numpy and stdlib only.
"""
__version__ = "0.1.0"
