import numpy as np
import pytest

from gg_core.body.model import load_body
from gg_core.errors import InputError
from gg_core.synth.garments import CLEARANCE, GARMENTS, tailor
from gg_core.synth.proximity import MeshProximity

BOUNDARY_LOOPS = {"skirt": 2, "dress": 2, "tshirt": 4}   # waist+hem; top+hem; neck+hem+2 sleeve ends


@pytest.fixture(scope="module")
def body():
    return load_body()


def _boundary_loops(faces: np.ndarray) -> tuple[int, int]:
    """(edges shared by more than two faces, number of boundary loops)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    boundary = edges[count == 1]
    n = faces.max() + 1
    graph = coo_matrix((np.ones(len(boundary)), (boundary[:, 0], boundary[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    return int((count > 2).sum()), len(np.unique(label[np.unique(boundary)]))


@pytest.mark.parametrize("name", sorted(GARMENTS))
def test_garment_sits_outside_the_rest_body(body, name):
    g = tailor(body, name, 1000)
    assert 900 <= len(g.vertices) <= 1300
    assert g.faces.min() >= 0 and g.faces.max() == len(g.vertices) - 1       # every vertex used
    non_manifold, loops = _boundary_loops(g.faces)
    assert non_manifold == 0
    assert loops == BOUNDARY_LOOPS[name]
    prox = MeshProximity(body.rest_vertices, body.faces)
    assert prox.signed_distance(g.vertices).min() >= 0.9 * CLEARANCE
    tri = g.vertices[g.faces]
    assert prox.signed_distance(tri.mean(axis=1)).min() > 0                  # no face cuts into the body
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = tri.mean(axis=1) * [1, 0, 1]
    assert (np.einsum("nc,nc->n", normals, outward) > 0).mean() > 0.8         # consistently outward winding
    # UV atlas: one UV per face corner, inside the unit square, metric scale near 1 m per UV unit
    assert g.face_uvs.shape == g.faces.shape
    assert g.uvs.min() >= 0 and g.uvs.max() <= 1
    assert 0.3 < g.uv_scale < 3
    for region in ("hem", "side_seam", "patch"):
        assert 0 < (g.regions[region] > 0).sum() < len(g.vertices) / 2


def test_resolution_follows_the_target(body):
    assert 2700 <= len(tailor(body, "skirt", 3000).vertices) <= 3300


def test_unknown_garment_is_an_input_error(body):
    with pytest.raises(InputError):
        tailor(body, "poncho", 1000)
