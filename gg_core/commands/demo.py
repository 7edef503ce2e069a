"""`gg demo`: the main job on embedded default data, end to end, resumable.

Generates the synthetic demo capture (Blender cloth + Cycles; the body model and garment templates ship with
the package, nothing is downloaded), validates it, reconstructs the template (stage 1), registers every frame
(stage 2), fits the behaviour stage to the registered motion and runs the missing-physics diagnosis on the
capture's ground-truth motion (on the demo preset's registered meshes it answers "none", 24 min: README; the
tiny preset's 8-frame sequences are too short for the temporal smoothing noisy meshes may need).
Each step is a regular `gg` command, so a re-run skips what is already finished. Writes <out>/reports/demo.json
with the steps, their reports and timings.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ..cli import add_progress_option

HELP = "run the main job on embedded default data: synthesize a capture, template, registration, behaviour, diagnosis"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=Path("out/demo"), help="demo folder (capture/, project/)")
    parser.add_argument("--preset", default="demo", help="synthetic capture preset (tiny for a quick look)")
    parser.add_argument("--garment", default="skirt", help="garment template of the synthetic capture")
    add_progress_option(parser)


def steps(args: argparse.Namespace) -> list[tuple[str, list[str], Path | None]]:
    """(name, gg argv, report path) of every demo step, in order."""
    capture, project = args.out / "capture", args.out / "project"
    progress = ["--progress", args.progress]
    return [
        ("synth", ["synth", "--preset", args.preset, "--garment", args.garment, "--out", str(capture), *progress],
         capture / "truth.json"),
        ("inspect", ["inspect", str(capture), "--quick", "--progress", "none"], None),
        ("template", ["template", str(capture), "--project", str(project), *progress],
         project / "reports" / "template.json"),
        ("register", ["register", str(capture), "--project", str(project), *progress],
         project / "reports" / "register.json"),
        ("behavior", ["behavior", str(capture), "--project", str(project), *progress],
         project / "reports" / "behavior.json"),
        ("diagnose", ["diagnose", str(capture), "--project", str(project), "--source", "gt", *progress],
         project / "reports" / "diagnose.json"),
    ]


def run(args: argparse.Namespace) -> int:
    from ..cli import main
    from ..storage import write_json

    done = []
    for name, argv, report in steps(args):
        start = time.perf_counter()
        code = main(argv)
        done.append({"step": name, "argv": argv, "exit_code": code, "seconds": round(time.perf_counter() - start, 2),
                     "report": str(report) if report else None})
        if code != 0:
            write_json(args.out / "reports" / "demo.json", {"steps": done, "ok": False})
            return code
    write_json(args.out / "reports" / "demo.json", {"steps": done, "ok": True})
    return 0
