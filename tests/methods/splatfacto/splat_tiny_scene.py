"""A tiny analytic street for the splatting tests: a textured road plane, a facade and a sky,
ray-cast exactly (independent of the rasterizer), with sky masks and sparse points on the
surfaces. Also a minimal training loop that drives a model the way the Trainer does."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path
from typing import Any, Optional

import pytest
import torch
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras, look_at
from nerf2gs_plugin.data.dataparser_outputs import DataparserOutputs
from nerf2gs_plugin.engine.callbacks import TrainingCallbackAttributes, TrainingCallbackLocation as Loc
from nerf2gs_plugin.engine.optimizers import Optimizers

WALL_Y = 0.8

# the rasterizer is a separate part of the project: rendering tests run once it is installed
needs_rasterizer = pytest.mark.skipif(importlib.util.find_spec("nerf2gs_plugin.rendering") is None,
                                      reason="nerf2gs_plugin.rendering is not available")


def _texture(a: Tensor, b: Tensor, base: Tensor) -> Tensor:
    check = ((torch.floor(a * 4) + torch.floor(b * 4)) % 2)[..., None]
    return base * (0.6 + 0.4 * check)


def make_cameras(n: int = 8, w: int = 40, h: int = 24, height: float = 0.25, pitch_deg: float = 0.0) -> Cameras:
    xs = torch.linspace(-0.5, 0.5, n)
    eye = torch.stack([xs, torch.full_like(xs, -0.6), torch.full_like(xs, height)], -1)
    pitch = math.tan(math.radians(pitch_deg))
    target = eye + torch.stack([0.15 * torch.sin(xs * 3), torch.ones_like(xs), torch.full_like(xs, -pitch)], -1)
    c2w = look_at(eye, target, torch.tensor([0.0, 0.0, 1.0]))
    f = 0.8 * w
    return Cameras(c2w, f, f, w / 2, h / 2, w, h)


def render_truth(cameras: Cameras) -> tuple[list[Tensor], list[Tensor]]:
    """Images ``[H,W,3]`` and sky masks ``[H,W,1]``: road z=0, facade y=WALL_Y, sky otherwise."""
    images, skies = [], []
    for i in range(len(cameras)):
        h, w = int(cameras.height[i]), int(cameras.width[i])
        rays = cameras.generate_rays(i)
        o, d = rays.origins, rays.directions
        t_road = torch.where(d[:, 2] < -1e-6, -o[:, 2] / d[:, 2], torch.full_like(d[:, 2], float("inf")))
        t_wall = torch.where(d[:, 1] > 1e-6, (WALL_Y - o[:, 1]) / d[:, 1], torch.full_like(d[:, 1], float("inf")))
        p_wall = o + d * t_wall[:, None].clamp_max(1e6)
        t_wall = torch.where(p_wall[:, 2] < 0.6, t_wall, torch.full_like(t_wall, float("inf")))
        p_road = o + d * t_road[:, None].clamp_max(1e6)
        road = _texture(p_road[:, 0], p_road[:, 1], torch.tensor([0.35, 0.35, 0.4]))
        wall = _texture(p_wall[:, 0], p_wall[:, 2], torch.tensor([0.8, 0.5, 0.3]))
        sky = torch.stack([0.5 + 0.3 * d[:, 2], 0.7 + 0.2 * d[:, 2], torch.full_like(d[:, 2], 0.95)], -1)
        img = torch.where((t_road < t_wall)[:, None], road, wall)
        is_sky = torch.isinf(torch.minimum(t_road, t_wall))
        img = torch.where(is_sky[:, None], sky, img)
        images.append(img.reshape(h, w, 3).clamp(0, 1))
        skies.append(is_sky.reshape(h, w, 1))
    return images, skies


def sparse_points(n: int = 600, seed: int = 0) -> tuple[Tensor, Tensor]:
    g = torch.Generator().manual_seed(seed)
    k = n // 2
    road = torch.stack([torch.rand(k, generator=g) * 2 - 1, torch.rand(k, generator=g) * 1.4 - 0.6, torch.zeros(k)], -1)
    wall = torch.stack([torch.rand(k, generator=g) * 2 - 1, torch.full((k,), WALL_Y), torch.rand(k, generator=g) * 0.6], -1)
    xyz = torch.cat([road, wall])
    rgb = torch.cat([_texture(road[:, 0], road[:, 1], torch.tensor([0.35, 0.35, 0.4])),
                     _texture(wall[:, 0], wall[:, 2], torch.tensor([0.8, 0.5, 0.3]))])
    return xyz, (rgb * 255).round().to(torch.uint8)


def make_train_data(cameras: Cameras, with_points: bool = True, with_sky: bool = True) -> DataparserOutputs:
    xyz, rgb = sparse_points() if with_points else (None, None)
    masks = {"sky": [None] * len(cameras)} if with_sky else {}
    return DataparserOutputs(
        image_filenames=[Path(f"img_{i:03d}.png") for i in range(len(cameras))],
        cameras=cameras,
        mask_filenames=masks,
        points3D_xyz=xyz,
        points3D_rgb=rgb,
        scene_box=torch.tensor([[-1.0, -1.0, -0.2], [1.0, 1.0, 0.8]]),
    )


def batch_for(images: list[Tensor], skies: Optional[list[Tensor]], i: int, weight: float = 1.0) -> dict[str, Any]:
    b: dict[str, Any] = {"image": images[i], "weight": torch.tensor(weight), "image_idx": i}
    if skies is not None:
        b["sky_mask"] = skies[i]
    return b


def psnr(model, cameras: Cameras, images: list[Tensor]) -> float:
    model.eval()
    mse = torch.stack([((model.render_camera(cameras[i])["rgb"] - images[i]) ** 2).mean() for i in range(len(cameras))]).mean()
    model.train()
    return float(-10 * torch.log10(mse))


def train(model, optimizer_configs: dict, cameras: Cameras, images: list[Tensor], skies: Optional[list[Tensor]],
          steps: int, start: int = 0, pipeline: Any = None) -> Optimizers:
    """The Trainer's step, without data manager or checkpoints (``pipeline``: what the callbacks see)."""
    opts = Optimizers(optimizer_configs, model.get_param_groups())
    callbacks = model.get_training_callbacks(TrainingCallbackAttributes(optimizers=opts, pipeline=pipeline))
    model.train()
    for step in range(start, start + steps):
        i = step % len(cameras)
        for cb in callbacks:
            cb.run(Loc.BEFORE_STEP, step)
        opts.zero_grad()
        out = model.get_outputs(cameras[i])
        batch = batch_for(images, skies, i)
        losses = model.get_loss_dict(out, batch, model.get_metrics_dict(out, batch))
        sum(losses.values()).backward()
        for cb in callbacks:
            cb.run(Loc.AFTER_BACKWARD, step)
        opts.step(step)
        for cb in callbacks:
            cb.run(Loc.AFTER_STEP, step)
    return opts


def write_dataset(root: Path, n_train: int = 6, w: int = 40, h: int = 24) -> Path:
    """The tiny street as a nerfstudio dataset (transforms.json, PNGs, sky masks, sparse PLY) with
    a ``street`` eval split, so the Trainer and the CLIs can run on it."""
    import json

    import numpy as np
    from PIL import Image

    root = Path(root)
    (root / "images").mkdir(parents=True, exist_ok=True)
    (root / "masks" / "sky").mkdir(parents=True, exist_ok=True)
    cams = make_cameras(n_train + 2, w, h)
    images, skies = render_truth(cams)
    frames = []
    for i in range(len(cams)):
        name = f"{i:03d}.png"
        Image.fromarray((images[i].numpy() * 255).round().astype(np.uint8)).save(root / "images" / name)
        Image.fromarray((skies[i][..., 0].numpy() * 255).astype(np.uint8)).save(root / "masks" / "sky" / name)
        c2w = torch.cat([cams.camera_to_worlds[i], torch.tensor([[0.0, 0, 0, 1]])]).tolist()
        frames.append({"file_path": f"images/{name}", "transform_matrix": c2w})
    xyz, rgb = sparse_points()
    lines = ["ply", "format ascii 1.0", f"element vertex {len(xyz)}", "property float x", "property float y", "property float z",
             "property uchar red", "property uchar green", "property uchar blue", "end_header"]
    lines += [f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {c[0]} {c[1]} {c[2]}" for p, c in zip(xyz.tolist(), rgb.tolist())]
    (root / "sparse_pc.ply").write_text("\n".join(lines) + "\n")
    eval_idx = [1, len(cams) - 2]
    meta = {
        "fl_x": float(cams.fx[0]), "fl_y": float(cams.fy[0]), "cx": float(cams.cx[0]), "cy": float(cams.cy[0]),
        "w": w, "h": h, "ply_file_path": "sparse_pc.ply", "up": [0.0, 0.0, 1.0],
        "frames": frames, "eval_splits": {"street": [frames[i]["file_path"] for i in eval_idx]},
    }
    (root / "transforms.json").write_text(json.dumps(meta))
    return root
