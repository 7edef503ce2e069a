"""Progress protocol shared by every long-running `gg` command and the Blender job runner.

With ``--progress jsonl`` each step is one JSON object per line on stdout:
``{"stage", "step", "total", "message", "eta_s"}`` and finally
``{"stage", "done": true, "report": path}``. The add-on parses exactly these lines.
"""
from __future__ import annotations

import json
import sys
import time
from typing import TextIO

MODES = ("bar", "jsonl", "none")


class Progress:
    """Reports steps of one stage as JSON lines, a human bar, or nothing."""

    def __init__(self, stage: str, total: int, mode: str = "bar", stream: TextIO | None = None) -> None:
        if mode not in MODES:
            raise ValueError(f"progress mode must be one of {MODES}, got {mode!r}")
        self.stage = stage
        self.total = max(int(total), 1)
        self.mode = mode
        self.stream = stream or (sys.stdout if mode == "jsonl" else sys.stderr)
        self.start = time.perf_counter()
        self.count = 0
        self._bar = None
        if mode == "bar":
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, desc=stage, file=self.stream, leave=False)

    def eta_s(self) -> float | None:
        if self.count == 0:
            return None
        elapsed = time.perf_counter() - self.start
        return elapsed / self.count * (self.total - self.count)

    def step(self, message: str = "", advance: int = 1) -> None:
        """Advance by `advance` steps and report the new position."""
        self.count = min(self.count + advance, self.total)
        if self.mode == "jsonl":
            eta = self.eta_s()
            self._emit({"stage": self.stage, "step": self.count, "total": self.total,
                        "message": message, "eta_s": None if eta is None else round(eta, 2)})
        elif self._bar is not None:
            self._bar.update(advance)
            if message:
                self._bar.set_postfix_str(message, refresh=False)

    def done(self, report: str | None = None) -> None:
        """Final line: the stage finished and its report lies at `report`."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if self.mode == "jsonl":
            self._emit({"stage": self.stage, "done": True, "report": report})

    def _emit(self, obj: dict) -> None:
        self.stream.write(json.dumps(obj) + "\n")
        self.stream.flush()


def parse_line(line: str) -> dict | None:
    """Parse one protocol line; anything else (log output) gives None."""
    line = line.strip()
    if not line.startswith("{"):
        return None
    try:
        obj = json.loads(line)
    except json.JSONDecodeError:
        return None
    return obj if isinstance(obj, dict) and "stage" in obj else None
