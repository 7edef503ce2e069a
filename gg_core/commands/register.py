"""`gg register`: stage 2, the template mesh fitted to every frame of every sequence (fixed topology)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..cli import add_progress_option

HELP = "stage 2: register the template mesh to every frame of each sequence (photometric tracking)"
ABLATION_CHOICES = ("full", "only-rgb", "no-body", "body-always")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("capture", type=Path, help="capture folder (REFERENCE.md §1 layout)")
    parser.add_argument("--project", type=Path, required=True,
                        help="project folder holding stage1/ (from gg template); stage2/ and reports/ are written")
    parser.add_argument("--sequences", nargs="+", default=[], metavar="SEQ",
                        help="sequences to register (default: all)")
    parser.add_argument("--ablation", choices=ABLATION_CHOICES, default="full",
                        help="loss terms: full (default), only-rgb (no geometric terms), no-body (no body "
                             "collision term), body-always (body term in every iteration, not only the second half)")
    parser.add_argument("--iterations", type=int, default=None,
                        help="optimization steps per frame (default: the tracker's; the first frame of a "
                             "sequence gets 8/3 as many)")
    parser.add_argument("--frames", type=int, default=None, help="register only the first N frames of each sequence")
    parser.add_argument("--align", choices=("body", "icp", "none"), default="body",
                        help="first-frame alignment of the template: body (rigid motion of the body under the "
                             "garment since the template frame; default), icp (body, then ICP against the frame's "
                             "reconstruction from its masks), none")
    parser.add_argument("--icp-scale", action="store_true", help="let ICP scale the template too (--align icp)")
    parser.add_argument("--texture-factor", type=int, default=None,
                        help="coarsen the stage 1 Gaussian texture by this power of two for registration (default: "
                             "automatic, about one Gaussian per garment pixel; 1 keeps it: slower, on the demo "
                             "capture 0.08 cm lower CD)")
    parser.add_argument("--texture-refit", type=int, default=1250, metavar="STEPS",
                        help="appearance steps refitting the coarsened texture on the template frame before "
                             "tracking, at twice the appearance fit's learning rates (default 1250, about 55 s on "
                             "the demo capture; fewer: faster, the mesh drifts more; 0: off)")
    parser.add_argument("--renders", type=int, default=3, help="frames per sequence rendered for inspection")
    parser.add_argument("--seed", type=int, default=0, help="seed of the camera sampling")
    parser.add_argument("--workers", type=int, default=None,
                        help="sequences registered at once, each in its own single-threaded process (default: one "
                             "per CPU core, at most one per sequence; 1: one after another in this process)")
    add_progress_option(parser)


def run(args: argparse.Namespace) -> int:
    from .. import registration  # noqa: F401, PLC0415 - sets the OpenMP wait policy before torch/numba start
    from ..stages.register import RegisterRequest, run_register  # noqa: PLC0415

    report = run_register(RegisterRequest(capture=args.capture, project=args.project, sequences=args.sequences,
                                          ablation=args.ablation, iterations=args.iterations, frames=args.frames,
                                          align=args.align, icp_scale=args.icp_scale,
                                          texture_factor=args.texture_factor,
                                          texture_refit=args.texture_refit, renders=args.renders, seed=args.seed,
                                          workers=args.workers, progress=args.progress))
    if args.progress != "jsonl":
        data = json.loads(report.read_text())
        print(json.dumps({"report": str(report), "ablation": data["ablation"], **data["mean"]}))
    return 0
