"""Importers: other capture layouts (4D-Dress, ActorsHQ, COLMAP) converted into the product's layout.

Each format module reads its source into a `SourceSequence` (source.py); `writer.write_sequence` places
it under `<capture>/<sequence>/` and validates the result, so every stage reads one format.
"""
from __future__ import annotations

import importlib
from pathlib import Path

from ...errors import InputError
from .source import SourceSequence

# format name -> module in this package; each module has FORMAT and read(src, **options) -> SourceSequence.
FORMATS: dict[str, str] = {"4d-dress": "four_d_dress", "actorshq": "actorshq", "colmap": "colmap"}
# which read() options each format takes (the CLI refuses the others instead of ignoring them).
OPTIONS: dict[str, tuple[str, ...]] = {"4d-dress": ("garment",), "actorshq": ("body",), "colmap": ("images", "body")}


def read_source(fmt: str, src: str | Path, **options: object) -> SourceSequence:
    """Read a foreign capture; options not given (None) are left to the format's defaults."""
    if fmt not in FORMATS:
        raise InputError(f"unknown capture format '{fmt}'", "--format", f"choose one of {', '.join(FORMATS)}")
    given = {k: v for k, v in options.items() if v is not None}
    wrong = [k for k in given if k not in OPTIONS[fmt]]
    if wrong:
        raise InputError(f"option(s) {', '.join('--' + k for k in wrong)} do not apply to format '{fmt}'",
                         "--format", f"'{fmt}' takes {', '.join('--' + k for k in OPTIONS[fmt])}")
    if not Path(src).exists():
        raise InputError("source not found", src, f"pass the {fmt} folder to import")
    module = importlib.import_module(f"{__package__}.{FORMATS[fmt]}")
    return module.read(Path(src), **given)
