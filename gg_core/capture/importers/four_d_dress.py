"""4D-Dress takes (eth-ait/4d-dress, dataset/README.md) -> product capture layout.

Source layout of one take, as the dataset ships it:
```
<subject>/<Inner|Outer>/<TakeN>/Capture/cameras.pkl       {cam_id: {"intrinsics": 3x3, "extrinsics": 3x4, ...}}
<subject>/<Inner|Outer>/<TakeN>/Capture/<cam>/images/capture-f#####.png
<subject>/<Inner|Outer>/<TakeN>/Capture/<cam>/masks/mask-f#####.png     (rendered person mask)
<subject>/<Inner|Outer>/<TakeN>/Capture/<cam>/labels/label-f#####.png   (optional, rendered by the dataset's
                                                                         postprocess.py: one RGB colour per label)
<subject>/<Inner|Outer>/<TakeN>/SMPLX/mesh-f#####_smplx.ply|.pkl        (body mesh | parameters)
```
Conventions (from the dataset's own renderer, which feeds `intrinsics` to PyTorch3D in screen space and
flips only the x/y camera axes of `extrinsics`): `extrinsics` is OpenCV world->camera [R|t], metres,
`intrinsics` a pinhole K whose pixel origin is the top-left corner of the top-left pixel, exactly the
product's convention, so both are taken as they are. No distortion. The image size is read from the files.

Frames keep their 5-digit names (`capture-f00011.png` -> `00011`); body meshes are renamed to them.
`masks/` become `foreground_masks/`. Garment masks: where `labels/` exist for every camera, the pixels of the
chosen garment label(s) (`garment`, default `outer` for Outer outfits; required for Inner outfits, which
hold upper and lower garments) become binary `garment_masks/`. Where no camera has `labels/`, the take is
imported without garment masks and with a warning; labels for only some cameras or frames are refused.

`cameras.pkl` is read with an unpickler that only admits numpy arrays and plain containers, so a crafted
file cannot run code.
"""
from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from ...errors import InputError
from ..images import image_size
from ..layout import FOREGROUND_MASK, GARMENT_MASK, RGB
from .source import SourceSequence, listed, numbered_files, pinhole_camera

FORMAT = "4d-dress"
# Label colours of the dataset's rendered label images (dataset/utility.py SURFACE_LABEL / _COLOR).
SURFACE_LABEL_COLORS = {"skin": (128, 128, 128), "hair": (255, 128, 0), "shoe": (128, 0, 255),
                        "upper": (180, 50, 50), "lower": (50, 180, 50), "outer": (0, 128, 255)}
DEFAULT_GARMENT = {"Outer": "outer"}

_PICKLE_GLOBALS = {("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
                   ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar"),
                   ("numpy", "ndarray"), ("numpy", "dtype"), ("_codecs", "encode"),
                   ("collections", "OrderedDict")}


def read(src: str | Path, garment: str | None = None) -> SourceSequence:
    """The take at `src` (the `TakeN` folder, or its `Capture` folder) as a SourceSequence."""
    take = _take_folder(Path(src))
    capture = take / "Capture"
    calibration = _load_pickle(capture / "cameras.pkl")
    if not isinstance(calibration, dict):
        raise InputError("cameras.pkl is not a {camera_id: parameters} dictionary", capture / "cameras.pkl",
                         "use the cameras.pkl shipped with the take")
    cam_dirs = sorted(p for p in capture.iterdir() if (p / "images").is_dir())
    if not cam_dirs:
        raise InputError("no camera folder with images/", capture, "download the take's Capture/<camera>/images")
    missing = {d.name for d in cam_dirs} - {str(k) for k in calibration}
    if missing:
        raise InputError(f"cameras.pkl has no entry for camera(s) {listed(missing)}", capture / "cameras.pkl",
                         "use the cameras.pkl of the same take")

    files: dict[str, dict[str, dict[str, Path]]] = {RGB: {}, FOREGROUND_MASK: {}, GARMENT_MASK: {}}
    cameras = {}
    for index, cam_dir in enumerate(cam_dirs):
        cid = cam_dir.name
        files[RGB][cid] = numbered_files(cam_dir / "images", r"capture-f(\d+)\.png")
        if not files[RGB][cid]:
            raise InputError("no capture-f#####.png images", cam_dir / "images", "download the camera's images")
        for kind, sub, pattern in ((FOREGROUND_MASK, "masks", r"mask-f(\d+)\.png"),
                                   (GARMENT_MASK, "labels", r"label-f(\d+)\.png")):
            found = numbered_files(cam_dir / sub, pattern)
            if found:
                files[kind][cid] = found
        cameras[cid] = _camera(cid, calibration, index, image_size(next(iter(files[RGB][cid].values()))),
                               capture / "cameras.pkl")

    garment, colors = _garment(garment, bool(files[GARMENT_MASK]), take)
    files = {kind: per_cam for kind, per_cam in files.items() if per_cam}
    smplx = take / "SMPLX"
    body = numbered_files(smplx, r"mesh-f(\d+)_smplx\.ply")
    params = numbered_files(smplx, r"mesh-f(\d+)_smplx\.pkl")
    if not body:
        only_params = ", only parameter .pkl files" if params else ""
        raise InputError(f"no SMPL-X body meshes (mesh-f#####_smplx.ply){only_params}", smplx,
                         "download the take's SMPLX folder with its .ply meshes (the dataset ships both)")
    return SourceSequence(FORMAT, take, take.name, cameras, files, body=body, body_params=params,
                          garment_colors=colors, options={"garment": garment})


def _take_folder(src: Path) -> Path:
    if (src / "Capture" / "cameras.pkl").is_file():
        return src
    if src.name == "Capture" and (src / "cameras.pkl").is_file():
        return src.parent
    if not src.is_dir():
        raise InputError("4D-Dress take folder not found", src, "pass <subject>/<Inner|Outer>/<TakeN>")
    raise InputError("not a 4D-Dress take (no Capture/cameras.pkl)", src, "pass <subject>/<Inner|Outer>/<TakeN>")


class _SafeUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> object:
        if (module, name) not in _PICKLE_GLOBALS:
            raise pickle.UnpicklingError(f"refusing to load {module}.{name}")
        return super().find_class(module, name)


def _load_pickle(path: Path) -> object:
    if not path.is_file():
        raise InputError("cameras.pkl not found", path, "download the take's Capture/cameras.pkl")
    try:
        with open(path, "rb") as fh:
            return _SafeUnpickler(fh, encoding="latin1").load()
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, ImportError) as exc:
        raise InputError(f"cameras.pkl cannot be read ({exc})", path,
                         "use the cameras.pkl shipped with the take") from None


def _camera(cid: str, calibration: dict, index: int, size: tuple[int, int], where: Path):
    entry = calibration.get(cid, calibration.get(int(cid)) if cid.isdigit() else None)
    if not isinstance(entry, dict) or "intrinsics" not in entry or "extrinsics" not in entry:
        raise InputError(f"camera '{cid}' lacks 'intrinsics' or 'extrinsics'", where,
                         "use the cameras.pkl shipped with the take")
    for key, value in entry.items():
        if "dist" in str(key).lower() and np.any(np.asarray(value, dtype=float) != 0):
            raise InputError(f"camera '{cid}' has non-zero distortion '{key}'", where,
                             "undistort the images first; 4D-Dress cameras are distortion-free")
    return pinhole_camera(cid, entry["intrinsics"], entry["extrinsics"], size[0], size[1], index, where)


def _garment(garment: str | None, have_labels: bool, take: Path) -> tuple[str | None, np.ndarray | None]:
    """(label names joined by commas, their RGB colours), or (None, None) for a take without labels."""
    if not have_labels:
        if garment:
            raise InputError("--garment needs rendered labels, but no camera has labels/label-f#####.png",
                             take / "Capture", "render them with the dataset's postprocess.py, or drop --garment")
        return None, None
    garment = garment or DEFAULT_GARMENT.get(take.parent.name)
    if not garment:
        raise InputError(f"choose which labelled garment to import ({', '.join(SURFACE_LABEL_COLORS)})", take,
                         "pass --garment, e.g. --garment upper or --garment upper,lower")
    names = [g.strip() for g in garment.split(",") if g.strip()]
    unknown = [n for n in names if n not in SURFACE_LABEL_COLORS]
    if unknown or not names:
        raise InputError(f"unknown 4D-Dress label(s) {', '.join(unknown) or repr(garment)}", take,
                         f"choose from {', '.join(SURFACE_LABEL_COLORS)}")
    return ",".join(names), np.array([SURFACE_LABEL_COLORS[n] for n in names], np.uint8)
