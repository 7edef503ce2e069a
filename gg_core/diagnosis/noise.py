"""Spatially correlated position noise, the error model of registered meshes: neighbouring vertices err together
(a registration shifts whole patches), independently from frame to frame."""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.spatial import cKDTree


def correlated_noise(template: np.ndarray, sigma: float, length: float, n_frames: int,
                     rng: np.random.Generator) -> np.ndarray:
    """[T,V,3] noise with standard deviation `sigma` (m) per coordinate and a Gaussian spatial correlation of
    length `length` (m) over the template: white noise smoothed by a truncated Gaussian kernel (3 lengths),
    each vertex rescaled to the exact standard deviation."""
    pairs = cKDTree(template).query_pairs(3 * length, output_type="ndarray")
    n = len(template)
    i = np.r_[pairs[:, 0], pairs[:, 1], np.arange(n)]
    j = np.r_[pairs[:, 1], pairs[:, 0], np.arange(n)]
    w = np.exp(-((template[i] - template[j]) ** 2).sum(1) / (2 * length ** 2))
    kernel = coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
    scale = sigma / np.sqrt(np.asarray(kernel.multiply(kernel).sum(1)).ravel())
    white = rng.normal(size=(n, 3 * n_frames))
    return (scale[:, None] * (kernel @ white)).reshape(n, n_frames, 3).transpose(1, 0, 2)
