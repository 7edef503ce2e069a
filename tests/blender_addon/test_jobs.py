"""The job runner on real child processes: protocol parsing, cancel of the whole process group, exit 2."""
from __future__ import annotations

import importlib
import os
import sys
import textwrap
import time

import pytest


@pytest.fixture
def jobs(extension_package):
    return importlib.import_module(f"{extension_package.__name__}.blender_addon.jobs")


def python_job(jobs, code: str, stage: str = "demo"):
    return jobs.Job([sys.executable, "-c", textwrap.dedent(code)], stage).start()


def test_progress_lines_are_parsed(jobs, tmp_path):
    events = []
    job = python_job(jobs, f"""
        import time
        from gg_core.jobs import Progress
        print("a log line that is not protocol", flush=True)
        p = Progress("demo", 4, "jsonl")
        for i in range(4):
            time.sleep(0.05)
            p.step(f"item {{i}}")
        p.done({str(tmp_path / 'report.json')!r})
    """)
    result = job.run_to_end(on_event=events.append)
    assert result.ok and result.returncode == 0
    assert [e.get("step") for e in events] == [1, 2, 3, 4, None]
    assert all(e["eta_s"] >= 0 for e in events[:4])
    assert events[-1] == {"stage": "demo", "done": True, "report": str(tmp_path / "report.json")}
    s = job.state
    assert (s.step, s.total, s.message, s.done, s.report) == (4, 4, "item 3", True, str(tmp_path / "report.json"))
    assert s.fraction == 1.0
    assert list(job.log) == ["a log line that is not protocol"]
    assert jobs.describe(s) == "demo 4/4 · item 3 · done"


def test_cancel_stops_the_process_group(jobs, tmp_path):
    pid_file = tmp_path / "child.pid"
    job = python_job(jobs, f"""
        import subprocess, sys, time
        from gg_core.jobs import Progress
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
        open({str(pid_file)!r}, "w").write(str(child.pid))
        p = Progress("demo", 10, "jsonl")
        p.step("first")
        time.sleep(60)
    """)
    deadline = time.monotonic() + 20
    while job.state.step < 1 and time.monotonic() < deadline:
        time.sleep(0.05)
        job.poll()
    assert job.state.step == 1 and job.running
    start = time.monotonic()
    job.cancel()
    result = job.run_to_end()  # returns only once the pipes close: every process of the group is gone
    assert time.monotonic() - start < 5.0
    assert result.cancelled and not result.ok and result.returncode != 0
    child = int(pid_file.read_text())
    deadline = time.monotonic() + 3
    while alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(child)  # the grandchild went down with the process group


def alive(pid: int) -> bool:
    """The process exists and is not a zombie waiting to be reaped by whoever adopted it."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_exit_code_2_gives_the_error_line(jobs):
    job = python_job(jobs, """
        import sys
        print("some warning", file=sys.stderr)
        print("gg: error: capture folder not found, /nowhere, pass the folder that holds the sequences",
              file=sys.stderr)
        sys.exit(2)
    """)
    result = job.run_to_end()
    assert result.returncode == 2 and not result.cancelled
    assert result.error_line == ("gg: error: capture folder not found, /nowhere, "
                                 "pass the folder that holds the sequences")


def test_crash_reports_the_last_stderr_line(jobs):
    result = python_job(jobs, "raise RuntimeError('boom')").run_to_end()
    assert result.returncode == 1 and result.error_line == "RuntimeError: boom"


def test_python_resolution_order(jobs, monkeypatch, tmp_path):
    monkeypatch.setenv("GG_PYTHON", "/opt/gg/bin/python")
    assert jobs.python_for_jobs("/configured/python") == "/configured/python"
    assert jobs.python_for_jobs("") == "/opt/gg/bin/python"
    monkeypatch.delenv("GG_PYTHON")
    venv_python = tmp_path / ".venv" / "bin" / "python"
    venv_python.parent.mkdir(parents=True)
    venv_python.write_text("")
    monkeypatch.setattr(jobs, "EXTENSION_ROOT", tmp_path)
    assert jobs.python_for_jobs("") == str(venv_python)
    venv_python.unlink()
    assert jobs.python_for_jobs("") is None


def test_job_command_line_and_environment(jobs):
    assert jobs.gg_argv("/py", "inspect", ["/cap ture"]) == ["/py", "-m", "gg_core", "inspect", "/cap ture",
                                                              "--progress", "jsonl"]
    env = jobs.job_env({"PYTHONPATH": "/other"})
    assert env["PYTHONPATH"].split(os.pathsep) == [str(jobs.EXTENSION_ROOT), "/other"]


@pytest.mark.parametrize("seconds, text", [(0.4, "0 s"), (59.6, "1 min 00 s"), (125, "2 min 05 s"),
                                           (7300, "2 h 01 min")])
def test_format_seconds(jobs, seconds, text):
    assert jobs.format_seconds(seconds) == text
