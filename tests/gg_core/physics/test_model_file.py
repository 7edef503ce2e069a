"""A fitted model file keeps what the simulator needs: rest state, material, pins, bending's rest, the terms."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from physics_helpers import sheet

from gg_core.physics.cloth import Cloth
from gg_core.physics.forces import make_terms
from gg_core.physics.material import MATERIAL_NAMES, Material
from gg_core.physics.model_file import model_arrays, read_model
from gg_core.storage import write_npz


def test_a_model_file_round_trips_the_cloth_and_its_fitted_terms(tmp_path):
    v, f = sheet(4, 3, 0.4, 0.3)
    pinned = np.zeros(len(v), bool)
    pinned[:3] = True
    density = np.linspace(0.1, 0.3, len(v))
    cloth = Cloth(v, f, material=Material.uniform(len(v), density=0.2), pinned=pinned, flat=True)
    cloth.material.density = torch.from_numpy(density)
    cloth.rest_lengths = cloth.rest_lengths * 0.97
    terms = make_terms(["gravity", "gravity_offset", "viscoelastic_damping"],
                       {"gravity_offset": {"delta_g": (1.5, 0.0, -0.25)}, "viscoelastic_damping": {"tau": 0.02}})
    model = read_model(write_npz(tmp_path / "model.npz", **model_arrays(cloth, terms, pinned)))
    assert model.cloth.flat and np.array_equal(model.cloth.pinned, pinned)
    np.testing.assert_array_equal(model.cloth.template, v)
    np.testing.assert_allclose(model.cloth.material.density.numpy(), density)
    np.testing.assert_allclose(model.cloth.rest_lengths.numpy(), cloth.rest_lengths.numpy())
    assert [n for n, _ in model.terms] == ["inertia", "gravity", "gravity_offset", "viscoelastic_damping"]
    stored = dict(model.terms)
    assert stored["gravity_offset"]["delta_g"] == [1.5, 0.0, -0.25] and stored["viscoelastic_damping"]["tau"] == 0.02
    rebuilt = make_terms([n for n, _ in model.terms], {n: p for n, p in model.terms if p})
    assert [t.describe()["params"] for t in rebuilt] == [t.describe()["params"] for t in terms]


def test_older_files_load_without_terms_and_mismatched_arrays_are_refused(tmp_path):
    v, f = sheet(3, 3, 0.3, 0.3)
    cloth = Cloth(v, f)
    arrays = {"template": v, "faces": f, "rest_lengths": cloth.rest_lengths.numpy(),
              **{n: getattr(cloth.material, n).numpy() for n in MATERIAL_NAMES}}
    np.savez(tmp_path / "old.npz", **arrays)
    old = read_model(tmp_path / "old.npz")
    assert old.terms is None and not old.cloth.flat and not old.cloth.pinned.any() and not old.cloth.uniform_mass
    np.savez(tmp_path / "short.npz", **{**arrays, "density": np.ones(len(v) - 1)})
    with pytest.raises(ValueError, match="do not match the 16-vertex template"):
        read_model(tmp_path / "short.npz")
    np.savez(tmp_path / "empty.npz", template=v, faces=f)
    with pytest.raises(ValueError, match="no rest_lengths"):
        read_model(tmp_path / "empty.npz")


def test_uniform_vertex_mass_is_stored_and_spreads_the_same_total_mass_evenly(tmp_path):
    v, f = sheet(4, 3, 0.4, 0.3)
    lumped = Cloth(v, f, material=Material.uniform(len(v), density=0.2))
    even = Cloth(v, f, material=Material.uniform(len(v), density=0.2), uniform_mass=True)
    m_lumped, m_even = lumped.numeric().mass, even.numeric().mass
    assert m_lumped.max() > 2 * m_lumped.min()                  # corners carry a quarter of an inner vertex's area
    np.testing.assert_allclose(m_even, m_lumped.sum() / len(v))
    arrays = model_arrays(even, make_terms(["gravity"]), np.zeros(len(v), bool))
    model = read_model(write_npz(tmp_path / "model.npz", **arrays))
    assert model.cloth.uniform_mass
    np.testing.assert_allclose(model.cloth.numeric().mass, m_even)
