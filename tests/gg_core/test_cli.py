"""Every `gg` command documents its options, and bad input never shows a traceback."""
from __future__ import annotations

import pytest

from gg_core.cli import COMMANDS, main
from gg_core.commands.bench import BENCHES


@pytest.mark.parametrize("argv", [[name, "--help"] for name in COMMANDS] + [["bench", b, "--help"] for b in BENCHES])
def test_help_of_every_command(argv, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: gg " + argv[0])


def test_unknown_capture_is_one_error_line(tmp_path, capsys) -> None:
    assert main(["inspect", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gg: error: capture folder not found")
