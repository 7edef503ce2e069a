"""Simulate Garment: the fitted model the panel names rolls out on a built-in motion (a real `gg simulate` job)
and plays back with its body; a missing model is one error line saying which stage makes it."""
from __future__ import annotations

import importlib

import pytest

from gg_core.body.model import load_body
from gg_core.physics.cloth import Cloth
from gg_core.physics.forces import DEFAULT_TERMS, make_terms
from gg_core.physics.model_file import model_arrays
from gg_core.storage import write_npz
from gg_core.synth.garments import tailor

pytestmark = pytest.mark.bpy


def test_the_diagnosed_model_is_simulated_on_a_motion_and_played_back_with_its_body(blender, tmp_path,
                                                                                     evaluated_vertices):
    garment = tailor(load_body(), "skirt", 200)
    cloth = Cloth(garment.vertices, garment.faces)
    terms = make_terms([*DEFAULT_TERMS, "gravity_offset"], {"gravity_offset": {"delta_g": [1.5, 0.0, 0.0]}})
    write_npz(tmp_path / "diagnose" / "model.npz", **model_arrays(cloth, terms, cloth.pinned))
    settings = blender.context.scene.gg
    settings.project_path, settings.simulation_motion, settings.simulation_frames = str(tmp_path), "squat", 3
    assert blender.ops.gg.simulate_garment() == {"FINISHED"}
    out = tmp_path / "simulate" / "diagnosed_squat"
    assert len(list(out.glob("*.ply"))) == 18 and (out / "body.npz").is_file()     # 15 settle frames + 3
    collection = blender.data.collections["gg_sim_diagnosed_squat"]
    garment_obj, body_obj = (collection.objects[f"diagnosed_squat_{part}"] for part in ("garment", "body"))
    scene = blender.context.scene
    scene.frame_set(scene.frame_start)
    first = evaluated_vertices(garment_obj)
    scene.frame_set(scene.frame_start + 17)
    last = evaluated_vertices(garment_obj)
    assert len(last) == cloth.n_vertices and abs(last - first).max() > 1e-3       # the garment moved
    assert len(evaluated_vertices(body_obj)) == len(load_body().rest_vertices)
    assert blender.ops.gg.load_simulations() == {"FINISHED"}                       # reloading replaces
    assert len(blender.data.collections["gg_sim_diagnosed_squat"].objects) == 2


def test_a_missing_model_names_the_stage_that_makes_it(blender, tmp_path):
    settings = blender.context.scene.gg
    settings.project_path, settings.simulation_model = str(tmp_path), "diagnosed"
    with pytest.raises(RuntimeError, match=r"gg: error: no diagnose/model.npz in the project, .*run Diagnose Physics"):
        blender.ops.gg.simulate_garment()
    settings.simulation_model = "behaviour"
    with pytest.raises(RuntimeError, match=r"gg: error: no stage4/behavior.npz in the project, .*run Fit Behaviour"):
        blender.ops.gg.simulate_garment()


def test_diagnose_physics_passes_the_panel_mass_spread(blender, extension_package, tmp_path):
    diagnose_arguments = importlib.import_module(f"{extension_package.__name__}.operators.stages").diagnose_arguments
    settings = blender.context.scene.gg
    settings.capture_path, settings.project_path = str(tmp_path / "capture"), str(tmp_path / "project")
    assert diagnose_arguments(blender.context)[-2:] == ["--vertex-mass", "area"]
    settings.diagnose_vertex_mass = "uniform"
    assert diagnose_arguments(blender.context) == [str(tmp_path / "capture"), "--project", str(tmp_path / "project"),
                                                   "--vertex-mass", "uniform"]
