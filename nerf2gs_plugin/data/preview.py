"""``ns2gs-data preview``: one PNG that shows a user what a dataset holds.

Left: for each split (train first, then the eval splits), a few images, each beside a copy with its
masks tinted (sky blue, ground green, transient red). Right: a top-down view (looking down the
dataset's up axis) of the sparse points in their colours, the training cameras and every eval
split's cameras with their viewing directions. Works on any dataset the parsers read.
"""

from __future__ import annotations

from pathlib import Path
from typing import Union

import numpy as np
import torch

from nerf2gs_plugin.data import list_splits, parse_dataset
from nerf2gs_plugin.data.dataparser_outputs import DataparserOutputs
from nerf2gs_plugin.data.images import load_image, load_mask
from nerf2gs_plugin.utils.io import atomic_write_bytes

_TINT = {"sky": (0.2, 0.45, 1.0), "ground": (0.1, 0.85, 0.2), "transient": (1.0, 0.1, 0.1)}
_SPLIT_COLOURS = ["black", "tab:orange", "tab:blue", "tab:purple", "tab:green", "tab:red", "tab:brown"]


def mask_overlay(image: np.ndarray, masks: dict[str, np.ndarray]) -> np.ndarray:
    """``image [H, W, 3]`` with each mask's pixels blended 55% toward its tint colour."""
    out = image.copy()
    for kind, m in masks.items():
        out[m] = 0.45 * out[m] + 0.55 * np.asarray(_TINT.get(kind, (1.0, 1.0, 0.0)), dtype=np.float32)
    return out


def _pick(n: int, k: int) -> list[int]:
    return sorted({int(round(v)) for v in np.linspace(0, n - 1, min(n, k))})


def _plane_basis(up: torch.Tensor) -> torch.Tensor:
    """Two unit vectors ``[2, 3]`` spanning the ground plane (perpendicular to ``up``)."""
    up = torch.nn.functional.normalize(up.float(), dim=0)
    ref = torch.tensor([1.0, 0.0, 0.0]) if abs(float(up[0])) < 0.9 else torch.tensor([0.0, 1.0, 0.0])
    e1 = torch.nn.functional.normalize(ref - (ref @ up) * up, dim=0)
    return torch.stack([e1, torch.linalg.cross(up, e1)])


def write_preview(data: Union[str, Path], out: Union[str, Path], rows: int = 3) -> Path:
    """Render the contact sheet of the dataset at ``data`` to ``out`` (PNG); returns ``out``."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list_splits(data)
    splits: dict[str, DataparserOutputs] = {s: parse_dataset(data, s) for s in names}
    rows = max(1, rows)
    n_rows = len(names)
    fig = plt.figure(figsize=(2.2 * 2 * rows + 6.5, max(2.0 * n_rows, 5.5)), dpi=110)
    gs = fig.add_gridspec(n_rows, 2 * rows + 1, width_ratios=[1.0] * (2 * rows) + [2.6])
    for r, name in enumerate(names):
        outs = splits[name]
        for c, i in enumerate(_pick(len(outs), rows)):
            img = load_image(outs.image_filenames[i]).numpy()
            hw = img.shape[:2]
            masks = {k: load_mask(v[i], hw).numpy() for k, v in outs.mask_filenames.items() if v[i] is not None}
            for j, panel in enumerate((img, mask_overlay(img, masks))):
                ax = fig.add_subplot(gs[r, 2 * c + j])
                ax.imshow(np.clip(panel, 0, 1))
                ax.set_xticks([])
                ax.set_yticks([])
                title = f"{name} #{i}" if j == 0 else "+ " + ",".join(k for k, m in masks.items() if m.any()) if masks else "no masks"
                ax.set_title(title, fontsize=7)

    train = splits[names[0]]
    basis = _plane_basis(train.up)
    ax = fig.add_subplot(gs[:, -1])
    if train.points3D_xyz is not None and len(train.points3D_xyz):
        p2 = (train.points3D_xyz.float() @ basis.T).numpy()
        rgb = train.points3D_rgb.numpy() / 255.0 if train.points3D_rgb is not None else "grey"
        ax.scatter(p2[:, 0], p2[:, 1], s=1.5, c=rgb, linewidths=0, label=f"sparse points ({len(p2)})")
    span = 1.0
    for k, name in enumerate(names):
        cams = splits[name].cameras
        c2 = (cams.camera_to_worlds[:, :, 3] @ basis.T).numpy()
        span = max(span, float(np.ptp(c2, axis=0).max()) if len(c2) > 1 else span)
    for k, name in enumerate(names):
        cams = splits[name].cameras
        c2 = (cams.camera_to_worlds[:, :, 3] @ basis.T).numpy()
        f2 = (-cams.camera_to_worlds[:, :, 2] @ basis.T).numpy()
        col = _SPLIT_COLOURS[k % len(_SPLIT_COLOURS)]
        ax.scatter(c2[:, 0], c2[:, 1], s=10, c=col, label=f"{name} ({len(c2)})", zorder=3)
        ax.quiver(c2[:, 0], c2[:, 1], f2[:, 0], f2[:, 1], color=col, angles="xy", scale_units="xy", scale=25.0 / span, width=0.003, zorder=3)
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title(f"top-down (1 unit = {train.world_to_metres(1.0):.2f} m)", fontsize=9)
    fig.suptitle(str(data), fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    out = Path(out)
    atomic_write_bytes(out, buf.getvalue())
    return out
