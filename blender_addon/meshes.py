"""Triangle meshes into Blender: one object from numpy arrays, animated by a Mesh Cache (PC2) modifier.

Shared by the capture import (animated body) and the stage results (template, registered sequences,
residual map). Positions arrive already in Blender's Z-up frame (convert.to_blender_points).
A Mesh Cache modifier is used rather than shape keys: ten times faster to import and to play back for
long sequences, and the PC2 file is written atomically so a cancelled import leaves no half file.
"""
from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from bpy.types import Object

from ..gg_core.geometry.pc2 import write_pc2
from ..gg_core.storage import atomic_path


def mesh_object(name: str, verts: np.ndarray, faces: np.ndarray, uvs: np.ndarray | None = None,
                face_uvs: np.ndarray | None = None, smooth: bool = True) -> Object:
    """A new (unlinked) object with a triangle mesh; `uvs`[face_uvs] become the "UVMap" layer when given."""
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(verts))
    mesh.vertices.foreach_set("co", np.asarray(verts, np.float32).ravel())
    faces = np.asarray(faces, np.int32)
    mesh.loops.add(faces.size)
    mesh.loops.foreach_set("vertex_index", faces.ravel())
    mesh.polygons.add(len(faces))
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    if uvs is not None and face_uvs is not None:
        layer = mesh.uv_layers.new(name="UVMap")
        layer.data.foreach_set("uv", np.asarray(uvs, np.float32)[np.asarray(face_uvs).ravel()].ravel())
    mesh.update()
    if smooth:
        mesh.shade_smooth()
    return bpy.data.objects.new(name, mesh)


def add_mesh_cache(obj: Object, positions: np.ndarray, cache: Path, frame_start: int,
                   label: str = "Motion") -> None:
    """Animate `obj` with `positions` [T, V, 3] (Z-up) through a PC2 file written atomically at `cache`."""
    cache.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(cache) as tmp:
        write_pc2(tmp, positions)
    modifier = obj.modifiers.new(label, "MESH_CACHE")
    modifier.cache_format = "PC2"
    modifier.filepath = str(cache)
    modifier.frame_start = frame_start


def vertex_colors(obj: Object, rgb: np.ndarray, name: str = "Col") -> None:
    """Per-vertex colour attribute (float RGBA) made the active colour, so Solid/Attribute view shows it."""
    mesh = obj.data
    attribute = mesh.color_attributes.new(name, "FLOAT_COLOR", "POINT")
    rgba = np.concatenate([np.asarray(rgb, np.float32), np.ones((len(rgb), 1), np.float32)], axis=1)
    attribute.data.foreach_set("color", rgba.ravel())
    mesh.color_attributes.active_color = attribute
    mesh.color_attributes.render_color_index = mesh.color_attributes.active_color_index
