"""A fitted garment model as one .npz file: what `gg simulate --behavior` rolls out.

Written by the behaviour stage (stage4/behavior.npz) and by the diagnosis (diagnose/model.npz: the accepted missing
physics included). Arrays: template [V,3] (rest positions), faces [F,3], attached [V] (pinned to the body),
rest_lengths [E], one [V] array per material field (MATERIAL_NAMES), flat (bending towards flat instead of the
template's angles), uniform_mass (Cloth.uniform_mass) and terms (JSON: the force-library terms with their fitted
parameters). Files from before flat, uniform_mass and terms were stored load with the template's angles, mass by
area and no terms (the reader's default terms then apply).
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from .cloth import Cloth
from .material import MATERIAL_NAMES, Material
from .terms import Term


@dataclass
class FittedModel:
    cloth: Cloth                                  # template, faces, material, rest lengths, pins, flat, mass
    terms: list[tuple[str, dict[str, Any]]] | None   # (name, parameters) in order; None: not stored


def model_arrays(cloth: Cloth, terms: list[Term], attached: np.ndarray) -> dict[str, np.ndarray]:
    """The arrays of a model file for `cloth` simulated with `terms` (write with storage.write_npz)."""
    stored = [{"name": t.name, "params": {k: v.detach().tolist() for k, v in t.params.items()}} for t in terms]
    return {"template": cloth.template, "faces": cloth.faces, "attached": np.asarray(attached, bool),
            "rest_lengths": cloth.rest_lengths.detach().numpy(), "flat": np.array(cloth.flat),
            "uniform_mass": np.array(cloth.uniform_mass),
            "terms": np.array(json.dumps(stored)),
            **{n: getattr(cloth.material, n).detach().numpy() for n in MATERIAL_NAMES}}


def read_model(path: str | os.PathLike) -> FittedModel:
    """The model stored at `path`; ValueError where its arrays do not fit together (the caller says how to fix)."""
    with np.load(path) as z:
        arrays = dict(z)
    missing = [k for k in ("template", "faces", "rest_lengths", *MATERIAL_NAMES) if k not in arrays]
    if missing:
        raise ValueError(f"no {', '.join(missing)} stored")
    cloth = Cloth(arrays["template"], arrays["faces"], flat=bool(arrays.get("flat", False)),
                  uniform_mass=bool(arrays.get("uniform_mass", False)),
                  pinned=arrays["attached"].astype(bool) if "attached" in arrays else None)
    n = cloth.n_vertices
    bad = [k for k in MATERIAL_NAMES if arrays[k].shape != (n,)]
    if bad or arrays["rest_lengths"].shape != cloth.rest_lengths.shape:
        raise ValueError(f"material or rest lengths do not match the {n}-vertex template")
    cloth.material = Material(**{k: torch.from_numpy(arrays[k].astype(np.float64)) for k in MATERIAL_NAMES})
    cloth.rest_lengths = torch.from_numpy(arrays["rest_lengths"].astype(np.float64))
    terms = None
    if "terms" in arrays:
        terms = [(t["name"], t["params"]) for t in json.loads(arrays["terms"].item())]
    return FittedModel(cloth, terms)
