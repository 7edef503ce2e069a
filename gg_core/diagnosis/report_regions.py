"""Which garment region each region candidate acted on, read from diagnose.json's localization: torch-free, since
the Blender add-on reads it too (its vertex groups) besides the benchmark (the region's overlap with the truth)."""
from __future__ import annotations


def candidate_regions(localization: dict) -> dict[str, list[int] | None]:
    """Each region candidate's own region where it scanned for one (scan.py; None where no patch explained enough)
    or chose between the maps' two extents (pipeline.choose_regions); a candidate not named acts on the maps' region
    (localization['region_vertices'])."""
    own = {n: scan["region_vertices"] for n, scan in localization.get("scanned_regions", {}).items()}
    return own | {n: choice["region_vertices"] for n, choice in localization.get("region_choices", {}).items()}
