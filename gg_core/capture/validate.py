"""Validation of a capture folder: every problem found, each as one InputError line (what, where, fix).

`gg inspect` prints these and the importers check what they wrote with them; the stages raise the same
InputErrors (exit 2) from the capture layout where they read a file, and `gg inspect` finds every one up front.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..errors import InputError
from ..geometry.meshio import read_mesh
from .images import read_image
from .layout import FOREGROUND_MASK, GARMENT_MASK, RGB, Capture, Sequence

MAX_LISTED = 4


@dataclass
class SequenceSummary:
    name: str
    cameras: list[str] = field(default_factory=list)
    resolutions: list[tuple[int, int]] = field(default_factory=list)
    frames: list[str] = field(default_factory=list)
    body_files: int = 0
    foreground_masks: bool = False
    ground_truth_frames: int = 0

    def to_json(self) -> dict:
        return {"name": self.name, "cameras": self.cameras, "resolutions": sorted(set(self.resolutions)),
                "frames": len(self.frames), "first_frame": self.frames[0] if self.frames else None,
                "last_frame": self.frames[-1] if self.frames else None, "body_files": self.body_files,
                "foreground_masks": self.foreground_masks, "ground_truth_frames": self.ground_truth_frames}


@dataclass
class Report:
    root: Path
    sequences: list[SequenceSummary]
    problems: list[InputError]
    truth: bool

    def to_json(self) -> dict:
        return {"capture": str(self.root), "sequences": [s.to_json() for s in self.sequences],
                "ground_truth": self.truth, "problems": [p.line() for p in self.problems]}


def validate_capture(root: str | Path, decode_images: bool = True,
                     on_sequence: Callable[[str], None] | None = None) -> Report:
    """Check everything a stage will read; decoding every image is the slow part (threaded).

    `on_sequence(name)` is called after each sequence (progress reporting)."""
    capture = Capture(Path(root))
    problems: list[InputError] = []
    summaries = []
    try:
        truth = capture.truth is not None
    except InputError as exc:
        problems.append(exc)
        truth = False
    for seq in capture.sequences.values():
        summary, seq_problems = _validate_sequence(seq, decode_images)
        summaries.append(summary)
        problems.extend(seq_problems)
        if on_sequence is not None:
            on_sequence(seq.name)
    return Report(capture.root, summaries, problems, truth)


def _listed(names: list[str] | set[str]) -> str:
    names = sorted(names)
    more = f" and {len(names) - MAX_LISTED} more" if len(names) > MAX_LISTED else ""
    return ", ".join(names[:MAX_LISTED]) + more


def _validate_sequence(seq: Sequence, decode_images: bool) -> tuple[SequenceSummary, list[InputError]]:
    summary = SequenceSummary(seq.name)
    problems: list[InputError] = []
    try:
        cameras = seq.cameras
    except InputError as exc:
        return summary, [exc]
    summary.cameras = list(cameras)
    summary.resolutions = [(c.width, c.height) for c in cameras.values()]

    reference: tuple[str, set[str]] | None = None
    checks: list[tuple[Path, tuple[int, int], str]] = []  # (file, expected (w, h), what it is)
    for cid, cam in cameras.items():
        folder = seq.root / cid
        if not folder.is_dir():
            problems.append(InputError(f"camera folder '{cid}' is missing", folder,
                                       "add the camera's images or remove the camera from cameras.json"))
            continue
        rgb = seq.files(cid, RGB)
        if not rgb:
            problems.append(InputError("no images", folder / RGB, "put the camera's frames (png/jpg) there"))
            continue
        if reference is None:
            reference = (cid, set(rgb))
        elif set(rgb) != reference[1]:
            problems.append(_mismatch(f"frame names of camera '{cid}' differ from camera '{reference[0]}'",
                                      folder / RGB, set(rgb), reference[1]))
        checks += [(p, (cam.width, cam.height), "image") for p in rgb.values()]
        for kind, required in ((GARMENT_MASK, True), (FOREGROUND_MASK, False)):
            masks = seq.files(cid, kind)
            if not masks:
                if required:
                    problems.append(InputError("no garment masks", folder / kind,
                                               "add one mask per frame (garment pixels non-zero)"))
                continue
            summary.foreground_masks |= kind == FOREGROUND_MASK
            if set(masks) != reference[1]:
                problems.append(_mismatch(f"{kind} frame names differ from the frames of camera '{reference[0]}'",
                                          folder / kind, set(masks), reference[1]))
            checks += [(p, (cam.width, cam.height), "mask") for p in masks.values()]
    summary.frames = sorted(reference[1]) if reference else []

    problems += _check_body(seq, summary)
    problems += _check_ground_truth(seq, summary)
    if decode_images:
        with ThreadPoolExecutor(max_workers=4) as pool:
            problems += [p for p in pool.map(lambda c: _check_image(*c), checks) if p is not None]
    return summary, problems


def _mismatch(what: str, where: Path, found: set[str], expected: set[str]) -> InputError:
    missing, extra = expected - found, found - expected
    detail = "; ".join(s for s in (f"missing {_listed(missing)}" if missing else "",
                                   f"unexpected {_listed(extra)}" if extra else "") if s)
    return InputError(f"{what} ({detail})", where, "name every file exactly like the frames of the other cameras")


def _check_image(path: Path, size: tuple[int, int], what: str) -> InputError | None:
    try:
        img = read_image(path)
    except InputError as exc:
        return exc
    found = (img.shape[1], img.shape[0])
    if found != size:
        return InputError(f"{what} is {found[0]}x{found[1]} but the camera is {size[0]}x{size[1]}", path,
                          "resize it to the camera's width/height or fix cameras.json")
    return None


def _check_body(seq: Sequence, summary: SequenceSummary) -> list[InputError]:
    body = seq.body_files
    summary.body_files = len(body)
    folder = seq.root / "body"
    if not body:
        return [InputError("no body meshes", folder, "add one body mesh per frame named like the frames (.ply/.obj)")]
    if summary.frames and set(body) != set(summary.frames):
        return [_mismatch("body mesh names do not match the image frame names", folder, set(body),
                          set(summary.frames))]
    problems = []
    counts = set()
    for path in body.values():
        try:
            verts, _ = read_mesh(path)
            counts.add(len(verts))
        except InputError as exc:
            problems.append(exc)
    if len(counts) > 1:
        problems.append(InputError(f"body meshes change vertex count across frames ({sorted(counts)})", folder,
                                   "export every frame with the same body topology"))
    return problems


def _check_ground_truth(seq: Sequence, summary: SequenceSummary) -> list[InputError]:
    gt = seq.gt_garment_files
    summary.ground_truth_frames = len(gt)
    if not gt:
        return []
    where = seq.root / "gt" / "garment"
    if summary.frames and set(gt) != set(summary.frames):
        return [_mismatch("ground-truth garment names do not match the frames", where, set(gt), set(summary.frames))]
    counts = {len(read_mesh(p)[0]) for p in gt.values()}
    if len(counts) > 1:
        return [InputError("ground-truth garment meshes change vertex count", where, "regenerate the capture")]
    return []

