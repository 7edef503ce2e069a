"""Stage 2 (register): the template mesh fitted to every frame of every sequence, with fixed topology.

Inputs: stage 1's <project>/stage1/template.obj and gaussians.npz (and reports/template.json, which names the
template frame), and per sequence the cameras, images, masks and body meshes. Per sequence the template is
first aligned rigidly to the first frame (--align): "body" moves it with the rigid motion of the body part
under it from the template frame to that frame; "icp" then refines that by ICP against a point cloud of the
frame reconstructed from its masks (stage 1's geometry code); "none" keeps the template where it is. Then every
frame is fitted by the tracker (registration.tracker), warm-started with a constant-velocity prediction from
the previous two frames; then the sequence's fits are refined by the stereo step (registration.stereo, which
compares neighbouring frames' evidence) and each vertex's trajectory is filtered in time (registration.temporal).

Outputs: <project>/stage2/<sequence>/meshes/<frame>.ply (template topology; each frame's own result before the
temporal filter in refined/<frame>.ply, its photometric fit in fit/<frame>.ply), renders for inspection
(<project>/stage2/<sequence>/renders/<frame>.png: target | render | difference for one camera),
<project>/stage2/<sequence>/frames.json (per-frame logs and input keys) and <project>/reports/register.json
with per sequence cd_cm, p2m_cm, fscore_1cm (only when the capture has ground-truth meshes), l_body (the
body term's value on the final meshes, mean over frames), s_per_frame (wall clock of the fit and of the
frame's share of the stereo step) and cpu_s_per_frame, and over all sequences wall_s_per_frame (the tracking's
wall clock over the frames: sequences are registered at once, one single-threaded process each,
gg_core/parallel.py). Ground truth is read only to score finished meshes.

Resumable per frame: a frame's fit is kept when its fit mesh exists and its key (stage 1 files, the options the
fits depend on, the frame's input files and the previous frame's key) is unchanged; changing one frame refits the
frames after it. The stereo step (about a fifth of the time) and the temporal filter (seconds) rerun over the whole
sequence whenever a fit or their own settings changed, or one of their meshes is missing; new stereo or filter
settings keep the fits.
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..capture.layout import FOREGROUND_MASK, GARMENT_MASK, RGB, Capture, Sequence
from ..errors import InputError
from ..geometry.meshio import read_mesh, read_obj, write_ply
from ..jobs import Progress
from ..parallel import check_workers, run_jobs, worker_count
from ..storage import atomic_path, file_stamps, write_json, write_npz, write_report

if TYPE_CHECKING:   # numba kernels and torch are imported when a stage runs, not with the CLI
    from ..reconstruction.photo_consistency import PhotoOptions
    from ..registration.tracker import TrackerConfig

STAGE = "register"
ICP_CLOUD_VERTICES = 2000    # points of the first frame's reconstruction that ICP aligns to
ALIGN_MODES = ("body", "icp", "none")
MIN_ATLAS = 32               # coarsest Gaussian texture side registration uses
REFIT_RATE_SCALE = 2.0       # learning rates of the registration texture's refit, times the appearance fit's


@dataclass
class RegisterRequest:
    capture: Path
    project: Path
    sequences: list[str] = field(default_factory=list)   # default: all
    ablation: str = "full"
    iterations: int | None = None        # per frame (default: the tracker's); the first frame gets 8/3 as many
    frames: int | None = None            # register only the first N frames of each sequence
    align: str = "body"                  # first-frame alignment: body | icp | none
    icp_scale: bool = False              # let ICP scale the template too
    texture_factor: int | None = None    # coarsen the Gaussian texture by this factor (None: automatic, 1: none)
    texture_refit: int = 1250            # appearance steps refitting a coarsened texture on the template frame
    renders: int = 3                     # frames per sequence rendered for inspection
    seed: int = 0
    workers: int | None = None           # sequences registered at once, one process each (None: one per core)
    progress: str = "bar"


@dataclass
class Stage1:
    verts: np.ndarray
    faces: np.ndarray
    texture: object                      # GaussianTexture
    files: list


def load_stage1(project: Path) -> Stage1:
    """The template and its Gaussian texture; InputError when stage 1 has not run or its files disagree."""
    from ..gaussians.texture import GaussianTexture  # noqa: PLC0415 - torch

    obj, gauss = project / "stage1" / "template.obj", project / "stage1" / "gaussians.npz"
    for path in (obj, gauss):
        if not path.is_file():
            raise InputError("stage 1 output missing", path, "run gg template first")
    verts, faces, _, _ = read_obj(obj)
    try:
        texture = GaussianTexture.load(gauss)
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"gaussians.npz cannot be read ({exc.__class__.__name__})", gauss,
                         "run gg template again") from None
    if len(faces) == 0 or (len(texture) and int(texture.face_ids.max()) >= len(faces)) or \
            (texture.face_uvs is not None and len(texture.face_uvs) != len(faces)):
        raise InputError(f"template topology mismatch: gaussians.npz binds to {_face_count(texture)} faces, "
                         f"template.obj has {len(faces)}", project / "stage1",
                         "run gg template again so both files come from one run")
    files = file_stamps((obj, gauss))
    return Stage1(verts, faces, texture, files)


def _face_count(texture) -> int:
    return len(texture.face_uvs) if texture.face_uvs is not None else int(texture.face_ids.max()) + 1


def check_sequence(seq: Sequence, frames: list[str]) -> None:
    """Every frame needs a body mesh (occluder and collider); fail before any work."""
    missing = [f for f in frames if f not in seq.body_files]
    if missing:
        raise InputError(f"body mesh missing for frame '{missing[0]}'" +
                         (f" and {len(missing) - 1} more" if len(missing) > 1 else ""), seq.root / "body",
                         "add <sequence>/body/<frame>.ply for every frame (names must match the image frames)")


def frame_files(seq: Sequence, frame: str) -> list:
    paths = [seq.root / "cameras.json", seq.body_path(frame)]
    for cid in seq.camera_ids:
        paths += [seq.image_path(cid, frame, kind) for kind in (RGB, GARMENT_MASK, FOREGROUND_MASK)]
    return file_stamps(paths, seq.root)


def _digest(obj: object) -> str:
    return hashlib.sha1(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def first_frame_cloud(seq: Sequence, frame: str) -> np.ndarray:
    """Points of the garment's surface in `frame`, reconstructed from its masks (stage 1's geometry code)."""
    from ..capture.images import read_mask  # noqa: PLC0415
    from ..reconstruction.template_mesh import TemplateGeometryOptions, reconstruct_template  # noqa: PLC0415

    cams = [seq.cameras[c] for c in seq.camera_ids]
    garment = [read_mask(seq.image_path(c, frame, GARMENT_MASK)) for c in seq.camera_ids]
    foreground = [read_mask(seq.image_path(c, frame, FOREGROUND_MASK)) for c in seq.camera_ids]
    try:
        geometry = reconstruct_template(cams, foreground, garment,
                                        options=TemplateGeometryOptions(vertices=ICP_CLOUD_VERTICES, photo=None))
    except ValueError as exc:
        raise InputError(f"cannot reconstruct the first frame '{frame}' for alignment ({exc})", seq.root,
                         "check the garment and foreground masks of that frame") from None
    return geometry.verts


def texture_factor(texture, views) -> int:
    """How much the stage 1 texture can be coarsened for registration: the largest power of two that keeps at
    least one Gaussian per garment pixel (about half of the garment faces a camera). Measured on the demo
    capture: the 42k-Gaussian texture halved to 10.5k gives the same CD (0.35 cm after 100 steps on frame 4)
    in half the time."""
    if texture.texels is None:
        return 1
    pixels = float(np.mean([float(v.garment.sum()) for v in views]))
    factor = 1
    while texture.resolution // (2 * factor) >= MIN_ATLAS and len(texture) / (2 * factor) ** 2 / 2 >= pixels:
        factor *= 2
    return factor


def registration_texture(capture: Capture, project: Path, stage1: Stage1, factor: int, refit: int,
                         progress: Progress | None = None) -> tuple:
    """(The Gaussian texture registration renders, a log): stage 1's coarsened by `factor` and, when coarsened,
    refitted for `refit` appearance steps on the template's own frame with the template mesh. The refitted
    texture is kept in <project>/stage2/texture.npz with the key of what it was made from, so a re-run reuses it.
    `progress` advances by `refit` steps when the factor is above 1, whether the refit runs, is reused or skipped.

    Averaging blocks of texels leaves the coarse Gaussians half transparent and blurred (demo capture: mean
    alpha 0.88 on garment pixels, L_rgb 0.0086 on the template frame vs 0.0034 for stage 1's texture), and the
    tracker moves the mesh to explain what the texture gets wrong: fitted from the 0.525 cm template on its own
    frame with L_rgb alone, the mesh drifts to 0.604 cm; after 300 / 1000 / 2500 refit steps (L_rgb 0.0036 /
    0.0023 / 0.0013) to 0.592 / 0.550 / 0.527 cm. Demo capture, 3 x 30 frames, CD / p2m / F@1cm: no refit 0.64 /
    0.59 cm / 81.8 %, 300 steps 0.60 / 0.55 cm / 85.9 %, 2500 steps 0.57 / 0.52 cm / 84.1 % (walk alone with 1000:
    0.60 / 0.55 / 84.2 %, between the two). More steps trade F@1cm for CD: the sharper texture holds the mesh
    closer everywhere except along the hem, which the template cuts 1.4 cm too high. 2500 steps cost about 100 s
    once per run; 1250 at REFIT_RATE_SCALE times the appearance fit's learning rates reach the same L_rgb (0.00134
    vs 0.00130) and the same fit of the template frame (0.525 vs 0.526 cm, walk frame 0 from the template) in half
    the time.
    """
    from ..registration.appearance import AppearanceConfig, downsample_texture, fit_appearance  # noqa: PLC0415
    from ..registration.views import load_body, load_views  # noqa: PLC0415

    texture = downsample_texture(stage1.texture, stage1.verts, stage1.faces, factor)
    source = template_frame(capture, project)
    if factor == 1 or refit == 0 or source is None:
        if progress is not None and factor > 1 and refit > 0:
            progress.step("registration texture: template frame unknown, not refitted", advance=refit)
        return texture, {"steps": 0, "reason": "not coarsened" if factor == 1 else
                         "refit off" if refit == 0 else "template frame unknown"}
    from ..gaussians.texture import GaussianTexture  # noqa: PLC0415 - torch

    seq, frame = source
    key = _digest([stage1.files, factor, refit, REFIT_RATE_SCALE, seq.name, frame, frame_files(seq, frame)])
    path, log_path = project / "stage2" / "texture.npz", project / "stage2" / "texture.json"
    if path.is_file() and log_path.is_file():
        log = json.loads(log_path.read_text())
        if log.get("key") == key:
            if progress is not None:
                progress.step("registration texture: refitted earlier, reused", advance=refit)
            return GaussianTexture.load(path), {**log, "reused": True}
    views = load_views(seq, frame, body=load_body(seq, frame))
    texture, fit = fit_appearance(texture, stage1.verts, stage1.faces, views, refit, progress,
                                  config=AppearanceConfig(init_colors=False).rates_scaled(REFIT_RATE_SCALE))
    log = {"key": key, "steps": refit, "frame": f"{seq.name}/{frame}", "rgb_loss_before": fit["rgb_loss_before"],
           "rgb_loss_after": fit["rgb_loss_after"], "seconds": fit["seconds"]}
    write_npz(path, **texture.state())
    write_json(log_path, log)
    return texture, log


def template_frame(capture: Capture, project: Path) -> tuple[Sequence, str] | None:
    """The (sequence, frame) stage 1 reconstructed the template from, per its report (None if unknown)."""
    path = project / "reports" / "template.json"
    if not path.is_file():
        return None
    try:
        report = json.loads(path.read_text())
        seq = capture.sequences.get(report.get("sequence"))
    except (json.JSONDecodeError, AttributeError):
        return None
    frame = report.get("frame")
    return (seq, frame) if seq is not None and frame in seq.body_files else None


def align_first_frame(capture: Capture, project: Path, seq: Sequence, frame: str, template: np.ndarray,
                      body: np.ndarray, mode: str, scale: bool) -> tuple[np.ndarray, dict]:
    """The template's vertices aligned to `frame` (the first of `seq`) and a log of how."""
    from ..registration.icp import Similarity, body_alignment, icp  # noqa: PLC0415

    start = time.perf_counter()
    log: dict = {"mode": mode}
    motion = Similarity()
    if mode in ("body", "icp"):
        source = template_frame(capture, project)
        if source is not None:
            source_body = read_mesh(source[0].body_path(source[1]))[0]
            if source_body.shape == body.shape:
                motion = body_alignment(template, source_body, body)
                log["from"] = f"{source[0].name}/{source[1]}"
        log["body_rotation_deg"] = float(np.degrees(np.arccos(np.clip((np.trace(motion.R) - 1) / 2, -1, 1))))
        log["body_translation_m"] = motion.t.tolist()
    if mode == "icp":
        cloud = first_frame_cloud(seq, frame)
        motion, icp_log = icp(template, cloud, init=motion, scale=scale)
        log.update(icp_rms_m=icp_log["rms"][-1], icp_iterations=icp_log["iterations"], scale=motion.s)
    log["seconds"] = time.perf_counter() - start
    return motion.apply(template), log


def run_register(req: RegisterRequest) -> Path:
    from ..registration.tracker import TrackerConfig, ablation_config  # noqa: PLC0415
    from ..registration.views import load_views  # noqa: PLC0415

    start = time.perf_counter()
    capture = Capture(req.capture)
    project = Path(req.project)
    stage1 = load_stage1(project)
    names = list(req.sequences) or list(capture.sequences)
    seqs = [capture.sequence(n) for n in names]
    if req.frames is not None and req.frames < 1:
        raise InputError(f"--frames must be at least 1, got {req.frames}", "--frames", "pass a positive count")
    frames_of = {s.name: s.frames[: req.frames] if req.frames else s.frames for s in seqs}
    for s in seqs:
        if not frames_of[s.name]:
            raise InputError("the sequence has no frames", s.root, "add rgb_images/<frame>.png for every camera")
        check_sequence(s, frames_of[s.name])
    base = TrackerConfig(seed=req.seed)
    if req.iterations is not None:
        if req.iterations < 1:
            raise InputError(f"--iterations must be at least 1, got {req.iterations}", "--iterations",
                             "pass a positive count")
        base = TrackerConfig(iterations=req.iterations, first_iterations=max(1, req.iterations * 8 // 3),
                             seed=req.seed)
    check_workers(req.workers)
    if req.align not in ALIGN_MODES:
        raise InputError(f"unknown alignment '{req.align}'", "--align", f"choose one of {', '.join(ALIGN_MODES)}")
    try:
        config = ablation_config(req.ablation, base)
    except ValueError as exc:
        raise InputError(str(exc), "--ablation", "choose full, only-rgb, no-body or body-always") from None
    first = seqs[0]
    if req.texture_factor is not None and (req.texture_factor < 1 or req.texture_factor & (req.texture_factor - 1)):
        raise InputError(f"--texture-factor must be a power of two, got {req.texture_factor}", "--texture-factor",
                         "pass 1 (the stage 1 texture as it is), 2, 4, ...")
    if req.texture_refit < 0:
        raise InputError(f"--texture-refit must be 0 or more, got {req.texture_refit}", "--texture-refit",
                         "pass 0 (no refit) or a step count such as 300")
    factor = req.texture_factor or texture_factor(stage1.texture, load_views(first, frames_of[first.name][0]))
    options = {"config": asdict(config), "ablation": req.ablation, "align": req.align, "icp_scale": req.icp_scale,
               "texture_factor": factor, "texture_refit": req.texture_refit}
    progress = Progress(STAGE, sum(2 * len(f) + 2 for f in frames_of.values()) + 1 +
                        (req.texture_refit if factor > 1 else 0), req.progress)
    texture, refit_log = registration_texture(capture, project, stage1, factor, req.texture_refit, progress)
    progress.step(f"registration texture: 1/{factor} resolution" + (
        f", refitted: L_rgb {refit_log['rgb_loss_before']:.4f} -> {refit_log['rgb_loss_after']:.4f}"
        if refit_log["steps"] else ""))
    state = texture.state()
    jobs = [SequenceJob(req.capture, project, s.name, frames_of[s.name], state, config, options, req.align,
                        req.icp_scale, req.renders) for s in seqs]
    workers = worker_count(req.workers, len(jobs))
    tracking = time.perf_counter()
    report = dict(zip(names, run_jobs(register_sequence, jobs, workers, progress, then=refine_next)))
    tracked_frames = sum(len(f) for f in frames_of.values())
    mean = {**_mean_metrics(report), "wall_s_per_frame": (time.perf_counter() - tracking) / tracked_frames}
    payload = {"ablation": req.ablation, "sequences": report, "mean": mean,
               "template": {"vertices": len(stage1.verts), "faces": len(stage1.faces),
                            "gaussians": len(stage1.texture), "texture_factor": factor,
                            "registration_gaussians": len(texture), "texture_refit": refit_log},
               "tracker": asdict(config), "workers": min(workers, len(jobs)),
               "seconds": time.perf_counter() - start,
               "inputs": {"stage1": stage1.files, "options": options}}
    path = write_report(project, STAGE, payload)
    progress.done(str(path))
    return path


@dataclass
class SequenceJob:
    """One sequence's registration: everything a worker process needs (it loads stage 1 itself)."""
    capture: Path
    project: Path
    sequence: str
    frames: list[str]
    texture: dict                        # the registration texture's state (GaussianTexture.from_state)
    config: object                       # TrackerConfig
    options: dict                        # what the frames' keys are made of
    align: str
    icp_scale: bool
    renders: int
    phase: str = "fit"                   # "fit", then "refine" (stereo, temporal filter, report, renders)


def register_sequence(job: SequenceJob, step) -> dict | None:
    """One phase of a sequence's registration. "fit": fit every frame (resuming unchanged frames); "refine":
    refine the fits by stereo, filter them in time, write the meshes, renders and the sequence's report entry,
    which it returns. `step(message, advance)` reports progress. Two phases so that a worker done fitting can
    refine another sequence while the last one is still being fitted (refine_next)."""
    from ..physics.contact import BodyCollider  # noqa: PLC0415
    from ..registration.views import load_body  # noqa: PLC0415
    from .behavior import hand_mask  # noqa: PLC0415

    capture, stage1 = Capture(job.capture), load_stage1(job.project)
    seq = capture.sequence(job.sequence)
    out_dir = job.project / "stage2" / seq.name
    log_path = out_dir / "frames.json"
    logs = json.loads(log_path.read_text()) if log_path.is_file() else {}
    body0 = load_body(seq, job.frames[0])
    collider = BodyCollider(body0[1], len(body0[0]), exclude=hand_mask(len(body0[0])))
    if job.phase == "fit":
        _fit_frames(job, capture, stage1, seq, collider, logs, log_path, step)
        return None
    return _refine_and_report(job, stage1, seq, collider, logs, log_path, step)


def refine_next(job: SequenceJob, result: dict | None) -> SequenceJob | None:
    """The follow-up of a sequence's fit phase (parallel.run_jobs `then`): its refine phase."""
    return replace(job, phase="refine") if job.phase == "fit" else None


def _fit_frames(job: SequenceJob, capture: Capture, stage1: Stage1, seq: Sequence, collider, logs: dict,
                log_path: Path, step) -> None:
    """Fits every frame into fit/<frame>.ply, keeping those whose key is unchanged; logs["_fits"] becomes the
    last frame's key, which chains every frame's."""
    from ..gaussians.texture import GaussianTexture  # noqa: PLC0415 - torch
    from ..registration.tracker import Tracker  # noqa: PLC0415
    from ..registration.views import load_body, load_views  # noqa: PLC0415

    frames, config, out_dir = job.frames, job.config, log_path.parent
    tracker = Tracker(GaussianTexture.from_state(job.texture), stage1.verts, stage1.faces, collider, config)
    key = _digest([stage1.files, _settings(job.options)["fit"], seq.name])
    previous: list[np.ndarray] = []
    align_log: dict = logs.get("_alignment", {})
    for k, frame in enumerate(frames):
        key = _digest([key, frame, frame_files(seq, frame)])
        fit_path = out_dir / "fit" / f"{frame}.ply"
        if fit_path.is_file() and logs.get(frame, {}).get("key") == key:
            previous = (previous + [read_mesh(fit_path)[0]])[-2:]
            step(f"{seq.name} {frame}: unchanged, kept", 2 if k == 0 else 1)
            continue
        body = load_body(seq, frame)
        views = load_views(seq, frame, body=body)
        if k == 0:
            guess, align_log = align_first_frame(capture, job.project, seq, frame, stage1.verts, body[0],
                                                 job.align, job.icp_scale)
            step(f"{seq.name}: aligned the template ({job.align})")
            iterations = config.first_iterations
        else:
            guess = previous[-1] if len(previous) < 2 else 2 * previous[-1] - previous[-2]
            iterations = config.iterations
        result = tracker.fit_frame(guess, views, body[0], previous=previous[-1] if previous else None,
                                   iterations=iterations)
        write_ply(fit_path, result.verts, stage1.faces)
        previous = (previous + [result.verts])[-2:]
        logs[frame] = {"key": key, **{k2: v for k2, v in result.log.items() if k2 != "trace"}}
        logs["_alignment"] = align_log
        write_json(log_path, logs)
        step(f"{seq.name} {frame}: {result.log['iterations']} iterations, {result.log['seconds']:.1f} s")
    logs["_fits"] = key
    write_json(log_path, logs)


def _refine_and_report(job: SequenceJob, stage1: Stage1, seq: Sequence, collider, logs: dict, log_path: Path,
                       step) -> dict:
    """Stereo over the fits and the temporal filter, each rerun when the fits or its settings changed; then the
    sequence's report entry and renders."""
    from ..metrics.surface import surface_metrics  # noqa: PLC0415

    frames, config, out_dir = job.frames, job.config, log_path.parent
    settings = _settings(job.options)
    key = _digest([logs["_fits"], settings["stereo"]])
    if logs.get("_stereo") != key or not _all_written(out_dir / "refined", frames):
        refine_sequence(seq, frames, out_dir, stage1.faces, config, collider, logs, step)
        logs["_stereo"] = key
        write_json(log_path, logs)
    else:
        step(f"{seq.name}: stereo unchanged, kept", len(frames))
    key = _digest([key, settings["temporal"]])
    if logs.get("_temporal") != key or not _all_written(out_dir / "meshes", frames):
        smooth_sequence(seq, frames, out_dir, stage1.faces, config, collider, logs)
        logs["_temporal"] = key
        write_json(log_path, logs)
    step(f"{seq.name}: temporal filter over {config.smooth_window} frames")
    report = sequence_report(seq, frames, logs, stage1.faces, out_dir, surface_metrics)
    report["alignment"] = logs.get("_alignment", {})
    _write_renders(seq, frames, out_dir, stage1, job.renders)
    return report


def _all_written(folder: Path, frames: list[str]) -> bool:
    return all((folder / f"{f}.ply").is_file() for f in frames)


def _settings(options: dict) -> dict[str, dict]:
    """The options split by the step they change: the fits, the stereo step, the temporal filter; so that new
    stereo or filter settings keep the fits (the slow part)."""
    config = options["config"]
    later = {name: {k: v for k, v in config.items() if k.startswith(f"{name}_")} for name in ("stereo", "smooth")}
    fit_config = {k: v for k, v in config.items() if not k.startswith(("stereo_", "smooth_"))}
    return {"fit": {**options, "config": fit_config}, "stereo": later["stereo"], "temporal": later["smooth"]}


def refine_sequence(seq: Sequence, frames: list[str], out_dir: Path, faces: np.ndarray, config, collider,
                    logs: dict, step) -> None:
    """Writes refined/<frame>.ply: the fits refined by the stereo step (registration.stereo), pushed out of each
    frame's body; each frame's log gets the step's ("stereo"). No rounds: the fits as they are."""
    import torch  # noqa: PLC0415

    from ..registration.losses import BodyTerm  # noqa: PLC0415
    from ..registration.stereo import stereo_sequence  # noqa: PLC0415
    from ..registration.tracker import pushed_out  # noqa: PLC0415
    from ..registration.views import load_body, load_views  # noqa: PLC0415

    fits = [read_mesh(out_dir / "fit" / f"{frame}.ply")[0] for frame in frames]
    bodies: dict[int, np.ndarray] = {}

    def load(t: int):
        body = load_body(seq, frames[t])
        bodies[t] = body[0]
        return load_views(seq, frames[t], body=body), (body[0], collider.faces)

    def done(t: int, verts: np.ndarray, log: dict) -> None:
        body = bodies.pop(t) if t in bodies else load_body(seq, frames[t])[0]
        x = torch.from_numpy(verts)
        if config.w_body > 0:
            x = pushed_out(x, BodyTerm(collider, body))
        write_ply(out_dir / "refined" / f"{frames[t]}.ply", x.numpy(), faces)
        logs[frames[t]]["stereo"] = log
        step(f"{seq.name} {frames[t]}: stereo, {log['seconds']:.1f} s")

    if config.stereo_rounds == 0:
        for t, verts in enumerate(fits):
            done(t, verts, {"rounds": [], "seconds": 0.0, "cpu_seconds": 0.0})
        return
    stereo_sequence(fits, faces, load, stereo_options(config), config.stereo_frames, done)


def stereo_options(config: TrackerConfig) -> PhotoOptions:
    """The photo-consistency options of the stereo step from a TrackerConfig's stereo_* settings."""
    from ..reconstruction.photo_consistency import PhotoOptions  # noqa: PLC0415

    return PhotoOptions(search_in=config.stereo_search, search_out=config.stereo_search,
                        rounds=config.stereo_rounds, stiffness=config.stereo_stiffness,
                        aggregate=config.stereo_aggregate, curvature_gain=config.stereo_curvature_gain,
                        weighting=config.stereo_weighting, normal_smoothing=config.stereo_normal_smoothing)


def smooth_sequence(seq: Sequence, frames: list[str], out_dir: Path, faces: np.ndarray, config, collider,
                    logs: dict) -> None:
    """Writes meshes/<frame>.ply: the refined frames' vertex trajectories filtered over time
    (registration.temporal), pushed out of each frame's body again; logs' l_body becomes the final meshes'."""
    import torch  # noqa: PLC0415

    from ..registration.losses import BodyTerm  # noqa: PLC0415
    from ..registration.temporal import smooth_trajectories  # noqa: PLC0415
    from ..registration.tracker import pushed_out  # noqa: PLC0415
    from ..registration.views import load_body  # noqa: PLC0415

    refined = np.stack([read_mesh(out_dir / "refined" / f"{frame}.ply")[0] for frame in frames])
    smoothed = smooth_trajectories(refined, config.smooth_window, config.smooth_order)
    for frame, verts in zip(frames, smoothed):
        body = BodyTerm(collider, load_body(seq, frame)[0])
        x = torch.from_numpy(verts)
        if config.w_body > 0:
            x = pushed_out(x, body)
        logs[frame]["l_body"] = float(body(x, body.contacts(x)))
        write_ply(out_dir / "meshes" / f"{frame}.ply", x.numpy(), faces)


def sequence_report(seq: Sequence, frames: list[str], logs: dict, faces: np.ndarray, out_dir: Path,
                    surface_metrics) -> dict:
    """Per-sequence means of the frame logs and, with ground truth, of the surface metrics per frame."""
    per_frame = []
    gt = seq.gt_garment_files
    for frame in frames:
        stereo = logs[frame].get("stereo", {})
        row = {"frame": frame, "l_body": logs[frame]["l_body"],
               "seconds": logs[frame]["seconds"] + stereo.get("seconds", 0.0),
               "cpu_seconds": logs[frame]["cpu_seconds"] + stereo.get("cpu_seconds", 0.0),
               "iterations": logs[frame]["iterations"]}
        if frame in gt:
            verts = read_mesh(out_dir / "meshes" / f"{frame}.ply")[0]
            gv, gf = read_mesh(gt[frame])
            row.update(surface_metrics(verts, faces, gv, gf))
        per_frame.append(row)
    out = {"frames": len(frames), "l_body": float(np.mean([r["l_body"] for r in per_frame])),
           "s_per_frame": float(np.mean([r["seconds"] for r in per_frame])),
           "cpu_s_per_frame": float(np.mean([r["cpu_seconds"] for r in per_frame]))}
    if all("cd_cm" in r for r in per_frame):
        out.update({k: float(np.mean([r[k] for r in per_frame])) for k in ("cd_cm", "p2m_cm", "fscore_1cm")})
    out["per_frame"] = per_frame
    return out


def _mean_metrics(report: dict) -> dict:
    keys = ("cd_cm", "p2m_cm", "fscore_1cm", "l_body", "s_per_frame", "cpu_s_per_frame")
    return {k: float(np.mean([r[k] for r in report.values()])) for k in keys
            if all(k in r for r in report.values())}


def _write_renders(seq: Sequence, frames: list[str], out_dir: Path, stage1: Stage1, count: int) -> None:
    """target | render | 3x difference of the camera that sees most of the garment, for `count` frames."""
    import torch  # noqa: PLC0415
    from PIL import Image  # noqa: PLC0415

    from ..registration.appearance import contrast_background  # noqa: PLC0415
    from ..registration.photometric import render_view  # noqa: PLC0415
    from ..registration.views import load_views  # noqa: PLC0415

    picks = sorted({frames[round(i * (len(frames) - 1) / max(count - 1, 1))] for i in range(count)}) if count else []
    for frame in picks:
        views = load_views(seq, frame)
        view = max(views, key=lambda v: float(v.garment.sum()))
        verts = torch.from_numpy(read_mesh(out_dir / "meshes" / f"{frame}.ply")[0]).float()
        bg = contrast_background(views)
        with torch.no_grad():
            image = render_view(stage1.texture, verts, stage1.faces, view, bg)["image"]
        target = view.target(bg)
        m = view.loss_mask[..., None]
        shown = image * m + target * (1 - m)
        row = torch.cat((target, shown, ((shown - target).abs() * 3).clamp(0, 1)), dim=1).numpy()
        with atomic_path(out_dir / "renders" / f"{frame}.png") as tmp:
            Image.fromarray((row * 255).round().astype(np.uint8)).save(tmp, format="PNG")
