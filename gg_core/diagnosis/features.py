"""State features per observed step and vertex: what a residual map or curve is compared with to say under which
conditions the model fails (fast normal motion points to drag, contact to friction, strain rate to damping...)."""
from __future__ import annotations

import numpy as np

from ..physics.simulator import ImplicitSimulator
from .residuals import FrameBatch, Pooling

FEATURES: dict[str, str] = {
    "normal_speed_sq": "squared normal velocity (v.n)^2",
    "speed": "speed |v|",
    "acceleration": "acceleration |a|",
    "contact": "pressed against the body",
    "strain": "edge strain |l/L - 1|",
    "strain_rate": "edge strain rate |dl/dt| / L",
    "height": "height above the garment's lowest point",
}


def _edge_to_vertex(values: np.ndarray, edges: np.ndarray, n_vertices: int) -> np.ndarray:
    """[N,E] edge values -> [N,V] mean over each vertex's edges."""
    total = np.zeros((values.shape[0], n_vertices))
    np.add.at(total.T, edges[:, 0], values.T)
    np.add.at(total.T, edges[:, 1], values.T)
    count = np.bincount(edges.ravel(), minlength=n_vertices)
    return total / np.maximum(count, 1)[None]


def state_features(sim: ImplicitSimulator, batch: FrameBatch, pooling: Pooling) -> dict[str, np.ndarray]:
    """Feature name -> [N,V] values at each observed step."""
    num = sim.num
    x_prev = np.stack([s.x_prev for s in batch.steps])
    normals = np.stack([s.normal_prev for s in batch.steps])
    v = batch.velocity
    e = num.edges
    length = np.linalg.norm(batch.x_next[:, e[:, 0]] - batch.x_next[:, e[:, 1]], axis=-1)
    length_prev = np.linalg.norm(x_prev[:, e[:, 0]] - x_prev[:, e[:, 1]], axis=-1)
    rest = num.rest_lengths[None]
    y = batch.x_next[..., 1]
    return {
        "normal_speed_sq": (v * normals).sum(-1) ** 2,
        "speed": np.linalg.norm(v, axis=-1),
        "acceleration": np.linalg.norm(batch.acceleration, axis=-1),
        "contact": pooling.contact.astype(np.float64),
        "strain": _edge_to_vertex(np.abs(length / rest - 1), e, len(num.mass)),
        "strain_rate": _edge_to_vertex(np.abs(length - length_prev) / (rest * batch.dt), e, len(num.mass)),
        "height": y - y.min(axis=1, keepdims=True),
    }
