"""`gg bench raster`: IN/OUT contract, JSON line, baseline agreement, bad input."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from gg_core.capture.cameras import Camera
from gg_core.cli import main
from gg_core.commands.bench_raster import standard_scene
from gg_core.gaussians.render import gsplat_available, render
from gg_core.gaussians.splats import Gaussians


@pytest.fixture(scope="module")
def scene() -> dict:
    return standard_scene(600, 48, 40)


def test_scene_file_in_out_npz_out(tmp_path, capsys, scene):
    np.savez(tmp_path / "in.npz", **scene)
    assert main(["bench", "raster", "--scene", str(tmp_path / "in.npz"), "--out", str(tmp_path / "out.npz")]) == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert line["bench"] == "raster" and line["gaussians"] == 600 and line["runs"] == 5
    for key in ("forward_ms", "backward_ms", "total_ms", "gaussians_x_pixels_per_s"):
        assert line[key] > 0 and line["baseline"][key] > 0
    assert line["max_abs_image_diff"] < 1e-4 and line["grad_means_rel_diff"] < 1e-4
    gpu = line["gsplat"]
    assert gpu["available"] == gsplat_available()
    if gpu["available"]:  # where CUDA and gsplat run: same scene, close images and gradients
        assert gpu["total_ms"] > 0 and gpu["mean_abs_image_diff_vs_cpu"] < 2e-3
        assert gpu["grad_means_cosine_vs_cpu"] > 0.98
    with np.load(tmp_path / "out.npz") as out:
        assert out["image"].shape == (40, 48, 3) and out["image"].dtype == np.float32
        assert out["alpha"].shape == (40, 48) and float(out["forward_ms"]) > 0 and float(out["backward_ms"]) > 0
        grad_means, grad_colors = out["grad_means"], out["grad_colors"]
    # the stored gradients are those of loss = sum(image * default_rng(0).random((H, W, 3)))
    params = {k: torch.tensor(scene[k], dtype=torch.float32, requires_grad=True)
              for k in ("means", "quats", "scales", "opacities", "colors")}
    cam = Camera("bench", scene["K"], scene["w2c"][:3, :3], scene["w2c"][:3, 3], 48, 40)
    image = render(Gaussians(**params), cam, torch.tensor(scene["background"], dtype=torch.float32))["image"]
    (image * torch.tensor(np.random.default_rng(0).random((40, 48, 3)), dtype=torch.float32)).sum().backward()
    assert np.allclose(grad_means, params["means"].grad.numpy(), rtol=1e-4, atol=1e-6)
    assert np.allclose(grad_colors, params["colors"].grad.numpy(), rtol=1e-4, atol=1e-6)


def test_sh_scene_writes_sh_gradients(tmp_path, capsys, scene):
    sh_scene = {k: v for k, v in scene.items() if k != "colors"}
    sh_scene["sh"] = np.random.default_rng(2).normal(0, 0.2, (600, 4, 3))
    np.savez(tmp_path / "in.npz", **sh_scene)
    assert main(["bench", "raster", "--scene", str(tmp_path / "in.npz"), "--out", str(tmp_path / "out.npz")]) == 0
    with np.load(tmp_path / "out.npz") as out:
        assert out["grad_sh"].shape == (600, 4, 3) and out["grad_colors"].shape == (600, 3)
        assert np.abs(out["grad_sh"]).sum() > 0


def test_bad_scene_is_one_line_error(tmp_path, capsys, scene):
    np.savez(tmp_path / "in.npz", **{k: v for k, v in scene.items() if k != "quats"})
    assert main(["bench", "raster", "--scene", str(tmp_path / "in.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gg: error: scene lacks quats") and "\n" not in err
    assert main(["bench", "raster", "--scene", str(tmp_path / "missing.npz")]) == 2
    assert main(["bench", "raster", "--runs", "3"]) == 2
