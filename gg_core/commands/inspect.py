"""`gg inspect <capture>`: summarize a capture and list every problem found (exit 2 if any)."""
from __future__ import annotations

import argparse
import json
import sys

from ..cli import add_progress_option

HELP = "validate a capture folder: sequences, cameras, frames, resolutions, body, ground truth, problems"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("capture", help="capture folder (layout of REFERENCE.md §1)")
    parser.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    parser.add_argument("--quick", action="store_true", help="skip decoding every image (file names only)")
    add_progress_option(parser)


def run(args: argparse.Namespace) -> int:
    from ..capture.layout import Capture
    from ..capture.validate import validate_capture
    from ..jobs import Progress

    sequences = Capture(args.capture).sequences  # fails early (exit 2) when it is no capture at all
    progress = Progress("inspect", len(sequences), args.progress)
    report = validate_capture(args.capture, decode_images=not args.quick, on_sequence=progress.step)
    if args.json:
        print(json.dumps(report.to_json()))
    elif args.progress != "jsonl":
        _print_human(report)
    progress.done(None)
    for problem in report.problems:
        print(problem.line(), file=sys.stderr)
    return 2 if report.problems else 0


def _print_human(report) -> None:
    print(f"capture {report.root}  ground truth: {'yes' if report.truth else 'no'}")
    for s in report.sequences:
        res = ", ".join(f"{w}x{h}" for w, h in sorted(set(s.resolutions))) or "?"
        frames = f"{len(s.frames)} frames ({s.frames[0]}..{s.frames[-1]})" if s.frames else "0 frames"
        print(f"  {s.name}: {len(s.cameras)} cameras [{res}], {frames}, body meshes {s.body_files}, "
              f"foreground masks {'yes' if s.foreground_masks else 'no'}, gt frames {s.ground_truth_frames}")
    print(f"{len(report.problems)} problem(s)")
