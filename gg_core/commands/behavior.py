"""`gg behavior`: stage 4, fit the simulator's material and rest lengths to the garment's motion."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..cli import add_progress_option, add_sim_vertices_option, add_source_option

HELP = "stage 4: fit material and rest lengths to the registered motion; evaluate on held-out sequences"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("capture", type=Path, help="capture folder")
    parser.add_argument("--project", type=Path, required=True, help="project folder to write stage4/ and reports/")
    add_source_option(parser)
    parser.add_argument("--train", nargs="+", default=[], metavar="SEQ",
                        help="training sequences (default: truth.json's suggestion, else all but the last)")
    parser.add_argument("--heldout", nargs="+", default=[], metavar="SEQ",
                        help="held-out sequences for evaluation (default: the others)")
    parser.add_argument("--noise-mm", type=float, default=0.0,
                        help="add Gaussian noise of this standard deviation (mm) to the garment meshes")
    parser.add_argument("--attach-tol-mm", type=float, default=3.0,
                        help="vertices that stay this close to a fixed place on the body are attached (pinned)")
    add_sim_vertices_option(parser)
    parser.add_argument("--global-iterations", type=int, default=20, help="L-BFGS iterations of the global fit")
    parser.add_argument("--local-iterations", type=int, default=20,
                        help="L-BFGS iterations of the per-vertex material / rest length fit (0 skips it)")
    parser.add_argument("--max-samples", type=int, default=None,
                        help="observed states used per fit evaluation (default 12, FitConfig)")
    parser.add_argument("--fit-horizon", type=int, default=None,
                        help="frames the simulator predicts ahead of each observed state in the fit (default 3: "
                             "one-frame fits learn the noise of registered meshes)")
    parser.add_argument("--force", action="append", default=[], metavar="TERM[:KEY=VALUE,...]",
                        help="switch on a force-library term in the simulator, e.g. mass_damping:alpha=0.5")
    parser.add_argument("--fit-term", nargs="*", default=None, metavar="TERM.PARAM",
                        help="term parameters fitted with the global material (default: collision.margin; "
                             "e.g. body_friction.mu)")
    parser.add_argument("--fps", type=float, default=30.0, help="frame rate of the sequences")
    parser.add_argument("--substeps", type=int, default=2, help="implicit steps per frame (fit and rollouts)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the added noise and of the frame subsample")
    add_progress_option(parser)


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..physics.fitting import FitConfig
    from ..physics.forces import parse_term_spec
    from ..stages.behavior import BehaviorRequest, run_behavior

    try:
        forces = dict(parse_term_spec(s) for s in args.force)
    except ValueError as exc:
        raise InputError(str(exc), "--force", "e.g. --force mass_damping:alpha=0.5") from None
    chosen = {k: v for k, v in (("max_samples", args.max_samples), ("horizon", args.fit_horizon)) if v is not None}
    req = BehaviorRequest(capture=args.capture, project=args.project, train=args.train, heldout=args.heldout,
                          forces=forces, source=args.source,
                          noise_mm=args.noise_mm, attach_tol_mm=args.attach_tol_mm, sim_vertices=args.sim_vertices,
                          fps=args.fps, substeps=args.substeps, seed=args.seed,
                          fit=FitConfig(global_iterations=args.global_iterations,
                                        local_iterations=args.local_iterations, **chosen,
                                        seed=args.seed, term_params=FitConfig.term_params if args.fit_term is None
                                        else tuple(args.fit_term)),
                          progress=args.progress)
    report = run_behavior(req)
    if args.progress != "jsonl":
        data = json.loads(report.read_text())
        keys = ("train_l2_default", "train_l2_fitted", "heldout_l2_default", "heldout_l2_fitted",
                "heldout_l2_reduction")
        print(json.dumps({"report": str(report), **{k: data[k] for k in keys}}))
    return 0
