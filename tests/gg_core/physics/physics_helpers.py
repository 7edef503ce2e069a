"""Test helpers of the physics tests: small meshes (sheet, lattice, sphere collider) and random cloth/step
inputs that exercise every term away from special cases."""
from __future__ import annotations

import numpy as np
import torch

from gg_core.physics.cloth import Cloth
from gg_core.physics.energies import vertex_normals
from gg_core.physics.material import Material
from gg_core.physics.terms import StepInputs


def sheet(nx: int, ny: int, width: float, height: float, y: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal sheet in the XZ plane at height y, normals +Y, (nx+1)*(ny+1) vertices."""
    xs, zs = np.meshgrid(np.linspace(-width / 2, width / 2, nx + 1), np.linspace(-height / 2, height / 2, ny + 1))
    verts = np.stack([xs.ravel(), np.full(xs.size, y), zs.ravel()], 1)
    idx = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    return verts, faces


def uv_sphere(radius: float, n_lat: int = 24, n_lon: int = 48, center=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Closed sphere with outward-facing triangles."""
    lat = np.linspace(0, np.pi, n_lat + 1)[1:-1]
    lon = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    th, ph = np.meshgrid(lat, lon, indexing="ij")
    ring = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], -1).reshape(-1, 3)
    verts = np.concatenate([[[0, 1, 0]], ring, [[0, -1, 0]]]) * radius + np.asarray(center)
    faces = []
    top, bottom = 0, len(verts) - 1
    row = lambda i: 1 + i * n_lon  # noqa: E731
    for j in range(n_lon):
        j2 = (j + 1) % n_lon
        faces.append([top, row(0) + j2, row(0) + j])
        for i in range(n_lat - 2):
            a, b, c, d = row(i) + j, row(i) + j2, row(i + 1) + j, row(i + 1) + j2
            faces += [[a, b, c], [b, d, c]]
        faces.append([bottom, row(n_lat - 2) + j, row(n_lat - 2) + j2])
    return verts.astype(np.float64), np.asarray(faces, np.int64)


def triangle_lattice(nx: int, ny: int, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Flat sheet of equilateral triangles (all angles acute) in the XZ plane, normals +Y."""
    h = spacing * np.sqrt(3) / 2
    verts = np.array([[i * spacing + (j % 2) * spacing / 2, 0.0, j * h] for j in range(ny + 1) for i in range(nx + 1)])
    idx = np.arange(len(verts)).reshape(ny + 1, nx + 1)
    faces = []
    for j in range(ny):
        for i in range(nx):
            a, b, c, d = idx[j, i], idx[j, i + 1], idx[j + 1, i], idx[j + 1, i + 1]
            faces += [[a, c, b], [b, c, d]] if j % 2 == 0 else [[a, d, b], [a, c, d]]
    return verts, np.asarray(faces, np.int64)


def random_cloth(seed: int = 0, nx: int = 4, ny: int = 3) -> Cloth:
    rng = np.random.default_rng(seed)
    v, f = sheet(nx, ny, 0.4, 0.3)
    v = v + rng.normal(0, 0.01, v.shape)
    n = len(v)
    mat = Material.uniform(n)
    mat.mu = mat.mu * torch.from_numpy(rng.uniform(0.7, 1.3, n))
    mat.lam = mat.lam * torch.from_numpy(rng.uniform(0.7, 1.3, n))
    mat.density = mat.density * torch.from_numpy(rng.uniform(0.7, 1.3, n))
    mat.bending = mat.bending * 100 * torch.from_numpy(rng.uniform(0.5, 1.5, n))
    return Cloth(v, f, material=mat)


def random_step(cloth: Cloth, x_prev: np.ndarray, seed: int = 1) -> StepInputs:
    rng = np.random.default_rng(seed)
    n = cloth.n_vertices
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return StepInputs(dt=1 / 30, x_prev=x_prev, v_prev=rng.normal(0, 0.3, (n, 3)), pin_target=x_prev,
                      contact_active=(rng.random(n) < 0.7).astype(float),
                      contact_point=x_prev + rng.normal(0, 0.004, (n, 3)), contact_normal=normal,
                      contact_motion=rng.normal(0, 0.003, (n, 3)), contact_distance=rng.uniform(-2e-3, 5e-3, n),
                      contact_force=rng.uniform(0, 1e-3, n),
                      normal_prev=vertex_normals(x_prev, cloth.faces))
