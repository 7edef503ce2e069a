"""The observed garment motion stage 4 and the diagnosis are fitted to: per sequence, garment meshes of one
topology with the body meshes of the same frames.

Two sources: the registered meshes of stage 2 (P/stage2/<seq>/meshes/<frame>.ply), which is what a real capture
has, and, on synthetic captures, the ground-truth meshes (gt/garment/), which isolate the physics from the
registration error. `auto` takes the registered meshes when stage 2 has finished every named sequence, else the
ground truth; the report records which one was used.
"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..capture.layout import Capture, Sequence
from ..errors import InputError
from ..geometry.meshio import read_mesh
from ..storage import file_stamps

if TYPE_CHECKING:   # torch stays out of `gg --help`, which lists SOURCES
    from ..physics.fitting import Observed

SOURCES = ("auto", "registered", "gt")
VERTEX_MASS = ("area", "uniform")   # how the simulated garment spreads its mass (physics.cloth.Cloth.uniform_mass)
SIM_VERTICES = 1200     # default: finer observed meshes are simulated on a remeshed copy of about this many vertices


def registered_files(project: Path, name: str) -> dict[str, Path]:
    folder = Path(project) / "stage2" / name / "meshes"
    return {p.stem: p for p in sorted(folder.glob("*.ply"))} if folder.is_dir() else {}


def _registration_complete(seq: Sequence, project: Path) -> bool:
    """Every frame registered (frames named by the body meshes, which every frame has: mesh-only captures have
    no cameras to list them)."""
    files = registered_files(project, seq.name)
    return bool(files) and set(seq.body_files) <= set(files)


def resolve_source(source: str, capture: Capture, names: list[str], project: Path) -> str:
    """`registered` or `gt`: what `source` means for these sequences (InputError for an unknown source)."""
    if source not in SOURCES:
        raise InputError(f"unknown source '{source}'", "--source", f"choose one of: {', '.join(SOURCES)}")
    if source != "auto":
        return source
    unfinished = [n for n in names if not _registration_complete(capture.sequence(n), project)]
    if not unfinished:
        return "registered"
    if all(capture.sequence(n).gt_garment_files for n in names):
        return "gt"
    raise InputError(f"registration has not finished sequence '{unfinished[0]}'",
                     Path(project) / "stage2" / unfinished[0] / "meshes", "run gg register on the capture first")


def garment_files(seq: Sequence, source: str, project: Path) -> dict[str, Path]:
    """Frame name -> garment mesh of the resolved `source`; InputError when there is none."""
    files = seq.gt_garment_files if source == "gt" else registered_files(project, seq.name)
    if not files:
        where = seq.root / "gt" / "garment" if source == "gt" else Path(project) / "stage2" / seq.name / "meshes"
        raise InputError(f"no {'ground-truth' if source == 'gt' else 'registered'} garment meshes for sequence "
                         f"'{seq.name}'", where,
                         "run registration first (gg register), or use --source gt on a synthetic capture")
    return files


def load_sequence(seq: Sequence, files: dict[str, Path], fps: float) -> tuple[Observed, np.ndarray, np.ndarray]:
    """(observation, garment faces, body faces) of one sequence from its garment meshes `files` and body meshes."""
    from ..physics.fitting import Observed  # noqa: PLC0415 - see TYPE_CHECKING above

    frames = sorted(files)
    missing = [f for f in frames if f not in seq.body_files]
    if missing:
        raise InputError(f"no body mesh for frames {missing[:3]}", seq.root / "body",
                         "name body meshes like the garment frames")
    meshes = [read_mesh(files[f]) for f in frames]
    bodies = [read_mesh(seq.body_files[f]) for f in frames]
    if len({m[0].shape for m in meshes}) != 1 or len({b[0].shape for b in bodies}) != 1:
        raise InputError("garment or body meshes change vertex count within the sequence", seq.root,
                         "register every frame to the template topology")
    garment = np.stack([m[0] for m in meshes])
    return Observed(seq.name, garment, np.stack([b[0] for b in bodies]), fps), meshes[0][1], bodies[0][1]


def simulation_mesh(sequences: list[Observed], faces: np.ndarray, max_vertices: int) -> tuple[np.ndarray, dict]:
    """(faces of the mesh the sequences are now on, a log): sequences observed on more than `max_vertices`
    vertices (0: no limit) are carried, in place, onto a remeshed copy of their first frame with about that many.

    Why: registered meshes have the template's resolution (7470 vertices on the demo capture), which the Gaussian
    texture needs and the simulator does not; the fits' cost grows with the vertex count (a diagnosis took 54 min
    there). Each coarse vertex is moved to its closest point on the first frame and follows that point's triangle
    (barycentric coordinates, synth.anchoring) in every frame, so the coarse sequences lie on the observed
    surfaces (the remesh's border relaxation had moved hem vertices up to 1 cm off the demo template)."""
    from ..reconstruction.remesh import coarsen  # noqa: PLC0415 - gpytoolbox only where meshes are remeshed
    from ..synth.anchoring import Anchors, bind  # noqa: PLC0415

    n = sequences[0].garment.shape[1]
    if max_vertices <= 0 or n <= max_vertices:
        return faces, {"vertices": n, "observed_vertices": n, "remeshed": False}
    rest = sequences[0].garment[0]
    verts, coarse_faces = coarsen(rest, faces, max_vertices)
    closest = bind(rest, faces, verts)
    on_surface = Anchors(closest.triangles, closest.bary, np.zeros_like(closest.offset))
    for obs in sequences:
        obs.garment = on_surface.apply(obs.garment)
    return coarse_faces, {"vertices": len(verts), "observed_vertices": n, "remeshed": True,
                          "max_projection_mm": float(np.linalg.norm(closest.offset, axis=1).max() * 1e3)}


def inputs_key(request: object, capture: Capture, names: list[str], source: str, project: Path) -> dict:
    """What a stage's result depends on: its options (a dataclass, less project, progress and worker count) and
    the meshes it reads (name, size, mtime), so a re-registered frame or a changed option reruns the stage."""
    files = {}
    for n in names:
        seq = capture.sequence(n)
        for kind, group in (("garment", garment_files(seq, source, project)), ("body", seq.body_files)):
            files[f"{n}/{kind}"] = file_stamps(group.values())
    options = {k: v for k, v in asdict(request).items() if k not in ("project", "progress", "workers")}
    return json.loads(json.dumps({"options": options, "source": source, "files": files}, default=str))
