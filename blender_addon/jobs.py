"""Background `gg` jobs for the add-on: launch, follow the progress protocol, cancel. No bpy here.

A job is `<python> -m gg_core <stage> <args> --progress jsonl` in a separate process (the add-on never
imports torch). Reader threads collect stdout protocol lines and stderr; the UI polls `Job.poll()` from a
timer (or, in background mode, blocks in `Job.run_to_end()`). The process gets its own process group so
Cancel stops it together with any worker processes it started.
"""
from __future__ import annotations

import collections
import os
import queue
import signal
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from ..gg_core.jobs import parse_line

# The extension root holds gg_core: put it first on the job's PYTHONPATH so the core always matches the add-on.
EXTENSION_ROOT = Path(__file__).resolve().parents[1]
CANCEL_GRACE_S = 5.0
OUTPUT_LINES_KEPT = 200


@dataclass
class JobState:
    """What the panel shows about the running (or last) job."""

    stage: str
    reporting: str = ""  # stage named by the latest line (composite commands report sub-stages)
    step: int = 0
    total: int = 0
    message: str = ""
    eta_s: float | None = None
    report: str | None = None
    done: bool = False  # the stage printed its final protocol line

    @property
    def fraction(self) -> float:
        return self.step / self.total if self.total else 0.0


@dataclass
class JobResult:
    returncode: int
    cancelled: bool
    error_line: str | None  # the `gg: error: ...` line (exit code 2), or the last stderr line on a crash
    stderr_tail: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.returncode == 0 and not self.cancelled


def gg_argv(python: str, stage: str, args: Sequence[str]) -> list[str]:
    """Command line of one protocol-speaking `gg` stage."""
    return [python, "-m", "gg_core", stage, *args, "--progress", "jsonl"]


def job_env(base: dict[str, str] | None = None) -> dict[str, str]:
    env = dict(os.environ if base is None else base)
    env["PYTHONPATH"] = os.pathsep.join([str(EXTENSION_ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env["PYTHONUNBUFFERED"] = "1"
    return env


class Job:
    """One child process speaking the progress protocol."""

    def __init__(self, argv: Sequence[str], stage: str, env: dict[str, str] | None = None):
        self.argv = list(argv)
        self.state = JobState(stage)
        self.env = job_env() if env is None else env
        self.process: subprocess.Popen | None = None
        self.cancelled = False
        self.log: collections.deque[str] = collections.deque(maxlen=OUTPUT_LINES_KEPT)  # non-protocol stdout
        self._stderr: collections.deque[str] = collections.deque(maxlen=OUTPUT_LINES_KEPT)
        self._events: queue.Queue[dict] = queue.Queue()
        self._threads: list[threading.Thread] = []

    def start(self) -> "Job":
        """Launch the process; an unusable executable raises OSError for the caller to report."""
        kwargs: dict = {"start_new_session": True} if os.name == "posix" else \
            {"creationflags": subprocess.CREATE_NEW_PROCESS_GROUP}
        self.process = subprocess.Popen(self.argv, env=self.env, stdin=subprocess.DEVNULL,
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1,
                                        encoding="utf-8", errors="replace", **kwargs)
        self._threads = [threading.Thread(target=self._read_stdout, daemon=True),
                         threading.Thread(target=self._read_stderr, daemon=True)]
        for th in self._threads:
            th.start()
        return self

    @property
    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def poll(self, on_event: Callable[[dict], None] | None = None) -> list[dict]:
        """Apply the protocol lines received so far to `state`, one by one, calling `on_event` after each."""
        events = []
        while True:
            try:
                event = self._events.get_nowait()
            except queue.Empty:
                return events
            self._apply(event)
            events.append(event)
            if on_event is not None:
                on_event(event)

    def finished(self) -> bool:
        """The process has exited and everything it printed has been read."""
        return not self.running and not any(th.is_alive() for th in self._threads)

    def result(self) -> JobResult:
        """Outcome once `finished()`; exit code 2 lines are the product's one-line user errors."""
        assert self.process is not None and self.process.returncode is not None, "job has not finished"
        self.poll()
        tail = list(self._stderr)
        error = next((l for l in reversed(tail) if l.startswith("gg: error:")), None)
        if error is None and self.process.returncode != 0 and tail:
            error = tail[-1]
        return JobResult(self.process.returncode, self.cancelled, error, tail)

    def run_to_end(self, on_event: Callable[[dict], None] | None = None, interval_s: float = 0.05) -> JobResult:
        """Block until the job ends (background mode, where timers never fire), reporting each event."""
        while not self.finished():
            time.sleep(interval_s)
            self.poll(on_event)
        self.poll(on_event)
        return self.result()

    def cancel(self) -> None:
        """Stop the whole process group: terminate, then kill after a grace period."""
        if not self.running:
            return
        self.cancelled = True
        assert self.process is not None
        try:
            if os.name == "posix":
                os.killpg(self.process.pid, signal.SIGTERM)
            else:
                self.process.send_signal(signal.CTRL_BREAK_EVENT)
            self.process.wait(CANCEL_GRACE_S)
        except subprocess.TimeoutExpired:
            if os.name == "posix":
                os.killpg(self.process.pid, signal.SIGKILL)
            else:
                self.process.kill()
            self.process.wait()
        except ProcessLookupError:
            pass
        for th in self._threads:
            th.join(1.0)

    def _apply(self, event: dict) -> None:
        s = self.state
        s.reporting = str(event["stage"])
        if event.get("done"):
            if event["stage"] != s.stage:  # a sub-stage of a composite command finished, not the job
                return
            s.done = True
            s.report = event.get("report")
            s.step = s.total or s.step
            s.eta_s = 0.0
            return
        s.step = int(event.get("step", s.step))
        s.total = int(event.get("total", s.total))
        s.message = str(event.get("message") or s.message)
        eta = event.get("eta_s")
        s.eta_s = float(eta) if isinstance(eta, (int, float)) else None

    def _read_stdout(self) -> None:
        assert self.process is not None and self.process.stdout is not None
        for line in self.process.stdout:
            event = parse_line(line)
            if event is None:
                self.log.append(line.rstrip("\n"))
            else:
                self._events.put(event)

    def _read_stderr(self) -> None:
        assert self.process is not None and self.process.stderr is not None
        for line in self.process.stderr:
            self._stderr.append(line.rstrip("\n"))


def describe(state: JobState) -> str:
    """One status line: `inspect 3/10 · message · ETA 12 s`."""
    name = state.reporting or state.stage
    parts = [f"{name} {state.step}/{state.total}" if state.total else name]
    if state.message:
        parts.append(state.message)
    if state.done:
        parts.append("done")
    elif state.eta_s is not None:
        parts.append(f"ETA {format_seconds(state.eta_s)}")
    return " · ".join(parts)


def format_seconds(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    if seconds < 60:
        return f"{seconds} s"
    minutes, sec = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes} min {sec:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


_current: Job | None = None


def current() -> Job | None:
    """The job the add-on is following (one at a time)."""
    return _current


def set_current(job: Job | None) -> None:
    global _current
    _current = job


def cancel_current() -> None:
    if _current is not None:
        _current.cancel()


def python_for_jobs(configured: str = "") -> str | None:
    """Interpreter for `gg` jobs: the preference, else $GG_PYTHON, else this checkout's .venv, else None."""
    if configured:
        return configured
    if os.environ.get("GG_PYTHON"):
        return os.environ["GG_PYTHON"]
    venv = EXTENSION_ROOT / ".venv"
    for candidate in (venv / "bin" / "python", venv / "Scripts" / "python.exe"):
        if candidate.is_file():
            return str(candidate)
    return None
