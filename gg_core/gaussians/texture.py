"""The Gaussian texture: one Gaussian per covered texel of a UV atlas (or one per face), 59 channels each.

A texel (row, col) of a `resolution`^2 texture has its centre at u = (col + 0.5) / res,
v = (row + 0.5) / res with v up, so row 0 is the bottom row (Blender's image buffer order). A texel
is covered when its centre lies inside a face's UV triangle; that face and the barycentric
coordinates of the centre are the Gaussian's surface point. Channel layout of `params` (raw,
pre-activation values, as optimized):

    0:48   SH coefficients, 16 x RGB (coefficient-major: channel 3*k + c), degree 3
    48     opacity logit                      -> sigmoid
    49:52  log scale, face-local units        -> exp, times the face scale k_f
    52:56  rotation quaternion (w, x, y, z)   -> normalized, composed with the face frame
    56:59  offset, face-local units           -> k_f R_f offset added to the surface point
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from numba import njit

from ..errors import InputError
from .sh import rgb_to_sh0

SH = slice(0, 48)
OPACITY = 48
LOG_SCALE = slice(49, 52)
ROTATION = slice(52, 56)
OFFSET = slice(56, 59)
CHANNELS = 59
INSIDE_EPS = 1e-9  # barycentric tolerance: texel centres exactly on a shared edge go to the first face


@dataclass
class GaussianTexture:
    """Where each Gaussian sits on the mesh (face + barycentrics) and its raw parameters [T, 59]."""

    face_ids: np.ndarray        # [T] int64
    barycentrics: np.ndarray    # [T, 3] float64, non-negative, rows sum to 1
    params: torch.Tensor        # [T, 59]
    resolution: int = 0         # 0 in one-Gaussian-per-face mode
    texels: np.ndarray | None = None     # [T, 2] int64 (row from the bottom, col); None per face
    uvs: np.ndarray | None = None        # [U, 2] atlas UV coordinates
    face_uvs: np.ndarray | None = None   # [F, 3] indices into uvs

    def __len__(self) -> int:
        return len(self.face_ids)

    def scatter(self, values: torch.Tensor) -> torch.Tensor:
        """Per-Gaussian values [T, C] -> texture image [res, res, C] (rows bottom-up, zeros where uncovered)."""
        if self.texels is None:
            raise ValueError("a per-face Gaussian texture has no texture image")
        image = values.new_zeros((self.resolution, self.resolution, values.shape[1]))
        image[torch.from_numpy(self.texels[:, 0]), torch.from_numpy(self.texels[:, 1])] = values
        return image

    def gather(self, image: torch.Tensor) -> torch.Tensor:
        """Texture image [res, res, C] -> per-Gaussian values [T, C] (inverse of scatter on covered texels)."""
        if self.texels is None:
            raise ValueError("a per-face Gaussian texture has no texture image")
        return image[torch.from_numpy(self.texels[:, 0]), torch.from_numpy(self.texels[:, 1])]

    def state(self) -> dict[str, np.ndarray]:
        """Arrays for storage.write_npz; `from_state` restores the texture."""
        out = {"face_ids": self.face_ids, "barycentrics": self.barycentrics,
               "params": self.params.detach().cpu().numpy(), "resolution": np.int64(self.resolution)}
        if self.texels is not None:
            out.update(texels=self.texels, uvs=self.uvs, face_uvs=self.face_uvs)
        return out

    @classmethod
    def from_state(cls, state: dict) -> "GaussianTexture":
        get = state.get
        return cls(np.asarray(state["face_ids"], np.int64), np.asarray(state["barycentrics"], np.float64),
                   torch.as_tensor(np.asarray(state["params"])), int(state["resolution"]),
                   None if get("texels") is None else np.asarray(get("texels"), np.int64),
                   None if get("uvs") is None else np.asarray(get("uvs"), np.float64),
                   None if get("face_uvs") is None else np.asarray(get("face_uvs"), np.int64))

    @classmethod
    def load(cls, path: str | Path) -> "GaussianTexture":
        """The texture stored by storage.write_npz(path, **texture.state())."""
        with np.load(path) as data:
            return cls.from_state({k: data[k] for k in data.files})


def uv_atlas(verts: np.ndarray, faces: np.ndarray, resolution: int, padding: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """(uvs [U,2], face_uvs [F,3]): an xatlas atlas packed into exactly one resolution^2 texture."""
    import xatlas  # noqa: PLC0415 - only needed when no UVs are given

    v = np.ascontiguousarray(verts, np.float32)
    f = np.ascontiguousarray(faces, np.uint32)
    pack = xatlas.PackOptions()
    pack.resolution, pack.padding, pack.bilinear = resolution, padding, True
    atlas = xatlas.Atlas()
    atlas.add_mesh(v, f)
    atlas.generate(pack_options=pack)  # charts (the slow part) + a texel density that roughly fits
    texels_per_unit = atlas.texels_per_unit * resolution / max(atlas.width, atlas.height)
    # Repack the same charts at exactly `resolution`: xatlas re-uses the first run's UVs as charts, so each
    # attempt costs a packing only (0.1 s instead of ~10 s of chart computation for 8k vertices).
    vmapping, indices, chart_uvs = atlas[0]  # mesh 0; charts spread over several atlases stay apart
    charts = xatlas.ChartOptions()
    charts.use_input_mesh_uvs = True
    positions = np.ascontiguousarray(v[vmapping])
    chart_uvs = np.ascontiguousarray(chart_uvs, np.float32)
    for _ in range(20):  # shrink the density until everything fits in one atlas of exactly that size
        pack.texels_per_unit = texels_per_unit
        atlas = xatlas.Atlas()
        atlas.add_mesh(positions, indices, uvs=chart_uvs)
        atlas.generate(chart_options=charts, pack_options=pack)
        if atlas.atlas_count == 1 and atlas.width == resolution and atlas.height == resolution:
            _, packed_indices, uvs = atlas[0]
            # packed vertices refer to chart vertices; faces keep their order, so faces map one to one
            return uvs.astype(np.float64), packed_indices.astype(np.int64)
        texels_per_unit *= 0.95
    raise InputError(f"xatlas could not pack the mesh into one {resolution}x{resolution} atlas",
                     f"mesh with {len(faces)} faces", "use a larger texture resolution or clean up the mesh")


def build_texture(verts: np.ndarray, faces: np.ndarray, resolution: int = 512, uvs: np.ndarray | None = None,
                  face_uvs: np.ndarray | None = None, color: tuple[float, float, float] = (0.5, 0.5, 0.5),
                  opacity: float = 0.5) -> GaussianTexture:
    """One Gaussian per covered texel of the mesh's own UVs (if given) or of a fresh xatlas atlas.

    Initial Gaussians are flat discs one texel wide (thin along the face normal), unrotated, at the
    surface point, with the given colour and opacity.
    """
    verts, faces = np.asarray(verts, np.float64), np.asarray(faces, np.int64)
    if (uvs is None) != (face_uvs is None):
        raise ValueError("pass both uvs and face_uvs, or neither")
    if uvs is None:
        uvs, face_uvs = uv_atlas(verts, faces, resolution)
    uvs, face_uvs = np.asarray(uvs, np.float64), np.asarray(face_uvs, np.int64)
    face_ids, bary, texels = _rasterize_uv(uvs[face_uvs] * resolution, resolution)
    if len(face_ids) == 0:
        raise InputError("the UV layout covers no texel centre", f"texture {resolution}x{resolution}",
                         "check the mesh UVs or raise the resolution")
    # texel footprint on the surface: sqrt(world area / texel count of the face's UV triangle)
    uv_area = np.abs(_tri_area2d(uvs[face_uvs])) * resolution ** 2
    world_area = _tri_area3d(verts[faces])
    texel_size = np.sqrt(world_area / np.maximum(uv_area, 1e-12))[face_ids]
    params = initial_params(verts, faces, face_ids, texel_size, color, opacity)
    return GaussianTexture(face_ids, bary, params, resolution, texels, uvs, face_uvs)


def face_texture(verts: np.ndarray, faces: np.ndarray, color: tuple[float, float, float] = (0.5, 0.5, 0.5),
                 opacity: float = 0.5) -> GaussianTexture:
    """One Gaussian per face, at its centroid, sized like the face."""
    verts, faces = np.asarray(verts, np.float64), np.asarray(faces, np.int64)
    face_ids = np.arange(len(faces), dtype=np.int64)
    bary = np.full((len(faces), 3), 1.0 / 3.0)
    size = np.sqrt(_tri_area3d(verts[faces]))
    return GaussianTexture(face_ids, bary, initial_params(verts, faces, face_ids, size, color, opacity))


def initial_params(verts: np.ndarray, faces: np.ndarray, face_ids: np.ndarray, world_size: np.ndarray,
                   color: tuple[float, float, float], opacity: float) -> torch.Tensor:
    """Raw [T, 59] parameters: flat discs of `world_size` (thin along the face normal, the frame's y axis)."""
    from .binding import face_scale  # noqa: PLC0415 - binding imports this module's layout

    n = len(face_ids)
    k = face_scale(torch.from_numpy(verts), torch.from_numpy(faces)).numpy()[face_ids]
    local = np.maximum(world_size / np.maximum(k, 1e-12), 1e-12)
    params = torch.zeros(n, CHANNELS, dtype=torch.float32)
    params[:, 0:3] = rgb_to_sh0(torch.tensor(color, dtype=torch.float32))
    params[:, OPACITY] = math.log(opacity / (1 - opacity))
    params[:, LOG_SCALE] = torch.from_numpy(np.log(np.stack((local, 0.1 * local, local), 1))).float()
    params[:, ROTATION.start] = 1.0
    return params


def _tri_area2d(t: np.ndarray) -> np.ndarray:
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def _tri_area3d(t: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)


@njit(cache=True)
def _rasterize_uv(tri: np.ndarray, res: int):
    """Texel centres inside UV triangles (given in texel units): (face ids, barycentrics, (row, col))."""
    owner = np.full((res, res), -1, np.int64)
    bary = np.zeros((res, res, 3))
    for f in range(tri.shape[0]):
        (x0, y0), (x1, y1), (x2, y2) = tri[f, 0], tri[f, 1], tri[f, 2]
        det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(det) < 1e-18:
            continue
        c_lo = max(int(math.floor(min(x0, x1, x2) - 0.5)), 0)
        c_hi = min(int(math.ceil(max(x0, x1, x2) - 0.5)), res - 1)
        r_lo = max(int(math.floor(min(y0, y1, y2) - 0.5)), 0)
        r_hi = min(int(math.ceil(max(y0, y1, y2) - 0.5)), res - 1)
        for r in range(r_lo, r_hi + 1):
            py = r + 0.5
            for c in range(c_lo, c_hi + 1):
                if owner[r, c] >= 0:
                    continue
                px = c + 0.5
                b1 = ((px - x0) * (y2 - y0) - (x2 - x0) * (py - y0)) / det
                b2 = ((x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)) / det
                b0 = 1.0 - b1 - b2
                if b0 >= -INSIDE_EPS and b1 >= -INSIDE_EPS and b2 >= -INSIDE_EPS:
                    owner[r, c] = f
                    b0, b1, b2 = max(b0, 0.0), max(b1, 0.0), max(b2, 0.0)
                    s = b0 + b1 + b2
                    bary[r, c, 0], bary[r, c, 1], bary[r, c, 2] = b0 / s, b1 / s, b2 / s
    rows, cols = np.nonzero(owner >= 0)
    n = rows.shape[0]
    face_ids = np.empty(n, np.int64)
    out_bary = np.empty((n, 3))
    texels = np.empty((n, 2), np.int64)
    for i in range(n):
        face_ids[i] = owner[rows[i], cols[i]]
        out_bary[i] = bary[rows[i], cols[i]]
        texels[i, 0], texels[i, 1] = rows[i], cols[i]
    return face_ids, out_bary, texels
