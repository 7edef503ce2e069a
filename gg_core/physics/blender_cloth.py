"""Blender's cloth modifier as a reference simulator (bpy worker, run in a subprocess of the project python).

`python -m gg_core.physics.blender_cloth JOB.npz OUT.npz` simulates a garment on an animated body with the
cloth modifier and writes the garment frames and the wall time of the simulation loop. The parent process
(`run_blender_cloth`) never imports bpy, so torch and bpy never share a process. Pinned vertices follow their
targets like the synthetic captures do (pin vertex group + Mesh Cache of the targets); the body collides through
a Collision modifier; both objects play their frames from PC2 files.
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..synth.blender_frame import from_blender, to_blender
from ..geometry.pc2 import write_pc2

def run_blender_cloth(garment_rest: np.ndarray, garment_faces: np.ndarray, body_frames: np.ndarray,
                      body_faces: np.ndarray, pinned: np.ndarray, pin_frames: np.ndarray, cloth: dict,
                      cloth_collision: dict, body_collision: dict, fps: int = 30,
                      timeout: float = 1800.0) -> tuple[np.ndarray, float]:
    """Garment frames [T,V,3] simulated by Blender for body frames [T,Vb,3] (frame 0 = rest state), and the
    seconds the frame loop took. `pin_frames` [T,V,3] holds the targets of the `pinned` vertices; `cloth`,
    `cloth_collision` and `body_collision` are Blender ClothSettings / ClothCollisionSettings / CollisionSettings
    attributes."""
    settings = {"fps": fps, "cloth": cloth, "cloth_collision": cloth_collision, "body_collision": body_collision}
    with tempfile.TemporaryDirectory(prefix="gg_blender_cloth_") as tmp:
        job, out = Path(tmp) / "job.npz", Path(tmp) / "out.npz"
        np.savez(job, garment_rest=garment_rest, garment_faces=garment_faces, body_frames=body_frames,
                 body_faces=body_faces, pinned=pinned, pin_frames=pin_frames, settings=json.dumps(settings))
        proc = subprocess.run([sys.executable, "-m", __name__, str(job), str(out)], capture_output=True, text=True,
                              timeout=timeout)
        if proc.returncode != 0 or not out.exists():
            raise RuntimeError(f"Blender cloth worker failed ({proc.returncode}): {proc.stderr[-2000:]}")
        with np.load(out) as z:
            return z["frames"], float(z["seconds"])


def _simulate(job: Path, out: Path) -> None:
    import bpy  # noqa: PLC0415 - worker process only

    from ..synth.blender_scene import play_pc2  # noqa: PLC0415 - imports bpy

    z = np.load(job)
    settings = json.loads(str(z["settings"]))
    n_frames = len(z["body_frames"])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = settings["fps"]
    scene.frame_start, scene.frame_end = 1, n_frames
    work = job.parent

    body = _mesh(scene, "body", z["body_frames"][0], z["body_faces"])
    write_pc2(work / "body.pc2", to_blender(z["body_frames"]))
    play_pc2(body, work / "body.pc2")
    body.modifiers.new("collision", "COLLISION")
    for key, value in settings["body_collision"].items():
        setattr(body.collision, key, value)

    garment = _mesh(scene, "garment", z["garment_rest"], z["garment_faces"])
    targets = np.where(z["pinned"][None, :, None], z["pin_frames"], z["garment_rest"][None])
    write_pc2(work / "targets.pc2", to_blender(targets))
    play_pc2(garment, work / "targets.pc2")
    cloth = garment.modifiers.new("cloth", "CLOTH")
    for key, value in settings["cloth"].items():
        setattr(cloth.settings, key, value)
    for key, value in settings["cloth_collision"].items():
        setattr(cloth.collision_settings, key, value)
    if z["pinned"].any():
        group = garment.vertex_groups.new(name="pin")
        group.add(np.flatnonzero(z["pinned"]).tolist(), 1.0, "REPLACE")
        cloth.settings.vertex_group_mass = "pin"
    cloth.point_cache.frame_start, cloth.point_cache.frame_end = 1, n_frames

    frames = np.empty((n_frames, len(z["garment_rest"]), 3))
    co = np.empty(len(z["garment_rest"]) * 3, np.float32)
    start = time.perf_counter()
    for f in range(n_frames):
        scene.frame_set(f + 1)
        mesh = garment.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        mesh.vertices.foreach_get("co", co)
        frames[f] = co.reshape(-1, 3)
    seconds = time.perf_counter() - start
    np.savez(out, frames=from_blender(frames), seconds=seconds)


def _mesh(scene, name: str, verts: np.ndarray, faces: np.ndarray):
    import bpy  # noqa: PLC0415

    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(to_blender(verts).tolist(), [], np.asarray(faces).tolist())
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


if __name__ == "__main__":
    _simulate(Path(sys.argv[1]), Path(sys.argv[2]))
