"""`gg template`: stage 1, the garment's template mesh (with UVs) and initial Gaussians from one frame."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..cli import add_progress_option

HELP = "stage 1: reconstruct the garment's template mesh (UV atlas) and initial Gaussians from one frame"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("capture", type=Path, help="capture folder (REFERENCE.md §1 layout)")
    parser.add_argument("--project", type=Path, required=True, help="project folder to write stage1/ and reports/")
    parser.add_argument("--sequence", default=None, help="sequence holding the template frame (default: the first)")
    parser.add_argument("--frame", default=None, help="template frame name, e.g. 000000 (default: the first)")
    parser.add_argument("--cameras", nargs="+", default=[], metavar="CAM",
                        help="cameras to use (default: all; e.g. leave held-out cameras out)")
    parser.add_argument("--vertices", type=int, default=None,
                        help="target vertex count of the template (default: 8000, fewer for small images)")
    parser.add_argument("--resolution", type=int, default=None,
                        help="Gaussian texture side in texels (default: from the image resolution, 64-512)")
    parser.add_argument("--voxel-mm", type=float, default=None,
                        help="voxel size of the visual hull in mm (default: a pixel's footprint, 3-10 mm)")
    parser.add_argument("--no-photo", dest="photo", action="store_false",
                        help="skip the photo-consistency refinement (silhouettes only)")
    parser.add_argument("--free-border-trim", type=float, default=1.0, metavar="EDGES",
                        help="edge lengths cut off the borders that hang free of the body, where the silhouettes' "
                             "hull curls under the garment (a hem; default: 1; 0 keeps them)")
    parser.add_argument("--appearance-iterations", type=int, default=300,
                        help="optimization steps of the initial Gaussian appearance (one view each)")
    add_progress_option(parser)


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..stages.template import TemplateRequest, run_template

    for name in ("vertices", "resolution", "voxel_mm"):
        value = getattr(args, name)
        if value is not None and value <= 0:
            raise InputError(f"--{name.replace('_', '-')} must be positive", f"got {value}", "pass a positive number")
    if args.free_border_trim < 0:
        raise InputError("--free-border-trim must not be negative", f"got {args.free_border_trim}", "pass 0 or more")
    if args.appearance_iterations < 0:
        raise InputError("--appearance-iterations must not be negative", f"got {args.appearance_iterations}",
                         "pass 0 or more")
    req = TemplateRequest(capture=args.capture, project=args.project, sequence=args.sequence, frame=args.frame,
                          cameras=args.cameras, vertices=args.vertices, resolution=args.resolution,
                          voxel_mm=args.voxel_mm, photo=args.photo, free_border_trim=args.free_border_trim,
                          appearance_iterations=args.appearance_iterations, progress=args.progress)
    report = run_template(req)
    if args.progress != "jsonl":
        data = json.loads(report.read_text())
        keys = ("sequence", "frame", "vertices", "faces", "gaussians", "cd_cm", "p2m_cm", "fscore_1cm")
        print(json.dumps({"report": str(report), **{k: data[k] for k in keys if k in data}}))
    return 0
