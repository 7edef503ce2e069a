"""Runs in a fresh process whose BLENDER_USER_RESOURCES is a temporary folder (set before bpy is imported):
install the built zip as a user extension, enable it, import a capture with its operator, run a gg job.
Prints one JSON object with what it found."""
from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

import bpy

zip_path, capture = sys.argv[1:3]
module = "bl_ext.user_default.gaussian_garments"
installed = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
addon = bpy.context.preferences.addons.get(module)
imported = bpy.ops.gg.import_capture(directory=capture)
new_collections = [c for c in bpy.data.collections if "gg_sequence" in c]
objects = [o for c in new_collections for o in c.objects]
body = next(o for o in objects if o.type == "MESH")
job = bpy.ops.gg.run_job(stage="inspect", arguments=shlex.join([capture]))
print(json.dumps({
    "installed": sorted(installed),
    "enabled": addon is not None,
    "preferences": type(addon.preferences).__name__ if addon else None,
    "package_dir": str(Path(sys.modules[module].__file__).parent),
    "imported": sorted(imported),
    "collections": sorted(c.name for c in new_collections),
    "cameras": sorted(o.name for o in objects if o.type == "CAMERA"),
    "body_cache": body.modifiers["Body Motion"].filepath,
    "job": sorted(job),
    "job_result": bpy.context.window_manager.gg_job.result,
}))
