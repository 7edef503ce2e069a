"""`gg simulate`: a garment on a body-mesh folder and on a built-in motion; bad input gives one error line."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parents[1] / "physics"))

from physics_helpers import sheet, uv_sphere  # noqa: E402

from gg_core.cli import main  # noqa: E402
from gg_core.geometry.meshio import read_mesh, write_ply  # noqa: E402


def test_simulate_on_body_folder(tmp_path):
    bv, bf = uv_sphere(0.2, 16, 32)
    for k in range(8):
        write_ply(tmp_path / "body" / f"{k:04d}.ply", bv + [0.0, -0.005 * k, 0.0], bf)
    v, f = sheet(10, 10, 0.6, 0.6, y=0.215)
    write_ply(tmp_path / "garment.ply", v, f)
    code = main(["simulate", "--garment", str(tmp_path / "garment.ply"), "--body", str(tmp_path / "body"),
                 "--out", str(tmp_path / "out"), "--pin", "none", "--force", "air_drag:coef=0.8", "--progress", "none"])
    assert code == 0
    frames = sorted((tmp_path / "out").glob("*.ply"))
    assert len(frames) == 8
    last, faces = read_mesh(frames[-1])
    np.testing.assert_array_equal(faces, f)
    assert last[:, 1].min() < 0.1                                # draped over the sphere
    report = json.loads((tmp_path / "out" / "simulate.json").read_text())
    assert report["penetration"]["max_fraction_deeper"] <= 0.01
    assert [t["name"] for t in report["terms"]][-1] == "air_drag"


def test_simulate_skirt_on_motion(tmp_path):
    from gg_core.body.model import load_body
    from gg_core.synth.garments import tailor

    garment = tailor(load_body(), "skirt", 300)
    write_ply(tmp_path / "skirt.ply", garment.vertices, garment.faces)
    code = main(["simulate", "--garment", str(tmp_path / "skirt.ply"), "--motion", "walk", "--frames", "4",
                 "--settle", "2", "--out", str(tmp_path / "out"), "--progress", "none"])
    assert code == 0
    report = json.loads((tmp_path / "out" / "simulate.json").read_text())
    assert report["frames"] == 6 and report["pinned_vertices"] > 0      # the waistband attaches itself
    with np.load(tmp_path / "out" / report["body"]) as body:           # the body it moved with, for the add-on
        assert body["positions"].shape == (6, len(load_body().rest_vertices), 3)
        assert body["faces"].max() < body["positions"].shape[1]
    assert report["penetration"]["max_fraction_deeper"] <= 0.01


def test_bad_input_is_one_error_line(tmp_path, capsys):
    assert main(["simulate", "--garment", str(tmp_path / "missing.ply"), "--motion", "walk",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gg: error: mesh file not found")
    v, f = sheet(2, 2, 0.1, 0.1)
    write_ply(tmp_path / "g.ply", v, f)
    assert main(["simulate", "--garment", str(tmp_path / "g.ply"), "--motion", "walk", "--out", str(tmp_path / "o"),
                 "--force", "lift:coef=1"]) == 2
    assert capsys.readouterr().err.startswith("gg: error: unknown force terms")
    assert main(["simulate", "--garment", str(tmp_path / "g.ply"), "--motion", "walk", "--out", str(tmp_path / "o"),
                 "--force", "bending_damping:tau=-0.1"]) == 2
    assert capsys.readouterr().err.startswith("gg: error: term 'bending_damping' parameter tau=-0.1 is not physical")
    assert not (tmp_path / "o").exists()


def test_a_fitted_behaviour_brings_its_own_garment_mesh(tmp_path):
    """Behaviour fitted to fine registered meshes lives on a remeshed simulation mesh: --behavior alone
    simulates that mesh; a missing file is one error line."""
    from gg_core.physics.cloth import Cloth
    from gg_core.physics.forces import DEFAULT_TERMS, make_terms
    from gg_core.physics.material import MATERIAL_NAMES, Material

    bv, bf = uv_sphere(0.2, 16, 32)
    for k in range(4):
        write_ply(tmp_path / "body" / f"{k:04d}.ply", bv, bf)
    v, f = sheet(6, 6, 0.4, 0.4, y=0.215)
    cloth = Cloth(v, f, material=Material.uniform(len(v), density=0.2))
    np.savez(tmp_path / "behavior.npz", template=v, faces=f, rest_lengths=cloth.rest_lengths.numpy(),
             **{n: getattr(cloth.material, n).numpy() for n in MATERIAL_NAMES})
    code = main(["simulate", "--behavior", str(tmp_path / "behavior.npz"), "--body", str(tmp_path / "body"),
                 "--out", str(tmp_path / "out"), "--pin", "none", "--progress", "none"])
    assert code == 0
    last, faces = read_mesh(sorted((tmp_path / "out").glob("*.ply"))[-1])
    assert len(last) == len(v) and np.array_equal(faces, f)
    terms = [t["name"] for t in json.loads((tmp_path / "out" / "simulate.json").read_text())["terms"]]
    assert terms == [t.name for t in make_terms(DEFAULT_TERMS)]          # no terms stored: the defaults
    assert main(["simulate", "--behavior", str(tmp_path / "nope.npz"), "--body", str(tmp_path / "body"),
                 "--out", str(tmp_path / "o")]) == 2
    assert main(["simulate", "--body", str(tmp_path / "body"), "--out", str(tmp_path / "o")]) == 2


def test_a_model_file_simulates_with_its_own_terms_and_the_command_line_overrides_them(tmp_path):
    """diagnose/model.npz carries the missing physics the diagnosis found (here a tilt of gravity along +x): the
    garment simulated from it drifts along the tilt; --force replaces a stored parameter."""
    from gg_core.physics.cloth import Cloth
    from gg_core.physics.forces import DEFAULT_TERMS, make_terms
    from gg_core.physics.model_file import model_arrays
    from gg_core.storage import write_npz

    bv, bf = uv_sphere(0.1, 8, 16, center=(0.0, -3.0, 0.0))         # a body far below: free fall
    for k in range(6):
        write_ply(tmp_path / "body" / f"{k:04d}.ply", bv, bf)
    v, f = sheet(4, 4, 0.3, 0.3)
    terms = make_terms(list(DEFAULT_TERMS) + ["gravity_offset"], {"gravity_offset": {"delta_g": (3.0, 0.0, 0.0)}})
    write_npz(tmp_path / "model.npz", **model_arrays(Cloth(v, f, uniform_mass=True), terms, np.zeros(len(v), bool)))

    def drift(*extra: str) -> tuple[float, list[str]]:
        out = tmp_path / f"out{len(list(tmp_path.glob('out*')))}"
        assert main(["simulate", "--behavior", str(tmp_path / "model.npz"), "--body", str(tmp_path / "body"),
                     "--out", str(out), "--pin", "none", "--progress", "none", *extra]) == 0
        last, _ = read_mesh(sorted(out.glob("*.ply"))[-1])
        report = json.loads((out / "simulate.json").read_text())
        assert report["vertex_mass"] == "uniform"          # the model's mass spread is kept
        return float(last[:, 0].mean() - v[:, 0].mean()), [t["name"] for t in report["terms"]]

    along, names = drift()
    assert "gravity_offset" in names and along > 0.01            # 3 m/s^2 over 5 frames: ~2 cm
    still, names = drift("--force", "gravity_offset:delta_g=0;0;0")
    assert names.count("gravity_offset") == 1 and abs(still) < 1e-6
