"""What an importer found in a foreign capture, in source terms, before anything is written.

Each importer turns its layout into one `SourceSequence`: calibrated cameras plus, per camera and
frame, the source file for every image kind. `check_consistent` then refuses anything the product
layout cannot hold (frames that differ between cameras, body meshes named differently from the
frames) with messages that name the *source* files, so the user fixes the dataset, not the copy.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import InputError
from ..cameras import Camera
from ..layout import FOREGROUND_MASK, GARMENT_MASK, MESH_EXTS, RGB

MAX_LISTED = 4
BODY_PARAM_EXTS = (".npz", ".pkl")


@dataclass
class SourceSequence:
    """One multi-view sequence of a foreign capture, ready to be written in the product layout.

    `files[kind][camera][frame]` is the source file of each image; kinds are the layout's folder names.
    Garment masks given as colour label images are converted on write: a pixel is garment when its RGB
    equals one of `garment_colors`; with `garment_colors` None they are masks already and are linked.
    """

    format: str
    source: Path
    name: str
    cameras: dict[str, Camera]
    files: dict[str, dict[str, dict[str, Path]]]
    body: dict[str, Path] = field(default_factory=dict)
    body_params: dict[str, Path] = field(default_factory=dict)
    garment_colors: np.ndarray | None = None
    options: dict[str, object] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    @property
    def frames(self) -> list[str]:
        rgb = self.files.get(RGB, {})
        return sorted(next(iter(rgb.values()))) if rgb else []


def pinhole_camera(cid: str, K: object, w2c: object, width: int, height: int, index: int, where: object) -> Camera:
    """A Camera from a 3x3 K and a 3x4 world->camera [R|t] read from a source; bad shapes or values refused."""
    try:
        K = np.asarray(K, dtype=np.float64)
        w2c = np.asarray(w2c, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"camera '{cid}' calibration is not numeric", where, "check the calibration file") from None
    if K.shape != (3, 3) or w2c.shape != (3, 4):
        raise InputError(f"camera '{cid}' has intrinsics of shape {K.shape} and extrinsics of shape {w2c.shape}, "
                         "expected (3, 3) and (3, 4)", where, "check the calibration file")
    if not (np.isfinite(K).all() and np.isfinite(w2c).all()):
        raise InputError(f"camera '{cid}' calibration holds NaN or infinite values", where, "re-export the calibration")
    return Camera(cid, K, w2c[:, :3].copy(), w2c[:, 3].copy(), int(width), int(height), index)


def listed(names: set[str] | list[str]) -> str:
    names = sorted(names)
    more = f" and {len(names) - MAX_LISTED} more" if len(names) > MAX_LISTED else ""
    return ", ".join(names[:MAX_LISTED]) + more


def numbered_files(folder: Path, pattern: str) -> dict[str, Path]:
    """Frame name -> file for the files of `folder` whose whole name matches `pattern` (group 1 = frame)."""
    regex = re.compile(pattern)
    if not folder.is_dir():
        return {}
    out = {}
    for path in sorted(folder.iterdir()):
        match = regex.fullmatch(path.name)
        if match and path.is_file():
            out[match.group(1)] = path
    return out


def body_from_folder(folder: Path) -> tuple[dict[str, Path], dict[str, Path]]:
    """(meshes, parameter files) of a per-frame body folder; file stems are the frame names."""
    if not folder.is_dir():
        raise InputError("body folder not found", folder, "pass a folder with one .ply/.obj body mesh per frame")
    meshes = {p.stem: p for p in sorted(folder.iterdir()) if p.suffix.lower() in MESH_EXTS and p.is_file()}
    params = {p.stem: p for p in sorted(folder.iterdir()) if p.suffix.lower() in BODY_PARAM_EXTS and p.is_file()}
    if not meshes:
        raise InputError("no body meshes (.ply/.obj)", folder, "export one body mesh per frame into that folder")
    return meshes, params


def check_consistent(seq: SourceSequence, where: Path) -> None:
    """Refuse a sequence whose cameras, image kinds and body do not all cover the same frames."""
    rgb = seq.files.get(RGB, {})
    if not rgb:
        raise InputError("no camera with images found", where, "point to the folder that holds the cameras")
    missing = set(rgb) - set(seq.cameras)
    if missing:
        raise InputError(f"no calibration for camera(s) {listed(missing)}", where,
                         "add them to the calibration or remove their image folders")
    ref_cam = sorted(rgb)[0]
    frames = set(rgb[ref_cam])
    if not frames:
        raise InputError(f"camera '{ref_cam}' has no images", where, "check the source layout")
    for kind in (RGB, FOREGROUND_MASK, GARMENT_MASK):
        per_cam = seq.files.get(kind, {})
        if not per_cam:
            continue
        absent = set(rgb) - set(per_cam)
        if absent:
            raise InputError(f"{kind}: camera(s) {listed(absent)} have none while camera(s) "
                             f"{listed(set(per_cam))} do", where, "provide them for every camera or for none")
        for cam, files in per_cam.items():
            if set(files) != frames:
                raise InputError(f"{kind} of camera '{cam}' {_difference(set(files), frames)} compared with the "
                                 f"images of camera '{ref_cam}'", _folder_of(files, where),
                                 "make every camera and image kind hold the same frames")
    if seq.body and set(seq.body) != frames:
        raise InputError(f"body meshes do not match the frames: {_body_mismatch(set(seq.body), frames)}",
                         _folder_of(seq.body, where),
                         "name the body meshes exactly like the frames (same digits, same zero padding)")
    if set(seq.body_params) - set(seq.body):
        raise InputError(f"body parameter files without a body mesh: {listed(set(seq.body_params) - set(seq.body))}",
                         _folder_of(seq.body_params, where), "give every parameter file its mesh, or remove it")


def _difference(found: set[str], expected: set[str]) -> str:
    parts = []
    if expected - found:
        parts.append(f"lacks frames {listed(expected - found)}")
    if found - expected:
        parts.append(f"has extra frames {listed(found - expected)}")
    return " and ".join(parts)


def _body_mismatch(body: set[str], frames: set[str]) -> str:
    """Spell out the common failure, equal frame numbers written with different zero padding."""
    def numbers(names: set[str]) -> set[int] | None:
        return {int(n) for n in names} if all(n.isdigit() for n in names) else None

    if numbers(body) is not None and numbers(body) == numbers(frames):
        digits = ["/".join(str(w) for w in sorted({len(n) for n in names})) for names in (body, frames)]
        return (f"same frame numbers, but the body files use {digits[0]} digits (e.g. '{sorted(body)[0]}') "
                f"and the frames {digits[1]} digits (e.g. '{sorted(frames)[0]}')")
    return f"the body {_difference(body, frames)}"


def _folder_of(files: dict[str, Path], fallback: Path) -> Path:
    return next(iter(files.values())).parent if files else fallback
