"""Synthetic multi-view garment captures: Blender cloth simulation + Cycles renders + ground truth.

The parent process (generate.py) never imports bpy; each sequence is simulated and rendered by
`python -m gg_core.synth.worker` inside the bpy module, so Blender and torch never share a process.
"""
