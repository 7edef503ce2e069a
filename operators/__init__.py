"""bpy operators of the extension: import a capture, run / cancel a `gg` job, look through a capture camera,
run the pipeline stages and load their results into the scene."""
from __future__ import annotations


def _classes() -> tuple:
    from . import import_capture, results, run_job, stages

    return (*run_job.CLASSES, *import_capture.CLASSES, *stages.CLASSES, *results.CLASSES)


def register() -> None:
    import bpy

    for cls in _classes():
        bpy.utils.register_class(cls)


def unregister() -> None:
    import bpy

    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
