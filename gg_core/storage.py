"""Crash-safe writes: everything goes to a temporary name in the target folder, then is renamed.

A cancelled or crashed stage therefore never leaves a half-written file under a final name. Also what stages
record of their inputs to resume (file_stamps).
"""
from __future__ import annotations

import json
import os
import platform
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to `path`; rename it onto `path` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix if suffix is not None else path.suffix,
                               dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


@contextmanager
def exclusive(lock_file: str | os.PathLike) -> Iterator[None]:
    """Hold an exclusive lock on `lock_file` (created if missing) for the block; other processes wait. POSIX
    only (fcntl); elsewhere the block runs unlocked.

    Why: several `gg bench diagnose` runs share one capture cache (one run per core); two generating the same
    capture at once removed each other's temporary files (session 43: a gravity and an air damping run both
    generating the reference capture, one crashed)."""
    try:
        import fcntl  # noqa: PLC0415 - POSIX only
    except ImportError:
        yield
        return
    lock_file = Path(lock_file)
    lock_file.parent.mkdir(parents=True, exist_ok=True)
    with open(lock_file, "a+b") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle.fileno(), fcntl.LOCK_UN)


def file_stamps(paths: Iterable[Path], root: Path | None = None) -> list[list]:
    """[name (relative to `root`, else the file name), size, mtime_ns] per file: what a stage's resume key records
    of its input files, so a rewritten input reruns the stage and an untouched one does not."""
    return [[str(p.relative_to(root)) if root else p.name, p.stat().st_size, p.stat().st_mtime_ns] for p in paths]


def write_json(path: str | os.PathLike, obj: Any) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2, default=_json_default) + "\n")
    return Path(path)


def write_npz(path: str | os.PathLike, **arrays: Any) -> Path:
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez_compressed(tmp, **arrays)
    return Path(path)


def write_report(project: str | os.PathLike, stage: str, payload: dict) -> Path:
    """Write `<project>/reports/<stage>.json` with versions and a timestamp added."""
    report = {"stage": stage, "created": time.strftime("%Y-%m-%dT%H:%M:%S"), "versions": versions()}
    report.update(payload)
    return write_json(Path(project) / "reports" / f"{stage}.json", report)


def versions() -> dict[str, str]:
    from . import __version__

    out = {"gg_core": __version__, "python": platform.python_version(), "numpy": np.__version__}
    try:
        import torch  # noqa: PLC0415 - optional here, always present in the project env

        out["torch"] = torch.__version__
    except ImportError:
        pass
    return out


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")
