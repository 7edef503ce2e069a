"""Crash-safe writes and the cross-process lock that lets benchmark runs share a capture cache."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from gg_core.storage import atomic_path, exclusive

HOLD = """
import sys, time
from gg_core.storage import exclusive
lock, log, tag = sys.argv[1:]
with exclusive(lock):
    with open(log, "a") as f:
        f.write(f"start {tag}\\n")
    time.sleep(0.4)
    with open(log, "a") as f:
        f.write(f"end {tag}\\n")
"""


@pytest.mark.skipif(sys.platform == "win32", reason="the lock is POSIX only")
def test_exclusive_lets_one_process_in_at_a_time(tmp_path):
    lock, log = tmp_path / "sub" / ".x.lock", tmp_path / "log.txt"
    root = Path(__file__).resolve().parents[2]
    procs = [subprocess.Popen([sys.executable, "-c", HOLD, str(lock), str(log), str(k)], cwd=root)
             for k in range(3)]
    assert [p.wait(timeout=60) for p in procs] == [0, 0, 0]
    lines = log.read_text().split()
    pairs = [(lines[i], lines[i + 1], lines[i + 2], lines[i + 3]) for i in range(0, len(lines), 4)]
    assert len(pairs) == 3
    assert all(a == "start" and c == "end" and b == d for a, b, c, d in pairs)     # never interleaved
    with exclusive(lock):       # released: taken again at once
        pass


def test_atomic_path_leaves_nothing_when_the_block_fails(tmp_path):
    target = tmp_path / "out.json"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash")
    assert list(tmp_path.iterdir()) == []
