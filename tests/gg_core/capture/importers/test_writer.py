"""Writing an imported sequence: copies keep timestamps, re-runs resume, foreign folders are never mixed."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from gg_core.capture.importers import read_source
from gg_core.capture.importers.writer import write_sequence
from gg_core.errors import InputError
from gg_core.jobs import parse_line


def test_copies_keep_timestamps_and_an_interrupted_import_resumes(actorshq_sequence: Path, tmp_path: Path) -> None:
    source = read_source("actorshq", actorshq_sequence)
    first = write_sequence(source, tmp_path / "out", decode_images=False)
    assert first.files_written == 3 * 3 * 2 and first.files_skipped == 0
    src = actorshq_sequence / "rgbs" / "Cam001" / "Cam001_rgb000001.jpg"
    dst = first.sequence / "Cam001" / "rgb_images" / "000001.jpg"
    assert not os.path.samefile(src, dst) and src.stat().st_mtime_ns == dst.stat().st_mtime_ns
    # a crash after some files: the claim record says incomplete, files are missing; the re-run fills them in
    record = json.loads(first.record.read_text())
    first.record.write_text(json.dumps({k: record[k] for k in ("format", "source", "options")} | {"complete": False}))
    shutil.rmtree(first.sequence / "Cam003")
    again = write_sequence(read_source("actorshq", actorshq_sequence), tmp_path / "out", decode_images=False)
    assert again.files_written == 3 * 2 and again.files_skipped == 2 * 3 * 2
    assert json.loads(again.record.read_text())["complete"] is True


def test_a_folder_not_written_by_import_is_refused(actorshq_sequence: Path, tmp_path: Path) -> None:
    (tmp_path / "out" / "Sequence1").mkdir(parents=True)
    (tmp_path / "out" / "Sequence1" / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="was not written by `gg import`"):
        write_sequence(read_source("actorshq", actorshq_sequence), tmp_path / "out")


def test_files_of_a_larger_earlier_import_are_refused(actorshq_sequence: Path, tmp_path: Path) -> None:
    write_sequence(read_source("actorshq", actorshq_sequence), tmp_path / "out", decode_images=False)
    for cam in ("Cam001", "Cam002", "Cam003"):
        (actorshq_sequence / "rgbs" / cam / f"{cam}_rgb000002.jpg").unlink()
        (actorshq_sequence / "masks" / cam / f"{cam}_mask000002.png").unlink()
    stale = r"would not write \(Cam001/foreground_masks/000002.png, Cam001/rgb_images/000002.jpg"
    with pytest.raises(InputError, match=stale):
        write_sequence(read_source("actorshq", actorshq_sequence), tmp_path / "out")


def test_bad_sequence_names_are_refused(actorshq_sequence: Path, tmp_path: Path) -> None:
    for name in ("../escape", ".hidden", "a/b"):
        with pytest.raises(InputError, match="invalid sequence name"):
            write_sequence(read_source("actorshq", actorshq_sequence), tmp_path / "out", name)


def test_progress_protocol_ends_with_the_import_record(actorshq_sequence: Path, tmp_path: Path, capsys) -> None:
    from gg_core.cli import main

    assert main(["import", "--format", "actorshq", str(actorshq_sequence), "--out", str(tmp_path / "out"),
                 "--progress", "jsonl", "--quick"]) == 0
    lines = [parse_line(l) for l in capsys.readouterr().out.splitlines()]
    assert all(lines) and [l["step"] for l in lines[:-1]] == [1, 2, 3, 4, 5]  # 3 cameras, body, validation
    assert lines[-1]["done"] and Path(lines[-1]["report"]) == tmp_path / "out" / "Sequence1" / "import.json"
