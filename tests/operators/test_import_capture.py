"""Import Capture in headless Blender: camera projection round trip, collections, animated body, images."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gg_core.capture.cameras import Camera, load_cameras, look_at, save_cameras
from gg_core.geometry.meshio import read_mesh, write_ply

pytestmark = pytest.mark.bpy


def test_camera_round_trip_within_half_a_pixel(blender, small_capture, z_up):
    """Points projected with cameras.json land where the imported Blender camera sees them."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    bpy = blender
    # Off-centre principal points, non-square images, fx != fy both ways.
    specs = {"cam00": (160, 90, 150.0, 150.0, 7.5, -5.0), "cam01": (94, 128, 100.0, 130.0, -9.0, 12.5),
             "cam02": (120, 120, 140.0, 110.0, 3.0, 9.0)}
    cams = {}
    for i, (cid, (w, h, fx, fy, dcx, dcy)) in enumerate(specs.items()):
        a = 2 * np.pi * i / 3 + 0.3
        base = look_at(cid, np.array([2.5 * np.sin(a), 1.4 + 0.2 * i, 2.5 * np.cos(a)]), np.array([0.1, 1.0, 0.0]),
                       50, w, h, index=i)
        K = np.array([[fx, 0.0, w / 2 + dcx], [0.0, fy, h / 2 + dcy], [0.0, 0.0, 1.0]])
        cams[cid] = Camera(cid, K, base.R, base.t, w, h, i)
    save_cameras(small_capture / "seq0" / "cameras.json", cams)

    assert bpy.ops.gg.import_capture(directory=str(small_capture), cache_dir=str(small_capture.parent / "cache")) \
        == {"FINISHED"}
    rng = np.random.default_rng(3)
    points = np.array([0.0, 1.0, 0.0]) + rng.uniform(-0.6, 0.6, (200, 3))
    for cid, cam in load_cameras(small_capture / "seq0" / "cameras.json").items():
        obj = bpy.data.objects[cid]
        assert obj.type == "CAMERA" and obj["gg_camera_id"] == cid and obj["gg_sequence"] == "seq0"
        bpy.context.view_layer.objects.active = obj
        assert bpy.ops.gg.use_capture_camera() == {"FINISHED"}
        scene = bpy.context.scene
        assert (scene.render.resolution_x, scene.render.resolution_y) == (cam.width, cam.height)
        uv, depth = cam.project(points)
        assert (depth > 0).all()
        ndc = np.array([tuple(world_to_camera_view(scene, obj, Vector(p))) for p in z_up(points)])
        pixels = np.stack([ndc[:, 0] * cam.width, (1.0 - ndc[:, 1]) * cam.height], axis=1)
        err = np.abs(pixels - uv).max()
        assert err < 0.5, f"{cid}: {err:.3g} px"
        np.testing.assert_allclose(ndc[:, 2], depth, rtol=1e-5)


def test_import_builds_one_collection_per_sequence(blender, capture_writer, tmp_path, z_up, evaluated_vertices):
    bpy = blender
    capture = capture_writer(tmp_path / "capture", n_cams=2, n_frames=4, sequences=("seqA", "seqB"))
    project = tmp_path / "project"
    bpy.context.scene.gg.project_path = str(project)
    assert bpy.ops.gg.import_capture(directory=str(capture)) == {"FINISHED"}

    scene = bpy.context.scene
    assert (scene.render.fps, scene.frame_start, scene.frame_end) == (30, 1, 4)
    for seq in ("seqA", "seqB"):
        coll = bpy.data.collections[seq]
        assert coll["gg_sequence"] == seq and list(coll["gg_frames"]) == [f"{k:06d}" for k in range(4)]
        cameras = sorted(o["gg_camera_id"] for o in coll.objects if o.type == "CAMERA")
        assert cameras == ["cam00", "cam01"]
        bodies = [o for o in coll.objects if o.type == "MESH"]
        assert len(bodies) == 1
        body = bodies[0]
        modifier = body.modifiers["Body Motion"]
        assert Path(modifier.filepath).parent == project / "blender"
        for k in range(4):
            scene.frame_set(scene.frame_start + k)
            verts, _ = read_mesh(capture / seq / "body" / f"{k:06d}.ply")
            np.testing.assert_allclose(evaluated_vertices(body), z_up(verts), atol=1e-6)
            cam = next(o for o in coll.objects if o.type == "CAMERA")
            background = cam.data.background_images[0]
            shown = background.image.filepath_from_user(image_user=background.image_user)
            assert Path(shown) == capture / seq / cam["gg_camera_id"] / "rgb_images" / f"{k:06d}.png"


def test_changing_body_topology_is_refused_before_anything_is_created(blender, capture_writer, tmp_path):
    bpy = blender
    capture = capture_writer(tmp_path / "capture", sequences=("seqA", "seqB"))
    write_ply(capture / "seqB" / "body" / "000001.ply", np.zeros((4, 3)), np.array([[0, 1, 2], [0, 2, 3]]))
    with pytest.raises(RuntimeError, match=r"gg: error: body topology changes at frame '000001' .*000001\.ply"):
        bpy.ops.gg.import_capture(directory=str(capture), cache_dir=str(tmp_path / "cache"))
    assert len(bpy.data.collections) == 0 and len(bpy.data.objects) == 0


def test_not_a_capture_is_one_error_line(blender, tmp_path):
    with pytest.raises(RuntimeError, match=r"gg: error: no sequence found"):
        blender.ops.gg.import_capture(directory=str(tmp_path))


def test_cameras_json_problem_is_reported(blender, small_capture):
    path = small_capture / "seq0" / "cameras.json"
    raw = json.loads(path.read_text())
    raw["cam01"]["extrinsics"][0][0] = float("nan")
    path.write_text(json.dumps(raw))
    with pytest.raises(RuntimeError, match=r"gg: error: extrinsics contains NaN.*camera cam01"):
        blender.ops.gg.import_capture(directory=str(small_capture), cache_dir=str(small_capture.parent / "cache"))


def test_unwritable_cache_folder_is_one_error_line(blender, small_capture, tmp_path):
    blocker = tmp_path / "not a folder"
    blocker.write_text("")
    with pytest.raises(RuntimeError, match=r"gg: error: cannot write the body animation cache .*not a folder"):
        blender.ops.gg.import_capture(directory=str(small_capture), cache_dir=str(blocker / "cache"))
