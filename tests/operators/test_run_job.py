"""gg.run_job in background mode: a real `gg inspect` job runs to its end; exit 2 becomes one error line."""
from __future__ import annotations

import importlib
import shlex

import pytest

pytestmark = pytest.mark.bpy


def test_inspect_job_runs_synchronously(blender, capture_writer, tmp_path, capsys):
    capture = capture_writer(tmp_path / "capture", n_cams=2, n_frames=2, sequences=("seqA", "seqB"))
    result = blender.ops.gg.run_job(stage="inspect", arguments=shlex.join([str(capture)]))
    assert result == {"FINISHED"}
    job = blender.context.window_manager.gg_job
    assert (job.running, job.failed, job.progress) == (False, False, 1.0)
    assert job.result == "gg inspect: done"
    assert job.status == "inspect 2/2 · seqB · done"
    echoed = capsys.readouterr().out
    assert "gg inspect 1/2 · seqA" in echoed  # background mode prints each step


def test_exit_2_is_reported_as_the_gg_error_line(blender, tmp_path):
    missing = tmp_path / "no capture here"
    with pytest.raises(RuntimeError, match=r"gg: error: capture folder not found, .*no capture here"):
        blender.ops.gg.run_job(stage="inspect", arguments=shlex.join([str(missing)]))
    job = blender.context.window_manager.gg_job
    assert job.failed and not job.running
    assert job.result.startswith("gg: error: capture folder not found")


def test_missing_python_is_a_clear_error(blender, extension_package, monkeypatch, tmp_path):
    jobs = importlib.import_module(f"{extension_package.__name__}.blender_addon.jobs")
    monkeypatch.delenv("GG_PYTHON", raising=False)
    monkeypatch.setattr(jobs, "EXTENSION_ROOT", tmp_path)  # no .venv next to the add-on
    with pytest.raises(RuntimeError, match=r"gg: error: no Python configured for gg jobs, add-on preferences"):
        blender.ops.gg.run_job(stage="inspect", arguments="x")


def test_unstartable_python_is_a_clear_error(blender, monkeypatch, tmp_path):
    monkeypatch.setenv("GG_PYTHON", str(tmp_path / "no-python"))
    with pytest.raises(RuntimeError, match=r"gg: error: cannot start the job's Python .*no-python"):
        blender.ops.gg.run_job(stage="inspect", arguments="x")


def test_modal_path_follows_progress_and_cancels(blender, extension_package):
    """The UI path: timer events drive modal(); Cancel in the panel stops the job. Background mode never sends
    timer events, so the test sends them to the operator's own modal() through a stand-in instance."""
    import sys
    import textwrap
    import time
    from types import SimpleNamespace

    jobs = importlib.import_module(f"{extension_package.__name__}.blender_addon.jobs")
    run_job = importlib.import_module(f"{extension_package.__name__}.operators.run_job")
    op_cls = run_job.GG_OT_run_job

    class StandIn:  # the attributes and methods Blender's operator instance would carry
        modal, _show, _finish, _fail = op_cls.modal, op_cls._show, op_cls._finish, op_cls._fail
        stage, then = "demo", ""

        def __init__(self):
            self.reports = []

        def report(self, kind, message):
            self.reports.append((set(kind), message))

    code = textwrap.dedent("""
        import time
        from gg_core.jobs import Progress
        p = Progress("demo", 4, "jsonl")
        for i in range(4):
            p.step(f"item {i}")
            time.sleep(0.3 if i < 2 else 60)
    """)
    context = blender.context
    op = StandIn()
    op._job = jobs.Job([sys.executable, "-c", code], "demo").start()
    jobs.set_current(op._job)
    op._timer = context.window_manager.event_timer_add(0.1, window=None)
    context.window_manager.gg_job.running = True
    timer = SimpleNamespace(type="TIMER")
    assert op.modal(context, SimpleNamespace(type="MOUSEMOVE")) == {"PASS_THROUGH"}
    seen = set()
    deadline = time.monotonic() + 30
    while context.window_manager.gg_job.progress < 0.75 and time.monotonic() < deadline:
        assert op.modal(context, timer) == {"PASS_THROUGH"}
        seen.add(round(context.window_manager.gg_job.progress, 2))
        time.sleep(0.05)
    assert {0.25, 0.5, 0.75} <= seen
    assert context.window_manager.gg_job.status.startswith("demo 3/4 · item 2 · ETA")
    assert blender.ops.gg.cancel_job.poll()
    assert blender.ops.gg.cancel_job() == {"FINISHED"}
    while (result := op.modal(context, timer)) == {"PASS_THROUGH"} and time.monotonic() < deadline:
        time.sleep(0.05)
    assert result == {"CANCELLED"}
    state = context.window_manager.gg_job
    assert (state.running, state.failed, state.result) == (False, True, "gg demo: cancelled")
    assert op.reports == [({"WARNING"}, "gg demo: cancelled")]
    assert not blender.ops.gg.cancel_job.poll()
