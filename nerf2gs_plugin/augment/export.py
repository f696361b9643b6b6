"""Write an augmented training set as a plain nerfstudio dataset, so external tools (nerfstudio,
gsplat's trainer) can train on the composites and bird's-eye views too (the picture of them:
``nerf2gs_plugin.augment.preview``)."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import torch

from nerf2gs_plugin.datamanagers.image_set import ImageSet
from nerf2gs_plugin.errors import UserError


def _frames(images: ImageSet, out: Path, prefixes: list[str]) -> list[dict]:
    """One frame per image, written as ``<its prefix>_<index>.png``."""
    from nerf2gs_plugin.data.images import write_image_atomic, write_mask_atomic

    frames = []
    cams = images.cameras
    for i in range(len(images)):
        name = f"{prefixes[i]}_{i:05d}.png"
        write_image_atomic(out / "images" / name, images.image(i).cpu())
        c2w = torch.cat([cams.camera_to_worlds[i].cpu(), torch.tensor([[0.0, 0.0, 0.0, 1.0]])]).tolist()
        frame = {"file_path": f"images/{name}", "transform_matrix": c2w, "fl_x": float(cams.fx[i]), "fl_y": float(cams.fy[i]),
                 "cx": float(cams.cx[i]), "cy": float(cams.cy[i]), "w": int(cams.width[i]), "h": int(cams.height[i])}
        for kind in ("sky", "ground"):
            m = images.mask(kind, i)
            if m is not None:
                write_mask_atomic(out / "masks" / kind / name, m[..., 0].cpu())
                frame[f"{kind}_mask_path"] = f"masks/{kind}/{name}"
        frames.append(frame)
    return frames


def extra_prefixes(datamanager) -> list[str]:
    """Per additional view the name of its family as its files' prefix (``birdseye`` for the bird's-eye
    views, as before the families; ``lane-shift``, ...), from the augmentation's manifest."""
    n = len(datamanager.extra_images)
    manifest = getattr(datamanager, "manifest", None)
    families = (manifest.extra_families if manifest is not None else None) or ["birds-eye"] * n
    return ["birdseye" if f == "birds-eye" else f for f in families]


def export_augmented_dataset(datamanager, out: Path, overwrite: bool = False) -> Path:
    """The datamanager's (augmented) training images and its additional views -> ``out/transforms.json``.

    Poses are written in the normalised world frame; ``metres_per_unit`` keeps metres meaningful.
    Eval splits are not exported (they are never augmented).
    """
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        if not overwrite:
            raise UserError("output folder is not empty (pass --overwrite)", out)
        shutil.rmtree(out)
    tmp = out.with_name(f".{out.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    frames = _frames(datamanager.train_images, tmp, ["input"] * len(datamanager.train_images))
    if datamanager.extra_images is not None:
        frames += _frames(datamanager.extra_images, tmp, extra_prefixes(datamanager))
    td = datamanager.train_data
    meta = {"camera_model": "PINHOLE", "frames": frames, "up": td.up.tolist(), "metres_per_unit": td.world_to_metres(1.0),
            "generator": "nerf2gs export-augmented"}
    pts = td.points3D_xyz
    if pts is not None:
        from nerf2gs_plugin.data.ply import write_ply_points

        rgb = td.points3D_rgb if td.points3D_rgb is not None else torch.full_like(pts, 128, dtype=torch.uint8)
        write_ply_points(tmp / "sparse_pc.ply", pts.cpu().numpy(), rgb.cpu().numpy())
        meta["ply_file_path"] = "sparse_pc.ply"
    (tmp / "transforms.json").write_text(json.dumps(meta, indent=1))
    if out.exists():
        out.rmdir()
    os.replace(tmp, out)
    return out
