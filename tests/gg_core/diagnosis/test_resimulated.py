"""Captures re-simulated by our simulator (the benchmark's well-specified reference): the layout a diagnosis reads,
pins that follow the recording, each Blender effect translated into our terms, nothing left half-written."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from diagnosis_helpers import BLENDER_TRUTH, write_blender_layout_capture

from gg_core.capture.layout import Capture
from gg_core.diagnosis.resimulated import our_effect, resimulate
from gg_core.errors import InputError
from gg_core.geometry.meshio import read_mesh

@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    return write_blender_layout_capture(tmp_path_factory.mktemp("resim") / "reference")


def _frames(capture: Path, seq: str) -> np.ndarray:
    files = Capture(capture).sequence(seq).gt_garment_files
    return np.stack([read_mesh(files[k])[0] for k in sorted(files)])


def test_blender_effects_become_our_terms_in_our_units():
    _, drag = our_effect("air_drag", [], BLENDER_TRUTH)
    assert drag.terms == {"mass_damping": {"alpha": pytest.approx(10.0)}}
    _, friction = our_effect("friction", ["friction=60"], BLENDER_TRUTH)
    assert friction.parameters == {"body_friction.mu": pytest.approx(0.5 + 0.55)}   # Blender's added Coulomb mu
    blender, gravity = our_effect("gravity", [], BLENDER_TRUTH)
    g = np.array(blender["blender"]["gravity"])
    assert np.allclose(np.array(gravity.terms["gravity_offset"]["delta_g"]) + [0, -9.81, 0], g)
    _, shrink = our_effect("shrink", ["factor=0.2"], BLENDER_TRUTH)
    assert shrink.region == "side_seam" and shrink.region_logs == {"rest": pytest.approx(np.log(0.8))}
    _, wind = our_effect("wind", ["azimuth_deg=90"], BLENDER_TRUTH)
    assert np.allclose(wind.terms["wind"]["velocity"], [0.0, 0.0, 0.7], atol=1e-12)
    assert np.allclose(wind.parameters["wind.push"], [0.0, 0.0, 0.6 * 0.49 / 0.15], atol=1e-12)   # per unit mass
    with pytest.raises(InputError):
        our_effect("magnetism", [], BLENDER_TRUTH)


def test_resimulated_capture_holds_the_recorded_pins_bodies_and_truth(reference, tmp_path):
    out = resimulate(reference, tmp_path / "none", "none", [], lambda n: None, substeps=2)
    assert sorted(Capture(out).sequences) == ["a", "b", "c"] and not (tmp_path / "none.partial").exists()
    pinned = np.asarray(json.loads((out / "truth.json").read_text())["garment"]["pinned_vertices"])
    recorded, ours = _frames(reference, "a"), _frames(out, "a")
    assert ours.shape == recorded.shape
    assert np.allclose(ours[:, pinned], recorded[:, pinned])
    # our material is not the recording's: the free vertices move differently
    assert np.abs(ours - recorded).max() > 1e-3
    truth = json.loads((out / "truth.json").read_text())
    assert truth["effect"]["name"] == "none" and truth["true_parameters"] == {}
    assert truth["split"]["heldout_sequences"] == ["c"]
    assert sorted(p.name for p in (out / "a" / "body").iterdir()) == \
        sorted(p.name for p in (reference / "a" / "body").iterdir())


def test_hidden_effects_move_the_resimulated_garment_as_they_should(reference, tmp_path):
    none = _frames(resimulate(reference, tmp_path / "none", "none", [], lambda n: None, substeps=2), "b")
    tilted = _frames(resimulate(reference, tmp_path / "gravity", "gravity", [], lambda n: None, substeps=2), "b")
    assert (tilted - none)[..., 0].mean() > 1e-3          # the tilt (azimuth 0) pushes the sheet towards +X
    out = resimulate(reference, tmp_path / "shrink", "shrink", ["factor=0.3"], lambda n: None, substeps=2)
    shrunk = _frames(out, "b")
    _, faces = read_mesh(reference / "gt" / "template.obj")
    low = np.load(reference / "gt" / "regions.npz")["side_seam"] > 0
    lower = faces[low[faces].all(1)]
    edges = lower[:, [0, 1]]
    length = np.linalg.norm(shrunk[-1, edges[:, 0]] - shrunk[-1, edges[:, 1]], axis=1).mean()
    plain = np.linalg.norm(none[-1, edges[:, 0]] - none[-1, edges[:, 1]], axis=1).mean()
    assert length < 0.9 * plain
    assert json.loads((out / "truth.json").read_text())["true_parameters"] == {"region.rest_scale": pytest.approx(0.7)}
