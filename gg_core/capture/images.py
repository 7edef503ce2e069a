"""Image and mask decoding with clear errors (Pillow; no console noise from codec libraries)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) from the header, after checking the whole file decodes."""
    return read_image(path).shape[1::-1]


def read_image(path: str | Path) -> np.ndarray:
    """Decode an image to uint8 HxW or HxWxC; corrupt files raise InputError."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    try:
        with Image.open(path) as im:
            im.load()
            if im.mode not in ("L", "RGB", "RGBA"):
                im = im.convert("RGBA" if "A" in im.mode else "RGB")
            return np.asarray(im)
    except FileNotFoundError:
        raise InputError("image file not found", path, "check the capture layout") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise InputError(f"image cannot be decoded ({exc.__class__.__name__})", path,
                         "re-export or delete the corrupt file") from None


def read_rgb(path: str | Path) -> np.ndarray:
    """Float32 HxWx3 in [0, 1]."""
    img = read_image(path)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    return img[..., :3].astype(np.float32) / 255.0


def read_mask(path: str | Path) -> np.ndarray:
    """Boolean HxW: any non-zero value (binary or label masks) counts as inside."""
    img = read_image(path)
    if img.ndim == 3:
        img = img[..., :3].max(axis=2)
    return img > 0
