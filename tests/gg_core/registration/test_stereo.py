import numpy as np
import pytest
import torch

from gg_core.geometry.raycast import RayCaster
from gg_core.reconstruction.photo_consistency import PhotoOptions, refine_along_normals
from gg_core.reconstruction.template_mesh import pixel_footprint
from gg_core.registration.stereo import (FISHER_CLIP, fisher_average, fisher_z, stereo_sequence,
                                         temporal_weights)
from gg_core.registration.views import View

from ..reconstruction.scenes import plane_image
from ..reconstruction.test_photo_consistency import FAR_TRIANGLE as FAR_BODY, _cameras, _plane


def _views(noise_seed: int | None = None) -> list[View]:
    """The textured plane z = 0 seen by five cameras; with a seed, images of noise that show no plane."""
    rng = None if noise_seed is None else np.random.default_rng(noise_seed)
    views = []
    for c in _cameras():
        image = plane_image(c) if rng is None else rng.random((c.height, c.width, 3)).astype(np.float32)
        views.append(View(c, torch.from_numpy(image).float(), torch.ones(c.height, c.width),
                          torch.zeros(c.height, c.width)))
    return views


def _run(fits, faces, views_of, options, frames):
    out, order = {}, []

    def done(t, verts, log):
        order.append(t)
        out[t] = (verts.copy(), log)

    stereo_sequence(fits, faces, lambda t: (views_of(t), FAR_BODY), options, frames, done)
    return out, order


def test_temporal_weights_are_triangular_and_odd():
    assert temporal_weights(5).tolist() == [1, 2, 3, 2, 1]
    assert temporal_weights(1).tolist() == [1]
    for bad in (0, 4, -1):
        with pytest.raises(ValueError):
            temporal_weights(bad)


def test_fisher_average_lets_a_clear_peak_outweigh_two_mediocre_ones():
    # one frame peaks clearly at depth 0 (0.95), two peak at depth 2 with mediocre scores (0.6): the plain mean
    # of the three picks depth 2, the mean of Fisher's z keeps depth 0; a vertex no frame scored stays at 0
    clear = np.array([[0.95, 0.3, 0.1]])
    mediocre = np.array([[0.1, 0.3, 0.6]])
    scored, unscored = np.ones(1), np.zeros(1)
    frames = [(fisher_z(clear), scored), (fisher_z(mediocre), scored), (fisher_z(mediocre), scored)]
    plain = np.mean([clear, mediocre, mediocre], axis=0)
    averaged = fisher_average(frames, np.ones(3))
    assert np.argmax(plain) == 2 and np.argmax(averaged) == 0
    z = (np.arctanh([0.95, 0.3, 0.1]) + 2 * np.arctanh([0.1, 0.3, 0.6])) / 3
    np.testing.assert_allclose(fisher_z(np.array([1.0, -1.0])), np.arctanh([FISHER_CLIP, -FISHER_CLIP]))
    np.testing.assert_allclose(averaged[0], np.tanh(z))
    np.testing.assert_allclose(fisher_average([(fisher_z(clear), unscored)], np.ones(1)), 0.0)
    # the frames' weights count: the clear frame alone at weight 1, the mediocre ones at 0
    np.testing.assert_allclose(fisher_average(frames, np.array([1.0, 0, 0])), clear)


def test_one_frame_window_pulls_each_fit_onto_the_cloth_like_the_template_refinement():
    verts, faces = _plane(15, 0.3, 0.0)
    fits = [verts + [0.0, 0.0, dz] for dz in (0.012, -0.008, 0.006, 0.01)]     # fits that ended off the cloth
    options = PhotoOptions(search_in=0.02, search_out=0.02, rounds=2, stiffness=1.0, aggregate=0, curvature_gain=1.5)
    out, order = _run(fits, faces, lambda t: _views(), options, 1)
    assert order == [0, 1, 2, 3]
    cams = _cameras()
    spacing = pixel_footprint(cams, fits[0].mean(axis=0))      # the sequence's depth grid is the first frame's
    images = [v.rgb.numpy() for v in _views()]
    for t, fit in enumerate(fits):
        moved, log = out[t]
        assert np.abs(moved[:, 2]).mean() < 0.003
        assert np.abs(moved[:, :2] - fit[:, :2]).max() < 1e-6            # along the plane's normal only
        assert len(log["rounds"]) == 2 and log["seconds"] > 0
        alone, _ = refine_along_normals(fit, faces, cams, images, RayCaster([(fit, faces), FAR_BODY]), spacing,
                                        options, [v.garment.numpy() for v in _views()])
        np.testing.assert_allclose(moved, alone, atol=1e-12)


def test_neighbouring_frames_carry_a_frame_whose_images_show_nothing():
    verts, faces = _plane(15, 0.3, 0.0)
    fits = [verts + [0.0, 0.0, 0.01] for _ in range(7)]
    blind = 3                                    # its cameras saw noise: its own score curves have no peak
    options = PhotoOptions(search_in=0.02, search_out=0.02, rounds=3, stiffness=1.0, aggregate=0, curvature_gain=1.5)

    def views_of(t):
        return _views(noise_seed=t) if t == blind else _views()

    alone, _ = _run(fits, faces, views_of, options, 1)
    pooled, order = _run(fits, faces, views_of, options, 5)
    assert order == list(range(7))
    assert np.abs(alone[blind][0][:, 2]).mean() > 0.004
    assert np.abs(pooled[blind][0][:, 2]).mean() < 0.003
    for t in (0, 6):                             # the ends average over fewer frames and still land
        assert np.abs(pooled[t][0][:, 2]).mean() < 0.003


def test_images_too_coarse_for_a_round_leave_every_fit_as_it_is():
    verts, faces = _plane(15, 0.3, 0.0)
    fits = [verts + [0.0, 0.0, dz] for dz in (0.012, -0.008, 0.006)]
    spacing = pixel_footprint(_cameras(), fits[0].mean(axis=0))
    tiny = 0.2 * spacing               # a search range under one half-pixel step: no grid of 3 depths
    options = PhotoOptions(search_in=tiny, search_out=tiny, rounds=3, stiffness=1.0, aggregate=0)
    loaded = []
    out, order = _run(fits, faces, lambda t: (loaded.append(t), _views())[1], options, 3)
    assert order == [0, 1, 2]
    assert loaded == [0]               # frame 0's cameras set the grid; no other frame's images are read
    for t, fit in enumerate(fits):
        assert np.array_equal(out[t][0], fit) and out[t][1]["rounds"] == []
