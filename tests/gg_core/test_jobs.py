from __future__ import annotations

import io
import json

from gg_core.jobs import Progress, parse_line


def test_jsonl_protocol_lines_parse_back() -> None:
    out = io.StringIO()
    p = Progress("register", 3, "jsonl", stream=out)
    for i in range(3):
        p.step(f"frame {i}")
    p.done("/tmp/report.json")
    lines = [parse_line(l) for l in out.getvalue().splitlines()]
    assert [l["step"] for l in lines[:3]] == [1, 2, 3] and all(l["total"] == 3 for l in lines[:3])
    assert lines[0]["message"] == "frame 0" and lines[2]["eta_s"] == 0
    assert lines[-1] == {"stage": "register", "done": True, "report": "/tmp/report.json"}
    assert parse_line("some log output") is None and parse_line(json.dumps({"x": 1})) is None
