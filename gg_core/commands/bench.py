"""`gg bench <what>`: performance benchmarks that time a fast path against a baseline in the same run."""
from __future__ import annotations

import argparse
import importlib

HELP = "benchmarks (JSON output): each compares the product's fast path with a baseline in the same run"

# benchmark name -> module under gg_core.commands exposing HELP, configure(parser), run(args)
BENCHES: dict[str, str] = {
    "raster": "bench_raster",
    "sim": "bench_sim",
    "register": "bench_register",
    "diagnose": "bench_diagnose",
    "stereo": "bench_stereo",
}


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bench", metavar="<benchmark>", required=True)
    for name, module_name in BENCHES.items():
        module = importlib.import_module(f"{__package__}.{module_name}")
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.configure(p)
        p.set_defaults(_run=module.run)


def run(args: argparse.Namespace) -> int:  # replaced by the chosen benchmark's run via set_defaults
    raise AssertionError("unreachable: argparse dispatches to the benchmark's run")
