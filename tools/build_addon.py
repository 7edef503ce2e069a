"""Validate and build the Blender extension zip with the extension tool shipped inside the bpy wheel.

`python tools/build_addon.py --out DIR` runs `blender_ext.py validate` (tags checked against Blender's own
list) and `blender_ext.py build` on the repository root, then prints the zip's path. Same checks as
`blender --command extension validate|build`, without a Blender install.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def bpy_scripts_dir() -> Path:
    """bpy/<version>/scripts of the installed bpy wheel, located without importing bpy (slow, heavy)."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("build_addon: the bpy module is not installed in this Python (run `make venv`)")
    found = sorted(Path(next(iter(spec.submodule_search_locations))).glob("*/scripts/addons_core/bl_pkg"))
    if not found:
        raise SystemExit("build_addon: bpy wheel has no bl_pkg extension tool")
    return found[-1].parents[1]


def run_tool(args: list[str]) -> str:
    scripts = bpy_scripts_dir()
    tool = scripts / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    tags = scripts / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    proc = subprocess.run([sys.executable, str(tool), *args, "--valid-tags", str(tags)], capture_output=True,
                          text=True)
    if proc.returncode != 0:
        raise SystemExit(f"build_addon: {args[0]} failed:\n{proc.stdout}{proc.stderr}")
    return proc.stdout


def build(out_dir: Path, source: Path = ROOT) -> Path:
    """Validate the source tree, build the zip into `out_dir`, validate the zip; returns its path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    run_tool(["validate", str(source)])
    output = run_tool(["build", "--source-dir", str(source), "--output-dir", str(out_dir)])
    created = [line for line in output.splitlines() if line.startswith("created:")]
    if not created:
        raise SystemExit(f"build_addon: the builder reported no zip:\n{output}")
    zip_path = Path(created[-1].split('"')[1])
    run_tool(["validate", str(zip_path)])
    return zip_path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "addon", help="folder for the zip")
    args = parser.parse_args(argv)
    print(build(args.out.resolve()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
