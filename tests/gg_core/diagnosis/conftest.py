"""Diagnosis tests import their helpers (diagnosis_helpers.py) and the physics test helpers from these folders."""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parents[1] / "physics"))
