"""`gg import`: bad formats, options and sources give exit 2 and one `gg: error:` line, no traceback."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from gg_core.cli import main


@pytest.mark.parametrize("args, message", [
    (["--format", "zip", "SRC"], "unknown capture format 'zip', --format, choose one of 4d-dress, actorshq, colmap"),
    (["--format", "colmap", "SRC", "--garment", "outer"], "option(s) --garment do not apply to format 'colmap'"),
    (["--format", "4d-dress", "SRC", "--body", "B"], "option(s) --body do not apply to format '4d-dress'"),
    (["--format", "actorshq", "MISSING"], "source not found"),
    (["--format", "4d-dress", "SRC"], "not a 4D-Dress take (no Capture/cameras.pkl)"),
    (["--format", "actorshq", "SRC"], "calibration.csv not found"),
])
def test_bad_input_is_one_line(tmp_path: Path, capsys, args: list[str], message: str) -> None:
    (tmp_path / "SRC").mkdir()
    args = [str(tmp_path / a) if a in ("SRC", "MISSING") else a for a in args]
    assert main(["import", *args, "--out", str(tmp_path / "out"), "--progress", "none"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gg: error: ") and message in err[0]
    assert not (tmp_path / "out").exists()


def test_console_entry_point_reports_without_traceback(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "gg_core", "import", "--format", "colmap", str(tmp_path),
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [proc.stderr.strip()] and "no COLMAP sparse model" in proc.stderr
