"""`gg` command line: one subcommand per stage or tool, each in gg_core/commands/<name>.py.

Command modules keep heavy imports (torch, bpy) inside `run` so `gg --help` stays instant. Each defines
`HELP` (one line), `configure(parser)` and `run(args) -> int`. InputError becomes exit code 2
and a single `gg: error: ...` line on stderr.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

from .errors import InputError

# name -> module under gg_core.commands. Keep sorted by pipeline order.
COMMANDS: dict[str, str] = {
    "synth": "synth",
    "import": "import_capture",
    "inspect": "inspect",
    "template": "template",
    "register": "register",
    "behavior": "behavior",
    "diagnose": "diagnose",
    "simulate": "simulate",
    "bench": "bench",
    "demo": "demo",
}


def add_progress_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--progress", choices=("bar", "jsonl", "none"), default="bar",
                        help="progress output: a human bar on stderr (default), JSON lines on stdout "
                             "for the Blender job runner, or nothing")


def add_sim_vertices_option(parser: argparse.ArgumentParser) -> None:
    from .stages.motion import SIM_VERTICES  # noqa: PLC0415 - light (no torch), keeps the default in one place

    parser.add_argument("--sim-vertices", type=int, default=SIM_VERTICES,
                        help="garment meshes with more vertices (registered meshes have the template's) are "
                             "simulated on a remeshed copy of about this many that follows the observed surfaces; "
                             "0 simulates the observed mesh itself")


def add_source_option(parser: argparse.ArgumentParser) -> None:
    from .stages.motion import SOURCES  # noqa: PLC0415 - light (no torch), keeps the choices in one place

    parser.add_argument("--source", choices=SOURCES, default="auto",
                        help="garment motion to fit: the registered meshes of stage 2 (P/stage2/<seq>/meshes), the "
                             "synthetic capture's ground truth (gt), or auto: registered when stage 2 has finished "
                             "every sequence, else gt")


def add_vertex_mass_option(parser: argparse.ArgumentParser, more_help: str = "") -> None:
    from .stages.motion import VERTEX_MASS  # noqa: PLC0415 - light (no torch), keeps the choices in one place

    parser.add_argument("--vertex-mass", choices=VERTEX_MASS, default="area",
                        help="how the garment's mass is spread: area = by each vertex's share of the surface (a real "
                             "fabric); uniform = the same on every vertex, as Blender's cloth does (for captures "
                             "Blender simulated)" + more_help)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gg", description="Gaussian Garments: simulation-ready garment assets "
                                     "from multi-view video.")
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(f"{__package__}.commands.{module_name}")
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.configure(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 0 if not argv else 2
    try:
        return int(args._run(args) or 0)
    except InputError as exc:
        print(exc.line(), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gg: cancelled", file=sys.stderr)
        return 130
