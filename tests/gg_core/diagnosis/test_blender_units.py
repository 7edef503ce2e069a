"""Blender's cloth solver, measured against what the benchmark says its settings mean: a cloth square falling
freely (no collision, no pins) with the benchmark's cloth settings. Its air damping is the velocity decay
`blender_units.truth_parameters` converts it to; its gravity is the scene's times 0.001 per frame^2 (0.9 g at
30 fps), which `gg synth` compensates through `blender_frame.scene_gravity` so captures fall at 9.81 m/s^2."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from gg_core.diagnosis.blender_units import truth_parameters
from gg_core.synth.blender_frame import scene_gravity

FRAMES, MASS, G = 40, 0.3, 9.81

FALL = textwrap.dedent("""
    import json, sys
    import bpy, numpy as np
    frames, mass, runs = int(sys.argv[1]), float(sys.argv[2]), json.loads(sys.argv[3])
    out = []
    for fps, air, gravity_z in runs:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scene.render.fps, scene.frame_start, scene.frame_end = fps, 1, frames
        scene.gravity = (0.0, 0.0, gravity_z)
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=6, y_subdivisions=6, size=0.5, location=(0, 0, 10))
        obj = bpy.context.active_object
        cloth = obj.modifiers.new("cloth", "CLOTH")
        cloth.settings.mass, cloth.settings.air_damping, cloth.settings.quality = mass, air, 5
        cloth.collision_settings.use_collision = False
        cloth.collision_settings.use_self_collision = False
        cloth.point_cache.frame_end = frames
        z = []
        for f in range(1, frames + 1):
            scene.frame_set(f)
            mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
            co = np.empty(len(mesh.vertices) * 3)
            mesh.vertices.foreach_get("co", co)
            z.append(float(co.reshape(-1, 3)[:, 2].mean()))
        out.append(z)
    print("@fall " + json.dumps(out))
""")


def _falls(runs: list[tuple[int, float, float]]) -> list[np.ndarray]:
    """Fall per frame (m/frame) of the square's mean height, one array per (fps, air damping, scene gravity z)."""
    run = subprocess.run([sys.executable, "-c", FALL, str(FRAMES), str(MASS), json.dumps(runs)], capture_output=True,
                         text=True, timeout=300, check=True)
    heights = json.loads(next(l for l in run.stdout.splitlines() if l.startswith("@fall "))[6:])
    return [-np.diff(np.array(z)) for z in heights]


def _per_s2(fall: np.ndarray, fps: int) -> float:
    return float(np.median(np.diff(fall)[2:])) * fps ** 2


@pytest.mark.bpy
def test_blender_air_damping_is_the_converted_alpha_and_its_gravity_is_scaled_per_frame():
    fps = 30
    compensated = {f: scene_gravity([0.0, -G, 0.0], f)[2] for f in (24, 30)}
    free, damped, comp24, comp30 = _falls([(fps, 0.0, -G), (fps, 10.0, -G),
                                           (24, 0.0, compensated[24]), (30, 0.0, compensated[30])])
    assert _per_s2(free, fps) == pytest.approx(0.001 * G * fps ** 2, rel=0.01)   # 8.83 m/s^2, not 9.81
    assert _per_s2(comp24, 24) == pytest.approx(G, rel=0.01)                     # what gg synth sets falls at g
    assert _per_s2(comp30, 30) == pytest.approx(G, rel=0.01)
    g = float(np.median(np.diff(free)[2:]))                                       # m/frame^2
    k = (g - np.diff(damped)[2:20]) / damped[2:20]                               # v' = g - k v, per frame
    truth = truth_parameters({"effect": {"name": "air_drag", "params": {"air_damping": 10.0}},
                              "material": {"blender_cloth": {"mass": MASS}}, "preset": {"fps": fps}})
    assert float(np.median(k)) * fps == pytest.approx(truth["mass_damping.alpha"], rel=0.02)
