"""Stage 1 end to end on the tiny synthetic capture (6 cameras of 72x96 px: about 2 cm per pixel)."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from gg_core.capture.images import read_mask, read_rgb
from gg_core.capture.layout import FOREGROUND_MASK, GARMENT_MASK, Capture
from gg_core.gaussians import GaussianTexture
from gg_core.geometry.meshio import read_mesh, read_obj
from gg_core.metrics.surface import surface_metrics
from gg_core.reconstruction.template_mesh import TemplateGeometryOptions, reconstruct_template
from gg_core.stages.template import TemplateRequest, auto_resolution, run_template

# measured on the tiny preset (seed 0, 00_walk frame 000000): CD 1.31 cm, p2m 1.24 cm, F@1cm 47 %
CD_BOUND_CM = 2.0
FSCORE_BOUND = 35.0


@pytest.fixture(scope="module")
def template_project(tiny_capture, tmp_path_factory):
    project = tmp_path_factory.mktemp("template") / "project"
    req = TemplateRequest(capture=tiny_capture, project=project, appearance_iterations=10, progress="none")
    return req, run_template(req)


def test_template_outputs_and_accuracy(template_project):
    req, report_path = template_project
    report = json.loads(report_path.read_text())
    verts, faces, uvs, face_uvs = read_obj(req.project / "stage1" / "template.obj")
    assert report["vertices"] == len(verts) and report["faces"] == len(faces)
    assert 700 <= len(verts) <= 1800                      # ~1000 for images this small
    assert report["cd_cm"] < CD_BOUND_CM and report["fscore_1cm"] > FSCORE_BOUND
    assert report["p2m_cm"] < CD_BOUND_CM
    assert [p["genus"] for p in report["geometry"]["pieces"]] == [0]   # one piece, no handles (a skirt: a tube)
    # the report's metrics are the template's, against the frame's ground truth
    gt = read_mesh(Capture(req.capture).sequence("00_walk").gt_garment_files["000000"])
    assert surface_metrics(verts, faces, *gt)["cd_cm"] == pytest.approx(report["cd_cm"], rel=1e-3)  # OBJ: 7 digits
    assert report["sequence"] == "00_walk" and report["frame"] == "000000" and len(report["cameras"]) == 6
    # the truth's stereo coverage: fewer cameras within tighter facing angles, so the shares can only grow
    cov = [report["truth_stereo_coverage"][f"cos_{c}"] for c in ("0.1", "0.3", "0.5")]
    assert all(0.0 <= c["unseen_pct"] <= c["fewer_than_two_pct"] < 50.0 for c in cov)
    assert cov[0]["fewer_than_two_pct"] <= cov[1]["fewer_than_two_pct"] <= cov[2]["fewer_than_two_pct"]
    # UV atlas: every face has UVs inside the unit square, and no UV triangle is degenerate
    assert uvs is not None and face_uvs.shape == faces.shape
    assert uvs.min() >= 0.0 and uvs.max() <= 1.0
    t = uvs[face_uvs]
    uv_area = 0.5 * np.abs((t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1])
                           - (t[:, 2, 0] - t[:, 0, 0]) * (t[:, 1, 1] - t[:, 0, 1]))
    assert uv_area.min() > 0
    # Gaussians bound to the template's faces, texture at the automatic resolution
    texture = GaussianTexture.from_state(dict(np.load(req.project / "stage1" / "gaussians.npz")))
    assert len(texture) == report["gaussians"] > len(faces)
    assert texture.face_ids.max() < len(faces) and texture.resolution == report["texture_resolution"]
    np.testing.assert_allclose(texture.uvs, uvs, atol=1e-6)
    assert report["appearance"]["rgb_loss_after"] < report["appearance"]["rgb_loss_before"]
    assert set(report["timings"]) >= {"load_s", "geometry_s", "appearance_s", "metrics_s", "total_s"}


def test_rerun_skips_and_appearance_change_keeps_the_mesh(template_project, monkeypatch):
    import gg_core.reconstruction.template_mesh as template_mesh
    import gg_core.registration.appearance as appearance

    req, report_path = template_project
    obj = req.project / "stage1" / "template.obj"
    before = (report_path.stat().st_mtime_ns, obj.stat().st_mtime_ns)
    monkeypatch.setattr(template_mesh, "reconstruct_template", lambda *a, **k: pytest.fail("geometry rebuilt"))
    with monkeypatch.context() as patch:
        patch.setattr(appearance, "fit_appearance", lambda *a, **k: pytest.fail("appearance refitted"))
        assert run_template(req) == report_path
    assert (report_path.stat().st_mtime_ns, obj.stat().st_mtime_ns) == before
    req2 = TemplateRequest(capture=req.capture, project=req.project, appearance_iterations=5, progress="none")
    report = json.loads(run_template(req2).read_text())
    assert obj.stat().st_mtime_ns == before[1]             # geometry reused
    assert report["appearance"]["iterations"] == 5 and report["inputs"]["options"]["appearance_iterations"] == 5


def test_the_free_hem_is_trimmed_and_the_trim_width_is_a_geometry_input(template_project, tmp_path):
    req, report_path = template_project
    trim = json.loads((req.project / "stage1" / "geometry.json").read_text())["log"]["free_border_trim"]
    assert trim["free_border_vertices"] > 0 and 0.0 < trim["area_removed_share"] < 0.1     # the hem, not the waist
    project = tmp_path / "project"
    shutil.copytree(req.project, project)
    untrimmed = TemplateRequest(capture=req.capture, project=project, appearance_iterations=10,
                                free_border_trim=0.0, progress="none")
    run_template(untrimmed)                                # the width changed: the mesh is rebuilt, untrimmed
    log = json.loads((project / "stage1" / "geometry.json").read_text())["log"]
    assert log["free_border_trim"]["width_m"] == 0.0 and "area_removed_share" not in log["free_border_trim"]
    kept, trimmed = (read_mesh(p / "stage1" / "template.obj")[0] for p in (project, req.project))
    assert len(kept) > len(trimmed) and kept[:, 1].min() < trimmed[:, 1].min()   # the hem reaches lower


def test_photo_consistency_lowers_the_error_of_the_silhouette_template(tiny_capture):
    seq = Capture(tiny_capture).sequence("00_walk")
    cams = list(seq.cameras.values())
    fg = [read_mask(seq.image_path(c.id, "000000", FOREGROUND_MASK)) for c in cams]
    gm = [read_mask(seq.image_path(c.id, "000000", GARMENT_MASK)) for c in cams]
    rgb = [read_rgb(seq.image_path(c.id, "000000")) for c in cams]
    gt = read_mesh(seq.gt_garment_files["000000"])
    hull = reconstruct_template(cams, fg, gm, None, TemplateGeometryOptions(photo=None))
    photo = reconstruct_template(cams, fg, gm, rgb)
    cd_hull = surface_metrics(hull.verts, hull.faces, *gt)["cd_cm"]
    cd_photo = surface_metrics(photo.verts, photo.faces, *gt)["cd_cm"]
    assert cd_photo < cd_hull - 0.4                        # measured 2.27 -> 1.31 cm


def test_auto_resolution_follows_the_pixel_footprint():
    assert auto_resolution(0.6, 0.0088) == 256             # demo preset
    assert auto_resolution(0.6, 0.0235) == 128             # tiny preset
    assert auto_resolution(0.6, 0.001) == 512              # capped
