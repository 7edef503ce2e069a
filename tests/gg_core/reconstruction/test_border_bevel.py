import numpy as np

from gg_core.reconstruction.border_bevel import free_border, trim_free_border
from gg_core.reconstruction.surface_cut import border_loop_labels, border_loops


def _tube(radius_of, heights: np.ndarray, sides: int = 48) -> tuple[np.ndarray, np.ndarray]:
    """An open tube around the y axis: ring k at height heights[k] with radius radius_of(heights[k])."""
    angle = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    verts = np.concatenate([np.stack([radius_of(h) * np.cos(angle), np.full(sides, h), radius_of(h) * np.sin(angle)],
                                     axis=1) for h in heights])
    faces = []
    for k in range(len(heights) - 1):
        for j in range(sides):
            a, b = k * sides + j, k * sides + (j + 1) % sides
            c, d = a + sides, b + sides
            faces += [(a, b, d), (a, d, c)]
    return verts, np.asarray(faces, np.int64)


def _body() -> tuple[np.ndarray, np.ndarray]:
    """A torso (radius 0.14) from y = 0.3 up and legs far inside below: the skirt's waist rests on it."""
    return _tube(lambda h: 0.14 if h > 0.3 else 0.05, np.linspace(-0.2, 0.8, 41))


def _skirt() -> tuple[np.ndarray, np.ndarray]:
    """Waist at y = 0.6 (radius 0.15, 1 cm off the torso), flaring to radius 0.25 at the hem, y = 0."""
    return _tube(lambda h: 0.25 - 0.1 * h / 0.6, np.linspace(0.0, 0.6, 31))


def test_border_loops_are_labelled_one_by_one():
    _, faces = _skirt()
    ids, loop = border_loop_labels(faces)
    assert border_loops(faces) == 2 and len(ids) == 96 and sorted(np.bincount(loop)) == [48, 48]


def test_only_the_border_that_hangs_free_of_the_body_is_free():
    verts, faces = _skirt()
    free = free_border(verts, faces, [_body()])
    assert np.array_equal(np.flatnonzero(free), np.arange(48))          # the hem ring, not the waist


def test_the_trim_cuts_a_band_of_the_given_width_off_the_hem_only():
    verts, faces = _skirt()
    slant = np.hypot(0.6, 0.1)                                          # the skirt's length along its surface
    out_v, out_f, log = trim_free_border(verts, faces, [_body()], 0.05)
    ids, loop = border_loop_labels(out_f)
    heights = [out_v[ids[loop == k], 1] for k in range(2)]
    hem, waist = sorted(heights, key=np.mean)
    assert np.allclose(waist, 0.6)                                      # the waist border is where it was
    assert np.allclose(hem, 0.05 * 0.6 / slant, atol=1e-9)              # 5 cm along the surface from the old hem
    new_radius = 0.25 - 0.1 * 0.05 / slant                              # a frustum's side: pi (r1 + r2) slant
    assert abs(log["area_removed_share"] - (0.25 + new_radius) * 0.05 / ((0.25 + 0.15) * slant)) < 0.002
    assert log["free_border_vertices"] == 48


def test_nothing_is_trimmed_where_every_border_rests_on_the_body_or_the_width_is_zero():
    verts, faces = _skirt()
    near = _tube(lambda h: 0.24 - 0.1 * h / 0.6, np.linspace(-0.1, 0.7, 9))   # a body just inside the whole skirt
    for bodies, width in (([near], 0.05), ([_body()], 0.0)):
        out_v, out_f, _ = trim_free_border(verts, faces, bodies, width)
        assert out_v is verts and out_f is faces
