"""Cameras from a COLMAP sparse model (cameras/images/points3D .bin or .txt, read with pycolmap) -> product layout.

COLMAP's conventions match the product's: `cam_from_world` is world->camera with x right, y down, z
forward, and the pixel origin is the top-left pixel's corner. Only undistorted perspective models are
accepted (PINHOLE, SIMPLE_PINHOLE, or a perspective model whose distortion parameters are all zero);
anything else is refused with the fix: undistort first (`pycolmap.undistort_images`) and import the
undistorted model. COLMAP models have arbitrary scale and orientation: the world frame is kept as it is,
so align it (metres, +Y up) before the physics stages, or reconstruct with known camera positions.

Which image is which camera and frame, from the image names in the model:
- `<camera>/<frame>.<ext>` (a video per camera): one camera per folder, one frame per file. All frames of
  a camera must share its intrinsics and pose (a fixed rig); a camera that moves is refused.
- `<name>.<ext>` (one still per camera): one camera per image named after it, a single frame `000000`.
Image files are looked up under `images` (default: `images/` beside the model or its project folder).
Body meshes come from `body`, a folder of per-frame meshes named exactly like the frames.
"""
from __future__ import annotations

import re
from pathlib import Path, PurePosixPath

import numpy as np

from ...errors import InputError
from ..cameras import Camera
from ..images import image_size
from ..layout import RGB
from .source import SourceSequence, body_from_folder, listed, pinhole_camera

FORMAT = "colmap"
SINGLE_FRAME = "000000"
POSE_TOL = 1e-6
PINHOLE_MODELS = ("SIMPLE_PINHOLE", "PINHOLE")


def read(src: str | Path, images: str | Path | None = None, body: str | Path | None = None) -> SourceSequence:
    """The sparse model at `src` (or a project folder with sparse/0 or sparse/) as a SourceSequence."""
    import pycolmap

    model = _model_folder(Path(src))
    try:
        rec = pycolmap.Reconstruction(str(model))
    except Exception as exc:  # noqa: BLE001 - pycolmap raises plain RuntimeError/ValueError with C++ messages
        raise InputError(f"COLMAP model cannot be read ({str(exc).strip().splitlines()[-1][:200]})", model,
                         "re-export it from COLMAP (File > Export model)") from None
    image_root = _image_folder(model, images)
    views: dict[str, dict[str, tuple[Path, np.ndarray, np.ndarray, tuple[int, int]]]] = {}
    origins: dict[str, str] = {}
    unposed = []
    for image in sorted(rec.images.values(), key=lambda im: im.name):
        if not image.has_pose:
            unposed.append(image.name)
            continue
        camera = rec.cameras[image.camera_id]
        _require_pinhole(camera, image.name, model)
        cid, frame, origin = _camera_and_frame(image.name)
        if origins.setdefault(cid, origin) != origin:
            raise InputError(f"image names '{origins[cid]}' and '{origin}' both become camera '{cid}'", model,
                             "rename the images so camera names differ in letters, digits, '.', '_' or '-'")
        path = image_root / image.name
        if not path.is_file():
            raise InputError(f"image '{image.name}' of the model is missing", path,
                             "pass --images with the folder the model was reconstructed from")
        views.setdefault(cid, {})[frame] = (path, camera.calibration_matrix(), image.cam_from_world().matrix(),
                                            (camera.width, camera.height))
    if not views:
        raise InputError("the model has no posed images", model, "reconstruct or register the images first")
    cameras = {cid: _camera(cid, index, frames, model) for index, (cid, frames) in enumerate(sorted(views.items()))}
    files = {RGB: {cid: {frame: view[0] for frame, view in frames.items()} for cid, frames in views.items()}}
    meshes, params = body_from_folder(Path(body)) if body is not None else ({}, {})
    warnings = [f"{len(unposed)} image(s) without a pose in the model were skipped ({listed(unposed)}), {model}, "
                "register them in COLMAP to use them"] if unposed else []
    return SourceSequence(FORMAT, model, _default_name(model), cameras, files, body=meshes, body_params=params,
                          options={"images": str(image_root.resolve()),
                                   "body": None if body is None else str(Path(body).resolve())},
                          warnings=warnings)


def _model_folder(src: Path) -> Path:
    for candidate in (src, src / "sparse" / "0", src / "sparse"):
        if any((candidate / f"cameras.{ext}").is_file() for ext in ("bin", "txt")):
            return candidate
    raise InputError("no COLMAP sparse model (cameras.bin/.txt)", src,
                     "pass the model folder (e.g. sparse/0) or the project folder that holds sparse/0")


def _image_folder(model: Path, images: str | Path | None) -> Path:
    if images is not None:
        if not Path(images).is_dir():
            raise InputError("images folder not found", images, "pass the folder the model's images lie in")
        return Path(images)
    for candidate in (model / "images", model.parent / "images", model.parent.parent / "images"):
        if candidate.is_dir():
            return candidate
    raise InputError("no images/ folder beside the model", model, "pass --images with the model's image folder")


def _require_pinhole(camera: object, image_name: str, model: Path) -> None:
    if camera.model_name in PINHOLE_MODELS or (camera.is_perspective_pinhole() and camera.is_undistorted()):
        return
    raise InputError(f"camera {camera.camera_id} (image '{image_name}') uses the {camera.model_name} model with "
                     "distortion", model, "undistort first with pycolmap.undistort_images(output, model, images) "
                     "and import the undistorted model")


def _camera_and_frame(name: str) -> tuple[str, str, str]:
    """(camera id, frame name, the part of the image name that named the camera)."""
    path = PurePosixPath(name)
    if path.parent.parts:
        return _safe("_".join(path.parent.parts)), path.stem, str(path.parent)
    return _safe(path.stem), SINGLE_FRAME, path.stem


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]", "_", name)


def _camera(cid: str, index: int, frames: dict, model: Path) -> Camera:
    """One camera from all its frames' views, which must agree (a static camera)."""
    first_frame, (path, K, w2c, size) = sorted(frames.items())[0]
    scale = max(1.0, float(np.abs(w2c[:, 3]).max()))
    for frame, (_, K2, w2c2, size2) in frames.items():
        if size2 != size or not np.allclose(K2, K, rtol=POSE_TOL, atol=0):
            raise InputError(f"camera '{cid}' changes intrinsics between frames '{first_frame}' and '{frame}'",
                             model, "share one COLMAP camera per physical camera")
        if np.abs(w2c2 - w2c).max() > POSE_TOL * scale:
            raise InputError(f"camera '{cid}' moves between frames '{first_frame}' and '{frame}'", model,
                             "register the cameras as a fixed rig, or import one frame per camera")
    found = image_size(path)
    if tuple(found) != tuple(size):
        raise InputError(f"image is {found[0]}x{found[1]} but the model's camera is {size[0]}x{size[1]}", path,
                         "use the images the model was reconstructed from")
    return pinhole_camera(cid, K, w2c, size[0], size[1], index, model)


def _default_name(model: Path) -> str:
    if model.parent.name == "sparse":
        return model.parent.parent.name
    if model.name == "sparse":
        return model.parent.name
    return model.name
