"""Gaussian texture: texel -> face mapping, channel layout, atlas packing, per-face mode."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from gg_core.errors import InputError
from gg_core.gaussians import texture as tex
from gg_core.gaussians.sh import C0
from gg_core.storage import write_npz


@pytest.fixture(scope="module")
def sphere():
    m = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    return np.asarray(m.vertices), np.asarray(m.faces)


@pytest.fixture(scope="module")
def atlas_texture(sphere):
    return tex.build_texture(*sphere, resolution=64)


def test_every_covered_texel_maps_to_a_valid_face(sphere, atlas_texture):
    verts, faces = sphere
    t = atlas_texture
    assert t.params.shape == (len(t), tex.CHANNELS) == (len(t), 59)
    assert len(t) > 0.3 * 64 * 64  # the atlas uses a good part of the texture
    assert (t.face_ids >= 0).all() and (t.face_ids < len(faces)).all()
    assert (t.barycentrics >= 0).all() and np.allclose(t.barycentrics.sum(1), 1)
    # the barycentric UV of each Gaussian is its texel centre (v up: row 0 at the bottom)
    uv = (t.barycentrics[:, :, None] * t.uvs[t.face_uvs[t.face_ids]]).sum(1)
    centre = (t.texels[:, ::-1] + 0.5) / t.resolution
    assert np.abs(uv - centre).max() < 1e-9
    assert len(np.unique(t.texels, axis=0)) == len(t)  # one Gaussian per texel
    assert set(np.unique(t.face_ids)) == set(range(len(faces)))  # no face lost at this resolution


def test_atlas_is_exactly_the_texture_resolution_and_charts_do_not_overlap(sphere, atlas_texture):
    t = atlas_texture
    assert t.uvs.min() >= 0 and t.uvs.max() <= 1
    # no texel centre lies in two UV triangles: recount coverage with each face rasterized alone
    hits = np.zeros((64, 64), int)
    for f in range(len(t.face_uvs)):
        ids, _, texels = tex._rasterize_uv(t.uvs[t.face_uvs[f:f + 1]] * 64, 64)
        hits[texels[:, 0], texels[:, 1]] += 1
    assert hits.max() == 1 and hits.sum() == len(t)


def test_mesh_uvs_are_used_when_given():
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uvs = verts[:, :2] * 0.5  # the lower-left quarter of the texture
    t = tex.build_texture(verts, faces, resolution=8, uvs=uvs, face_uvs=faces)
    assert len(t) == 16 and set(map(tuple, t.texels)) == {(r, c) for r in range(4) for c in range(4)}
    # the texel above the diagonal (u < v) belongs to the second face
    upper = t.face_ids[(t.texels[:, 0] == 3) & (t.texels[:, 1] == 0)]
    assert upper.tolist() == [1]


def test_initial_parameters_decode_to_the_requested_look(atlas_texture):
    p = atlas_texture.params
    assert torch.allclose(p[:, 0:3] * C0 + 0.5, torch.tensor(0.5))
    assert torch.allclose(torch.sigmoid(p[:, tex.OPACITY]), torch.tensor(0.5))
    assert torch.equal(p[:, tex.ROTATION], torch.tensor([1.0, 0, 0, 0]).expand(len(p), 4))
    assert (p[:, tex.OFFSET] == 0).all() and (p[:, 3:48] == 0).all()


def test_scatter_gather_roundtrip_and_state(atlas_texture):
    values = torch.randn(len(atlas_texture), 5)
    image = atlas_texture.scatter(values)
    assert image.shape == (64, 64, 5) and torch.equal(atlas_texture.gather(image), values)
    assert (image.abs().sum(-1) > 0).sum() == len(atlas_texture)
    again = tex.GaussianTexture.from_state(atlas_texture.state())
    assert np.array_equal(again.face_ids, atlas_texture.face_ids) and torch.equal(again.params, atlas_texture.params)


def test_a_stored_texture_loads_back_unchanged(atlas_texture, tmp_path):
    path = write_npz(tmp_path / "texture.npz", **atlas_texture.state())
    again = tex.GaussianTexture.load(path)
    assert torch.equal(again.params, atlas_texture.params) and again.resolution == atlas_texture.resolution
    assert np.array_equal(again.texels, atlas_texture.texels) and np.array_equal(again.face_uvs, atlas_texture.face_uvs)


def test_one_gaussian_per_face(sphere):
    verts, faces = sphere
    t = tex.face_texture(verts, faces)
    assert len(t) == len(faces) and np.array_equal(t.face_ids, np.arange(len(faces)))
    assert np.allclose(t.barycentrics, 1 / 3)
    with pytest.raises(ValueError, match="per-face"):
        t.scatter(torch.zeros(len(t), 1))
    again = tex.GaussianTexture.from_state(t.state())
    assert again.texels is None and again.resolution == 0


def test_uv_layout_outside_the_texture_is_an_input_error():
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    with pytest.raises(InputError, match="covers no texel"):
        tex.build_texture(verts, np.array([[0, 1, 2]]), resolution=8, uvs=verts[:, :2] + 5,
                          face_uvs=np.array([[0, 1, 2]]))
