"""`gg simulate`: simulate a garment on a body sequence (mesh folder) or a built-in body motion."""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ..cli import add_progress_option
from ..errors import InputError

HELP = "simulate a garment mesh on a body sequence or motion and write one PLY per frame"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--garment", type=Path,
                        help="garment mesh (PLY/OBJ, +Y up, metres); default with --behavior: the mesh it was fitted "
                             "on (its template, remeshed when the registered meshes were finer than the simulator's)")
    body = parser.add_mutually_exclusive_group(required=True)
    body.add_argument("--body", type=Path, help="folder of body meshes, one per frame (sorted by name)")
    body.add_argument("--motion", help="built-in motion of the default body (e.g. walk, arm_swing, jump)")
    parser.add_argument("--out", type=Path, required=True,
                        help="output folder: <frame>.ply per frame + simulate.json (+ body.npz for --motion: the "
                             "body frames, for the add-on to show the body moving with the garment)")
    parser.add_argument("--frames", type=int, default=60, help="frames of --motion (after the settle frames)")
    parser.add_argument("--settle", type=int, default=15,
                        help="frames of --motion that blend from the rest pose into the motion first")
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--substeps", type=int, default=1, help="implicit steps per frame")
    parser.add_argument("--pin", default="auto",
                        help="attached vertices: 'auto' (boundary vertices within --pin-distance of the body in the "
                             "first frame, e.g. a waistband), 'none', or a .npy/.txt file of vertex indices")
    parser.add_argument("--pin-distance", type=float, default=0.02, help="metres, for --pin auto")
    parser.add_argument("--behavior", type=Path,
                        help="fitted model: stage4/behavior.npz from `gg behavior` (material, rest lengths, terms) or "
                             "diagnose/model.npz from `gg diagnose` (with the missing physics it found)")
    parser.add_argument("--material", action="append", default=[], metavar="NAME=VALUE",
                        help="uniform material value (density, mu, lam, bending), repeatable")
    parser.add_argument("--force", action="append", default=[], metavar="TERM[:KEY=VALUE,...]",
                        help="switch on a force-library term, e.g. air_drag:coef=0.8 or wind:velocity=1;0;0")
    add_progress_option(parser)


def _body_frames(args: argparse.Namespace):
    from ..geometry.meshio import read_mesh

    if args.motion:
        from ..body.model import load_body
        from ..body.motions import animate

        body = load_body()
        frames = animate(body, args.motion, args.frames, fps=int(args.fps), settle_frames=args.settle)
        return frames.astype(np.float64), body.faces.astype(np.int64), body.hand_mask
    files = sorted(p for p in args.body.iterdir() if p.suffix.lower() in (".ply", ".obj")) if args.body.is_dir() else []
    if not files:
        raise InputError("no body meshes found", args.body, "pass a folder of per-frame .ply/.obj body meshes")
    meshes = [read_mesh(p) for p in files]
    if len({m[0].shape for m in meshes}) != 1:
        raise InputError("body meshes change vertex count", args.body, "use one topology for the whole sequence")
    return np.stack([m[0] for m in meshes]), meshes[0][1], None


def _pinned(args: argparse.Namespace, cloth, body0: np.ndarray, collider) -> np.ndarray:
    n = cloth.n_vertices
    if args.pin == "none":
        return np.zeros(n, bool)
    if args.pin == "auto":
        near = collider.query(cloth.template, body0, reach=max(args.pin_distance, 1e-3)).found
        return near & cloth.topology.boundary_vertices
    path = Path(args.pin)
    if not path.is_file():
        raise InputError("pin file not found", path, "pass 'auto', 'none' or a .npy/.txt file of vertex indices")
    idx = np.load(path) if path.suffix == ".npy" else np.loadtxt(path, dtype=np.int64, ndmin=1)
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        raise InputError("pin indices outside the garment's vertices", path, f"use indices 0..{n - 1}")
    mask = np.zeros(n, bool)
    mask[np.asarray(idx, np.int64)] = True
    return mask


def with_overrides(stored: list[tuple[str, dict]], forces: list[tuple[str, dict]]) -> list:
    """The terms `stored` (a fitted model's, or the defaults) with the command line's `forces` switched on, their
    parameters replacing the stored ones key by key."""
    from ..physics.forces import make_terms

    params = {name: dict(p) for name, p in stored}
    for name, p in forces:
        params[name] = {**params.get(name, {}), **p}
    return make_terms([n for n, _ in stored] + [n for n, _ in forces], {n: p for n, p in params.items() if p})


def run(args: argparse.Namespace) -> int:
    from ..geometry.meshio import read_mesh, write_ply
    from ..jobs import Progress
    from ..physics.cloth import Cloth
    from ..physics.contact import BodyCollider, penetration_stats
    from ..physics.forces import DEFAULT_TERMS, parse_term_spec
    from ..physics.material import MATERIAL_NAMES, Material
    from ..physics.model_file import read_model
    from ..physics.simulator import ClothState, ImplicitSimulator
    from ..storage import write_json, write_npz
    from ..synth.anchoring import bind

    fitted = None
    if args.behavior is not None:
        if not args.behavior.is_file():
            raise InputError("no fitted behaviour file", args.behavior, "run gg behavior first, or fix the path")
        try:
            fitted = read_model(args.behavior)
        except (ValueError, OSError) as exc:
            raise InputError(f"fitted behaviour cannot be read ({exc})", args.behavior,
                             "run gg behavior (or gg diagnose) again") from None
    if args.garment is not None:
        verts, faces = read_mesh(args.garment)
    elif fitted is not None:
        verts, faces = fitted.cloth.template, fitted.cloth.faces
    else:
        raise InputError("no garment to simulate", "--garment",
                         "pass --garment MESH or --behavior P/stage4/behavior.npz")
    body, body_faces, hands = _body_frames(args)
    collider = BodyCollider(body_faces, body.shape[1], exclude=hands)
    values = {}
    for item in args.material:
        key, _, value = item.partition("=")
        if key not in MATERIAL_NAMES:
            raise InputError(f"unknown material value '{key}'", "--material", f"use one of {', '.join(MATERIAL_NAMES)}")
        values[key] = float(value)
    cloth = Cloth(verts, faces, material=Material.uniform(len(verts), **values))
    if fitted is not None:
        if fitted.cloth.n_vertices != len(verts) or len(fitted.cloth.rest_lengths) != len(cloth.rest_lengths):
            raise InputError("fitted behaviour belongs to another garment mesh", args.behavior,
                             "simulate the garment the behaviour was fitted on (same vertices and faces)")
        cloth.material, cloth.rest_lengths = fitted.cloth.material, fitted.cloth.rest_lengths
        cloth.flat, cloth.uniform_mass = fitted.cloth.flat, fitted.cloth.uniform_mass
    cloth.pinned = _pinned(args, cloth, body[0], collider)
    try:
        stored = [(n, {}) for n in DEFAULT_TERMS] if fitted is None or fitted.terms is None else fitted.terms
        terms = with_overrides(stored, [parse_term_spec(s) for s in args.force])
    except ValueError as exc:
        raise InputError(str(exc), "--force", "see the force library in gg_core/physics/forces.py") from None
    sim = ImplicitSimulator(cloth, terms=terms, collider=collider, fps=args.fps, substeps=args.substeps)
    pins = np.repeat(verts[None], len(body), 0)
    if cloth.pinned.any():
        pins[:, cloth.pinned] = bind(body[0], body_faces, verts[cloth.pinned]).apply(body)

    progress = Progress("simulate", len(body), args.progress)
    args.out.mkdir(parents=True, exist_ok=True)
    write_ply(args.out / f"{0:06d}.ply", verts, faces)
    start = time.perf_counter()

    def save(t: int, state: ClothState) -> None:
        write_ply(args.out / f"{t:06d}.ply", state.x, faces)
        progress.step(f"frame {t}")

    traj = sim.rollout(ClothState(verts.copy(), np.zeros_like(verts)), body, pin_frames=pins, callback=save)
    seconds = time.perf_counter() - start
    stale = [p for p in args.out.glob("*.ply") if p.stem.isdigit() and int(p.stem) >= len(body)]
    for path in stale:          # frames of an earlier, longer simulation into the same folder
        path.unlink()
    if args.motion:     # the built-in body exists nowhere else on disk
        write_npz(args.out / "body.npz", positions=body.astype(np.float32), faces=body_faces.astype(np.int32))
    report = write_json(args.out / "simulate.json", {
        "body": "body.npz" if args.motion else str(args.body.resolve()), "frames": len(body),
        "vertices": len(verts), "pinned_vertices": int(cloth.pinned.sum()),
        "seconds": seconds, "fps": (len(body) - 1) / seconds,
        "penetration": penetration_stats(traj, body, collider),
        "terms": [t.describe() for t in terms], "material": cloth.material.summary(),
        "vertex_mass": "uniform" if cloth.uniform_mass else "area"})
    progress.done(str(report))
    if args.progress != "jsonl":
        print(json.dumps(json.loads(report.read_text())["penetration"] | {"out": str(args.out)}))
    return 0
