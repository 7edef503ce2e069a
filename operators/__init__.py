"""bpy operators of the extension: import a capture, run / cancel a `gg` job, look through a capture camera."""
from __future__ import annotations


def _classes() -> tuple:
    from . import import_capture, run_job

    return (*run_job.CLASSES, *import_capture.CLASSES)


def register() -> None:
    import bpy

    for cls in _classes():
        bpy.utils.register_class(cls)


def unregister() -> None:
    import bpy

    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
