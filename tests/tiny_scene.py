"""A tiny analytic scene written as a nerfstudio dataset, for fast engine and method tests:
a checkered ground plane under a sky gradient, with a red 'car' patch as a transient."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import torch

from nerf2gs_plugin.cameras import Cameras, look_at


def _render(cams: Cameras, i: int) -> tuple[np.ndarray, np.ndarray]:
    rays = cams.generate_rays(i)
    o, d = rays.origins, rays.directions
    t = -o[:, 2] / d[:, 2].clamp(max=-1e-6)
    hit = (d[:, 2] < -1e-3) & (t < 60)
    p = o + t[:, None] * d
    checker = ((torch.floor(p[:, 0] * 2) + torch.floor(p[:, 1] * 2)) % 2)[:, None]
    ground = torch.tensor([0.25, 0.25, 0.28]) + checker * torch.tensor([0.5, 0.45, 0.3])
    sky = torch.tensor([0.55, 0.7, 0.95]) - 0.3 * d[:, 2:3].clamp(0, 1)
    rgb = torch.where(hit[:, None], ground, sky)
    h, w = int(cams.height[i]), int(cams.width[i])
    return rgb.reshape(h, w, 3).numpy(), hit.reshape(h, w).numpy()


def _cams(n: int, radius: float, height: float, target_z: float, w: int, h: int, phase: float = 0.0) -> Cameras:
    ang = torch.linspace(0, 2 * math.pi, n + 1)[:-1] + phase
    eye = torch.stack([radius * torch.cos(ang), radius * torch.sin(ang), torch.full_like(ang, height)], -1)
    target = torch.tensor([0.0, 0.0, target_z]).expand(n, 3)
    return Cameras(look_at(eye, target, torch.tensor([0.0, 0.0, 1.0])), fx=w * 0.8, fy=w * 0.8, cx=w / 2, cy=h / 2, width=w, height=h)


def write_tiny_scene(root: Path, n_train: int = 8, w: int = 32, h: int = 24, transients: bool = True) -> Path:
    root = Path(root)
    for sub in ("images", "masks/sky", "masks/ground", "masks/transient"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    splits = {"train": _cams(n_train, 4.0, 1.5, 0.5, w, h), "street": _cams(2, 4.0, 1.5, 0.5, w, h, phase=0.3),
              "bev_1": _cams(2, 3.0, 4.0, 0.0, w, h, phase=0.5)}
    frames, eval_splits = [], {}
    for split, cams in splits.items():
        entries = []
        for i in range(len(cams)):
            name = f"{split}_{i:03d}"
            rgb, hit = _render(cams, i)
            transient = np.zeros((h, w), bool)
            if transients and split == "train" and i % 2 == 0:
                transient[h // 2 : h // 2 + 5, 3 + i : 10 + i] = True
                rgb = rgb.copy()
                rgb[transient] = [0.9, 0.1, 0.1]
            cv2.imwrite(str(root / "images" / f"{name}.png"), (rgb[..., ::-1] * 255).round().astype(np.uint8))
            cv2.imwrite(str(root / "masks/sky" / f"{name}.png"), (~hit).astype(np.uint8) * 255)
            cv2.imwrite(str(root / "masks/ground" / f"{name}.png"), hit.astype(np.uint8) * 255)
            cv2.imwrite(str(root / "masks/transient" / f"{name}.png"), transient.astype(np.uint8) * 255)
            c2w = torch.cat([cams.camera_to_worlds[i], torch.tensor([[0.0, 0, 0, 1]])]).tolist()
            entries.append({"file_path": f"images/{name}.png", "transform_matrix": c2w})
        if split == "train":
            frames = entries
        else:
            eval_splits[split] = entries
    g = np.random.default_rng(0)
    pts = np.concatenate([g.uniform(-3, 3, (200, 2)), np.zeros((200, 1))], 1)
    with open(root / "points.ply", "w") as f:
        f.write("ply\nformat ascii 1.0\nelement vertex 200\nproperty float x\nproperty float y\nproperty float z\n"
                "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
        for p in pts:
            f.write(f"{p[0]:.4f} {p[1]:.4f} {p[2]:.4f} 120 120 110\n")
    meta = {"camera_model": "PINHOLE", "fl_x": w * 0.8, "fl_y": w * 0.8, "cx": w / 2, "cy": h / 2, "w": w, "h": h,
            "up": [0, 0, 1], "metres_per_unit": 1.0, "ply_file_path": "points.ply", "frames": frames, "eval_splits": eval_splits}
    (root / "transforms.json").write_text(json.dumps(meta))
    return root


def train_tiny_run(data: Path, out_dir: Path, steps: int = 5) -> Path:
    """A few steps of the voxel-grid method on ``data``: a real run folder for tests of what reads runs."""
    import dataclasses

    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    cfg = dataclasses.replace(get_method("voxel-grid").config, data=data, output_dir=out_dir, max_num_iterations=steps,
                              steps_per_save=1000, steps_per_eval_image=0, progress=False, timestamp="run")
    trainer = Trainer(cfg)
    trainer.setup()
    return trainer.train()
