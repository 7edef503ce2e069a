"""The CPU backend: numba kernels wrapped in a torch.autograd.Function.

Projection, SH and activations stay in torch (per Gaussian, cheap, autograd for free); only the
per-pixel compositing, where the time goes, runs in the compiled kernels of `cpu_kernels`.
"""
from __future__ import annotations

import numba
import numpy as np
import torch

from . import cpu_kernels as K
from .projection import ScreenGaussians


def rasterize(screen: ScreenGaussians, width: int, height: int, background: torch.Tensor) -> dict[str, torch.Tensor]:
    """Composite projected Gaussians: image [H,W,3], alpha [H,W], depth [H,W] (alpha-weighted z)."""
    image, alpha, depth = _Rasterize.apply(screen.means2d, screen.conics, screen.opacities, screen.depths,
                                           screen.colors, background, screen.support, screen.extents,
                                           int(width), int(height))
    return {"image": image, "alpha": alpha, "depth": depth}


def _np(t: torch.Tensor) -> np.ndarray:
    return t.detach().contiguous().numpy()


class _Rasterize(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, opacities, depths, colors, background, support, extents, width, height):
        dtype = means2d.dtype
        if any(t.dtype != dtype for t in (conics, opacities, depths, colors, background)):
            raise TypeError("rasterize: all inputs must share one float dtype")
        np_dtype = np.float32 if dtype == torch.float32 else np.float64
        offsets, ids = K.bin_tiles(_np(means2d), _np(extents), _np(depths), width, height, K.TILE)
        packed = np.empty((ids.shape[0], K.PACKED), np_dtype)
        K.pack_pairs(ids, _np(means2d), _np(conics), _np(opacities), _np(depths), _np(support), _np(colors),
                     _np(extents), packed)
        # heaviest tiles first, handed out one by one: balances threads when coverage is uneven
        order = np.argsort(-np.diff(offsets), kind="stable")
        xs = np.arange(width, dtype=np_dtype) + np_dtype(0.5)
        ys = np.arange(height, dtype=np_dtype) + np_dtype(0.5)
        bg = _np(background)
        consts = K.constants(np_dtype)
        image = np.zeros((height, width, 3), np_dtype)
        alpha = np.empty((height, width), np_dtype)
        depth = np.zeros((height, width), np_dtype)
        t_final = np.ones((height, width), np_dtype)
        n_used = np.zeros((height, width), np.int32)
        with numba.parallel_chunksize(1):
            K.forward(packed, offsets, order, xs, ys, K.TILE, bg, consts, image, alpha, depth, t_final, n_used)
        ctx.set_materialize_grads(False)
        ctx.state = (packed, offsets, ids, order, xs, ys, bg, consts, t_final, n_used, means2d.shape[0])
        return torch.from_numpy(image), torch.from_numpy(alpha), torch.from_numpy(depth)

    @staticmethod
    def backward(ctx, g_image, g_alpha, g_depth):
        packed, offsets, ids, order, xs, ys, bg, consts, t_final, n_used, n = ctx.state
        h, w = t_final.shape
        g_image, g_alpha, g_depth = (
            np.zeros(shape, packed.dtype) if grad is None else _np(grad).astype(packed.dtype, copy=False)
            for grad, shape in ((g_image, (h, w, 3)), (g_alpha, (h, w)), (g_depth, (h, w))))
        pair_grads = np.empty((ids.shape[0], K.GRAD), packed.dtype)
        with numba.parallel_chunksize(1):
            K.backward(packed, offsets, order, xs, ys, K.TILE, bg, consts, t_final, n_used,
                       g_image, g_alpha, g_depth, pair_grads)
        g = torch.from_numpy(K.scatter_pairs(ids, pair_grads, n))
        g_background = None
        if ctx.needs_input_grad[5]:  # d image / d background = final transmittance
            g_background = torch.from_numpy(np.einsum("hwc,hw->c", g_image, t_final))
        return g[:, 0:2], g[:, 2:5], g[:, 5], g[:, 6], g[:, 7:10], g_background, None, None, None, None
