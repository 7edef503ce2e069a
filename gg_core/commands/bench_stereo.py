"""`gg bench stereo`: the photo-consistency patch kernel against its numpy formulation.

The stereo step (registration/stereo.py) and the template's photo-consistency spend most of their time turning
patch samples into normalized colour vectors (reconstruction/patch_kernels.py). This times that kernel and the
numpy formulation it replaced (project, bilinear sample of image and garment mask, weighted per-channel centring,
unit length; it lives here as the baseline) on the same inputs: one chunk of the demo capture's sweep by default,
1024 vertices x 10 depths of 5 x 5 samples in a 256 x 192 image, and reports their agreement.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from ..capture.cameras import Camera, look_at
from ..errors import InputError
from ..reconstruction.patch_kernels import normalized_patches
from ..reconstruction.visual_hull import bilinear

HELP = "photo-consistency patches: ms per camera and chunk of the numba kernel vs the numpy formulation"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--patches", type=int, default=10240, help="patches per call (vertices x depths)")
    parser.add_argument("--samples", type=int, default=25, help="samples per patch")
    parser.add_argument("--runs", type=int, default=5, help="timed runs of each path (median reported)")
    parser.add_argument("--seed", type=int, default=0)


def numpy_patches(points: np.ndarray, camera: Camera, image: np.ndarray, weight: np.ndarray,
                  mask: np.ndarray | None) -> np.ndarray:
    """The baseline: normalized_patches in numpy, with its temporaries."""
    m, p = points.shape[:2]
    uv, _ = camera.project(points.reshape(-1, 3))
    colour = bilinear(image, uv[:, 0], uv[:, 1]).reshape(m, p, 3)
    w = np.broadcast_to(weight, (m, p))
    if mask is not None:
        w = w * bilinear(mask, uv[:, 0], uv[:, 1]).reshape(m, p)
        w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-12)
    colour = (colour - np.einsum("mpc,mp->mc", colour, w)[:, None, :]) * np.sqrt(w)[..., None]
    colour = colour.reshape(m, p * 3)
    return (colour / np.maximum(np.linalg.norm(colour, axis=1, keepdims=True), 1e-6)).astype(np.float32)


def _median_ms(fn, runs: int) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        fn()
        times.append(1000 * (time.perf_counter() - start))
    return statistics.median(times)


def run(args: argparse.Namespace) -> int:
    for name in ("patches", "samples", "runs"):
        if getattr(args, name) < 1:
            raise InputError(f"--{name} must be at least 1, got {getattr(args, name)}", f"--{name}",
                             "pass a positive count")
    rng = np.random.default_rng(args.seed)
    camera = look_at("bench", np.array([0.0, 1.2, 3.2]), np.array([0.0, 0.9, 0.0]), 40.0, 192, 256)
    image = rng.random((256, 192, 3)).astype(np.float32)
    mask = (rng.random((256, 192)) > 0.2).astype(np.float32)
    side = int(np.ceil(np.sqrt(args.samples)))
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2)[:args.samples]
    centres = np.array([0.0, 0.9, 0.0]) + rng.normal(0.0, 0.15, (args.patches, 3))
    points = centres[:, None, :] + 0.0088 * np.concatenate([grid - (side - 1) / 2,
                                                            np.zeros((len(grid), 1))], axis=1)[None]
    weight = np.exp(-0.5 * ((grid - (side - 1) / 2) ** 2).sum(axis=1))
    weight /= weight.sum()
    fast = normalized_patches(points, camera, image, weight, mask)       # compiles (or loads) the kernel
    slow = numpy_patches(points, camera, image, weight, mask)
    kernel_ms = _median_ms(lambda: normalized_patches(points, camera, image, weight, mask), args.runs)
    numpy_ms = _median_ms(lambda: numpy_patches(points, camera, image, weight, mask), args.runs)
    line = {"bench": "stereo", "patches": args.patches, "samples": args.samples, "runs": args.runs,
            "kernel_ms": round(kernel_ms, 3), "baseline": {"numpy_ms": round(numpy_ms, 3)},
            "speedup": round(numpy_ms / kernel_ms, 2), "max_abs_diff": float(np.abs(fast - slow).max())}
    print(json.dumps(line))
    return 0
