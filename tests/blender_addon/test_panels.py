"""The sidebar panels' draw() against a layout that checks every property, operator and icon it is given
(headless Blender has no UI to draw into)."""
from __future__ import annotations

import importlib
import shlex
from types import SimpleNamespace

import pytest

pytestmark = pytest.mark.bpy


class CheckingLayout:
    """Records draw calls and fails on names Blender's UILayout would reject."""

    def __init__(self, bpy, log: list):
        self.bpy, self.log, self.enabled = bpy, log, True

    def _icon(self, icon: str) -> None:
        icons = self.bpy.types.UILayout.bl_rna.functions["label"].parameters["icon"].enum_items
        assert icon in icons, f"unknown icon {icon}"

    def column(self, **_):
        return CheckingLayout(self.bpy, self.log)

    row = column

    def prop(self, data, name: str, **_) -> None:
        assert name in data.bl_rna.properties, name
        self.log.append(("prop", name))

    def label(self, text: str = "", icon: str = "NONE") -> None:
        self._icon(icon)
        self.log.append(("label", text))

    def progress(self, factor: float, type: str, text: str) -> None:
        self.log.append(("progress", round(factor, 3), text))

    def operator(self, idname: str, text: str = "", icon: str = "NONE"):
        self._icon(icon)
        module, name = idname.split(".")
        rna = getattr(getattr(self.bpy.ops, module), name).get_rna_type()
        record: dict = {}
        self.log.append(("operator", idname, record))
        return OperatorProperties(rna.properties, record)


class OperatorProperties:
    def __init__(self, allowed, record: dict):
        object.__setattr__(self, "_allowed", allowed)
        object.__setattr__(self, "_record", record)

    def __setattr__(self, name: str, value) -> None:
        assert name in self._allowed, f"operator has no property {name}"
        self._record[name] = value


def draw(bpy, panel_cls) -> list:
    log: list = []
    panel_cls.draw(SimpleNamespace(layout=CheckingLayout(bpy, log)), bpy.context)
    return log


def test_main_panel(blender, extension_package):
    panels = importlib.import_module(f"{extension_package.__name__}.blender_addon.panels")
    blender.context.scene.gg.capture_path = "/data/my capture"
    log = draw(blender, panels.GG_PT_garments)
    assert ("prop", "capture_path") in log and ("prop", "project_path") in log
    ops = {entry[1]: entry[2] for entry in log if entry[0] == "operator"}
    assert ops["gg.import_capture"] == {"directory": "/data/my capture"}
    assert ops["gg.run_job"] == {"stage": "inspect", "arguments": shlex.join(["/data/my capture"])}


def test_job_panel_states(blender, extension_package):
    panels = importlib.import_module(f"{extension_package.__name__}.blender_addon.panels")
    assert draw(blender, panels.GG_PT_job) == [("label", "No job has run yet")]
    job = blender.context.window_manager.gg_job
    job.running, job.progress, job.status = True, 0.25, "inspect 1/4 · seqA · ETA 3 s"
    log = draw(blender, panels.GG_PT_job)
    assert log[0] == ("progress", 0.25, "inspect 1/4 · seqA · ETA 3 s") and log[1][1] == "gg.cancel_job"
    job.running, job.failed, job.result = False, True, "gg: error: capture folder not found, /x, fix"
    assert draw(blender, panels.GG_PT_job) == [("label", "gg: error: capture folder not found, /x, fix")]


def test_pipeline_panel_offers_each_stage_and_its_loader(blender, extension_package):
    panels = importlib.import_module(f"{extension_package.__name__}.blender_addon.panels")
    log = draw(blender, panels.GG_PT_stages)
    ops = [entry[1] for entry in log if entry[0] == "operator"]
    assert ops == ["gg.reconstruct_template", "gg.load_template", "gg.register_sequences", "gg.load_registration",
                   "gg.fit_behavior", "gg.show_behavior", "gg.diagnose_physics", "gg.show_residuals"]
    assert not any(entry[0] == "label" for entry in log)
    assert [e[1] for e in log if e[0] == "prop"] == ["diagnose_vertex_mass"]
    blender.context.scene.gg.behavior = "Behaviour (registered motion): held-out rollout 31.2 -> 12.5 mm"
    blender.context.scene.gg.diagnosis = "Missing physics: air_drag (+42% held-out)"
    assert draw(blender, panels.GG_PT_stages)[-2:] == [
        ("label", "Behaviour (registered motion): held-out rollout 31.2 -> 12.5 mm"),
        ("label", "Missing physics: air_drag (+42% held-out)")]


def test_simulate_panel_offers_model_motion_and_frames(blender, extension_package):
    panels = importlib.import_module(f"{extension_package.__name__}.blender_addon.panels")
    log = draw(blender, panels.GG_PT_simulate)
    assert [e[1] for e in log if e[0] == "prop"] == ["simulation_model", "simulation_motion", "simulation_frames"]
    assert [e[1] for e in log if e[0] == "operator"] == ["gg.simulate_garment", "gg.load_simulations"]
    settings = blender.context.scene.gg
    assert (settings.simulation_model, settings.simulation_motion) == ("diagnosed", "walk")
    settings.simulation_motion = "jump"      # every built-in motion is offered
