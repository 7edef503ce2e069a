"""`gg bench stereo`: one JSON line timing the patch kernel against its numpy baseline, which agree."""
from __future__ import annotations

import json

from gg_core.cli import main


def test_bench_prints_both_timings_and_their_agreement(capsys):
    assert main(["bench", "stereo", "--patches", "500", "--runs", "2"]) == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert line["bench"] == "stereo" and line["patches"] == 500 and line["samples"] == 25
    assert line["kernel_ms"] > 0 and line["baseline"]["numpy_ms"] > 0 and line["speedup"] > 0
    assert line["max_abs_diff"] < 1e-5


def test_bad_counts_exit_2_with_one_line(capsys):
    assert main(["bench", "stereo", "--patches", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--patches must be at least 1" in err[0]
