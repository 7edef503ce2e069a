"""`gg synth`: generate a synthetic multi-view garment capture with ground truth (Blender cloth + Cycles)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..cli import add_progress_option

HELP = "generate a synthetic multi-view capture (Blender cloth simulation + Cycles) with ground truth"


def configure(parser: argparse.ArgumentParser) -> None:
    from ..synth.effects import EFFECTS
    from ..synth.fabrics import PATTERNS
    from ..synth.garments import GARMENTS
    from ..synth.presets import PRESETS

    parser.add_argument("--preset", choices=list(PRESETS), default="tiny",
                        help="size: tiny (CI, ~1 min), demo (~10 min), bench (large); see gg_core/synth/presets.py")
    parser.add_argument("--out", type=Path, required=True, help="capture folder to write (resumed if it exists)")
    parser.add_argument("--seed", type=int, default=0, help="seed of colours, cameras jitter and motion variation")
    parser.add_argument("--garment", choices=list(GARMENTS), default="skirt", help="garment template")
    parser.add_argument("--motions", nargs="+", metavar="MOTION", default=[],
                        help="motion of each sequence (cycled; default: the preset's list), e.g. walk arm_swing")
    parser.add_argument("--effect", choices=list(EFFECTS), default="none",
                        help="hidden physics made by Blender only: " + "; ".join(
                            f"{n}: {e.description}".replace("%", "%%") for n, e in EFFECTS.items()))
    parser.add_argument("--effect-param", action="append", default=[], metavar="KEY=VALUE",
                        help="override an effect parameter (repeatable), e.g. strength=40 or region=hem")
    parser.add_argument("--texture", choices=list(PATTERNS), default="print",
                        help="fabric pattern: print, weave, or fuzzy (fur-like fibres with sheen)")
    parser.add_argument("--sequences", type=int, metavar="N",
                        help="number of sequences (default: the preset's); e.g. 1 to time a large preset quickly")
    parser.add_argument("--frames", type=int, metavar="N", help="recorded frames per sequence (default: the preset's)")
    parser.add_argument("--no-render", action="store_true",
                        help="simulate and write ground truth only (no images; the capture is then incomplete)")
    parser.add_argument("--no-check", action="store_true", help="skip the quality checks in the report")
    add_progress_option(parser)


def run(args: argparse.Namespace) -> int:
    from ..synth.generate import SynthRequest, generate
    from ..synth.presets import get_preset, resized

    preset = resized(get_preset(args.preset), args.sequences, args.frames)
    req = SynthRequest(preset=preset, out=args.out, seed=args.seed, garment=args.garment,
                       motions=args.motions, effect=args.effect, effect_params=args.effect_param,
                       texture=args.texture, render=not args.no_render, check=not args.no_check,
                       progress=args.progress)
    report = generate(req)
    if args.progress != "jsonl":
        summary = json.loads(report.read_text())
        print(json.dumps({"report": str(report), "timings": summary["timings"],
                          "quality": summary.get("quality")}, indent=1))
    return 0
