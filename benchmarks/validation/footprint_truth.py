"""How finely the street views resolve what a synthetic street's test views from above see, with the true
depth (no NeRF in it): per split, over the ground pixels, the finest observing training view's footprint over
the view's own (``augment/confidence.py:relative_footprint``; below 1: a street view sees it more finely).

Usage: python benchmarks/validation/footprint_truth.py STREET_DATA   (an ``ns2gs-data synth-street`` folder)
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from nerf2gs_plugin.augment.confidence import relative_footprint
from nerf2gs_plugin.cameras import Cameras

SKY_Z = 1e4
"""The synthetic depth's sky (0) as a far surface: no view observes it."""


def _cameras(t: dict, frames: list[dict]) -> Cameras:
    c2w = torch.tensor([f["transform_matrix"][:3] for f in frames], dtype=torch.float32)
    return Cameras(c2w, fx=t["fl_x"], fy=t["fl_y"], cx=t["cx"], cy=t["cy"], width=t["w"], height=t["h"])


def _z(root: Path, frame: dict) -> torch.Tensor:
    d = torch.from_numpy(np.load(root / frame["depth_file_path"])).float()
    return torch.where(d > 0, d, torch.full_like(d, SKY_Z))


def split_ratios(root: Path, split: str) -> torch.Tensor:
    """The ratios ``[P]`` over the ground pixels of every view of ``split``."""
    t = json.loads((root / "transforms.json").read_text())
    train = _cameras(t, t["frames"])
    train_z = [_z(root, f) for f in t["frames"]]
    frames = t["eval_splits"][split]
    views, out = _cameras(t, frames), []
    for j, f in enumerate(frames):
        ground = torch.from_numpy(np.array(Image.open(root / f["ground_mask_path"]).convert("L")) > 127)
        ratio = relative_footprint(_z(root, f)[..., None], views[torch.tensor([j])], "z", train, train_z)
        out.append(ratio[ground])
    return torch.cat(out)


def main(root: Path) -> None:
    for split in ("bev_1", "bev_2", "street"):
        r = split_ratios(root, split)
        q = np.quantile(r.clamp(max=1e3).numpy(), [0.1, 0.25, 0.5, 0.75, 0.9])
        print(f"{split}: {len(r)} ground pixels, observed by no street view {float(torch.isinf(r).float().mean()):.3f}, "
              f"ratio < 1 {float((r < 1).float().mean()):.3f}, < 2 {float((r < 2).float().mean()):.3f}; "
              "quantiles 10/25/50/75/90%: " + " ".join(f"{x:.2f}" for x in q))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", type=Path, help="an ns2gs-data synth-street folder")
    main(parser.parse_args().data)
