"""Add-on preferences: which Python runs the `gg` jobs (it needs torch; Blender's own Python does not)."""
from __future__ import annotations

import bpy
from bpy.props import StringProperty
from bpy.types import AddonPreferences, Context

from ..gg_core.errors import InputError
from .jobs import python_for_jobs

# bl_idname of add-on preferences is the extension's own package (bl_ext.<repo>.gaussian_garments), our parent.
ADDON_PACKAGE = __package__.rpartition(".")[0]


class GG_AddonPreferences(AddonPreferences):
    bl_idname = ADDON_PACKAGE

    python_path: StringProperty(
        name="Python",
        subtype="FILE_PATH",
        description="Python interpreter of the Gaussian Garments environment (with torch and gg_core's "
                    "dependencies). Empty: $GG_PYTHON, else the .venv of the repository checkout",
    )

    def draw(self, context: Context) -> None:
        layout = self.layout
        layout.prop(self, "python_path")
        resolved = python_for_jobs(bpy.path.abspath(self.python_path))
        if resolved:
            layout.label(text=f"Jobs run with: {resolved}", icon="CHECKMARK")
        else:
            layout.label(text="No Python found: set it here or in $GG_PYTHON", icon="ERROR")


def python_executable(context: Context) -> str:
    """The interpreter for jobs; InputError (shown to the user as one line) when none is configured."""
    addon = context.preferences.addons.get(ADDON_PACKAGE)
    configured = bpy.path.abspath(addon.preferences.python_path) if addon and addon.preferences else ""
    python = python_for_jobs(configured)
    if python is None:
        raise InputError("no Python configured for gg jobs", "add-on preferences",
                         "set 'Python' to the interpreter of the Gaussian Garments environment (or set $GG_PYTHON)")
    return python
