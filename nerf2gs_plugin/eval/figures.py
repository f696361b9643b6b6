"""Pictures people would rather look at than numbers: eval grids and bench charts."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import torch
from torch import Tensor

from nerf2gs_plugin.utils.plotting import pyplot, save_figure


def save_eval_grid(path: Path, pairs: Sequence[tuple[Tensor, Tensor]], title: str = "",
                   row_labels: Sequence[str] = ()) -> None:
    """Rows of GT | render | error (|GT-render| x4, clipped), written atomically; ``row_labels``
    name each row's view (left of the GT)."""
    plt = pyplot()
    n = len(pairs)
    fig, axes = plt.subplots(n, 3, figsize=(9, 1.9 * n + 0.4), squeeze=False)
    for r, (gt, pred) in enumerate(pairs):
        err = ((gt - pred).abs().mean(-1) * 4).clamp(0, 1)
        for c, (img, label) in enumerate(((gt, "GT"), (pred, "render"), (err, "|error| x4"))):
            ax = axes[r][c]
            ax.imshow(img.numpy(), cmap="inferno" if img.ndim == 2 else None, vmin=0, vmax=1)
            ax.set_xticks([])
            ax.set_yticks([])
            if c == 0 and r < len(row_labels):
                ax.set_ylabel(row_labels[r], fontsize=8)
            if r == 0:
                ax.set_title(label, fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)


def image_row(images: Sequence[Tensor], labels: Sequence[str], path: Path, title: str = "") -> None:
    """One labelled row of images (e.g. real | composite | BEV | enhanced BEV)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(images), figsize=(3.2 * len(images), 2.2), squeeze=False)
    for ax, img, label in zip(axes[0], images, labels):
        ax.imshow(torch.as_tensor(img).clamp(0, 1).numpy())
        ax.set_title(label, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
