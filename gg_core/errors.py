"""User-facing errors: bad input becomes exit code 2 and one line, never a traceback."""
from __future__ import annotations


class InputError(Exception):
    """Bad input the user can fix. Rendered as `gg: error: <what>, <where>, <how to fix>`."""

    def __init__(self, what: str, where: str | object = "", fix: str = "") -> None:
        self.what = what
        self.where = str(where)
        self.fix = fix
        super().__init__(self.line())

    def __reduce__(self):
        """Pickles with its three parts (a worker process's error re-raised in the parent reads the same)."""
        return type(self), (self.what, self.where, self.fix)

    def line(self) -> str:
        parts = [self.what] + [p for p in (self.where, self.fix) if p]
        return "gg: error: " + ", ".join(parts)
