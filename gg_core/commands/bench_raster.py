"""`gg bench raster`: forward+backward time of the CPU Gaussian rasterizer against a tiled PyTorch baseline.

Both paths share the torch projection (gaussians.projection) and differ only in compositing: the
product's numba kernels versus a straightforward tiled PyTorch rasterizer (per 16x16 tile: the
Gaussians touching it in depth order, dense pixel x Gaussian weights, cumprod transmittance,
autograd backward), which lives here as the speed baseline. The loss is sum(image * weights) with
weights = numpy.random.default_rng(0).random((H, W, 3)).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np

from ..errors import InputError

HELP = ("Gaussian rasterizer: forward+backward ms of the numba CPU backend vs a tiled PyTorch baseline "
        "(+ gsplat on CUDA where it runs)")

SCENE_KEYS = ("means", "quats", "scales", "opacities", "K", "w2c", "width", "height", "background")
STANDARD = {"gaussians": 16384, "width": 512, "height": 512}


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scene", type=Path, help="input .npz: means [N,3], quats [N,4] (w,x,y,z), scales [N,3], "
                        "opacities [N], colors [N,3] or sh [N,K,3], K [3,3], w2c [4,4] (OpenCV), width, height, "
                        "background [3]; default: the standard 16k-Gaussian 512x512 garment-like scene")
    parser.add_argument("--out", type=Path, help="output .npz: image, alpha, forward_ms, backward_ms, grad_means, "
                        "grad_colors (+ grad_sh for SH input)")
    parser.add_argument("--runs", type=int, default=5, help="timed runs per path (median reported, >= 5)")


def run(args: argparse.Namespace) -> int:
    import torch  # noqa: PLC0415 - heavy import only when the benchmark runs

    if args.runs < 5:
        raise InputError(f"--runs {args.runs} is too few", "gg bench raster", "use at least 5 runs for a median")
    scene = load_scene(args.scene) if args.scene else standard_scene(**STANDARD)
    width, height = int(scene["width"]), int(scene["height"])
    weights = torch.from_numpy(np.random.default_rng(0).random((height, width, 3)).astype(np.float32))

    from ..gaussians import cpu_backend  # noqa: PLC0415

    fast = _measure(scene, weights, cpu_backend.rasterize, args.runs)
    base = _measure(scene, weights, tiled_torch_rasterize, args.runs)
    n = len(scene["means"])
    result = {
        "bench": "raster", "gaussians": n, "width": width, "height": height, "runs": args.runs,
        **_figures(fast, n * width * height),
        "first_call_ms": fast["first_ms"],
        "baseline": {"name": "tiled-torch", **_figures(base, n * width * height)},
        "speedup": round((base["forward_ms"] + base["backward_ms"]) / (fast["forward_ms"] + fast["backward_ms"]), 2),
        "max_abs_image_diff": float(np.abs(fast["image"] - base["image"]).max()),
        "max_abs_alpha_diff": float(np.abs(fast["alpha"] - base["alpha"]).max()),
        "grad_means_rel_diff": _rel(fast["grads"]["means"], base["grads"]["means"]),
        "grad_colors_rel_diff": _rel(fast["grads"]["colors"], base["grads"]["colors"]),
        "threads": {"numba": _numba_threads(), "torch": torch.get_num_threads()},
        "load_avg_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count(),
        "gsplat": _gsplat_figures(scene, weights, args.runs, fast),
    }
    if args.out:
        from ..storage import write_npz  # noqa: PLC0415

        extra = {"grad_sh": fast["grads"]["sh"]} if "sh" in fast["grads"] else {}
        write_npz(args.out, image=fast["image"], alpha=fast["alpha"], forward_ms=fast["forward_ms"],
                  backward_ms=fast["backward_ms"], grad_means=fast["grads"]["means"],
                  grad_colors=fast["grads"]["colors"], **extra)
    print(json.dumps(result))
    return 0


def load_scene(path: Path) -> dict:
    if not path.is_file():
        raise InputError("scene file not found", path, "pass an .npz written with numpy.savez")
    try:
        with np.load(path) as data:
            scene = {k: data[k] for k in data.files}
    except (OSError, ValueError) as exc:
        raise InputError(f"scene file cannot be read ({exc})", path, "write it with numpy.savez") from None
    missing = [k for k in SCENE_KEYS if k not in scene] + ([] if "colors" in scene or "sh" in scene else ["colors|sh"])
    if missing:
        raise InputError(f"scene lacks {', '.join(missing)}", path, f"add the keys {', '.join(SCENE_KEYS)} "
                         "and colors or sh")
    n = len(scene["means"])
    shapes = {"means": (n, 3), "quats": (n, 4), "scales": (n, 3), "opacities": (n,), "K": (3, 3), "w2c": (4, 4),
              "background": (3,)}
    if "colors" in scene:
        shapes["colors"] = (n, 3)
    for key, shape in shapes.items():
        if scene[key].shape != shape:
            raise InputError(f"scene '{key}' has shape {scene[key].shape}, expected {shape}", path, "fix the array")
    if "sh" in scene and "colors" not in scene and (scene["sh"].ndim != 3 or scene["sh"].shape[::2] != (n, 3)):
        raise InputError(f"scene 'sh' has shape {scene['sh'].shape}, expected ({n}, K, 3)", path, "fix the array")
    return scene


def standard_scene(gaussians: int, width: int, height: int, seed: int = 0) -> dict:
    """A garment-like test scene: a wavy flared skirt of surface-aligned flat Gaussians seen slightly from above,
    so rays cross a front and (through the opening) a back layer, as in a real garment render."""
    import torch  # noqa: PLC0415

    from ..capture.cameras import look_at  # noqa: PLC0415
    from ..gaussians.rotations import rotmat_to_quat  # noqa: PLC0415

    rng = np.random.default_rng(seed)
    n_theta = int(np.ceil(np.sqrt(gaussians)))
    n_y = int(np.ceil(gaussians / n_theta))
    theta, v = np.meshgrid(np.linspace(0, 2 * np.pi, n_theta, endpoint=False), np.linspace(0, 1, n_y), indexing="ij")
    theta, v = theta.ravel()[:gaussians], v.ravel()[:gaussians]
    radius = (0.28 + 0.14 * v) * (1 + 0.06 * np.sin(8 * theta))
    y = 0.45 - 0.9 * v
    means = np.stack((radius * np.cos(theta), y, radius * np.sin(theta)), 1)
    # surface frame: tangent around the skirt, tangent down it, normal
    d_theta = np.stack((-np.sin(theta), np.zeros_like(theta), np.cos(theta)), 1)
    d_v = np.stack((0.14 * np.cos(theta), -0.9 * np.ones_like(theta), 0.14 * np.sin(theta)), 1)
    d_v -= (d_v * d_theta).sum(1, keepdims=True) * d_theta
    d_v /= np.linalg.norm(d_v, axis=1, keepdims=True)
    frames = np.stack((d_theta, d_v, np.cross(d_theta, d_v)), axis=2)
    spacing_theta = 2 * np.pi * radius / n_theta
    spacing_v = 0.9 / max(n_y - 1, 1)
    ones = np.ones_like(radius)
    scales = np.stack((0.7 * spacing_theta, 0.7 * spacing_v * ones, 0.05 * spacing_v * ones), 1)
    cam = look_at("bench", np.array([0.0, 0.55, -1.25]), np.array([0.0, -0.02, 0.0]), 50, width, height)
    return {"means": means, "quats": rotmat_to_quat(torch.from_numpy(frames)).numpy(),
            "scales": scales * np.exp(rng.normal(0, 0.1, scales.shape)), "opacities": rng.uniform(0.5, 1.0, gaussians),
            "colors": rng.uniform(0, 1, (gaussians, 3)), "K": cam.K, "w2c": cam.w2c, "width": width, "height": height,
            "background": np.array([1.0, 1.0, 1.0])}


def tiled_torch_rasterize(screen, width: int, height: int, background):
    """The baseline: same outputs and per-pixel rules as the CPU backend, in plain PyTorch per 16x16 tile."""
    import torch  # noqa: PLC0415

    tile = 16
    dtype = screen.means2d.dtype
    order = torch.argsort(screen.depths.detach(), stable=True)
    order = order[(screen.extents[order] > 0).all(1)]
    m2, conic = screen.means2d[order], screen.conics[order]
    opac, z, col, support = screen.opacities[order], screen.depths[order], screen.colors[order], screen.support[order]
    ext, md = screen.extents[order], screen.means2d.detach()[order]
    lo_x = torch.ceil(md[:, 0] - ext[:, 0] - 0.5).clamp(0, width - 1)
    hi_x = torch.floor(md[:, 0] + ext[:, 0] - 0.5).clamp(-1, width - 1)
    lo_y = torch.ceil(md[:, 1] - ext[:, 1] - 0.5).clamp(0, height - 1)
    hi_y = torch.floor(md[:, 1] + ext[:, 1] - 0.5).clamp(-1, height - 1)
    image = background.expand(height, width, 3).clone()
    alpha = torch.zeros(height, width, dtype=dtype)
    depth = torch.zeros(height, width, dtype=dtype)
    for y0 in range(0, height, tile):
        y1 = min(y0 + tile, height)
        for x0 in range(0, width, tile):
            x1 = min(x0 + tile, width)
            hit = (lo_x <= x1 - 1) & (hi_x >= x0) & (lo_y <= y1 - 1) & (hi_y >= y0) & (lo_x <= hi_x) & (lo_y <= hi_y)
            ids = hit.nonzero().squeeze(1)
            if ids.numel() == 0:
                continue
            py, px = torch.meshgrid(torch.arange(y0, y1, dtype=dtype) + 0.5, torch.arange(x0, x1, dtype=dtype) + 0.5,
                                    indexing="ij")
            dx = m2[ids, 0][None, :] - px.reshape(-1, 1)
            dy = m2[ids, 1][None, :] - py.reshape(-1, 1)
            c = conic[ids]
            maha = c[:, 0] * dx * dx + c[:, 2] * dy * dy + 2 * c[:, 1] * dx * dy
            a = torch.where(maha <= support[ids], (opac[ids] * torch.exp(-0.5 * maha)).clamp(max=0.99), 0.0)
            a = torch.where(torch.cumprod(1 - a, dim=1) >= 1e-4, a, 0.0)   # stop before the cut-off
            t_after = torch.cumprod(1 - a, dim=1)
            w = a * torch.cat((torch.ones_like(t_after[:, :1]), t_after[:, :-1]), dim=1)
            t_final = t_after[:, -1]
            shape = (y1 - y0, x1 - x0)
            image[y0:y1, x0:x1] = (w @ col[ids] + t_final[:, None] * background).reshape(shape + (3,))
            alpha[y0:y1, x0:x1] = (1 - t_final).reshape(shape)
            depth[y0:y1, x0:x1] = (w @ z[ids]).reshape(shape)
    return {"image": image, "alpha": alpha, "depth": depth}


def _scene_params(scene: dict, device: str = "cpu") -> dict:
    import torch  # noqa: PLC0415

    colour_key = "colors" if "colors" in scene else "sh"
    return {k: torch.tensor(np.asarray(scene[k]), dtype=torch.float32, device=device, requires_grad=True)
            for k in ("means", "quats", "scales", "opacities", colour_key)}


def _measure(scene: dict, weights, rasterize, runs: int) -> dict:
    import torch  # noqa: PLC0415

    from ..gaussians.projection import camera_tensors, project  # noqa: PLC0415
    from ..gaussians.splats import Gaussians  # noqa: PLC0415

    params = _scene_params(scene)
    K, w2c = camera_tensors(scene["K"], scene["w2c"], torch.float32)
    width, height = int(scene["width"]), int(scene["height"])
    bg = torch.as_tensor(np.asarray(scene["background"]), dtype=torch.float32)
    screens = []

    def forward() -> dict:
        screens[:] = [project(Gaussians(**params), K, w2c, width, height)]
        screens[0].colors.retain_grad()
        return rasterize(screens[0], width, height, bg)

    timings, out = _time_runs(params, runs, forward, lambda o: (o["image"] * weights).sum(), lambda: None)
    grads = {k: p.grad.numpy() for k, p in params.items()}
    grads["colors"] = screens[0].colors.grad.numpy()  # per-Gaussian RGB (after SH evaluation for SH input)
    return {**timings, "image": out["image"].detach().numpy(), "alpha": out["alpha"].detach().numpy(),
            "grads": grads}


def _time_runs(params: dict, runs: int, forward, loss, sync) -> tuple[dict, dict]:
    """(median forward and backward ms over `runs` calls after a first one reported apart, which compiles or
    loads kernels; the last outputs). `sync` waits for the device before each clock reading."""
    fwd, bwd = [], []
    for i in range(runs + 1):
        for p in params.values():
            p.grad = None
        sync()
        t0 = time.perf_counter()
        out = forward()
        sync()
        t1 = time.perf_counter()
        loss(out).backward()
        sync()
        t2 = time.perf_counter()
        if i == 0:
            first_ms = 1e3 * (t2 - t0)
        else:
            fwd.append(1e3 * (t1 - t0))
            bwd.append(1e3 * (t2 - t1))
    return {"forward_ms": statistics.median(fwd), "backward_ms": statistics.median(bwd), "first_ms": first_ms}, out


def _gsplat_figures(scene: dict, weights, runs: int, cpu: dict) -> dict:
    """gsplat (CUDA) on the same scene and loss, against the CPU backend's result, where CUDA and gsplat run.

    Timed with CUDA synchronisation around each phase; the first call (gsplat's JIT build on a fresh
    machine) is reported apart. Image and gradient agreement are measured against the CPU backend.
    """
    import torch  # noqa: PLC0415

    from ..capture.cameras import Camera  # noqa: PLC0415
    from ..gaussians.render import gsplat_available, render  # noqa: PLC0415
    from ..gaussians.splats import Gaussians  # noqa: PLC0415

    if not gsplat_available():
        return {"available": False, "why": "needs CUDA and the gsplat package"}
    params = _scene_params(scene, "cuda")
    width, height = int(scene["width"]), int(scene["height"])
    w2c = np.asarray(scene["w2c"], float)
    camera = Camera("bench", np.asarray(scene["K"], float), w2c[:3, :3], w2c[:3, 3], width, height)
    bg, w = torch.as_tensor(np.asarray(scene["background"]), dtype=torch.float32, device="cuda"), weights.cuda()
    m, out = _time_runs(params, runs, lambda: render(Gaussians(**params), camera, bg, backend="gsplat"),
                        lambda o: (o["image"] * w).sum(), torch.cuda.synchronize)
    image = out["image"].detach().cpu().numpy()
    grad_means = params["means"].grad.cpu().numpy().ravel()
    cpu_means = cpu["grads"]["means"].ravel()
    cosine = float(grad_means @ cpu_means / max(np.linalg.norm(grad_means) * np.linalg.norm(cpu_means), 1e-30))
    return {"available": True, "device": torch.cuda.get_device_name(),
            **_figures(m, len(scene["means"]) * width * height),
            "first_call_ms": round(m["first_ms"], 1),
            "speedup_vs_cpu": round((cpu["forward_ms"] + cpu["backward_ms"]) / (m["forward_ms"] + m["backward_ms"]), 2),
            "max_abs_image_diff_vs_cpu": float(np.abs(image - cpu["image"]).max()),
            "mean_abs_image_diff_vs_cpu": float(np.abs(image - cpu["image"]).mean()),
            "grad_means_cosine_vs_cpu": round(cosine, 4)}


def _figures(m: dict, gauss_pixels: int) -> dict:
    total = m["forward_ms"] + m["backward_ms"]
    return {"forward_ms": round(m["forward_ms"], 2), "backward_ms": round(m["backward_ms"], 2),
            "total_ms": round(total, 2), "gaussians_x_pixels_per_s": float(f"{gauss_pixels / (total / 1e3):.4g}")}


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-30))


def _numba_threads() -> int:
    import numba  # noqa: PLC0415

    return numba.get_num_threads()
