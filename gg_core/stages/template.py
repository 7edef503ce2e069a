"""Stage 1 (template): the garment's mesh with a UV atlas and its initial Gaussian appearance, from one frame.

Inputs: one frame of one sequence (default: the first of each), its cameras, RGB images, garment and
foreground masks, and the body mesh (an occluder of the Gaussians in the appearance fit). Ground truth, when
the capture has it, is read only after the reconstruction, to score it (REFERENCE §7).

Outputs: <project>/stage1/template.obj (with UVs), <project>/stage1/gaussians.npz (GaussianTexture.state()),
<project>/stage1/geometry.json (what the mesh was made from; lets a re-run with new appearance options keep the
mesh) and <project>/reports/template.json. A re-run with unchanged inputs and options does nothing.

Measured and not kept: refining the mesh photometrically on its own frame after the appearance fit (stage 2's
tracker, 300 iterations, 4 cameras per step, rest shape = the current mesh), alternated with the appearance fit:
demo capture CD 0.616 -> 0.657 -> 0.664 cm over two rounds (F@1cm 82.1 -> 83.5 -> 83.3 %). The Gaussians fitted to
the mesh absorb its errors, so the images hold the mesh where it is rather than pulling it to the cloth.
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..capture.images import read_mask
from ..capture.layout import GARMENT_MASK, Capture, Sequence
from ..errors import InputError
from ..geometry.meshio import read_mesh, read_obj, write_obj
from ..jobs import Progress
from ..storage import file_stamps, write_json, write_npz, write_report

STAGE = "template"
MIN_CAMERAS = 3              # cameras that must see the garment
MIN_GARMENT_PIXELS = 10      # a camera "sees" the garment with at least this many mask pixels
TEXELS_PER_PIXEL = 2.0       # automatic texture resolution: texels this much finer than the pixel footprint
ATLAS_FILL = 0.6             # share of an xatlas atlas its charts cover, about
RESOLUTION_RANGE = (64, 512)


@dataclass
class TemplateRequest:
    capture: Path
    project: Path
    sequence: str | None = None          # default: the capture's first sequence
    frame: str | None = None             # default: the sequence's first frame
    cameras: list[str] = field(default_factory=list)   # default: all
    vertices: int | None = None          # default: 8000, fewer for coarse images
    resolution: int | None = None        # Gaussian texture side; default: from the pixel footprint
    voxel_mm: float | None = None        # default: one pixel footprint, 3-10 mm
    photo: bool = True                   # photo-consistency refinement of the silhouette geometry
    free_border_trim: float = 1.0        # edge lengths cut off borders that hang free of the body (the hull's bevel)
    appearance_iterations: int = 300
    progress: str = "bar"


def select_frame(capture: Capture, sequence: str | None, frame: str | None) -> tuple[Sequence, str]:
    seq = capture.sequence(sequence) if sequence else next(iter(capture.sequences.values()))
    if not seq.camera_ids:
        raise InputError("the sequence has no cameras", seq.root / "cameras.json", "calibrate at least 3 cameras")
    if not seq.frames:
        raise InputError("the sequence has no frames", seq.root, "add rgb_images/<frame>.png for every camera")
    name = frame if frame is not None else seq.frames[0]
    if name not in seq.frames:
        raise InputError(f"frame '{name}' not found", seq.root / seq.camera_ids[0] / "rgb_images",
                         f"choose one of {seq.frames[0]} ... {seq.frames[-1]}")
    return seq, name


def check_garment_visible(seq: Sequence, frame: str, camera_ids: list[str]) -> list[str]:
    """Cameras whose garment mask shows the garment; InputError if fewer than MIN_CAMERAS."""
    seeing = [cid for cid in camera_ids
              if read_mask(seq.image_path(cid, frame, GARMENT_MASK)).sum() >= MIN_GARMENT_PIXELS]
    if not seeing:
        raise InputError(f"the garment masks of frame '{frame}' are empty in every camera", seq.root,
                         "check the garment_masks folders (non-zero pixels mark the garment)")
    if len(seeing) < MIN_CAMERAS:
        raise InputError(f"the garment is visible in only {len(seeing)} camera(s) in frame '{frame}' "
                         f"(at least {MIN_CAMERAS} needed)", seq.root,
                         "choose a frame where more cameras see the garment (--frame) or add cameras")
    return seeing


def inputs_key(req: TemplateRequest, seq: Sequence, frame: str, camera_ids: list[str]) -> dict:
    """What the outputs depend on: options and the frame's files (name, size, mtime)."""
    paths = [seq.root / "cameras.json", seq.body_path(frame)]
    for cid in camera_ids:
        paths += [seq.image_path(cid, frame, kind) for kind in ("rgb_images", GARMENT_MASK, "foreground_masks")]
    files = file_stamps(paths, seq.root)
    options = {k: v for k, v in asdict(req).items() if k not in ("project", "progress", "capture")}
    return json.loads(json.dumps({"options": options, "sequence": seq.name, "frame": frame, "files": files},
                                 default=str))


def geometry_part(key: dict) -> dict:
    """The part of the inputs key the mesh depends on (not the appearance options)."""
    geometry_options = ("vertices", "voxel_mm", "photo", "free_border_trim", "cameras", "sequence", "frame")
    return {**key, "options": {k: v for k, v in key["options"].items() if k in geometry_options}}


def auto_resolution(area: float, footprint: float) -> int:
    """Texture side (power of two) giving TEXELS_PER_PIXEL texels across each pixel footprint."""
    texels = area / (footprint / TEXELS_PER_PIXEL) ** 2 / ATLAS_FILL
    side = 2 ** int(np.ceil(np.log2(max(np.sqrt(texels), 1.0))))
    return int(np.clip(side, *RESOLUTION_RANGE))


def run_template(req: TemplateRequest) -> Path:
    start = time.perf_counter()
    capture = Capture(req.capture)
    seq, frame = select_frame(capture, req.sequence, req.frame)
    camera_ids = list(req.cameras) or seq.camera_ids
    unknown = [c for c in camera_ids if c not in seq.cameras]
    if unknown:
        raise InputError(f"unknown cameras {unknown}", seq.root / "cameras.json", f"choose from {seq.camera_ids}")
    key = inputs_key(req, seq, frame, camera_ids)
    project = Path(req.project)
    stage_dir = project / "stage1"
    obj_path, gauss_path = stage_dir / "template.obj", stage_dir / "gaussians.npz"
    geom_path = stage_dir / "geometry.json"
    report_path = project / "reports" / f"{STAGE}.json"
    if report_path.is_file() and obj_path.is_file() and gauss_path.is_file() and \
            json.loads(report_path.read_text()).get("inputs") == key:
        Progress(STAGE, 1, req.progress).done(str(report_path))
        return report_path
    seeing = check_garment_visible(seq, frame, camera_ids)
    # heavy imports (torch, numba kernels) only once the input is known to be good: bad input fails fast
    from ..gaussians import build_texture
    from ..gaussians.texture import uv_atlas
    from ..metrics.coverage import stereo_coverage
    from ..metrics.surface import surface_metrics
    from ..reconstruction.photo_consistency import PhotoOptions
    from ..reconstruction.template_mesh import GEOMETRY_STEPS, TemplateGeometryOptions, reconstruct_template
    from ..registration.appearance import fit_appearance
    from ..registration.views import load_body, load_views

    geometry_steps = GEOMETRY_STEPS if req.photo else GEOMETRY_STEPS - 1
    progress = Progress(STAGE, 2 + geometry_steps + req.appearance_iterations, req.progress)
    timings: dict[str, float] = {}
    t = time.perf_counter()
    body = load_body(seq, frame)
    views = load_views(seq, frame, camera_ids, body=body)
    timings["load_s"] = time.perf_counter() - t
    progress.step("loaded views")

    t = time.perf_counter()
    previous = json.loads(geom_path.read_text()) if geom_path.is_file() and obj_path.is_file() else None
    uvs = atlas_resolution = None
    if previous is not None and previous.get("inputs") == geometry_part(key):
        verts, faces, uvs, face_uvs = read_obj(obj_path)
        geometry_log, atlas_resolution = previous["log"], previous["atlas_resolution"]
        progress.step("kept the template mesh of the previous run", advance=geometry_steps)
    else:
        options = TemplateGeometryOptions(vertices=req.vertices,
                                          voxel=None if req.voxel_mm is None else req.voxel_mm * 1e-3,
                                          photo=PhotoOptions() if req.photo else None,
                                          free_border_trim=req.free_border_trim)
        try:
            geometry = reconstruct_template(
                [v.camera for v in views], [v.background.numpy() < 0.5 for v in views],
                [v.garment.numpy() > 0.5 for v in views], [v.rgb.numpy() for v in views] if req.photo else None,
                options, step=lambda name: progress.step(name), occluders=[body])
        except ValueError as exc:
            raise InputError(f"no template could be reconstructed: {exc}", f"{seq.root} frame {frame}",
                             "check that the foreground and garment masks match the cameras") from None
        verts, faces, geometry_log = geometry.verts, geometry.faces, geometry.log
    resolution = req.resolution or auto_resolution(geometry_log["coarse_garment_area_m2"],
                                                   geometry_log["pixel_footprint_m"])
    if uvs is None or atlas_resolution != resolution:
        uvs, face_uvs = uv_atlas(verts, faces, resolution)
        write_obj(obj_path, verts, faces, uvs, face_uvs)
        write_json(geom_path, {"inputs": geometry_part(key), "log": geometry_log, "atlas_resolution": resolution})
    progress.step("UV atlas")
    timings["geometry_s"] = time.perf_counter() - t

    t = time.perf_counter()
    texture = build_texture(verts, faces, resolution, uvs=uvs, face_uvs=face_uvs)
    texture, appearance_log = fit_appearance(texture, verts, faces, views, req.appearance_iterations, progress)
    write_npz(gauss_path, **texture.state())
    timings["appearance_s"] = time.perf_counter() - t

    metrics = None
    gt_path = seq.gt_garment_files.get(frame)
    if gt_path is not None:     # metrics only: ground truth never feeds the reconstruction
        t = time.perf_counter()
        gt_verts, gt_faces = read_mesh(gt_path)
        metrics = surface_metrics(verts, faces, gt_verts, gt_faces)
        # what any multi-view method could triangulate of the truth (a ceiling on the recall, metrics/coverage.py)
        metrics["truth_stereo_coverage"] = stereo_coverage(gt_verts, gt_faces, [v.camera for v in views], [body])
        timings["metrics_s"] = time.perf_counter() - t
    timings["total_s"] = time.perf_counter() - start
    payload = {
        "sequence": seq.name, "frame": frame, "cameras": camera_ids, "cameras_seeing_garment": seeing,
        "vertices": int(len(verts)), "faces": int(len(faces)), "texture_resolution": int(resolution),
        "gaussians": int(len(texture)), **(metrics or {}), "ground_truth": None if gt_path is None else str(gt_path),
        "geometry": geometry_log,
        "appearance": {k: v for k, v in appearance_log.items() if k != "loss"} |
                      {"final_loss": appearance_log["loss"][-1] if appearance_log["loss"] else None},
        "outputs": {"template": str(obj_path), "gaussians": str(gauss_path)},
        "inputs": key, "timings": timings,
    }
    report = write_report(project, STAGE, payload)
    progress.done(str(report))
    return report
