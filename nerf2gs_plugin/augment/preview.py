"""A picture of an augmented training set (``ns2gs-data preview-augmented``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nerf2gs_plugin.augment.datamanager import AugmentedDataManager
from nerf2gs_plugin.utils.plotting import pyplot as _mpl, save_figure


def preview_augmented(datamanager: AugmentedDataManager, path: Path, n: int = 3) -> Path:
    """Rows of real image | composite | bird's-eye render | enhanced bird's-eye view (| its confidence
    with ``--augment.confidence``: where the reference's pixels are trusted)."""
    plt = _mpl()
    views = datamanager.views
    real_set = datamanager.original_train_images
    comp_set = datamanager.train_images
    ids = [i for i in range(len(real_set)) if real_set.mask("transient", i) is not None and bool(real_set.mask("transient", i).any())]
    ids = (ids or list(range(len(real_set))))[:n]
    cols = ["real image", "composite (transients from reference)", "bird's-eye view (reference)"]
    if views.extra_raw is not None and views.extra is not None:
        cols.append("bird's-eye view, enhanced")
    conf = views.extra.confidence is not None if views.extra is not None else False
    if conf:
        cols.append("its confidence (0 black, 1 white)")
    fig, axes = plt.subplots(len(ids), len(cols), figsize=(3.3 * len(cols), 2.1 * len(ids) + 0.4), squeeze=False)
    every = datamanager.every_n
    for r, i in enumerate(ids):
        row = [real_set.image(i), comp_set.image(i)]
        j = i // every
        if views.extra_raw is not None and j < len(views.extra_raw):
            row.append(views.extra_raw[j])
            if views.extra is not None:
                row.append(views.extra.image(j))
            if conf:
                row.append(views.extra.image_batch(j)["confidence"].expand(-1, -1, 3))
        for c, img in enumerate(row):
            ax = axes[r][c]
            ax.imshow(np.clip(img.cpu().numpy(), 0, 1))
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(cols[c], fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    return Path(path)
