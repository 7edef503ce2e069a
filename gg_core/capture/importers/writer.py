"""Write a `SourceSequence` in the product's capture layout, then validate what was written.

Images and masks are hard-linked (`link=True`, no extra disk) or copied with their timestamps; every
file goes to a temporary name first and is renamed, so a cancelled import never leaves half files.
Re-running the same import skips files already in place. A sequence folder that holds files of a
different import (other source, options, cameras or frames) is refused rather than mixed.

Kinds the source does not provide (garment masks, body meshes) are not invented: the import succeeds
with one warning each, and `gg inspect` keeps reporting the capture as incomplete until they are added.
"""
from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputError
from ...jobs import Progress
from ...storage import atomic_path, write_json
from ..cameras import save_cameras
from ..images import read_image
from ..layout import FOREGROUND_MASK, GARMENT_MASK, IMAGE_KINDS, RGB
from .source import SourceSequence, check_consistent, listed

IMPORT_RECORD = "import.json"
BODY = "body"


@dataclass
class ImportResult:
    sequence: Path
    cameras: int
    frames: list[str]
    files_written: int
    files_skipped: int
    warnings: list[str]
    record: Path


def write_sequence(seq: SourceSequence, capture: str | Path, name: str | None = None, link: bool = False,
                   decode_images: bool = True, progress: str = "none") -> ImportResult:
    """Place `seq` under `<capture>/<name>` and validate it; InputError for anything wrong or inconsistent."""
    start = time.perf_counter()
    check_consistent(seq, seq.source)
    name = name or seq.name
    if not name or Path(name).name != name or name.startswith("."):
        raise InputError(f"invalid sequence name '{name}'", capture, "pass --sequence with a plain folder name")
    root = Path(capture) / name
    identity = {"format": seq.format, "source": str(seq.source.resolve()), "options": seq.options}
    _refuse_foreign(root, identity, seq)
    write_json(root / IMPORT_RECORD, {**identity, "complete": False})  # claims the folder; resumable after a crash

    used = {cid: seq.cameras[cid] for cid in sorted(seq.files[RGB])}
    steps = Progress("import", len(used) + 2, progress)
    save_cameras(root / "cameras.json", used)
    counts = [0, 0]  # written, skipped
    for cid in used:
        for kind, per_cam in seq.files.items():
            convert = kind == GARMENT_MASK and seq.garment_colors is not None
            for frame, src in per_cam.get(cid, {}).items():
                dst = root / cid / kind / (frame + (".png" if convert else src.suffix.lower()))
                done = _write_mask(src, dst, seq.garment_colors) if convert else _place(src, dst, link)
                counts[0 if done else 1] += 1
        steps.step(f"camera {cid}")
    for files in (seq.body, seq.body_params):
        for frame, src in files.items():
            counts[0 if _place(src, root / BODY / (frame + src.suffix.lower()), link) else 1] += 1
    steps.step("body")

    warnings = list(seq.warnings) + _validate(root, seq, decode_images)
    steps.step("validated")
    frames = seq.frames
    record = write_json(root / IMPORT_RECORD, {
        **identity, "complete": True, "link": link, "cameras": list(used), "frames": len(frames),
        "first_frame": frames[0], "last_frame": frames[-1], "body_meshes": len(seq.body),
        "kinds": [k for k in IMAGE_KINDS if seq.files.get(k)], "files_written": counts[0],
        "files_skipped": counts[1], "warnings": warnings, "seconds": round(time.perf_counter() - start, 3)})
    steps.done(str(record))
    return ImportResult(root, len(used), frames, counts[0], counts[1], warnings, record)


def _refuse_foreign(root: Path, identity: dict, seq: SourceSequence) -> None:
    """A sequence folder may only be re-filled by the same import: never mix two sources in one folder."""
    record = root / IMPORT_RECORD
    if record.is_file():
        try:
            previous = json.loads(record.read_text())
        except json.JSONDecodeError:
            previous = {}
        if {k: previous.get(k) for k in identity} != identity:
            raise InputError(f"sequence folder holds an earlier import ({previous.get('format')} from "
                             f"{previous.get('source')}, options {previous.get('options')})", root,
                             "delete the folder or choose another --sequence")
    elif root.exists() and any(root.iterdir()):
        raise InputError("sequence folder exists and was not written by `gg import`", root,
                         "delete it or choose another --sequence")
    if not root.is_dir():
        return
    expected = {cid: {kind: set(files[cid]) for kind, files in seq.files.items() if cid in files}
                for cid in seq.files[RGB]}
    extra = []
    for folder in sorted(p for p in root.iterdir() if p.is_dir() and p.name != BODY and not p.name.startswith(".")):
        if folder.name not in expected:
            extra.append(folder.name)
            continue
        for kind, frames in expected[folder.name].items():
            extra += [f"{folder.name}/{kind}/{p.name}" for p in sorted((folder / kind).glob("[!.]*"))
                      if p.is_file() and p.stem not in frames]
    if seq.body and (root / BODY).is_dir():
        extra += [f"{BODY}/{p.name}" for p in sorted((root / BODY).glob("[!.]*")) if p.is_file()
                  and p.stem not in seq.body]
    if extra:
        raise InputError(f"sequence folder holds files this import would not write ({listed(extra)})", root,
                         "delete them or import into another --sequence")


def _place(src: Path, dst: Path, link: bool) -> bool:
    """Hard-link or copy `src` to `dst` atomically; False when an identical file is already there."""
    if dst.exists():
        if link and os.path.samefile(src, dst):
            return False
        s, d = src.stat(), dst.stat()
        if not link and s.st_size == d.st_size and s.st_mtime_ns == d.st_mtime_ns:
            return False
    with atomic_path(dst) as tmp:
        if link:
            tmp.unlink()
            try:
                os.link(src, tmp)
            except OSError as exc:
                raise InputError(f"cannot hard-link ({exc.strerror})", src,
                                 "drop --link to copy, or put the capture on the same file system") from None
        else:
            shutil.copy2(src, tmp)
    return True


def _write_mask(label_image: Path, dst: Path, colors: np.ndarray) -> bool:
    """Binary PNG (0/255): pixels whose RGB equals one of the garment label colours."""
    from PIL import Image

    if dst.exists() and dst.stat().st_mtime_ns >= label_image.stat().st_mtime_ns:
        return False
    img = read_image(label_image)
    if img.ndim != 3:
        raise InputError("label image is not a colour image", label_image, "render the labels as RGB")
    rgb = img[..., :3].astype(np.int16)
    mask = (rgb[:, :, None, :] == np.asarray(colors, np.int16)[None, None]).all(-1).any(-1)
    with atomic_path(dst) as tmp:
        Image.fromarray(mask.astype(np.uint8) * 255).save(tmp, format="PNG")
    return True


def _validate(root: Path, seq: SourceSequence, decode_images: bool) -> list[str]:
    """Validate the written sequence; kinds the source lacks become warnings, anything else an InputError."""
    from ..validate import validate_capture

    report = validate_capture(root.parent, decode_images=decode_images)
    inside = str(root) + os.sep
    problems = [p for p in report.problems if p.where.startswith(inside) or p.where == str(root)]
    absent = set()
    if not seq.files.get(GARMENT_MASK):
        absent |= {str(root / cid / GARMENT_MASK) for cid in seq.files[RGB]}
    if not seq.body:
        absent.add(str(root / BODY))
    real = [p for p in problems if p.where not in absent]
    if real:
        raise real[0]
    warnings = []
    if not seq.files.get(GARMENT_MASK):
        warnings.append(f"the {seq.format} source has no garment masks, {root}/<camera>/{GARMENT_MASK}, "
                        "add one mask per frame (garment pixels non-zero) before running the stages")
    if not seq.body:
        warnings.append(f"the {seq.format} source has no body meshes, {root / BODY}, "
                        "add one body mesh per frame named like the frames (or import with --body)")
    if not seq.files.get(FOREGROUND_MASK):
        warnings.append(f"the {seq.format} source has no foreground masks, {root}/<camera>/{FOREGROUND_MASK}, "
                        "optional, but the registration loss uses them to count background pixels")
    return warnings
