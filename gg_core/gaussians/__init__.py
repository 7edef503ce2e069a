"""Mesh-bound Gaussian texture and a differentiable Gaussian rasterizer (numba on CPU, gsplat on CUDA).

Public API (what stages 1-3 call); everything is torch and differentiable unless noted:

    texture = build_texture(verts, faces, resolution=512)         # one Gaussian per covered texel of an
                                                                  # xatlas atlas, or of the mesh's own UVs
                                                                  # (uvs=, face_uvs=); face_texture(verts,
                                                                  # faces) gives one Gaussian per face
    texture.params                                                # [T, 59] raw parameters to optimize
                                                                  # (layout in gaussians.texture)
    gaussians = bind(texture, verts, faces, params=None)          # world Gaussians on the current mesh;
                                                                  # gradients reach verts [V, 3] and params
    keep = visible_mask(surface_points(texture, verts, faces).detach().numpy(), camera,
                        RayCaster([(body_verts, body_faces), ...]))   # numpy bool [T]; layered outfits
    out = render(gaussians[torch.from_numpy(keep)], camera, background=(1, 1, 1))
    out["image"] [H, W, 3], out["alpha"] [H, W], out["depth"] [H, W] (alpha-weighted camera z)

`camera` is a gg_core.capture.cameras.Camera (OpenCV, pixel centres at +0.5). `render` runs the numba
CPU rasterizer for CPU tensors and gsplat for CUDA tensors when gsplat imports (backend="auto"); the
gsplat path was checked on an H200 (2026-11-26: tests pass, `gg bench raster` agrees). Semantics shared by both: EWA
projection with 0.3 px^2 dilation, Gaussians closer than 0.01 m culled, a Gaussian drawn where it is
within 3 sigma and alpha = min(0.99, o * exp(-d^2/2)) >= 1/255, front-to-back compositing that stops
before transmittance would fall below 1e-4. Texture I/O: texture.state() / GaussianTexture.from_state().
"""
from ..geometry.raycast import RayCaster
from .binding import bind, surface_points
from .render import gsplat_available, render
from .sh import eval_sh, rgb_to_sh0
from .splats import Gaussians
from .texture import CHANNELS, GaussianTexture, build_texture, face_texture
from .visibility import visible_mask

__all__ = ["CHANNELS", "GaussianTexture", "Gaussians", "RayCaster", "bind", "build_texture", "eval_sh",
           "face_texture", "gsplat_available", "render", "rgb_to_sh0", "surface_points", "visible_mask"]
