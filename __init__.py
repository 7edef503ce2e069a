"""Gaussian Garments for Blender: extension entry point (the repository root is the extension root).

register() brings up the UI (blender_addon: preferences, properties, panels) and the operators. The imports
sit inside the functions so the package's bpy-free modules stay importable outside Blender.
"""


def register() -> None:
    from . import blender_addon, operators

    blender_addon.register()
    operators.register()


def unregister() -> None:
    from . import blender_addon, operators

    operators.unregister()
    blender_addon.unregister()
