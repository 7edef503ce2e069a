"""Batch Blender session for pipeline TDs: install the extension zip, import a capture, save a .blend.

Runs the same way inside Blender and with the bpy module:
    blender --background --python tools/blender_batch.py -- --addon ZIP --capture DIR --save OUT.blend
    python tools/blender_batch.py --addon ZIP --capture DIR --save OUT.blend [--user-resources DIR]
With --user-resources the extension is installed into that Blender user folder (BLENDER_USER_RESOURCES must be
set before bpy loads, so the script re-runs itself once with it set). Prints one JSON summary line.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

MODULE = "bl_ext.user_default.gaussian_garments"


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--addon", type=Path, required=True, help="extension zip built by `make addon`")
    parser.add_argument("--capture", type=Path, required=True, help="capture folder to import")
    parser.add_argument("--save", type=Path, required=True, help=".blend file to write")
    parser.add_argument("--user-resources", type=Path, help="Blender user folder to install the extension into")
    return parser.parse_args(argv)


def blender_args() -> list[str]:
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]


def main() -> int:
    args = parse(blender_args())
    wanted = str(args.user_resources.resolve()) if args.user_resources else None
    if wanted and os.environ.get("BLENDER_USER_RESOURCES") != wanted and "bpy" not in sys.modules:
        env = dict(os.environ, BLENDER_USER_RESOURCES=wanted)
        return subprocess.call([sys.executable, __file__, *blender_args()], env=env)
    import bpy

    if bpy.context.preferences.addons.get(MODULE) is None:
        bpy.ops.extensions.package_install_files(filepath=str(args.addon.resolve()), repo="user_default",
                                                 enable_on_install=True)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.gg.project_path = str(args.save.resolve().parent)
    try:
        bpy.ops.gg.import_capture(directory=str(args.capture.resolve()))
    except RuntimeError as exc:  # the operator's ERROR report, already a `gg: error:` line
        print(str(exc).removeprefix("Error: ").strip(), file=sys.stderr)
        return 2
    args.save.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(args.save.resolve()))
    collections = [c for c in bpy.data.collections if "gg_sequence" in c]
    print(json.dumps({"saved": str(args.save), "sequences": [c.name for c in collections],
                      "cameras": sum(o.type == "CAMERA" for c in collections for o in c.objects),
                      "frames": [bpy.context.scene.frame_start, bpy.context.scene.frame_end]}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
