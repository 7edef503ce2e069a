"""Presets: sizes, and --sequences/--frames overrides that keep everything else."""
from __future__ import annotations

import pytest

from gg_core.cli import main
from gg_core.errors import InputError
from gg_core.synth.presets import PRESETS, get_preset, resized


def test_resized_changes_only_counts():
    bench = get_preset("bench")
    small = resized(bench, 1, 4)
    assert (small.n_sequences, small.n_frames) == (1, 4)
    assert (small.camera_rows, small.height, small.samples) == (bench.camera_rows, bench.height, bench.samples)
    assert resized(bench) == bench
    with pytest.raises(InputError, match="--frames must be at least 1"):
        resized(bench, None, 0)


def test_presets_grow_from_tiny_to_bench():
    tiny, demo, bench = (PRESETS[n] for n in ("tiny", "demo", "bench"))
    assert tiny.n_cameras < demo.n_cameras < bench.n_cameras
    assert tiny.height < demo.height < bench.height


def test_bad_count_is_exit_2(tmp_path, capsys):
    assert main(["synth", "--out", str(tmp_path / "x"), "--sequences", "0"]) == 2
    assert capsys.readouterr().err.startswith("gg: error: --sequences must be at least 1")
    assert not (tmp_path / "x").exists()
