"""The Blender scene of one synthetic sequence: animated body, cloth garment, cameras, lights, studio.

Runs inside the bpy worker only. Geometry arrives in gg coordinates and is converted to Blender's +Z up
here (blender_frame). Animation is played from PC2 files through Mesh Cache modifiers: the body (and its
hand-less collider) from the posed body frames, the garment from its body-anchored targets, which are
what pinned vertices follow while the cloth modifier simulates the rest.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import bpy
import mathutils
import numpy as np

from ..capture.cameras import load_cameras
from .blender_frame import blender_camera, from_blender, to_blender
from .fabrics import Look
from .job import GROUP_PREFIX, SequenceJob
from .materials import fabric_material, plain_material
from .passes import BODY_INDEX, GARMENT_INDEX
from ..geometry.pc2 import write_pc2

SKIN = (0.80, 0.58, 0.46)
FLOOR = (0.30, 0.30, 0.32)
WORLD = (0.42, 0.45, 0.50)
FLOOR_HALF_SIZE = 1.5
PIN_GROUP = "pin"


@dataclass
class SceneHandles:
    scene: bpy.types.Scene
    body: bpy.types.Object
    garment: bpy.types.Object
    cameras: dict[str, bpy.types.Object]
    workdir: Path


def build_scene(job: SequenceJob, arrays: dict[str, np.ndarray], workdir: Path) -> SceneHandles:
    """A fresh scene ready to simulate frames 1..n_sim_frames (frame 1 is the rest pose)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = job.fps
    scene.frame_start, scene.frame_end = 1, job.n_sim_frames
    scene.use_gravity = True
    scene.gravity = tuple(job.scene_gravity)
    workdir.mkdir(parents=True, exist_ok=True)

    body_pc2 = workdir / "body.pc2"
    write_pc2(body_pc2, to_blender(arrays["body_frames"]))
    body = _mesh_object(scene, "body", arrays["body_frames"][0], arrays["body_faces"])
    play_pc2(body, body_pc2)
    body.pass_index = BODY_INDEX
    body.data.materials.append(plain_material("skin", SKIN, roughness=0.45, specular=0.5))

    collider = _mesh_object(scene, "body_collider", arrays["body_frames"][0], arrays["collider_faces"])
    play_pc2(collider, body_pc2)
    collider.hide_render = True
    collider.modifiers.new("collision", "COLLISION")
    _assign(collider.collision, job.body_collision)

    garment = _mesh_object(scene, "garment", arrays["garment_rest"], arrays["garment_faces"])
    _add_uvs(garment.data, arrays["garment_uvs"], arrays["garment_face_uvs"])
    for key, weights in arrays.items():
        if key.startswith(GROUP_PREFIX):
            _vertex_group(garment, key[len(GROUP_PREFIX):], weights)
    targets_pc2 = workdir / "garment_targets.pc2"
    write_pc2(targets_pc2, to_blender(arrays["garment_targets"]))
    play_pc2(garment, targets_pc2)
    garment.pass_index = GARMENT_INDEX
    garment.data.materials.append(fabric_material(Look(**job.look), job.uv_scale))
    _add_cloth(garment, job)

    for i, spec in enumerate(job.force_fields):
        _force_field(scene, f"field{i}", spec)
    cameras = _add_cameras(scene, job)
    _add_studio(scene, job.lights)
    return SceneHandles(scene, body, garment, cameras, workdir)


def simulate(handles: SceneHandles, on_frame) -> None:
    """Step the cloth through every frame in order; `on_frame(frame, vertices_gg)` sees each result."""
    scene = handles.scene
    for frame in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(frame)
        on_frame(frame, evaluated_vertices(handles.garment))


def evaluated_vertices(obj: bpy.types.Object) -> np.ndarray:
    """World-space vertices of the object after its modifiers, in gg coordinates."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = obj.evaluated_get(depsgraph).data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    return from_blender(co.reshape(-1, 3).astype(np.float64))


def replay_garment(handles: SceneHandles, frames: np.ndarray, first_frame: int) -> None:
    """Drop the cloth solver and play recorded garment frames [T,V,3] (gg) from scene frame `first_frame`.

    Renders then show exactly the ground-truth meshes, and re-rendering after a resume needs no re-simulation.
    """
    garment = handles.garment
    garment.modifiers.remove(garment.modifiers["cloth"])
    path = handles.workdir / "garment_gt.pc2"
    write_pc2(path, to_blender(frames))
    cache = garment.modifiers["cache"]
    cache.filepath = str(path)
    cache.frame_start = first_frame


def _mesh_object(scene: bpy.types.Scene, name: str, verts: np.ndarray, faces: np.ndarray) -> bpy.types.Object:
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(to_blender(verts).tolist(), [], np.asarray(faces).tolist())
    mesh.shade_smooth()
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def play_pc2(obj: bpy.types.Object, pc2: Path) -> None:
    """Mesh Cache modifier: scene frame f shows sample f - 1 of the PC2 file (already in Blender axes)."""
    mod = obj.modifiers.new("cache", "MESH_CACHE")
    mod.cache_format = "PC2"
    mod.filepath = str(pc2)
    mod.frame_start = 1.0
    mod.forward_axis, mod.up_axis = "POS_Y", "POS_Z"


def _add_uvs(mesh: bpy.types.Mesh, uvs: np.ndarray, face_uvs: np.ndarray) -> None:
    layer = mesh.uv_layers.new(name="UVMap")
    loop_uvs = uvs[np.asarray(face_uvs).ravel()]       # from_pydata keeps triangle corners in order
    layer.data.foreach_set("uv", loop_uvs.astype(np.float32).ravel())


def _vertex_group(obj: bpy.types.Object, name: str, weights: np.ndarray) -> None:
    group = obj.vertex_groups.new(name=name)
    for value in np.unique(weights[weights > 0]):
        group.add(np.flatnonzero(weights == value).tolist(), float(value), "REPLACE")


def _assign(target: object, settings: dict) -> None:
    for key, value in settings.items():
        setattr(target, key, value)


def _add_cloth(garment: bpy.types.Object, job: SequenceJob) -> None:
    cloth = garment.modifiers.new("cloth", "CLOTH")
    _assign(cloth.settings, job.cloth)
    _assign(cloth.collision_settings, job.cloth_collision)
    if PIN_GROUP in garment.vertex_groups:
        cloth.settings.vertex_group_mass = PIN_GROUP
    for attribute, region in job.cloth_vertex_groups.items():
        setattr(cloth.settings, attribute, region)
    cloth.point_cache.frame_start = 1
    cloth.point_cache.frame_end = job.n_sim_frames


def _force_field(scene: bpy.types.Scene, name: str, spec: dict) -> None:
    direction = mathutils.Vector(to_blender(np.asarray(spec["direction"], float)))
    bpy.ops.object.effector_add(type=spec["type"], location=(0.0, 0.0, 1.0),  # fields push along local +Z
                                rotation=direction.to_track_quat("Z", "Y").to_euler())
    obj = bpy.context.object
    obj.name = name
    _assign(obj.field, {k: v for k, v in spec.items() if k not in ("type", "direction")})


def _add_cameras(scene: bpy.types.Scene, job: SequenceJob) -> dict[str, bpy.types.Object]:
    out = {}
    for cid, cam in load_cameras(Path(job.seq_dir) / "cameras.json").items():
        bc = blender_camera(cam)
        data = bpy.data.cameras.new(cid)
        data.sensor_fit = "HORIZONTAL"
        data.sensor_width = bc.sensor_width_mm
        data.lens = bc.lens_mm
        data.shift_x, data.shift_y = bc.shift_x, bc.shift_y
        data.clip_start, data.clip_end = 0.05, 50.0
        obj = bpy.data.objects.new(cid, data)
        obj.matrix_world = mathutils.Matrix(bc.matrix_world.tolist())
        scene.collection.objects.link(obj)
        out[cid] = obj
        scene.render.resolution_x, scene.render.resolution_y = bc.width, bc.height
    return out


def _add_studio(scene: bpy.types.Scene, lights: list[dict]) -> None:
    world = bpy.data.worlds.new("studio")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (*WORLD, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.5
    scene.world = world
    floor = bpy.data.meshes.new("floor")
    # a 3 m square is enough for the shadows; floor pixels cost ~3x background pixels in Cycles
    h = FLOOR_HALF_SIZE
    floor.from_pydata([(-h, -h, -0.002), (h, -h, -0.002), (h, h, -0.002), (-h, h, -0.002)], [], [(0, 1, 2, 3)])
    floor_obj = bpy.data.objects.new("floor", floor)
    floor.materials.append(plain_material("floor", FLOOR, roughness=0.8, specular=0.3))
    scene.collection.objects.link(floor_obj)
    for i, spec in enumerate(lights):
        light = bpy.data.lights.new(f"light{i}", spec["type"])
        light.color = spec["color"]
        light.energy = spec["strength"]
        obj = bpy.data.objects.new(f"light{i}", light)
        scene.collection.objects.link(obj)
        if spec["type"] == "SUN":
            light.angle = np.radians(spec["angle_deg"])
            direction = mathutils.Vector(to_blender(np.asarray(spec["direction"], float)))
        else:
            light.size = spec["size"]
            obj.location = tuple(to_blender(np.asarray(spec["location"], float)))
            direction = mathutils.Vector(to_blender(np.asarray(spec["target"], float))) - obj.location
        obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()   # lights shine along local -Z
