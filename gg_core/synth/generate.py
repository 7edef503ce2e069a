"""Orchestration of `gg synth`: tailor the garment, pose the body, run one bpy worker per sequence,
write truth.json and a report with timings and quality checks.

Resumable: a sequence whose job (settings + array digest) is unchanged keeps its simulation and the views
already rendered; a changed job clears that sequence's generated files first. Never imports bpy.
"""
from __future__ import annotations

import collections
import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..body.model import load_body
from ..body.motions import MOTIONS, animate
from ..capture.cameras import save_cameras
from ..capture.layout import IMAGE_KINDS
from ..errors import InputError
from ..geometry.meshio import write_obj
from ..jobs import Progress
from ..storage import write_json, write_npz, write_report
from .anchoring import bind
from .blender_frame import scene_gravity
from .effects import ResolvedEffect, region_names, resolve_effect
from .fabrics import FABRICS, Look, random_look
from .garments import Garment, tailor
from .job import GROUP_PREFIX, SequenceJob
from .presets import Preset
from .quality import capture_quality
from .rig import camera_dome, held_out_cameras, lights
from .worker import PREFIX
from .writer import GT_GARMENT, frame_name, write_meshes

WORK = ".synth"          # inputs of the workers (jobs, arrays, PC2 caches), kept for resuming
COLLISION = {"use_collision": True, "distance_min": 0.006, "use_self_collision": False,
             "self_distance_min": 0.005, "self_friction": 5.0}
BODY_COLLISION = {"thickness_outer": 0.006, "thickness_inner": 0.05, "cloth_friction": 5.0, "damping": 0.1}


@dataclass
class SynthRequest:
    preset: Preset
    out: Path
    seed: int = 0
    garment: str = "skirt"
    motions: list[str] = field(default_factory=list)
    effect: str = "none"
    effect_params: list[str] = field(default_factory=list)
    texture: str = "print"
    render: bool = True
    check: bool = True
    progress: str = "bar"


def generate(req: SynthRequest) -> Path:
    """Write the capture under `req.out`; return the report path."""
    start, cpu_start = time.perf_counter(), time.process_time() + _children_cpu_s()
    timings: dict[str, object] = {}
    preset = req.preset
    motions = req.motions or list(preset.motions)
    bad = [m for m in motions if m not in MOTIONS]
    if bad:
        raise InputError(f"unknown motion '{bad[0]}'", "--motions", f"choose from: {', '.join(MOTIONS)}")
    n_seq = max(preset.n_sequences, len(req.motions))
    seq_motions = [motions[k % len(motions)] for k in range(n_seq)]
    rng = np.random.default_rng(req.seed)
    look = random_look(rng, req.texture)
    cameras = camera_dome(preset, rng)
    studio = lights(rng)

    t0 = time.perf_counter()
    body = load_body()
    garment = tailor(body, req.garment, preset.garment_vertices)
    timings["tailor_s"] = time.perf_counter() - t0
    physics = _physics(req, preset, garment)
    effect = physics.effect

    out = Path(req.out)
    out.mkdir(parents=True, exist_ok=True)
    names = [f"{k:02d}_{m}" for k, m in enumerate(seq_motions)]
    _remove_stale_sequences(out, names)
    write_obj(out / "gt" / "template.obj", garment.vertices, garment.faces, garment.uvs, garment.face_uvs)
    write_npz(out / "gt" / "regions.npz", **garment.regions)
    collider_faces = body.faces[~body.hand_mask[body.faces].any(axis=1)]
    anchors = bind(body.rest_vertices.astype(np.float64), body.faces, garment.vertices)

    per_view = preset.n_frames * len(cameras) if req.render else 0
    progress = Progress("synth", n_seq * (preset.settle_frames + preset.n_frames + per_view), req.progress)
    seq_timings = {}
    for k, (name, motion) in enumerate(zip(names, seq_motions)):
        t0 = time.perf_counter()
        frames = animate(body, motion, preset.n_frames, preset.fps, seed=req.seed + k,
                         settle_frames=preset.settle_frames).astype(np.float64)
        seq_dir = out / name
        frame_names = [frame_name(i) for i in range(preset.n_frames)]
        arrays = {"body_frames": frames, "body_faces": body.faces, "collider_faces": collider_faces,
                  "garment_rest": garment.vertices, "garment_faces": garment.faces, "garment_uvs": garment.uvs,
                  "garment_face_uvs": garment.face_uvs, "garment_targets": anchors.apply(frames),
                  **{GROUP_PREFIX + r: w for r, w in garment.regions.items()}}
        work = out / WORK / name
        job = SequenceJob(
            sequence=name, seq_dir=str(seq_dir.resolve()), arrays=str((work / "arrays.npz").resolve()),
            arrays_digest=_digest(arrays), settle_frames=preset.settle_frames, frame_names=frame_names,
            fps=preset.fps, cloth=physics.cloth, cloth_collision=physics.collision,
            body_collision=physics.body_collision,
            scene_gravity=scene_gravity(physics.gravity, preset.fps),
            force_fields=effect.blender.get("force_fields", []),
            cloth_vertex_groups=effect.blender.get("vertex_groups", {}),
            cameras={cid: c.to_json() for cid, c in cameras.items()}, lights=studio, look=look.to_json(),
            uv_scale=garment.uv_scale,
            render={"samples": preset.samples, "denoise": preset.denoise, "seed": req.seed})
        resumed = _prepare(job, work, seq_dir)
        if not (work / "arrays.npz").is_file():
            write_npz(work / "arrays.npz", **arrays)
        # a resumed sequence keeps its files untouched: later stages key their results on file times
        if not (resumed and (seq_dir / "cameras.json").is_file()):
            save_cameras(seq_dir / "cameras.json", cameras)
        if not (resumed and all((seq_dir / "body" / f"{n}.ply").is_file() for n in frame_names)):
            write_meshes(seq_dir / "body", frame_names, frames[preset.settle_frames:], body.faces)
        job.save(work / "job.json")
        seq_timings[name] = _run_worker(work / "job.json", progress, render=req.render)
        seq_timings[name]["total_s"] = time.perf_counter() - t0

    timings["sequences"] = seq_timings
    timings["generation_s"] = time.perf_counter() - start
    timings["generation_cpu_s"] = time.process_time() + _children_cpu_s() - cpu_start
    truth = _truth(req, preset, garment, physics, look, names, seq_motions, list(cameras), timings)
    write_json(out / "truth.json", truth)
    report: dict[str, object] = {"preset": preset.name, "seed": req.seed, "garment": garment.name,
                                 "effect": effect.to_json(), "timings": timings}
    if req.render and req.check:
        t0 = time.perf_counter()
        report["quality"] = capture_quality(out, collider_faces)
        timings["quality_s"] = time.perf_counter() - t0
    path = write_report(out, "synth", report)
    progress.done(str(path))
    return path


@dataclass
class _Physics:
    """Everything Blender's solver gets: cloth material, collisions, gravity, and the hidden effect."""

    effect: ResolvedEffect
    cloth: dict
    collision: dict
    body_collision: dict
    gravity: list[float]


def _physics(req: SynthRequest, preset: Preset, garment: Garment) -> _Physics:
    cloth = FABRICS[garment.fabric].cloth_settings()
    cloth.update(quality=preset.cloth_quality, pin_stiffness=1.0)
    effect = resolve_effect(req.effect, req.effect_params, cloth)
    missing = region_names(effect) - set(garment.regions)
    if missing:
        raise InputError(f"garment '{garment.name}' has no region '{sorted(missing)[0]}'", "--effect-param region=",
                         f"choose one of: {', '.join(sorted(garment.regions))}")
    cloth.update(effect.blender.get("cloth", {}))
    return _Physics(effect, cloth,
                    dict(COLLISION, collision_quality=preset.collision_quality,
                         use_self_collision=preset.self_collision),
                    dict(BODY_COLLISION, **effect.blender.get("body_collision", {})),
                    list(effect.blender.get("gravity", [0.0, -9.81, 0.0])))


def _remove_stale_sequences(out: Path, names: list[str]) -> None:
    """Sequences an earlier run generated here under other names (other motions or count) would linger."""
    work = out / WORK
    for folder in sorted(work.iterdir()) if work.is_dir() else []:
        if folder.name not in names:
            shutil.rmtree(out / folder.name, ignore_errors=True)
            shutil.rmtree(folder)


def _digest(arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h.update(key.encode() + str(a.dtype).encode() + str(a.shape).encode() + a.tobytes())
    return h.hexdigest()


def _prepare(job: SequenceJob, work: Path, seq_dir: Path) -> bool:
    """Keep a sequence's finished work only if it was made by exactly this job (True), else clear it (False)."""
    saved = work / "job.json"
    if saved.is_file() and _resume_key(json.loads(saved.read_text())) == _resume_key(job.to_json()):
        return True
    if work.exists():
        shutil.rmtree(work)
    for sub in [seq_dir / GT_GARMENT, seq_dir / "body"] + [seq_dir / cid / kind for cid in job.cameras
                                                           for kind in IMAGE_KINDS]:
        if sub.exists():
            shutil.rmtree(sub)
    return False


def _resume_key(job: dict) -> str:
    """The job without its absolute paths, so a moved or copied capture still resumes."""
    return json.dumps({k: v for k, v in job.items() if k not in ("seq_dir", "arrays")}, sort_keys=True)


def _run_worker(job_path: Path, progress: Progress, render: bool) -> dict:
    """Run the bpy worker on one sequence, relaying its progress lines; return its timings."""
    # gg_core only uses relative imports, so it imports as a top-level package from its parent folder
    # even when it is loaded as a subpackage of the Blender extension
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]))
    cmd = [sys.executable, "-m", "gg_core.synth.worker", str(job_path)] + ([] if render else ["--no-render"])
    tail: collections.deque[str] = collections.deque(maxlen=40)
    steps = {"sim": 0, "render": 0}
    cpu_before = _children_cpu_s()
    timings: dict = {}
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                          preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None) as proc:
        try:
            for line in proc.stdout:
                if not line.startswith(PREFIX):
                    tail.append(line.rstrip())
                    continue
                msg = json.loads(line[len(PREFIX):])
                if msg["phase"] == "done":
                    timings = msg["timings"]
                    continue
                delta = msg["step"] - steps[msg["phase"]]
                steps[msg["phase"]] = msg["step"]
                if delta > 0:
                    progress.step(f"{job_path.parent.name}: {msg['phase']} {msg['step']}/{msg['total']}", delta)
        except BaseException:
            proc.kill()
            raise
    if proc.returncode != 0:
        raise RuntimeError(f"synth worker failed on {job_path} (exit {proc.returncode}):\n" + "\n".join(tail))
    timings["worker_cpu_s"] = _children_cpu_s() - cpu_before   # wall time depends on other load; CPU time less
    return timings


def _children_cpu_s() -> float:
    import resource  # noqa: PLC0415 - POSIX only, like the worker's death signal

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _die_with_parent() -> None:
    """Linux: the worker gets SIGTERM when the gg process dies (a job runner's cancel kills only gg)."""
    import ctypes  # noqa: PLC0415
    import signal  # noqa: PLC0415

    ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # 1 = PR_SET_PDEATHSIG


def _truth(req: SynthRequest, preset: Preset, garment: Garment, physics: _Physics, look: Look, names: list[str],
           motions: list[str], camera_ids: list[str], timings: dict) -> dict:
    held_seq = names[-1:] if len(names) > 1 else []
    held_cam = held_out_cameras(camera_ids)
    return {
        "generator": "gg synth (Blender cloth modifier + Cycles)",
        "preset": preset.to_json(),
        "seed": req.seed,
        "garment": {"name": garment.name, "vertices": len(garment.vertices), "faces": len(garment.faces),
                    "area_m2": garment.area, "template": "gt/template.obj", "regions": "gt/regions.npz",
                    "region_vertices": {k: int((v > 0).sum()) for k, v in garment.regions.items()},
                    "pinned_vertices": np.flatnonzero(garment.regions.get("pin", np.zeros(0)) > 0).tolist(),
                    "look": look.to_json(), "uv_scale_m": garment.uv_scale},
        "material": {"fabric": garment.fabric, "blender_cloth": physics.cloth,
                     "blender_cloth_collision": physics.collision, "blender_body_collision": physics.body_collision,
                     "gravity": physics.gravity,
                     "blender_scene_gravity": scene_gravity(physics.gravity, preset.fps),
                     "collider": "body mesh without the hands"},
        "effect": physics.effect.to_json(),
        "sequences": {n: {"motion": m, "motion_seed": req.seed + k, "frames": preset.n_frames,
                          "settle_frames": preset.settle_frames, "fps": preset.fps}
                      for k, (n, m) in enumerate(zip(names, motions))},
        "split": {"train_sequences": [n for n in names if n not in held_seq], "heldout_sequences": held_seq,
                  "train_cameras": [c for c in camera_ids if c not in held_cam], "heldout_cameras": held_cam},
        "timings": timings,
    }
