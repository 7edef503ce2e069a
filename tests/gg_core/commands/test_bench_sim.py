"""`gg bench sim`: one JSON line comparing this simulator with Blender's cloth modifier (small, quick run)."""
from __future__ import annotations

import json

import pytest

from gg_core.cli import main


@pytest.mark.bpy
def test_bench_sim_json_line(capsys):
    assert main(["bench", "sim", "--vertices", "300", "--frames", "4", "--settle", "2", "--quality", "2"]) == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert line["bench"] == "sim" and line["frames"] == 5 and 250 < line["vertices"] < 400
    assert line["ours_fps"] > 0 and line["blender_fps"] > 0
    assert line["speedup"] == pytest.approx(line["ours_fps"] / line["blender_fps"])
    for who in ("ours", "blender"):
        stats = line[f"{who}_penetration"]
        assert 0.0 <= stats["max_fraction_deeper"] <= 1.0 and stats["depth_threshold_m"] == 0.002
    assert line["mean_distance_between_m"] < 0.05                  # both simulated the same garment on the same body
