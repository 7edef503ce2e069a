"""Numba kernels of the CPU rasterizer: tile binning, forward compositing, backward pass.

Work is split into 16x16-pixel tiles processed in parallel. Each tile holds the Gaussians whose
drawn ellipse box touches it, sorted front to back (one global depth sort, then a stable bucket
fill). Inside a tile the Gaussians are visited in depth order and each one only touches the
pixels of its own bounding box (typically a quarter of the tile), updating per-pixel
transmittance and colour in place; every pixel still sees its Gaussians front to back with the
same arithmetic as a per-pixel loop, so results are exact. The forward pass stores each pixel's
final transmittance and how many of the tile's Gaussians it used; the backward pass visits the
Gaussians back to front, recovers each transmittance by division (alpha <= 0.99 keeps that well
conditioned) and sums each Gaussian's gradient over its pixels in registers, writing it once per
(tile, Gaussian) pair, so threads never write the same memory. The kernels are generic in the
float type (float32 for speed, float64 for gradient checks); every constant comes in `consts`
with the array dtype so float32 runs never promote to float64.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

TILE = 16
ALPHA_MAX = 0.99
T_MIN = 1e-4
# packed per-pair row: mean x, mean y, conic a, b, c, opacity, depth, support, r, g, b, extent x, extent y
P_MX, P_MY, P_A, P_B, P_C, P_O, P_Z, P_S, P_R, P_EX, P_EY = 0, 1, 2, 3, 4, 5, 6, 7, 8, 11, 12
PACKED = 13
# gradient row: d/d mean x, mean y, conic a, b, c, opacity, depth, r, g, b
GRAD = 10


def constants(dtype: np.dtype) -> np.ndarray:
    """[0.5, ALPHA_MAX, T_MIN, 1, 2, 0] in `dtype`."""
    return np.array([0.5, ALPHA_MAX, T_MIN, 1.0, 2.0, 0.0], dtype=dtype)


@njit(cache=True)
def bin_tiles(means2d, extents, depths, width, height, tile):
    """(offsets [n_tiles+1], ids [P]): tile t holds Gaussians ids[offsets[t]:offsets[t+1]], front to back."""
    n = means2d.shape[0]
    ntx = (width + tile - 1) // tile
    nty = (height + tile - 1) // tile
    rect = np.full((n, 4), -1, np.int64)
    counts = np.zeros(ntx * nty + 1, np.int64)
    for g in range(n):
        ex, ey = extents[g, 0], extents[g, 1]
        if not (ex > 0 and ey > 0):
            continue
        # pixel j is drawn only if its centre j + 0.5 lies within mean +- extent
        lo_x = max(math.ceil(max(means2d[g, 0] - ex - 0.5, -1.0)), 0)
        hi_x = min(math.floor(min(means2d[g, 0] + ex - 0.5, width + 1.0)), width - 1)
        lo_y = max(math.ceil(max(means2d[g, 1] - ey - 0.5, -1.0)), 0)
        hi_y = min(math.floor(min(means2d[g, 1] + ey - 0.5, height + 1.0)), height - 1)
        if lo_x > hi_x or lo_y > hi_y:
            continue
        rect[g, 0], rect[g, 1] = lo_x // tile, hi_x // tile
        rect[g, 2], rect[g, 3] = lo_y // tile, hi_y // tile
        for ty in range(rect[g, 2], rect[g, 3] + 1):
            for tx in range(rect[g, 0], rect[g, 1] + 1):
                counts[ty * ntx + tx + 1] += 1
    offsets = np.cumsum(counts)
    ids = np.empty(offsets[-1], np.int32)
    cursor = offsets[:-1].copy()
    for g in np.argsort(depths, kind="mergesort"):
        if rect[g, 0] < 0:
            continue
        for ty in range(rect[g, 2], rect[g, 3] + 1):
            for tx in range(rect[g, 0], rect[g, 1] + 1):
                t = ty * ntx + tx
                ids[cursor[t]] = g
                cursor[t] += 1
    return offsets, ids


@njit(parallel=True, cache=True)
def pack_pairs(ids, means2d, conics, opacities, depths, support, colors, extents, out):
    """Gather each pair's Gaussian into contiguous rows (tile loops then stream through memory)."""
    for j in prange(ids.shape[0]):
        g = ids[j]
        out[j, P_MX] = means2d[g, 0]
        out[j, P_MY] = means2d[g, 1]
        out[j, P_A] = conics[g, 0]
        out[j, P_B] = conics[g, 1]
        out[j, P_C] = conics[g, 2]
        out[j, P_O] = opacities[g]
        out[j, P_Z] = depths[g]
        out[j, P_S] = support[g]
        out[j, P_R] = colors[g, 0]
        out[j, P_R + 1] = colors[g, 1]
        out[j, P_R + 2] = colors[g, 2]
        out[j, P_EX] = extents[g, 0]
        out[j, P_EY] = extents[g, 1]


@njit(inline="always")
def _box(packed, j, x0, x1, y0, y1, half):
    """Pixels of tile [x0, x1) x [y0, y1) whose centre lies in Gaussian j's box (inclusive bounds).

    Clamped in floating point before rounding, so far off-screen coordinates never overflow an int."""
    lo_x = int(math.ceil(max(packed[j, P_MX] - packed[j, P_EX] - half, x0)))
    hi_x = int(math.floor(min(packed[j, P_MX] + packed[j, P_EX] - half, x1 - 1)))
    lo_y = int(math.ceil(max(packed[j, P_MY] - packed[j, P_EY] - half, y0)))
    hi_y = int(math.floor(min(packed[j, P_MY] + packed[j, P_EY] - half, y1 - 1)))
    return lo_x, hi_x, lo_y, hi_y


@njit(inline="always")
def _tile(t, offsets, tile, width, height):
    """Sorted-pair range and pixel bounds [x0, x1) x [y0, y1) of tile t (row-major tiles)."""
    ntx = (width + tile - 1) // tile
    x0, y0 = (t % ntx) * tile, (t // ntx) * tile
    return offsets[t], offsets[t + 1], x0, min(x0 + tile, width), y0, min(y0 + tile, height)


@njit(parallel=True, cache=True)
def forward(packed, offsets, order, xs, ys, tile, background, consts, image, alpha, depth, t_final, n_used):
    """Front-to-back compositing; image/depth/n_used must come zeroed and t_final filled with ones."""
    half, amax, tmin, one, two = consts[0], consts[1], consts[2], consts[3], consts[4]
    for k in prange(order.shape[0]):
        start, end, x0, x1, y0, y1 = _tile(order[k], offsets, tile, xs.shape[0], ys.shape[0])
        done = np.zeros((y1 - y0, x1 - x0), np.bool_)
        n_done, n_pix = 0, (y1 - y0) * (x1 - x0)
        for j in range(start, end):
            if n_done == n_pix:
                break
            mx, my, ca, cb, cc = packed[j, P_MX], packed[j, P_MY], packed[j, P_A], packed[j, P_B], packed[j, P_C]
            op, sup = packed[j, P_O], packed[j, P_S]
            lo_x, hi_x, lo_y, hi_y = _box(packed, j, x0, x1, y0, y1, half)
            for py in range(lo_y, hi_y + 1):
                dy = my - ys[py]
                for px in range(lo_x, hi_x + 1):
                    if done[py - y0, px - x0]:
                        continue
                    dx = mx - xs[px]
                    maha = ca * dx * dx + cc * dy * dy + two * cb * dx * dy
                    if maha > sup:
                        continue
                    a = min(amax, op * math.exp(-half * maha))
                    T = t_final[py, px]
                    nt = T * (one - a)
                    if nt < tmin:
                        done[py - y0, px - x0] = True
                        n_done += 1
                        continue
                    w = a * T
                    image[py, px, 0] += w * packed[j, P_R]
                    image[py, px, 1] += w * packed[j, P_R + 1]
                    image[py, px, 2] += w * packed[j, P_R + 2]
                    depth[py, px] += w * packed[j, P_Z]
                    t_final[py, px] = nt
                    n_used[py, px] = j - start + 1
        for py in range(y0, y1):
            for px in range(x0, x1):
                T = t_final[py, px]
                image[py, px, 0] += T * background[0]
                image[py, px, 1] += T * background[1]
                image[py, px, 2] += T * background[2]
                alpha[py, px] = one - T


@njit(parallel=True, cache=True)
def backward(packed, offsets, order, xs, ys, tile, background, consts, t_final, n_used,
             g_image, g_alpha, g_depth, pair_grads):
    """Back-to-front pass; writes d loss / d (mean2d, conic, opacity, depth, colour) of every pair."""
    half, amax, one, two, zero = consts[0], consts[1], consts[3], consts[4], consts[5]
    for k in prange(order.shape[0]):
        start, end, x0, x1, y0, y1 = _tile(order[k], offsets, tile, xs.shape[0], ys.shape[0])
        # per pixel: transmittance in front of the current Gaussian, then the colour, alpha and depth of
        # everything behind it as seen through it (starting from the background)
        state = np.empty((y1 - y0, x1 - x0, 6), t_final.dtype)
        for iy in range(y1 - y0):
            for ix in range(x1 - x0):
                state[iy, ix, 0] = t_final[y0 + iy, x0 + ix]
                state[iy, ix, 1] = background[0]
                state[iy, ix, 2] = background[1]
                state[iy, ix, 3] = background[2]
                state[iy, ix, 4] = zero
                state[iy, ix, 5] = zero
        for j in range(end - 1, start - 1, -1):
            mx, my, ca, cb, cc = packed[j, P_MX], packed[j, P_MY], packed[j, P_A], packed[j, P_B], packed[j, P_C]
            op, sup, z = packed[j, P_O], packed[j, P_S], packed[j, P_Z]
            cr, cg, cbl = packed[j, P_R], packed[j, P_R + 1], packed[j, P_R + 2]
            lo_x, hi_x, lo_y, hi_y = _box(packed, j, x0, x1, y0, y1, half)
            g_mx = g_my = g_a = g_b = g_c = g_o = g_z = g_r = g_g = g_bl = zero
            rank = j - start
            for py in range(lo_y, hi_y + 1):
                dy = my - ys[py]
                for px in range(lo_x, hi_x + 1):
                    if rank >= n_used[py, px]:
                        continue
                    dx = mx - xs[px]
                    maha = ca * dx * dx + cc * dy * dy + two * cb * dx * dy
                    if maha > sup:
                        continue
                    gauss = math.exp(-half * maha)
                    raw = op * gauss
                    a = min(amax, raw)
                    iy, ix = py - y0, px - x0
                    T = state[iy, ix, 0] / (one - a)
                    w = a * T
                    gi0, gi1, gi2 = g_image[py, px, 0], g_image[py, px, 1], g_image[py, px, 2]
                    ga, gd = g_alpha[py, px], g_depth[py, px]
                    g_r += w * gi0
                    g_g += w * gi1
                    g_bl += w * gi2
                    g_z += w * gd
                    b0, b1, b2, b3, b4 = (state[iy, ix, 1], state[iy, ix, 2], state[iy, ix, 3], state[iy, ix, 4],
                                          state[iy, ix, 5])
                    g_alpha_j = T * (gi0 * (cr - b0) + gi1 * (cg - b1) + gi2 * (cbl - b2) + ga * (one - b3)
                                     + gd * (z - b4))
                    state[iy, ix, 0] = T
                    state[iy, ix, 1] = a * cr + (one - a) * b0
                    state[iy, ix, 2] = a * cg + (one - a) * b1
                    state[iy, ix, 3] = a * cbl + (one - a) * b2
                    state[iy, ix, 4] = a + (one - a) * b3
                    state[iy, ix, 5] = a * z + (one - a) * b4
                    if raw < amax:
                        g_o += g_alpha_j * gauss
                        g_m = -half * a * g_alpha_j  # d loss / d maha
                        g_mx += g_m * two * (ca * dx + cb * dy)
                        g_my += g_m * two * (cb * dx + cc * dy)
                        g_a += g_m * dx * dx
                        g_b += g_m * two * dx * dy
                        g_c += g_m * dy * dy
            pair_grads[j, 0], pair_grads[j, 1] = g_mx, g_my
            pair_grads[j, 2], pair_grads[j, 3], pair_grads[j, 4] = g_a, g_b, g_c
            pair_grads[j, 5], pair_grads[j, 6] = g_o, g_z
            pair_grads[j, 7], pair_grads[j, 8], pair_grads[j, 9] = g_r, g_g, g_bl


@njit(cache=True)
def scatter_pairs(ids, pair_grads, n):
    """Sum pair gradients per Gaussian: [n, GRAD]."""
    out = np.zeros((n, pair_grads.shape[1]), pair_grads.dtype)
    for j in range(ids.shape[0]):
        g = ids[j]
        for c in range(pair_grads.shape[1]):
            out[g, c] += pair_grads[j, c]
    return out
