import numpy as np
import pytest

from gg_core.geometry.raycast import RayCaster
from gg_core.reconstruction.photo_consistency import (PhotoOptions, Sweep, fit_weights, local_quadrics,
                                                      refine_along_normals, sweep_scores, tangent_frames,
                                                      visible_cameras)
from gg_core.reconstruction.mesh_graph import adjacency, vertex_normals

from .scenes import cylinder_image, pixel_rays, plane_image, sphere_mesh

FAR_TRIANGLE = (np.array([[9.0, 9, 9], [9.1, 9, 9], [9, 9.1, 9]]), np.array([[0, 1, 2]]))   # occludes nothing


def _plane(n: int, size: float, z: float) -> tuple[np.ndarray, np.ndarray]:
    g = np.linspace(-size / 2, size / 2, n)
    xx, yy = np.meshgrid(g, g, indexing="ij")
    verts = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return verts, faces


def _camera_facing_plane() -> tuple[np.ndarray, np.ndarray]:
    """The 15 x 15 plane z = 0 of _plane with its faces wound so that its normals face the cameras (+z)."""
    verts, faces = _plane(15, 0.3, 0.0)
    return verts, faces if vertex_normals(verts, faces)[0, 2] > 0 else faces[:, ::-1]


def _cameras():
    from gg_core.capture.cameras import look_at

    eyes = [(0.0, 0.0, 1.0), (0.4, 0.0, 0.9), (-0.4, 0.0, 0.9), (0.0, 0.4, 0.9), (0.0, -0.4, 0.9)]
    return [look_at(f"c{i}", np.array(e), np.zeros(3), 40.0, 96, 96, up=np.array([0, 1.0, 0]), index=i)
            for i, e in enumerate(eyes)]


def test_sweep_scores_peak_at_the_true_depth():
    cams = _cameras()
    images = [plane_image(c) for c in cams]
    verts, faces = _plane(5, 0.1, 0.0)
    normals = vertex_normals(verts, faces)
    normals *= np.sign(normals[:, 2:3])                 # towards the cameras (+z)
    offsets = np.linspace(-0.03, 0.03, 13)
    scores = sweep_scores(verts + 0.02 * normals, normals, offsets, np.ones((len(cams), len(verts)), bool),
                          cams, images, 0.005, 5)
    np.testing.assert_allclose(offsets[np.argmax(scores, axis=1)], -0.02)
    assert np.all(scores.max(axis=1) > 0.9)


def test_best_camera_pairs_ignore_a_camera_that_sees_something_else():
    # camera 0's view of the plane is blocked by something the visibility test does not know (a fold's ridge):
    # its image is unrelated texture. All pairs dilute the peak with its 4 pairs; the better half of the 10 pairs
    # are pairs of the 4 cameras that agree.
    cams = _cameras()
    images = [plane_image(c) for c in cams]
    images[0] = np.random.default_rng(0).random(images[0].shape)
    verts, faces = _plane(5, 0.1, 0.0)
    normals = np.tile([0.0, 0.0, 1.0], (len(verts), 1))
    offsets = np.linspace(-0.03, 0.03, 13)
    seen = np.ones((len(cams), len(verts)), bool)
    mean_all = sweep_scores(verts + 0.02 * normals, normals, offsets, seen, cams, images, 0.005, 5, 1.0)
    best_half = sweep_scores(verts + 0.02 * normals, normals, offsets, seen, cams, images, 0.005, 5, 0.5)
    np.testing.assert_allclose(offsets[np.argmax(best_half, axis=1)], -0.02)
    assert np.all(best_half.max(axis=1) > 0.9) and np.all(mean_all.max(axis=1) < 0.8)
    # a vertex seen by one camera has no pair to score it
    seen[1:, 0] = False
    assert np.isnan(sweep_scores(verts, normals, offsets, seen, cams, images, 0.005, 5, 0.5)[0]).all()


def test_local_quadrics_recover_the_curvature_of_a_sphere_and_a_plane():
    verts, faces = sphere_mesh(0.1, subdivisions=4)
    normals = vertex_normals(verts, faces)
    normals *= np.sign(np.einsum("ij,ij->i", normals, verts))[:, None]      # outwards: the surface bends away
    q = local_quadrics(verts, normals, adjacency(faces, len(verts)))
    np.testing.assert_allclose(q[:, [0, 2]], -10.0, rtol=0.03)             # h = -(a^2 + b^2) / (2 R)
    np.testing.assert_allclose(q[:, 1], 0.0, atol=0.3)
    verts, faces = _plane(7, 0.3, 0.0)
    q = local_quadrics(verts, vertex_normals(verts, faces), adjacency(faces, len(verts)))
    np.testing.assert_allclose(q, 0.0, atol=1e-9)


def test_curved_patches_find_a_crest_that_plane_patches_place_too_deep():
    # a 3 cm cylinder's crest line, seen by five cameras: a tangent-plane patch leaves the surface on both sides
    # and matches best a few millimetres inside; bent to the crest's curvature it matches on the surface
    radius = 0.03
    cams = _cameras()
    images = [cylinder_image(c, radius) for c in cams]
    ys = np.linspace(-0.05, 0.05, 11)
    verts = np.stack([np.zeros_like(ys), ys, np.full_like(ys, radius)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (len(ys), 1))
    _, t2 = tangent_frames(normals)
    across = np.abs(t2[0, 0]) > 0.99                     # which tangent axis runs around the cylinder
    quadrics = np.tile([0.0, 0.0, -1 / radius] if across else [-1 / radius, 0.0, 0.0], (len(ys), 1))
    offsets = np.arange(-0.01, 0.0100001, 0.0005)
    seen = np.ones((len(cams), len(ys)), bool)
    peak = {}
    for name, q in (("plane", None), ("curved", quadrics)):
        scores = sweep_scores(verts, normals, offsets, seen, cams, images, 0.0076, 5, 1.0, 1.0, q)
        peak[name] = offsets[np.argmax(scores, axis=1)].mean()
    assert peak["plane"] < -0.001 and abs(peak["curved"]) < 0.4 * abs(peak["plane"])   # -1.4 mm and -0.4 mm


def test_masks_keep_the_background_out_of_patches_at_the_garment_edge():
    # the cloth ends at x = 0; beyond it each camera sees its own background (noise), which the garment masks mark
    cams = _cameras()
    rng = np.random.default_rng(0)
    images, masks = [], []
    for cam in cams:
        origin, d = pixel_rays(cam)
        on_cloth = (origin[0] - origin[2] / d[:, 2] * d[:, 0] < 0.0).reshape(cam.height, cam.width)
        noise = rng.uniform(0.3, 0.7, (cam.height, cam.width, 3))
        images.append(np.where(on_cloth[..., None], plane_image(cam), noise))
        masks.append(on_cloth.astype(np.float64))
    ys = np.linspace(-0.04, 0.04, 9)
    verts = np.stack([np.full_like(ys, -0.006), ys, np.zeros_like(ys)], axis=1)      # under a pixel from the edge
    normals = np.tile([0.0, 0.0, 1.0], (len(ys), 1))
    offsets = np.arange(-0.01, 0.0100001, 0.001)
    seen = np.ones((len(cams), len(ys)), bool)
    plain = sweep_scores(verts, normals, offsets, seen, cams, images, 0.0076, 5, 1.0, 1.0)
    masked = sweep_scores(verts, normals, offsets, seen, cams, images, 0.0076, 5, 1.0, 1.0, masks=masks)
    np.testing.assert_allclose(offsets[np.argmax(masked, axis=1)], 0.0, atol=0.0011)
    assert masked.max(axis=1).min() > 0.9 and np.all(plain.max(axis=1) < masked.max(axis=1) - 0.05)


def _offset_plane() -> tuple[np.ndarray, np.ndarray, dict]:
    """(true plane vertices, refined vertices, log): a textured plane's mesh started 2 cm in front of it (like a
    hull) and refined with 4 cm of search."""
    cams = _cameras()
    images = [plane_image(c) for c in cams]
    verts, faces = _camera_facing_plane()
    far = RayCaster([FAR_TRIANGLE])
    moved, log = refine_along_normals(verts + [0.0, 0.0, 0.02], faces, cams, images, far, 0.005,
                                      PhotoOptions(search_in=0.04))
    return verts, moved, log


def test_refinement_moves_an_offset_plane_back_onto_the_textured_plane():
    verts, moved, log = _offset_plane()
    assert np.abs(moved[:, 2]).mean() < 0.003
    assert log["rounds"][0]["confident_vertices"] > 0.8 * len(verts)


def test_an_occluder_hides_the_vertices_behind_it_from_that_camera_only():
    cams = _cameras()
    verts, faces = _plane(5, 0.1, 0.0)
    normals = np.tile([0.0, 0.0, 1.0], (len(verts), 1))
    plane_only = RayCaster([(verts, faces)])
    seen = visible_cameras(verts, normals, cams, plane_only, 0.5, 0.005)
    assert seen.all()
    # a card halfway between camera 1 (eye at x = 0.4) and the plane: an arm in front of the garment
    card_v, card_f = _plane(3, 0.3, 0.0)
    card_v = card_v + 0.5 * cams[1].center
    seen = visible_cameras(verts, normals, cams, RayCaster([(verts, faces), (card_v, card_f)]), 0.5, 0.005)
    assert not seen[1].any()
    assert seen[[0, 2, 3, 4]].all()


def test_curvature_gain_scales_the_patches_bend():
    # a bumped plane (a 2 cm Gaussian bump): gain 0 bends the patches by nothing, as flat patches do; gain 1 by
    # the mesh's own quadric, which moves the bump's vertices differently
    cams = _cameras()
    images = [plane_image(c) for c in cams]
    verts, faces = _camera_facing_plane()
    verts[:, 2] = 0.02 * np.exp(-(verts[:, 0] ** 2 + verts[:, 1] ** 2) / (2 * 0.04 ** 2))
    far = RayCaster([FAR_TRIANGLE])
    moved = {}
    for name, options in (("flat", PhotoOptions(search_in=0.03, rounds=1, curved=False)),
                          ("gain 0", PhotoOptions(search_in=0.03, rounds=1, curvature_gain=0.0)),
                          ("gain 1", PhotoOptions(search_in=0.03, rounds=1, curvature_gain=1.0))):
        moved[name] = refine_along_normals(verts, faces, cams, images, far, 0.005, options)[0]
    np.testing.assert_allclose(moved["gain 0"], moved["flat"], atol=1e-9)
    assert np.abs(moved["gain 1"] - moved["flat"]).max() > 2e-5      # measured: 0.08 mm


def test_rounds_stop_before_one_with_fewer_than_three_depths():
    # coarse images: a late round's range is under two steps (a 40 x 30 px capture hit this with 4 rounds)
    verts, faces = _plane(5, 0.3, 0.0)
    options = PhotoOptions(search_in=0.02, search_out=0.02, rounds=4)
    sweep = Sweep(faces, len(verts), options)
    fine = sweep.depths(0.002)
    assert len(fine) == 4 and all(len(d) >= 3 for d in fine)
    coarse = sweep.depths(0.02)            # 1 cm steps: 5 depths, then 4 and 3 at 5 and 2.5 mm, then 2: stop
    assert [len(d) for d in coarse] == [5, 4, 3]
    assert sweep.depths(0.1) == []          # not even the first round: nothing moves
    move, _ = sweep.solve(np.tile([0.2, 0.9, 0.3], (len(verts), 1)), np.ones(len(verts)), np.array([-1e-3, 0, 1e-3]))
    assert np.all(np.abs(move) < 1e-3) and np.abs(move).max() > 0


def test_snr_weights_grow_with_the_score_as_its_signal_to_noise_ratio():
    np.testing.assert_allclose(fit_weights(np.array([0.5, 0.9, 0.99]), "snr"), [1.0, 9.0, 49.0])
    np.testing.assert_allclose(fit_weights(np.array([0.5, 0.9]), "score"), [0.5, 0.9])
    with pytest.raises(ValueError, match="weighting"):
        PhotoOptions(weighting="sharpness")


def test_snr_weighting_lets_a_clear_match_outweigh_a_mediocre_one():
    # half the vertices see a clear peak 1 mm out (0.95), half a mediocre one 1 mm in (0.6); a stiff field
    # moves them together by the weighted mean: the score weighs the clear half 1.6x, the SNR 12.7x
    verts, faces = _plane(6, 0.3, 0.0)
    offsets = np.array([-1e-3, 0.0, 1e-3])
    clear = np.arange(len(verts)) % 2 == 0
    curves = np.where(clear[:, None], [0.2, 0.5, 0.95], [0.6, 0.3, 0.1])
    move = {}
    for weighting in ("score", "snr"):
        sweep = Sweep(faces, len(verts), PhotoOptions(stiffness=1e3, weighting=weighting))
        move[weighting] = sweep.solve(curves, np.ones(len(verts)), offsets)[0]
    np.testing.assert_allclose(move["score"], 1e-3 * (0.95 - 0.6) / 1.55, atol=2e-5)
    np.testing.assert_allclose(move["snr"], 1e-3 * (19 - 1.5) / 20.5, atol=2e-5)


def _wrinkled_plane(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 15 x 15 plane mesh with 4 mm of vertex noise in height: wrinkles smaller than a patch, which tilt each
    vertex's own normal by about 7 degrees."""
    verts, faces = _camera_facing_plane()
    verts[:, 2] += np.random.default_rng(seed).normal(0.0, 0.004, len(verts))
    return verts, faces


def test_sweep_normals_are_the_vertex_normals_smoothed_over_the_set_steps():
    verts, faces = _wrinkled_plane()
    raw = Sweep(faces, len(verts), PhotoOptions(normal_smoothing=0)).normals(verts)
    np.testing.assert_allclose(raw, vertex_normals(verts, faces))
    smoothed = Sweep(faces, len(verts), PhotoOptions(normal_smoothing=10)).normals(verts)
    np.testing.assert_allclose(np.linalg.norm(smoothed, axis=1), 1.0)
    inner = (np.abs(verts[:, 0]) < 0.1) & (np.abs(verts[:, 1]) < 0.1)
    tilt = {name: np.degrees(np.arccos(np.clip(n[inner, 2], -1, 1))).mean() for name, n in
            (("raw", raw), ("smoothed", smoothed))}
    assert tilt["raw"] > 5.0 and tilt["smoothed"] < 0.3 * tilt["raw"]
    with pytest.raises(ValueError, match="normal_smoothing"):
        PhotoOptions(normal_smoothing=-1)


def test_smoothed_normals_carry_a_wrinkled_mesh_onto_the_plane_without_sliding_it_sideways():
    # the mesh starts 2 cm in front of the textured plane: moved along each vertex's own (tilted) normal, the
    # vertices slide sideways and land unevenly; along the smoothed normals they come down together
    cams = _cameras()
    images = [plane_image(c) for c in cams]
    verts, faces = _wrinkled_plane()
    start = verts + [0.0, 0.0, 0.02]
    far = RayCaster([FAR_TRIANGLE])
    result = {}
    for steps in (0, 10):
        moved, _ = refine_along_normals(start, faces, cams, images, far, 0.005,
                                        PhotoOptions(search_in=0.04, normal_smoothing=steps))
        inner = (np.abs(moved[:, 0]) < 0.1) & (np.abs(moved[:, 1]) < 0.1)
        result[steps] = (moved[inner, 2].mean(), np.linalg.norm(moved[inner, :2] - start[inner, :2], axis=1).mean())
    assert abs(result[10][0]) < 0.001          # come down the 2 cm (the 4 mm noise stays: the field is smooth)
    assert result[10][1] < 0.25 * result[0][1]
