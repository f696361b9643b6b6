"""ns2gs-data export-augmented / preview-augmented: the augmented training set, as files or a picture."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import tyro

from nerf2gs_plugin.augment.config import AugmentConfig


def _augmented_datamanager(data: Path, reference: Path, augment: AugmentConfig, device: str):
    from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
    from nerf2gs_plugin.augment.reference import augmented_datamanager
    from nerf2gs_plugin.engine.trainer import pick_device

    dev = pick_device(device)
    return augmented_datamanager(FullImageDataManagerConfig().setup(data=data, device=dev), reference, augment, dev)


@dataclass
class ExportAugmented:
    """Write the augmented training set (composites + bird's-eye views) as a nerfstudio dataset."""

    data: tyro.conf.Positional[Path]
    reference: Path = Path("outputs/street/streetnerf")
    """Reference run directory or .ckpt (as --augment-from)."""
    out: Path = Path("data/street_augmented")
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    overwrite: bool = False
    device: str = "auto"

    def main(self) -> None:
        from nerf2gs_plugin.augment.export import export_augmented_dataset

        dm = _augmented_datamanager(self.data, self.reference, self.augment, self.device)
        out = export_augmented_dataset(dm, self.out, overwrite=self.overwrite)
        n_extra = len(dm.extra_images) if dm.extra_images is not None else 0
        print(f"wrote {out}/transforms.json: {len(dm.train_images)} input views, {n_extra} bird's-eye views")


@dataclass
class PreviewAugmented:
    """PNG: real image | composite | bird's-eye render | enhanced bird's-eye view."""

    data: tyro.conf.Positional[Path]
    reference: Path = Path("outputs/street/streetnerf")
    out: Path = Path("augmented_preview.png")
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    rows: int = 3
    device: str = "auto"

    def main(self) -> None:
        from nerf2gs_plugin.augment.preview import preview_augmented

        dm = _augmented_datamanager(self.data, self.reference, self.augment, self.device)
        print(f"wrote {preview_augmented(dm, self.out, self.rows)}")


AUGMENTED_SUBCOMMANDS = {
    "export-augmented": ExportAugmented,
    "preview-augmented": PreviewAugmented,
}
