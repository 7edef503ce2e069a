"""UI side of the extension: preferences, scene/job properties, sidebar panels; `jobs` runs `gg` processes.

Submodules that need bpy are imported in register() so the bpy-free ones (jobs, convert, mesh_cache) can be
used and tested without Blender.
"""
from __future__ import annotations


def register() -> None:
    import bpy

    from . import panels, preferences, properties

    bpy.utils.register_class(preferences.GG_AddonPreferences)
    properties.register()
    panels.register()


def unregister() -> None:
    import bpy

    from . import jobs, panels, preferences, properties

    jobs.cancel_current()
    panels.unregister()
    properties.unregister()
    bpy.utils.unregister_class(preferences.GG_AddonPreferences)
