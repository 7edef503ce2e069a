"""`python -m gg_core.synth.worker JOB.json`: simulate and render one sequence inside the bpy module.

Runs in its own process so the gg process never holds bpy and torch together. Reports progress as
lines `@gg {json}` on stdout (Blender's own log lines are ignored by the parent). Resumes: finished
ground-truth meshes skip the simulation, finished views skip their render.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

PREFIX = "@gg "


def emit(**message: object) -> None:
    print(PREFIX + json.dumps(message), flush=True)


def run(job_path: Path, render_views: bool = True) -> None:
    from ..geometry.meshio import read_mesh
    from . import render
    from .blender_scene import build_scene, replay_garment, simulate
    from .job import SequenceJob
    from .passes import read_views
    from .writer import GT_GARMENT, gt_path, views_done, write_meshes, write_views

    job = SequenceJob.load(job_path)
    seq_dir = Path(job.seq_dir)
    with np.load(job.arrays) as z:
        arrays = {k: z[k] for k in z.files}
    workdir = Path(job.arrays).parent
    timings: dict[str, float] = {}
    start = time.perf_counter()
    handles = build_scene(job, arrays, workdir)
    if render_views:
        render.configure(handles.scene, **job.render)
    timings["scene_s"] = time.perf_counter() - start

    names = job.frame_names
    gt_files = [gt_path(seq_dir, name) for name in names]
    start = time.perf_counter()
    recorded: list[np.ndarray] = []
    if all(p.is_file() for p in gt_files):
        gt = np.stack([read_mesh(p)[0] for p in gt_files])
        emit(phase="sim", step=job.n_sim_frames, total=job.n_sim_frames)
    else:
        def on_frame(frame: int, verts: np.ndarray) -> None:
            if frame > job.settle_frames:
                recorded.append(verts)
            emit(phase="sim", step=frame, total=job.n_sim_frames)

        simulate(handles, on_frame)
        gt = np.stack(recorded)
        write_meshes(seq_dir / GT_GARMENT, names, gt, arrays["garment_faces"])
    timings["simulate_s"] = time.perf_counter() - start
    timings["resumed_simulation"] = len(recorded) == 0

    if not render_views:
        emit(phase="done", timings=timings)
        return
    replay_garment(handles, gt, first_frame=job.settle_frames + 1)
    todo = [(i, cid) for i, name in enumerate(names) for cid in handles.cameras if not views_done(seq_dir, cid, name)]
    total_views = len(names) * len(handles.cameras)
    done = total_views - len(todo)
    emit(phase="render", step=done, total=total_views)
    start = time.perf_counter()
    exr = workdir / "view.exr"
    for i, cid in todo:
        if handles.scene.frame_current != job.settle_frames + 1 + i:
            handles.scene.frame_set(job.settle_frames + 1 + i)
        render.render_view(handles.scene, handles.cameras[cid], exr)
        write_views(seq_dir, cid, names[i], read_views(exr))
        done += 1
        emit(phase="render", step=done, total=total_views)
    exr.unlink(missing_ok=True)
    timings["render_s"] = time.perf_counter() - start
    timings["rendered_views"] = len(todo)
    emit(phase="done", timings=timings)


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3) or sys.argv[2:] not in ([], ["--no-render"]):
        sys.exit("usage: python -m gg_core.synth.worker JOB.json [--no-render]")
    run(Path(sys.argv[1]), render_views=len(sys.argv) == 2)
