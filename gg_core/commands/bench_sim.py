"""`gg bench sim`: this simulator against Blender's cloth modifier on the same garment, body motion and pins.

Both simulate a tailored garment (gg_core.synth.garments, waistband pinned to the body like the synthetic
captures) on the default body playing a motion, hands excluded from collision in both; Blender uses the
synthetic captures' fabric and collision settings (self-collision off, like this simulator) at the given
quality. Blender runs in a bpy subprocess and times its frame loop; this simulator times its rollout after a
short JIT warm-up. One JSON line: frames per second of both, their ratio, vertex count, body-penetration
statistics of both.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

HELP = "cloth simulation speed and body penetration: this simulator vs Blender's cloth modifier"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--garment", default="skirt", help="garment template of gg_core.synth.garments")
    parser.add_argument("--vertices", type=int, default=2000, help="target garment vertex count")
    parser.add_argument("--motion", default="walk", help="body motion")
    parser.add_argument("--frames", type=int, default=60, help="motion frames (after the settle frames)")
    parser.add_argument("--settle", type=int, default=10, help="frames blending from the rest pose into the motion")
    parser.add_argument("--quality", type=int, default=5, help="Blender cloth quality (steps per frame)")
    parser.add_argument("--seed", type=int, default=0)


def run(args: argparse.Namespace) -> int:
    from ..body.model import load_body
    from ..body.motions import animate
    from ..physics.blender_cloth import run_blender_cloth
    from ..physics.cloth import Cloth
    from ..physics.contact import BodyCollider, penetration_stats
    from ..physics.simulator import ClothState, ImplicitSimulator
    from ..synth.anchoring import bind
    from ..synth.fabrics import FABRICS
    from ..synth.garments import tailor
    from ..synth.generate import BODY_COLLISION, COLLISION

    body = load_body()
    frames = animate(body, args.motion, args.frames, seed=args.seed, settle_frames=args.settle).astype(np.float64)
    garment = tailor(body, args.garment, args.vertices)
    verts, faces = garment.vertices, garment.faces
    pinned = garment.regions.get("pin", np.zeros(len(verts))) > 0
    pins = np.repeat(verts[None], len(frames), 0)
    pins[:, pinned] = bind(body.rest_vertices.astype(np.float64), body.faces, verts[pinned]).apply(frames)
    collider = BodyCollider(body.faces, len(body.rest_vertices), exclude=body.hand_mask)

    sim = ImplicitSimulator(Cloth(verts, faces, pinned=pinned), collider=collider)
    start_state = ClothState(verts.copy(), np.zeros_like(verts))
    sim.rollout(start_state, frames[:3], pin_frames=pins[:3])          # compile / warm the kernels
    sim.log.newton_iterations.clear()
    sim.log.cg_iterations.clear()
    start = time.perf_counter()
    ours = sim.rollout(start_state, frames, pin_frames=pins)
    ours_s = time.perf_counter() - start

    collider_faces = body.faces[collider.face_ok]
    theirs, blender_s = run_blender_cloth(verts, faces, frames, collider_faces, pinned, pins,
                                          cloth={**FABRICS[garment.fabric].cloth_settings(), "quality": args.quality},
                                          cloth_collision=COLLISION, body_collision=BODY_COLLISION)
    steps = len(frames) - 1
    result = {
        "bench": "sim", "garment": args.garment, "vertices": len(verts), "faces": len(faces),
        "body_vertices": len(body.rest_vertices), "motion": args.motion, "frames": steps,
        "ours_fps": steps / ours_s, "blender_fps": steps / blender_s, "speedup": blender_s / ours_s,
        "ours_penetration": penetration_stats(ours, frames, collider),
        "blender_penetration": penetration_stats(theirs, frames, collider),
        "ours_newton_per_frame": float(np.mean(sim.log.newton_iterations)),
        "ours_cg_per_frame": float(np.mean(sim.log.cg_iterations)),
        "blender_quality": args.quality,
        "mean_distance_between_m": float(np.linalg.norm(ours - theirs, axis=2).mean()),
    }
    print(json.dumps(result))
    return 0
