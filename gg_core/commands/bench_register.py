"""`gg bench register`: the paper's Table 1 (registration ablations) on a synthetic capture.

Runs stage 1 (gg template) once, then stage 2 (gg register) four times: full, only-rgb (no geometric
terms), no-body (no collision term) and body-always (collision term from the first iteration), each into its
own project folder holding a copy of the same stage 1 outputs, as many at once as there are cores (each in a
single-threaded process: the seconds per frame are those of one core). The ablations switch loss terms only:
every one keeps stage 2's multi-view stereo step over the fits (registration/stereo.py), which is not a
loss term. Prints one JSON line with, per ablation, the mean over sequences of CD (cm), p2m (cm),
F-score@1cm (%), L_body and seconds per frame (wall and CPU), plus the paper's figures on 4D-Dress for
reference; a readable table goes to stderr. Without --capture the tiny preset is synthesized.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

HELP = "registration ablations (paper Table 1: CD, p2m, F-score, L_body, s/frame) on a synthetic capture"

ABLATIONS = ("full", "only-rgb", "no-body", "body-always")
PAPER = {"full": {"fscore_1cm": 89.6, "cd_cm": 1.04, "p2m_cm": 0.504, "l_body": 1.03e-5},
         "only-rgb": {"fscore_1cm": 4.4}, "no-body": {"fscore_1cm": 88.4}, "body-always": {"cd_cm": 6.57}}
COLUMNS = ("cd_cm", "p2m_cm", "fscore_1cm", "l_body", "s_per_frame", "cpu_s_per_frame")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--capture", type=Path, default=None,
                        help="synthetic capture with ground truth (default: synthesize the tiny preset)")
    parser.add_argument("--project", type=Path, default=None,
                        help="work folder (default: a temporary one); stage 1 is reused when it is up to date")
    parser.add_argument("--sequences", nargs="+", default=[], metavar="SEQ", help="sequences (default: all)")
    parser.add_argument("--frames", type=int, default=None, help="frames per sequence (default: all)")
    parser.add_argument("--iterations", type=int, default=None, help="registration steps per frame")
    parser.add_argument("--vertices", type=int, default=None, help="template vertex count for gg template "
                        "(default: stage 1's)")
    parser.add_argument("--ablations", nargs="+", choices=ABLATIONS, default=list(ABLATIONS),
                        help="ablations to run (default: all four)")


def run(args: argparse.Namespace) -> int:
    from .. import registration  # noqa: F401, PLC0415 - sets the OpenMP wait policy before torch/numba start

    with tempfile.TemporaryDirectory(prefix="gg_bench_register_") as tmp:
        work = args.project or Path(tmp)
        capture = args.capture or synthesize_tiny(work / "capture")
        table = run_ablations(capture, work, args.ablations, args.sequences, args.frames, args.iterations,
                              args.vertices)
    result = {"bench": "register", "capture": str(capture), "frames": args.frames, "iterations": args.iterations,
              "vertices": args.vertices,
              "table": table, "paper_4d_dress": PAPER}
    print(format_table(table), file=sys.stderr)
    print(json.dumps(result))
    return 0


def synthesize_tiny(out: Path) -> Path:
    from ..synth.generate import SynthRequest, generate  # noqa: PLC0415
    from ..synth.presets import get_preset  # noqa: PLC0415

    if not (out / "truth.json").is_file():
        generate(SynthRequest(preset=get_preset("tiny"), out=out, progress="none"))
    return out


def run_ablations(capture: Path, work: Path, ablations: list[str], sequences: list[str], frames: int | None,
                  iterations: int | None, vertices: int | None = None) -> dict[str, dict]:
    """Stage 1 once, then the ablations at once, one single-threaded process each (gg_core/parallel.py)."""
    from ..jobs import Progress  # noqa: PLC0415
    from ..parallel import default_workers, run_jobs  # noqa: PLC0415
    from ..stages.register import RegisterRequest  # noqa: PLC0415
    from ..stages.template import TemplateRequest, run_template  # noqa: PLC0415

    template_project = work / "template"
    run_template(TemplateRequest(capture=capture, project=template_project, vertices=vertices, progress="none"))
    requests = []
    for name in ablations:
        _copy_stage1(template_project, work / name)
        requests.append(RegisterRequest(capture=capture, project=work / name, sequences=sequences, ablation=name,
                                        iterations=iterations, frames=frames, renders=0, workers=1,
                                        progress="none"))
    means = run_jobs(_register_mean, requests, default_workers(len(requests)),
                     Progress("bench register", len(requests), "none"))
    return dict(zip(ablations, means))


def _register_mean(req, step) -> dict:
    from ..stages.register import run_register  # noqa: PLC0415

    mean = json.loads(run_register(req).read_text())["mean"]
    step(req.ablation)
    return mean


def _copy_stage1(source: Path, project: Path) -> None:
    """Stage 1 outputs (and report: it names the template frame) into an ablation's own project folder."""
    for rel in ("stage1/template.obj", "stage1/gaussians.npz", "reports/template.json"):
        src, dst = source / rel, project / rel
        if src.is_file() and (not dst.is_file() or dst.stat().st_mtime_ns < src.stat().st_mtime_ns):
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst)


def format_table(table: dict[str, dict]) -> str:
    lines = [f"{'ablation':<12}" + "".join(f"{c:>14}" for c in COLUMNS)]
    for name, row in table.items():
        cells = [f"{row[c]:>14.3g}" if c in row else f"{'-':>14}" for c in COLUMNS]
        lines.append(f"{name:<12}" + "".join(cells))
    return "\n".join(lines)
