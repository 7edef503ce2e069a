"""Bring stage results into the scene: the stage-1 template, registered sequences, the fitted material, the
residual heat map, simulations of a fitted model with their body.

Each loader reads the project folder the stages wrote (layout in gg_core.stages; no torch here) and replaces
what an earlier load of the same result created, so re-running a stage and loading again never piles up
duplicates. Registered sequences and simulations are animated like the imported body: one mesh + a PC2 Mesh Cache.
"""
from __future__ import annotations

import json
from pathlib import Path

import bpy
import numpy as np
from bpy.types import Collection, Context, Object, Operator, Scene

from ..blender_addon.colormap import heat_colors
from ..blender_addon.convert import to_blender_points
from ..blender_addon.meshes import add_mesh_cache, mesh_object, vertex_colors
from ..gg_core.diagnosis.report_regions import candidate_regions
from ..gg_core.errors import InputError
from ..gg_core.geometry.meshio import read_mesh, read_obj

RESULTS_COLLECTION = "Gaussian Garments"


def project_dir(scene: Scene) -> Path:
    """The scene's project folder; InputError when it is not set or missing."""
    if not scene.gg.project_path:
        raise InputError("no project folder set", "Garments panel > Project", "choose the folder the stages write to")
    path = Path(bpy.path.abspath(scene.gg.project_path))
    if not path.is_dir():
        raise InputError("project folder not found", path, "run a stage first or choose another folder")
    return path


def _required(path: Path, how: str) -> Path:
    if not path.is_file():
        raise InputError(f"{path.name} not found", path, how)
    return path


def _replace_object(obj: Object, collection: Collection) -> Object:
    """Link `obj` into `collection`, removing an earlier object of the same result (same gg_result tag)."""
    for old in [o for o in collection.objects if o.get("gg_result") == obj["gg_result"]]:
        bpy.data.objects.remove(old, do_unlink=True)
    collection.objects.link(obj)
    obj.name = obj["gg_result"]
    return obj


def _results_collection(scene: Scene, name: str = RESULTS_COLLECTION) -> Collection:
    collection = bpy.data.collections.get(name)
    if collection is None:
        collection = bpy.data.collections.new(name)
    if collection.name not in scene.collection.children:
        scene.collection.children.link(collection)
    return collection


class _Loader(Operator):
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context: Context) -> set[str]:
        try:
            message = self.load(context.scene, project_dir(context.scene))
        except InputError as exc:
            self.report({"ERROR"}, exc.line())
            return {"CANCELLED"}
        self.report({"INFO"}, message)
        return {"FINISHED"}

    def load(self, scene: Scene, project: Path) -> str:
        raise NotImplementedError


class GG_OT_load_template(_Loader):
    """Show the stage-1 template mesh (with its UV atlas) of the project"""

    bl_idname = "gg.load_template"
    bl_label = "Load Template"

    def load(self, scene: Scene, project: Path) -> str:
        path = _required(project / "stage1" / "template.obj", "run Reconstruct Template first")
        verts, faces, uvs, face_uvs = read_obj(path)
        obj = mesh_object("garment_template", to_blender_points(verts), faces, uvs, face_uvs)
        obj["gg_result"] = "garment_template"
        _replace_object(obj, _results_collection(scene))
        return f"template: {len(verts)} vertices, {len(faces)} faces"


class GG_OT_load_registration(_Loader):
    """Show every registered sequence as an animated garment mesh (Mesh Cache), next to its capture sequence"""

    bl_idname = "gg.load_registration"
    bl_label = "Load Registration"

    def load(self, scene: Scene, project: Path) -> str:
        folders = sorted(p for p in (project / "stage2").glob("*/meshes") if any(p.glob("*.ply")))
        if not folders:
            raise InputError("no registered frames", project / "stage2", "run Register Sequences first")
        loaded = [self._sequence(scene, folder.parent.name, sorted(folder.glob("*.ply")), project)
                  for folder in folders]
        return f"registered garment: {len(loaded)} sequence(s), {sum(loaded)} frames"

    @staticmethod
    def _sequence(scene: Scene, name: str, files: list[Path], project: Path) -> int:
        positions, faces0 = _mesh_frames(files, "registered meshes", f"run Register Sequences again for {name}")
        # Place the animation on the capture's timeline: the imported sequence keeps its frame names.
        collection = next((c for c in bpy.data.collections if c.get("gg_sequence") == name), None)
        names = list(collection["gg_frames"]) if collection is not None and "gg_frames" in collection else []
        first = files[0].stem
        frame_start = scene.frame_start + (names.index(first) if first in names else 0)
        obj = _animated_mesh(f"{name}_garment", positions, faces0, project / "blender" / f"{name}_garment.pc2",
                             frame_start, "Registered Motion")
        obj["gg_sequence"] = name
        _replace_object(obj, collection if collection is not None else _results_collection(scene))
        return len(files)


def _mesh_frames(files: list[Path], what: str, how: str) -> tuple[np.ndarray, np.ndarray]:
    """Positions [T, V, 3] (Z-up) and faces of one mesh per frame; InputError where the topology changes."""
    frames, faces0 = [], None
    for path in files:
        verts, faces = read_mesh(path)
        if faces0 is None:
            faces0 = faces
        elif not np.array_equal(faces, faces0):
            raise InputError(f"{what} change topology", path, how)
        frames.append(to_blender_points(verts))
    return np.stack(frames), faces0


def _animated_mesh(result: str, positions: np.ndarray, faces: np.ndarray, cache: Path, frame_start: int,
                   label: str) -> Object:
    """A mesh tagged `result` at the first of `positions` [T, V, 3], played back through a Mesh Cache at `cache`."""
    obj = mesh_object(result, positions[0], faces)
    obj["gg_result"] = result
    if len(positions) > 1:
        add_mesh_cache(obj, positions, cache, frame_start, label)
    return obj


class GG_OT_load_simulations(_Loader):
    """Play back every simulation of the project (Simulate Garment): the garment and the body it moved with, from
    the scene's first frame, one collection per simulation"""

    bl_idname = "gg.load_simulations"
    bl_label = "Load Simulations"

    def load(self, scene: Scene, project: Path) -> str:
        folders = sorted(p.parent for p in (project / "simulate").glob("*/simulate.json"))
        if not folders:
            raise InputError("no simulations", project / "simulate", "run Simulate Garment first")
        frames = [self._simulation(scene, folder, project) for folder in folders]
        return f"simulations: {', '.join(f'{f.name} ({n} frames)' for f, n in zip(folders, frames))}"

    @staticmethod
    def _simulation(scene: Scene, folder: Path, project: Path) -> int:
        how = f"run Simulate Garment again for {folder.name}"
        report = _report_file(folder / "simulate.json", how)
        files = [folder / f"{t:06d}.ply" for t in range(int(report.get("frames", 0)))]
        if not files or not all(f.is_file() for f in files):
            raise InputError(f"simulation is missing garment frames (simulate.json says {len(files)})", folder, how)
        positions, faces = _mesh_frames(files, "simulated garment meshes", how)
        collection = _results_collection(scene, f"gg_sim_{folder.name}")
        cache = project / "blender" / "simulate"
        _replace_object(_animated_mesh(f"{folder.name}_garment", positions, faces,
                                       cache / f"{folder.name}_garment.pc2", scene.frame_start, "Simulated Motion"),
                        collection)
        body_path = folder / "body.npz"
        if body_path.is_file():      # built-in motions; a simulation on a body folder shows the user's own meshes
            try:
                with np.load(body_path) as z:
                    body, body_faces = z["positions"], z["faces"]
            except (OSError, ValueError, KeyError) as exc:
                raise InputError(f"simulated body cannot be read ({exc.__class__.__name__})", body_path, how) from None
            if len(body) != len(positions):
                raise InputError(f"simulated body has {len(body)} frames for {len(positions)} garment frames",
                                 body_path, how)
            _replace_object(_animated_mesh(f"{folder.name}_body", to_blender_points(body), body_faces,
                                           cache / f"{folder.name}_body.pc2", scene.frame_start, "Body Motion"),
                            collection)
        return len(files)


def _heat_map(scene: Scene, result: str, verts: np.ndarray, faces: np.ndarray, values: np.ndarray,
              attribute: str) -> Object:
    """A mesh of the results collection coloured by per-vertex `values` (colour attribute `attribute`, rendered
    by an emission material); the value at the top of the ramp is kept as gg_<attribute>_max for a legend."""
    colors, vmax = heat_colors(values)
    obj = mesh_object(result, to_blender_points(verts), faces)
    obj["gg_result"] = result
    obj[f"gg_{attribute}_max"] = vmax
    vertex_colors(obj, colors, attribute)
    obj.data.materials.append(_attribute_material(attribute))
    return _replace_object(obj, _results_collection(scene))


def _second_map(obj: Object, values: np.ndarray, attribute: str) -> None:
    """One more colour attribute on a heat-map object (switch to it in the viewport); the first stays shown."""
    attributes = obj.data.color_attributes
    shown = attributes.active_color_name
    colors, vmax = heat_colors(values)
    vertex_colors(obj, colors, attribute)
    obj[f"gg_{attribute}_max"] = vmax
    attributes.active_color = attributes[shown]
    attributes.render_color_index = attributes.active_color_index


def _report(project: Path, stage: str, how: str) -> dict:
    return _report_file(_required(project / "reports" / f"{stage}.json", how), how)


def _report_file(path: Path, how: str) -> dict:
    stage = path.stem
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"{stage} report cannot be read ({exc.__class__.__name__})", path, how) from None


class GG_OT_show_behavior(_Loader):
    """Colour the rest garment by its fitted stretch stiffness and show the held-out rollout error in the panel"""

    bl_idname = "gg.show_behavior"
    bl_label = "Show Fitted Material"

    def load(self, scene: Scene, project: Path) -> str:
        report = _report(project, "behavior", "run Fit Behaviour first")
        path = _required(project / "stage4" / "behavior.npz", "run Fit Behaviour again")
        with np.load(path) as z:
            verts, faces, mu = z["template"], z["faces"], z["mu"]
        if mu.shape != (len(verts),):
            raise InputError(f"fitted material has {mu.shape} values for {len(verts)} vertices", path,
                             "run Fit Behaviour again")
        _heat_map(scene, "behavior_material", verts, faces, mu, "stiffness")
        scene.gg.behavior = behavior_summary(report)
        return scene.gg.behavior


def behavior_summary(report: dict) -> str:
    """One line for the panel: held-out rollout error (mm) with the default and the fitted material."""
    before, after = report.get("heldout_l2_default"), report.get("heldout_l2_fitted")
    if before is None or after is None:
        return f"Behaviour fitted to the {report.get('source', '?')} motion (no held-out sequence)"
    return (f"Behaviour ({report.get('source', '?')} motion): held-out rollout {before * 1e3:.1f} -> "
            f"{after * 1e3:.1f} mm")


class GG_OT_show_residuals(_Loader):
    """Colour the garment by the diagnosis' residual force map and show the verdict in the panel"""

    bl_idname = "gg.show_residuals"
    bl_label = "Show Residual Map"

    def load(self, scene: Scene, project: Path) -> str:
        report = _report(project, "diagnose", "run Diagnose Physics first")
        verts, faces = read_mesh(_required(project / "diagnose" / "template.ply", "run Diagnose Physics again"))
        residual = np.load(_required(project / "diagnose" / "residual_vertex.npy", "run Diagnose Physics again"))
        if residual.shape != (len(verts),):
            raise InputError(f"residual map has {residual.shape} values for {len(verts)} vertices",
                             project / "diagnose", "run Diagnose Physics again")
        obj = _heat_map(scene, "diagnosis_residual", verts, faces, residual, "residual")
        activity_path = project / "diagnose" / "activity_vertex.npy"
        if activity_path.is_file():      # written since the deformation-activity localization
            activity = np.load(activity_path)
            if activity.shape != (len(verts),):
                raise InputError(f"activity map has {activity.shape} values for {len(verts)} vertices",
                                 project / "diagnose", "run Diagnose Physics again")
            _second_map(obj, np.maximum(-activity, 0.0), "stiffer_than_modelled")
        for name, indices in region_groups(report).items():
            if max(indices) >= len(verts):      # region_groups keeps non-empty regions only
                raise InputError(f"diagnosis region '{name}' names vertex {max(indices)} of {len(verts)}",
                                 project / "reports" / "diagnose.json", "run Diagnose Physics again")
            obj.vertex_groups.new(name=name).add(indices, 1.0, "REPLACE")
        scene.gg.diagnosis = summary(report)
        return scene.gg.diagnosis


def region_groups(report: dict) -> dict[str, list[int]]:
    """Vertex groups of the garment regions region candidates were tried on (select them in Edit Mode): the one
    the maps singled out, its grown extent, and each candidate's own where it scanned or chose one."""
    loc = report.get("localization", {})
    groups = {"gg_region_maps": loc.get("region_vertices") or [],
              "gg_region_maps_grown": loc.get("grown_region_vertices") or []}
    for name, own in candidate_regions(loc).items():
        groups[f"gg_region_{name}"] = own or []
    return {name: [int(i) for i in indices] for name, indices in groups.items() if indices}


def summary(report: dict) -> str:
    """One line for the panel: the verdict, the accepted effects and how much they lower the held-out rollout
    error (each alone, as the mean over the folds where it was cross-validated, or together where two were
    accepted: the joint refit is what was confirmed), the form it was refitted in where the candidate has several
    (library.Form), and the candidate it was chosen over where the rollouts tied
    (folds.CrossValidation.residual_tie_break) or, where nothing chose, the rivals it was not told from
    (verdict.unresolved), and the delivered values the recordings do not fix at all (identify.profiles: every
    multiple profiled rolls out about as well), which a user should not read as measured. A `none` names the
    candidate that came closest where it was refitted in every fold and lowered the held-out error there
    (verdict.closest, report.closest_sentence): weak evidence; and it says when the rest state was a loaded frame or
    the recordings' noise swamps the cloth's stretching (report.noisy_stretch_caveat): what a `none` may miss."""
    if report.get("verdict") != "missing":
        loaded = "; rest state a loaded frame, a steady load may hide in it" if report.get("rest_mesh_given") is False \
            else ""
        noisy = "; noise swamps the cloth's stretching, a stiffer region may hide" \
            if report.get("localization", {}).get("activity_blind") else ""
        near = report.get("closest") or {}
        closest = f"; closest: {near['name']} (held-out error {-near['heldout_gain']:+.1%}, not enough to name it)" \
            if near.get("near_miss") else ""
        return f"Nothing missing: the simulator explains the recordings{closest}{loaded}{noisy}"
    accepted = report.get("accepted", [])
    if len(accepted) > 1 and report.get("heldout_gain") is not None:
        return f"Missing physics: {' + '.join(accepted)} (held-out error {-report['heldout_gain']:+.0%} together)"
    effects = {e["name"]: e for e in report.get("effects", [])}

    def gain(name: str) -> str:
        effect = effects.get(name, {})
        cv = effect.get("cross_validated") or {}
        rivals = effect.get("not_separated_from") or []
        over = f"; chosen over {effect['residual_chose_over']} by the residual" if effect.get("residual_chose_over") \
            else (f"; {' or '.join(rivals)} fits as well" if rivals else "")
        loose = [k for k, r in ((effect.get("uncertainty") or {}).get("delivered_ranges") or {}).items()
                 if r["factors"] == [None, None]]
        over += f"; not fixed by the recordings: {', '.join(loose)}" if loose else ""
        label = f"{name} as {effect['form']}" if effect.get("form") else name
        if cv.get("complete"):
            return f"{label} (held-out error {-cv['heldout_gain']:+.0%}, mean of {cv['folds']} folds{over})"
        if effect.get("heldout_gain") is None:
            return label
        return f"{label} (held-out error {-effect['heldout_gain']:+.0%}{over})"

    return "Missing physics: " + ", ".join(gain(name) for name in accepted)


def _attribute_material(attribute: str) -> bpy.types.Material:
    """A material that renders the colour attribute, so the heat map shows in Material/Rendered view too."""
    name = f"gg_{attribute}"
    material = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    color = nodes.new("ShaderNodeVertexColor")
    color.layer_name = attribute
    emission = nodes.new("ShaderNodeEmission")
    output = nodes.new("ShaderNodeOutputMaterial")
    links.new(color.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], output.inputs["Surface"])
    return material


CLASSES = (GG_OT_load_template, GG_OT_load_registration, GG_OT_show_behavior, GG_OT_show_residuals,
           GG_OT_load_simulations)
