"""Run one `gg` stage as a job: progress, ETA and Cancel in the panel; synchronous in background mode.

Other operators reuse it: bpy.ops.gg.run_job(stage="register", arguments=shlex.join([...]), then="load_registration")
runs the stage, then the operator that brings its results into the scene.
In the UI the job is followed by a modal operator woken by a timer; with `blender --background` timers and
modal handlers never fire, so the same job runs to its end inside execute().
"""
from __future__ import annotations

import shlex

import bpy
from bpy.props import StringProperty
from bpy.types import Context, Event, Operator

from ..blender_addon import jobs
from ..blender_addon.preferences import python_executable
from ..gg_core.errors import InputError

TIMER_INTERVAL_S = 0.2


class GG_OT_run_job(Operator):
    """Run a Gaussian Garments stage in the configured Python, showing its progress"""

    bl_idname = "gg.run_job"
    bl_label = "Run gg Job"

    stage: StringProperty(name="Stage", description="gg command to run (e.g. inspect, template, register)")
    arguments: StringProperty(name="Arguments", description="Command-line arguments after the stage, shell-quoted")
    then: StringProperty(name="Then", description="gg operator to run after the job succeeds (e.g. load_template) "
                                                  "to show its results in the scene")

    def execute(self, context: Context) -> set[str]:
        previous = jobs.current()
        if previous is not None and not previous.finished():
            self.report({"ERROR"}, f"gg: error: a '{previous.state.stage}' job is still running, Garments panel, "
                                   "wait for it or cancel it")
            return {"CANCELLED"}
        try:
            python = python_executable(context)
            argv = jobs.gg_argv(python, self.stage, shlex.split(self.arguments))
        except InputError as exc:
            return self._fail(context, exc.line())
        except ValueError as exc:  # shlex: unbalanced quotes
            return self._fail(context, f"gg: error: arguments cannot be parsed ({exc}), {self.arguments}, "
                                       "quote them with shlex.join")
        job = jobs.Job(argv, self.stage)
        try:
            job.start()
        except OSError as exc:
            return self._fail(context, f"gg: error: cannot start the job's Python ({exc.strerror}), {python}, "
                                       "set 'Python' in the add-on preferences")
        jobs.set_current(job)
        state = context.window_manager.gg_job
        state.running, state.stage, state.progress, state.status = True, self.stage, 0.0, f"{self.stage}: starting"
        state.result, state.failed = "", False
        if bpy.app.background:
            result = job.run_to_end(on_event=lambda _event: self._show(context, job, echo=True))
            return self._finish(context, job, result)
        self._job = job
        wm = context.window_manager
        self._timer = wm.event_timer_add(TIMER_INTERVAL_S, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context: Context, event: Event) -> set[str]:
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        job = self._job
        if job.poll():
            self._show(context, job)
        if not job.finished():
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        return self._finish(context, job, job.result())

    def _show(self, context: Context, job: jobs.Job, echo: bool = False) -> None:
        state = context.window_manager.gg_job
        state.progress = job.state.fraction
        state.status = jobs.describe(job.state)
        if echo:
            print(f"gg {state.status}", flush=True)
        _redraw_sidebars(context)

    def _finish(self, context: Context, job: jobs.Job, result: jobs.JobResult) -> set[str]:
        state = context.window_manager.gg_job
        state.running = False
        self._show(context, job)
        if result.ok:
            state.result = f"gg {self.stage}: done" + (f", report {job.state.report}" if job.state.report else "")
            state.failed = False
            self.report({"INFO"}, state.result)
            if self.then:
                getattr(bpy.ops.gg, self.then)()
            return {"FINISHED"}
        if result.cancelled:
            state.result, state.failed = f"gg {self.stage}: cancelled", True
            self.report({"WARNING"}, state.result)
            return {"CANCELLED"}
        if result.returncode == 2 and result.error_line:
            return self._fail(context, result.error_line)
        return self._fail(context, f"gg {self.stage} failed with exit code {result.returncode}: "
                                   f"{result.error_line or 'no error output'}")

    def _fail(self, context: Context, line: str) -> set[str]:
        state = context.window_manager.gg_job
        state.running, state.result, state.failed = False, line, True
        self.report({"ERROR"}, line)
        _redraw_sidebars(context)
        return {"CANCELLED"}


class GG_OT_cancel_job(Operator):
    """Stop the running Gaussian Garments job (finished outputs are kept: stages write atomically)"""

    bl_idname = "gg.cancel_job"
    bl_label = "Cancel Job"

    @classmethod
    def poll(cls, context: Context) -> bool:
        job = jobs.current()
        return job is not None and job.running

    def execute(self, context: Context) -> set[str]:
        jobs.cancel_current()
        return {"FINISHED"}


def _redraw_sidebars(context: Context) -> None:
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


CLASSES = (GG_OT_run_job, GG_OT_cancel_job)
