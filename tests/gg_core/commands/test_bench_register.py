"""`gg bench register`: the ablations run side by side in worker processes and come back as one table."""
from __future__ import annotations

import json

import pytest

from gg_core.cli import main

pytestmark = pytest.mark.slow


def test_two_ablations_in_workers_give_one_json_table(tiny_capture, tmp_path, capsys):
    assert main(["bench", "register", "--capture", str(tiny_capture), "--project", str(tmp_path),
                 "--sequences", "00_walk", "--frames", "1", "--iterations", "6",
                 "--ablations", "full", "only-rgb"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["bench"] == "register" and list(result["table"]) == ["full", "only-rgb"]
    for row in result["table"].values():
        assert row["cd_cm"] > 0 and row["s_per_frame"] > 0 and row["wall_s_per_frame"] > 0
    for name in ("full", "only-rgb"):
        report = json.loads((tmp_path / name / "reports" / "register.json").read_text())
        assert report["ablation"] == name and report["workers"] == 1
