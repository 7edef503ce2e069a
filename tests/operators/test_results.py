"""Loading stage results into the scene: template with UVs, registered sequences as Mesh Cache animation,
residual heat map with the verdict; stage buttons refuse to run without folders."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gg_core.geometry.meshio import write_obj, write_ply

pytestmark = pytest.mark.bpy

QUAD = np.array([[0.0, 1.0, 0.0], [0.2, 1.0, 0.0], [0.2, 1.2, 0.1], [0.0, 1.2, 0.1]])
TRIS = np.array([[0, 1, 2], [0, 2, 3]])


def test_template_loads_with_its_uv_atlas(blender, tmp_path, z_up):
    uvs = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]])
    (tmp_path / "stage1").mkdir()
    write_obj(tmp_path / "stage1" / "template.obj", QUAD, TRIS, uvs, TRIS)
    blender.context.scene.gg.project_path = str(tmp_path)
    for _ in range(2):  # loading again replaces, never duplicates
        assert blender.ops.gg.load_template() == {"FINISHED"}
    objs = [o for o in blender.data.objects if o.get("gg_result") == "garment_template"]
    assert len(objs) == 1
    mesh = objs[0].data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    np.testing.assert_allclose(co.reshape(-1, 3), z_up(QUAD), atol=1e-6)
    loop_uv = np.empty(len(mesh.loops) * 2, np.float32)
    mesh.uv_layers["UVMap"].data.foreach_get("uv", loop_uv)
    np.testing.assert_allclose(loop_uv.reshape(-1, 2), uvs[TRIS.ravel()], atol=1e-6)


def test_registration_plays_back_every_frame_on_the_capture_timeline(blender, capture_writer, tmp_path, z_up,
                                                                      evaluated_vertices):
    bpy = blender
    capture = capture_writer(tmp_path / "capture", n_cams=1, n_frames=4, sequences=("seqA",))
    project = tmp_path / "project"
    bpy.context.scene.gg.project_path = str(project)
    assert bpy.ops.gg.import_capture(directory=str(capture)) == {"FINISHED"}
    frames = {f"{k:06d}": QUAD + [0.0, 0.0, 0.05 * k] for k in (1, 2, 3)}  # frame 0 not registered (yet)
    for name, verts in frames.items():
        (project / "stage2" / "seqA" / "meshes").mkdir(parents=True, exist_ok=True)
        write_ply(project / "stage2" / "seqA" / "meshes" / f"{name}.ply", verts, TRIS)
    assert bpy.ops.gg.load_registration() == {"FINISHED"}
    garment = bpy.data.objects["seqA_garment"]
    assert garment.users_collection[0].name == "seqA"
    scene = bpy.context.scene
    for k, (name, verts) in enumerate(frames.items(), start=1):
        scene.frame_set(scene.frame_start + k)
        np.testing.assert_allclose(evaluated_vertices(garment), z_up(verts), atol=1e-6)


def test_registration_with_changing_topology_is_refused(blender, tmp_path):
    meshes = tmp_path / "stage2" / "seqA" / "meshes"
    meshes.mkdir(parents=True)
    write_ply(meshes / "000000.ply", QUAD, TRIS)
    write_ply(meshes / "000001.ply", QUAD, TRIS[::-1])
    blender.context.scene.gg.project_path = str(tmp_path)
    with pytest.raises(RuntimeError, match=r"gg: error: registered meshes change topology, .*000001\.ply"):
        blender.ops.gg.load_registration()


def _write_behavior(project: Path, report: dict, mu: np.ndarray) -> None:
    (project / "reports").mkdir(parents=True)
    (project / "stage4").mkdir()
    (project / "reports" / "behavior.json").write_text(json.dumps(report))
    np.savez(project / "stage4" / "behavior.npz", template=QUAD, faces=TRIS, mu=mu)


def test_fitted_material_colours_the_garment_and_states_the_heldout_error(blender, tmp_path, z_up):
    report = {"source": "registered", "heldout_l2_default": 0.0312, "heldout_l2_fitted": 0.0125}
    _write_behavior(tmp_path, report, np.array([1000.0, 1000.0, 4000.0, 8000.0]))
    blender.context.scene.gg.project_path = str(tmp_path)
    for _ in range(2):  # loading again replaces, never duplicates
        assert blender.ops.gg.show_behavior() == {"FINISHED"}
    objs = [o for o in blender.data.objects if o.get("gg_result") == "behavior_material"]
    assert len(objs) == 1
    co = np.empty(4 * 3, np.float32)
    objs[0].data.vertices.foreach_get("co", co)
    np.testing.assert_allclose(co.reshape(-1, 3), z_up(QUAD), atol=1e-6)
    colors = np.empty(4 * 4, np.float32)
    objs[0].data.color_attributes["stiffness"].data.foreach_get("color", colors)
    colors = colors.reshape(4, 4)
    assert np.allclose(colors[0], colors[1]) and not np.allclose(colors[0], colors[3])
    assert blender.context.scene.gg.behavior == \
        "Behaviour (registered motion): held-out rollout 31.2 -> 12.5 mm"


def test_fitted_material_of_wrong_length_is_refused(blender, tmp_path):
    _write_behavior(tmp_path, {"source": "gt"}, np.zeros(3))
    blender.context.scene.gg.project_path = str(tmp_path)
    with pytest.raises(RuntimeError, match=r"gg: error: fitted material has \(3,\) values for 4 vertices"):
        blender.ops.gg.show_behavior()


def _write_diagnosis(project: Path, report: dict, residual: np.ndarray, activity: np.ndarray | None = None) -> None:
    (project / "reports").mkdir(parents=True)
    (project / "diagnose").mkdir()
    (project / "reports" / "diagnose.json").write_text(json.dumps(report))
    write_ply(project / "diagnose" / "template.ply", QUAD, TRIS)
    np.save(project / "diagnose" / "residual_vertex.npy", residual)
    if activity is not None:
        np.save(project / "diagnose" / "activity_vertex.npy", activity)


def test_residual_map_colours_the_garment_and_states_the_verdict(blender, tmp_path):
    report = {"verdict": "missing", "accepted": ["air_drag"],
              "effects": [{"name": "air_drag", "heldout_gain": 0.42}, {"name": "wind", "heldout_gain": 0.05}]}
    _write_diagnosis(tmp_path, report, np.array([0.0, 1.0, 2.0, 4.0]))
    blender.context.scene.gg.project_path = str(tmp_path)
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    obj = blender.data.objects["diagnosis_residual"]
    colors = np.empty(4 * 4, np.float32)
    obj.data.color_attributes["residual"].data.foreach_get("color", colors)
    colors = colors.reshape(4, 4)
    assert not np.allclose(colors[0], colors[3])  # low and high residual differ
    assert blender.context.scene.gg.diagnosis == "Missing physics: air_drag (held-out error -42%)"
    report.update(accepted=["wind", "gravity_offset"], heldout_gain=0.25)       # a joint refit was confirmed
    _write_diagnosis(tmp_path / "joint", report, np.array([0.0, 1.0, 2.0, 4.0]))
    blender.context.scene.gg.project_path = str(tmp_path / "joint")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == "Missing physics: wind + gravity_offset (held-out error -25% together)"
    cv = {"heldout_gain": 0.21, "train_rollout_gain": 0.3, "folds": 3, "complete": True}
    report = {"verdict": "missing", "accepted": ["mass_damping"],            # confirmed over the folds
              "effects": [{"name": "mass_damping", "heldout_gain": 0.04, "cross_validated": cv}]}
    _write_diagnosis(tmp_path / "folds", report, np.array([0.0, 1.0, 2.0, 4.0]))
    blender.context.scene.gg.project_path = str(tmp_path / "folds")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == "Missing physics: mass_damping (held-out error -21%, mean of 3 folds)"
    report["effects"][0]["residual_chose_over"] = "gravity_offset"        # the rollouts tied, the residual chose
    _write_diagnosis(tmp_path / "tie", report, np.array([0.0, 1.0, 2.0, 4.0]))
    blender.context.scene.gg.project_path = str(tmp_path / "tie")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == ("Missing physics: mass_damping (held-out error -21%, mean of 3 "
                                                  "folds; chosen over gravity_offset by the residual)")
    del report["effects"][0]["residual_chose_over"]
    report["effects"][0]["not_separated_from"] = ["gravity_offset"]      # the rollouts tied and nothing chose
    _write_diagnosis(tmp_path / "open", report, np.array([0.0, 1.0, 2.0, 4.0]))
    blender.context.scene.gg.project_path = str(tmp_path / "open")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == ("Missing physics: mass_damping (held-out error -21%, mean of 3 "
                                                  "folds; gravity_offset fits as well)")
    report["effects"][0]["uncertainty"] = {"delivered_ranges": {                    # pipeline.final_fit's profiles
        "mass_damping.alpha": {"factors": [0.8, 1.3]}, "wind.velocity": {"factors": [None, None]}}}
    _write_diagnosis(tmp_path / "loose", report, np.array([0.0, 1.0, 2.0, 4.0]))
    blender.context.scene.gg.project_path = str(tmp_path / "loose")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == ("Missing physics: mass_damping (held-out error -21%, mean of 3 "
                                                  "folds; gravity_offset fits as well; not fixed by the recordings: "
                                                  "wind.velocity)")
    report["effects"] = [{"name": "wind", "form": "moving air", "heldout_gain": 0.35}]    # refitted in another form
    report["accepted"] = ["wind"]
    _write_diagnosis(tmp_path / "form", report, np.array([0.0, 1.0, 2.0, 4.0]))
    blender.context.scene.gg.project_path = str(tmp_path / "form")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == "Missing physics: wind as moving air (held-out error -35%)"


def test_activity_map_is_a_second_attribute_with_the_residual_still_shown(blender, tmp_path):
    _write_diagnosis(tmp_path, {"verdict": "none"}, np.array([0.0, 1.0, 2.0, 4.0]), np.array([-6.0, 0.0, 1.0, 2.0]))
    blender.context.scene.gg.project_path = str(tmp_path)
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    obj = blender.data.objects["diagnosis_residual"]
    assert obj.data.color_attributes.active_color_name == "residual"
    colors = np.empty(4 * 4, np.float32)
    obj.data.color_attributes["stiffer_than_modelled"].data.foreach_get("color", colors)
    colors = colors.reshape(4, 4)
    assert not np.allclose(colors[0], colors[1]) and np.allclose(colors[1], colors[3])  # only the stiff vertex
    assert obj["gg_stiffer_than_modelled_max"] > 0


def test_tried_regions_become_vertex_groups(blender, tmp_path):
    report = {"verdict": "none", "localization": {
        "region_vertices": [0, 1], "grown_region_vertices": [0, 1, 2],
        "scanned_regions": {"rest_length_region": {"region_vertices": [2, 3]},
                            "heavy_region": {"region_vertices": None}},
        "region_choices": {"region_stiffness": {"chosen": "grown", "region_vertices": [0, 1, 2]}}}}
    _write_diagnosis(tmp_path, report, np.zeros(4))
    blender.context.scene.gg.project_path = str(tmp_path)
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    obj = blender.data.objects["diagnosis_residual"]
    assert sorted(g.name for g in obj.vertex_groups) == ["gg_region_maps", "gg_region_maps_grown",
                                                         "gg_region_region_stiffness", "gg_region_rest_length_region"]
    for name, expected in (("gg_region_rest_length_region", [2, 3]), ("gg_region_region_stiffness", [0, 1, 2])):
        group = obj.vertex_groups[name].index
        assert [v.index for v in obj.data.vertices if any(g.group == group for g in v.groups)] == expected


def test_region_beyond_the_mesh_is_refused(blender, tmp_path):
    report = {"verdict": "none", "localization": {"scanned_regions": {"rest_length_region": {"region_vertices": [9]}}}}
    _write_diagnosis(tmp_path, report, np.zeros(4))
    blender.context.scene.gg.project_path = str(tmp_path)
    with pytest.raises(RuntimeError,
                       match=r"gg: error: diagnosis region 'gg_region_rest_length_region' names vertex 9 of 4"):
        blender.ops.gg.show_residuals()


def test_residual_map_of_wrong_length_is_refused(blender, tmp_path):
    _write_diagnosis(tmp_path, {"verdict": "none"}, np.zeros(3))
    blender.context.scene.gg.project_path = str(tmp_path)
    with pytest.raises(RuntimeError, match=r"gg: error: residual map has \(3,\) values for 4 vertices"):
        blender.ops.gg.show_residuals()


def test_nothing_missing_is_said_plainly(blender, tmp_path):
    _write_diagnosis(tmp_path, {"verdict": "none", "accepted": []}, np.zeros(4))
    blender.context.scene.gg.project_path = str(tmp_path)
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == "Nothing missing: the simulator explains the recordings"
    _write_diagnosis(tmp_path / "loaded", {"verdict": "none", "accepted": [], "rest_mesh_given": False}, np.zeros(4))
    blender.context.scene.gg.project_path = str(tmp_path / "loaded")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis.endswith("rest state a loaded frame, a steady load may hide in it")
    _write_diagnosis(tmp_path / "noisy", {"verdict": "none", "accepted": [],
                                          "localization": {"activity_excess": 3.7, "activity_blind": True}},
                     np.zeros(4))
    blender.context.scene.gg.project_path = str(tmp_path / "noisy")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == ("Nothing missing: the simulator explains the recordings; noise "
                                                  "swamps the cloth's stretching, a stiffer region may hide")
    near = {"name": "wind", "heldout_gain": 0.084, "folds": [{}, {}], "near_miss": True,
            "why_not": ["mean held-out gain +8.4%, under 10%"]}
    _write_diagnosis(tmp_path / "near", {"verdict": "none", "accepted": [], "closest": near}, np.zeros(4))
    blender.context.scene.gg.project_path = str(tmp_path / "near")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == ("Nothing missing: the simulator explains the recordings; closest: "
                                                  "wind (held-out error -8.4%, not enough to name it)")
    near.update(folds=[{}], near_miss=False)   # a few percent on the split alone, never refitted in other folds
    _write_diagnosis(tmp_path / "split", {"verdict": "none", "accepted": [], "closest": near}, np.zeros(4))
    blender.context.scene.gg.project_path = str(tmp_path / "split")
    assert blender.ops.gg.show_residuals() == {"FINISHED"}
    assert blender.context.scene.gg.diagnosis == "Nothing missing: the simulator explains the recordings"


@pytest.mark.parametrize("operator", ["reconstruct_template", "register_sequences", "fit_behavior",
                                      "diagnose_physics"])
def test_stage_buttons_need_both_folders(blender, operator):
    with pytest.raises(RuntimeError, match=r"gg: error: no capture folder set, Garments panel > Capture"):
        getattr(blender.ops.gg, operator)()


def test_load_without_project_is_one_error_line(blender):
    with pytest.raises(RuntimeError, match=r"gg: error: no project folder set"):
        blender.ops.gg.load_template()


def test_a_simulation_whose_body_and_garment_disagree_is_refused(blender, tmp_path):
    out = tmp_path / "simulate" / "behaviour_walk"
    for t in range(3):
        write_ply(out / f"{t:06d}.ply", QUAD + [0.0, 0.0, 0.01 * t], TRIS)
    (out / "simulate.json").write_text(json.dumps({"frames": 3, "body": "body.npz"}))
    np.savez(out / "body.npz", positions=np.zeros((2, 4, 3), np.float32), faces=TRIS)
    blender.context.scene.gg.project_path = str(tmp_path)
    with pytest.raises(RuntimeError, match=r"gg: error: simulated body has 2 frames for 3 garment frames"):
        blender.ops.gg.load_simulations()
    (out / "000002.ply").unlink()
    with pytest.raises(RuntimeError, match=r"gg: error: simulation is missing garment frames \(simulate.json says 3\)"):
        blender.ops.gg.load_simulations()
