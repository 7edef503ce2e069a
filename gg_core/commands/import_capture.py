"""`gg import --format F SRC --out CAPTURE`: convert a 4D-Dress, ActorsHQ or COLMAP capture into the product layout."""
from __future__ import annotations

import argparse
import sys

from ..cli import add_progress_option

HELP = "import a 4D-Dress take, an ActorsHQ sequence or a COLMAP model as a sequence of a capture folder"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", help="4D-Dress take folder (<subject>/<Inner|Outer>/<TakeN>), ActorsHQ folder "
                                       "holding calibration.csv, or COLMAP sparse model / project folder")
    parser.add_argument("--format", required=True, metavar="FORMAT", help="4d-dress, actorshq or colmap")
    parser.add_argument("--out", required=True, help="capture folder to write the sequence into (created if needed)")
    parser.add_argument("--sequence", help="sequence name (default: the take, sequence or project folder name)")
    parser.add_argument("--link", action="store_true",
                        help="hard-link images and masks instead of copying them (same file system only)")
    parser.add_argument("--garment", help="4d-dress: label(s) whose pixels form the garment mask, comma separated "
                                          "(skin, hair, shoe, upper, lower, outer; default outer for Outer takes)")
    parser.add_argument("--body", help="actorshq, colmap: folder of per-frame body meshes named like the frames")
    parser.add_argument("--images", help="colmap: folder holding the model's images (default: images/ beside it)")
    parser.add_argument("--quick", action="store_true",
                        help="validate names, calibration and meshes only, without decoding every image")
    add_progress_option(parser)


def run(args: argparse.Namespace) -> int:
    from ..capture.importers import read_source
    from ..capture.importers.writer import write_sequence

    source = read_source(args.format, args.source, garment=args.garment, body=args.body, images=args.images)
    result = write_sequence(source, args.out, args.sequence, link=args.link, decode_images=not args.quick,
                            progress=args.progress)
    for warning in result.warnings:
        print(f"gg: warning: {warning}", file=sys.stderr)
    if args.progress != "jsonl":
        frames = result.frames
        print(f"imported {source.format} {source.source} -> {result.sequence}: {result.cameras} cameras, "
              f"{len(frames)} frames ({frames[0]}..{frames[-1]}), {result.files_written} files written, "
              f"{result.files_skipped} already in place")
    return 0
