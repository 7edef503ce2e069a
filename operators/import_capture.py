"""Import Capture: one collection per sequence with its cameras, the animated body and the camera images.

Cameras: OpenCV [R|t] + K become Blender camera objects (blender_addon.convert holds the maths); the scene
render size and pixel aspect are per scene in Blender, so each camera keeps its own in custom properties and
"Use Capture Camera" applies them. Body: one mesh (frame 0) + a Mesh Cache modifier reading a PC2 file of all
frames, chosen over one shape key per frame because it imports about ten times faster (150 frames x 10k
vertices: 0.03 s vs 0.3 s) and plays back faster (0.4 vs 2 ms per frame); topology changes are refused.
Images: each camera's frames as its background image (an image sequence when the frame names are numbered
consecutively, else the first frame).
"""
from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np
from bpy.props import BoolProperty, StringProperty
from bpy.types import Context, Event, Object, Operator, Scene
from mathutils import Matrix

from ..blender_addon.convert import blender_camera, to_blender_points
from ..blender_addon.meshes import add_mesh_cache, mesh_object
from ..blender_addon.preferences import ADDON_PACKAGE
from ..gg_core.capture.cameras import Camera
from ..gg_core.capture.layout import Capture, Sequence
from ..gg_core.errors import InputError
from ..gg_core.geometry.meshio import read_mesh

FPS = 30
CAMERA_DISPLAY_SIZE = 0.2
NUMBERED = re.compile(r"^(.*?)(\d+)$")


class GG_OT_import_capture(Operator):
    """Import a multi-view capture: cameras, animated body and images, one collection per sequence"""

    bl_idname = "gg.import_capture"
    bl_label = "Import Capture"
    bl_options = {"REGISTER", "UNDO"}

    directory: StringProperty(name="Capture", subtype="DIR_PATH",
                              description="Capture folder (one sub-folder per sequence with cameras.json)")
    cache_dir: StringProperty(name="Cache Folder", subtype="DIR_PATH",
                              description="Where the body animation (.pc2) is written. Empty: <project>/blender "
                                          "when the scene has a project folder, else the extension's user folder")
    load_images: BoolProperty(name="Camera Images", default=True,
                              description="Show each camera's images as its background")

    def invoke(self, context: Context, event: Event) -> set[str]:
        if self.directory:
            return self.execute(context)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context: Context) -> set[str]:
        scene = context.scene
        try:
            capture = Capture(bpy.path.abspath(self.directory))
            loaded = [load_sequence(seq) for seq in capture.sequences.values()]  # all checks before any change
            cache_dir = self._cache_dir(scene)
            scene.render.fps, scene.render.fps_base = FPS, 1.0
            scene.frame_start = 1
            scene.frame_end = max([1] + [len(data.frames) for data in loaded])
            imported = [build_sequence(scene, data, cache_dir, self.load_images) for data in loaded]
        except InputError as exc:
            self.report({"ERROR"}, exc.line())
            return {"CANCELLED"}
        except OSError as exc:
            self.report({"ERROR"}, f"gg: error: cannot write the body animation cache ({exc.strerror}), "
                                   f"{exc.filename}, choose a writable Cache Folder or project folder")
            return {"CANCELLED"}
        cameras = [o for c in imported for o in c.objects if "gg_camera_id" in o]
        if cameras and (scene.camera is None or "gg_camera_id" not in scene.camera):
            use_capture_camera(scene, cameras[0])
        self.report({"INFO"}, f"imported {len(imported)} sequence(s), {len(cameras)} cameras from {capture.root}")
        return {"FINISHED"}

    def _cache_dir(self, scene: Scene) -> Path:
        if self.cache_dir:
            return Path(bpy.path.abspath(self.cache_dir))
        if scene.gg.project_path:
            return Path(bpy.path.abspath(scene.gg.project_path)) / "blender"
        return Path(bpy.utils.extension_path_user(ADDON_PACKAGE, path="body_cache", create=True))


class GG_OT_use_capture_camera(Operator):
    """Look through the active capture camera with its own image size and pixel aspect"""

    bl_idname = "gg.use_capture_camera"
    bl_label = "Use Capture Camera"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Context) -> bool:
        return context.active_object is not None and "gg_camera_id" in context.active_object

    def execute(self, context: Context) -> set[str]:
        use_capture_camera(context.scene, context.active_object)
        return {"FINISHED"}


def use_capture_camera(scene: Scene, obj: Object) -> None:
    """Make `obj` the scene camera and set the render size / pixel aspect its intrinsics were converted for."""
    scene.camera = obj
    render = scene.render
    render.resolution_x, render.resolution_y = (int(v) for v in obj["gg_resolution"])
    render.pixel_aspect_x, render.pixel_aspect_y = (float(v) for v in obj["gg_pixel_aspect"])
    render.resolution_percentage = 100


@dataclass
class SequenceData:
    """What one sequence contributes to the scene, read and checked before anything is created."""

    seq: Sequence
    frames: list[str]
    cameras: list[Camera]
    body: tuple[np.ndarray, np.ndarray] | None  # Blender Z-up positions [T, V, 3], triangles


def load_sequence(seq: Sequence) -> SequenceData:
    """Read cameras and body of one sequence; raises InputError for data the import cannot represent."""
    frames = seq.frames or sorted(seq.body_files)
    body = _read_body(seq, frames) if seq.body_files else None
    return SequenceData(seq, frames, list(seq.cameras.values()), body)


def build_sequence(scene: Scene, data: SequenceData, cache_dir: Path, load_images: bool) -> bpy.types.Collection:
    """The collection of one sequence: its cameras (with background images) and its animated body."""
    seq, frames = data.seq, data.frames
    collection = bpy.data.collections.new(seq.name)
    scene.collection.children.link(collection)
    collection["gg_capture"] = str(seq.root.parent)
    collection["gg_sequence"] = seq.name
    collection["gg_frames"] = frames
    for camera in data.cameras:
        obj = _camera_object(camera, seq)
        collection.objects.link(obj)
        if load_images and frames:
            _set_background(obj, seq, camera.id, frames, scene.frame_start)
    if data.body is not None:
        collection.objects.link(_body_object(seq, *data.body, cache_dir, scene.frame_start))
    return collection


def _camera_object(camera: Camera, seq: Sequence) -> Object:
    params = blender_camera(camera.K, camera.R, camera.t, camera.width, camera.height)
    data = bpy.data.cameras.new(camera.id)
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width = params.sensor_width
    data.lens = params.lens
    data.shift_x, data.shift_y = params.shift_x, params.shift_y
    data.clip_start, data.clip_end = 0.01, 1000.0
    data.display_size = CAMERA_DISPLAY_SIZE
    obj = bpy.data.objects.new(camera.id, data)
    obj.matrix_world = Matrix(params.matrix_world.tolist())
    obj["gg_camera_id"] = camera.id
    obj["gg_camera_index"] = camera.index
    obj["gg_sequence"] = seq.name
    obj["gg_capture"] = str(seq.root.parent)
    obj["gg_resolution"] = [params.resolution_x, params.resolution_y]
    obj["gg_pixel_aspect"] = [params.pixel_aspect_x, params.pixel_aspect_y]
    if params.skew:
        obj["gg_skew_dropped"] = params.skew  # Blender cameras have no skew; kept for the record
    return obj


def _set_background(obj: Object, seq: Sequence, camera_id: str, frames: list[str], frame_start: int) -> None:
    files = seq.files(camera_id)
    if frames[0] not in files:
        return
    image = bpy.data.images.load(str(files[frames[0]]), check_existing=True)
    background = obj.data.background_images.new()
    background.image = image
    obj.data.show_background_images = True
    first = _first_number_if_consecutive(frames)
    if first is not None and len(frames) > 1:
        image.source = "SEQUENCE"
        user = background.image_user
        user.frame_start = frame_start
        user.frame_duration = len(frames)
        user.frame_offset = first - 1  # Blender shows file number (frame - frame_start + 1) + frame_offset
        user.use_auto_refresh = True


def _first_number_if_consecutive(frames: list[str]) -> int | None:
    """Number of the first frame when names are <prefix><n>, <prefix><n+1>, ... with equal width."""
    matches = [NUMBERED.match(f) for f in frames]
    if not all(matches) or len({(m.group(1), len(m.group(2))) for m in matches}) != 1:
        return None
    numbers = [int(m.group(2)) for m in matches]
    return numbers[0] if numbers == list(range(numbers[0], numbers[0] + len(numbers))) else None


def _read_body(seq: Sequence, frames: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(Blender Z-up vertices [T, V, 3], triangles) for every frame; the topology must not change."""
    positions, faces0 = [], None
    for frame in frames:
        path = seq.body_path(frame)
        verts, faces = read_mesh(path)
        if faces0 is None:
            faces0, count0 = faces, len(verts)
        elif len(verts) != count0 or not np.array_equal(faces, faces0):
            raise InputError(f"body topology changes at frame '{frame}' ({len(verts)} vertices / {len(faces)} faces "
                             f"vs {count0} / {len(faces0)} in frame '{frames[0]}')", path,
                             "export every body frame with the same mesh connectivity (e.g. the fitted body model)")
        positions.append(to_blender_points(verts))
    return np.stack(positions), faces0


def _body_object(seq: Sequence, positions: np.ndarray, faces: np.ndarray, cache_dir: Path, frame_start: int) -> Object:
    obj = mesh_object(f"{seq.name}_body", positions[0], faces)
    obj["gg_sequence"] = seq.name
    obj["gg_capture"] = str(seq.root.parent)
    if len(positions) > 1:
        key = hashlib.sha1(str(seq.root.resolve()).encode()).hexdigest()[:10]
        add_mesh_cache(obj, positions, cache_dir / f"{seq.name}_body_{key}.pc2", frame_start, "Body Motion")
    return obj


CLASSES = (GG_OT_import_capture, GG_OT_use_capture_camera)
