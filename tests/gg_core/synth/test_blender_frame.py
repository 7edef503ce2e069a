import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from gg_core.capture.cameras import Camera, look_at
from gg_core.synth.blender_frame import blender_camera, from_blender, to_blender


def _camera() -> Camera:
    cam = look_at("c", np.array([1.5, 1.6, 2.5]), np.array([0.0, 1.0, 0.0]), 50, 120, 90)
    K = cam.K.copy()
    K[0, 2] += 9.3          # off-centre principal point: exercises the lens shift
    K[1, 2] -= 6.1
    return Camera("c", K, cam.R, cam.t, 120, 90)


def test_axes_round_trip_and_up_is_blender_z():
    p = np.random.default_rng(0).normal(size=(10, 3))
    np.testing.assert_allclose(from_blender(to_blender(p)), p)
    np.testing.assert_allclose(to_blender(np.array([0.0, 1.0, 0.0])), [0, 0, 1])


def test_blender_camera_looks_where_the_opencv_camera_looks():
    cam = _camera()
    bc = blender_camera(cam)
    forward_gg = cam.R[2]                                           # OpenCV +z in world
    np.testing.assert_allclose(-bc.matrix_world[:3, 2], to_blender(forward_gg), atol=1e-12)
    np.testing.assert_allclose(bc.matrix_world[:3, 3], to_blender(cam.center), atol=1e-12)
    assert bc.lens_mm == pytest.approx(cam.K[0, 0] * bc.sensor_width_mm / cam.width)


RENDER = textwrap.dedent("""
    import json, sys
    import bpy, mathutils, numpy as np, OpenEXR
    from gg_core.capture.cameras import Camera
    from gg_core.synth.blender_frame import blender_camera, to_blender
    spec = json.loads(sys.argv[1])
    cam = Camera("c", np.array(spec["K"]), np.array(spec["R"]), np.array(spec["t"]), spec["w"], spec["h"])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"; scene.cycles.samples = 1; scene.cycles.filter_width = 0.01
    scene.render.resolution_x, scene.render.resolution_y = cam.width, cam.height
    bc = blender_camera(cam)
    data = bpy.data.cameras.new("c"); obj = bpy.data.objects.new("c", data); scene.collection.objects.link(obj)
    data.sensor_fit = "HORIZONTAL"; data.sensor_width = bc.sensor_width_mm; data.lens = bc.lens_mm
    data.shift_x, data.shift_y = bc.shift_x, bc.shift_y
    obj.matrix_world = mathutils.Matrix(bc.matrix_world.tolist()); scene.camera = obj
    for i, p in enumerate(spec["points"]):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.03, location=tuple(to_blender(np.array(p))))
        bpy.context.object.pass_index = i + 1
    scene.view_layers[0].use_pass_object_index = True
    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    scene.render.filepath = spec["out"]
    bpy.ops.render.render(write_still=True)
    with OpenEXR.File(spec["out"]) as f:
        index = next(c.pixels for p in f.parts for n, c in p.channels.items() if n.endswith("Object Index.X"))
    centroids = []
    for i in range(len(spec["points"])):
        ys, xs = np.nonzero(np.rint(index) == i + 1)
        centroids.append([xs.mean() + 0.5, ys.mean() + 0.5])
    print("@centroids " + json.dumps(centroids))
""")


@pytest.mark.bpy
def test_rendered_points_land_where_camera_project_says(tmp_path):
    """Render small spheres with a Blender camera built from K,R,t; their pixel centroids must match project()."""
    cam = _camera()
    points = np.array([0.0, 1.0, 0.0]) + np.random.default_rng(3).uniform(-0.4, 0.4, (6, 3))
    spec = {"K": cam.K.tolist(), "R": cam.R.tolist(), "t": cam.t.tolist(), "w": cam.width, "h": cam.height,
            "points": points.tolist(), "out": str(tmp_path / "proj.exr")}
    out = subprocess.run([sys.executable, "-c", RENDER, json.dumps(spec)], capture_output=True, text=True,
                         check=True).stdout
    centroids = np.array(json.loads(next(l for l in out.splitlines() if l.startswith("@centroids "))[11:]))
    uv, _ = cam.project(points)
    # sphere centres project to the centroid of their disc up to perspective bias (<< 1 px here)
    assert np.abs(centroids - uv).max() < 0.35
