"""Frames of a path: each camera rendered, its outputs coloured and tiled (left to right), and
several runs' frames side by side under their labels."""

from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np
import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.render.colorize import colorize

LABEL_BAND = 22  # pixels above each run's tile where its label is written


def model_device(model) -> torch.device:
    return getattr(model, "device", None) or next(iter(model.parameters()), torch.empty(0)).device


@torch.no_grad()
def check_outputs(model, camera: Cameras, names: Sequence[str]) -> dict:
    """One render of ``camera``; a requested output the method does not render is a clear error."""
    out = model.render_camera(camera.to(model_device(model)))
    missing = [n for n in names if n not in out]
    if missing:
        raise ConfigError(f"--rendered-output-names {' '.join(missing)}: this method renders {', '.join(k for k in out if out[k].ndim == 3)}")
    return out


@torch.no_grad()
def render_outputs(model, cameras: Cameras) -> Iterator[dict]:
    """``model.render_camera`` of each camera in turn, on the model's device."""
    device = model_device(model)
    for i in range(len(cameras)):
        yield model.render_camera(cameras[i].to(device))


def tile(outputs: dict, names: Sequence[str]) -> np.ndarray:
    """The named outputs of one render, coloured (depth: turbo map) and placed left to right."""
    return np.concatenate([colorize(outputs, n) for n in names], axis=1)


def put_label(img: np.ndarray, text: str) -> np.ndarray:
    """``img`` under a black band holding ``text`` in white (scaled to the band)."""
    import cv2

    band = np.zeros((LABEL_BAND, img.shape[1], 3), np.uint8)
    scale = 0.5
    (w, _), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    if w > img.shape[1] - 8:  # a long label on a small tile: smaller letters
        scale = max(0.25, scale * (img.shape[1] - 8) / w)
    cv2.putText(band, text, (4, LABEL_BAND - 7), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return np.concatenate([band, img], axis=0)


def side_by_side(tiles: Sequence[np.ndarray], labels: Sequence[str], gap: int = 4) -> np.ndarray:
    """Runs' tiles left to right, each under its label, ``gap`` black pixels apart."""
    h = max(t.shape[0] for t in tiles)
    cols = []
    for k, (t, label) in enumerate(zip(tiles, labels)):
        if t.shape[0] < h:
            t = np.pad(t, ((0, h - t.shape[0]), (0, 0), (0, 0)))
        cols.append(put_label(t, label))
        if k < len(tiles) - 1:
            cols.append(np.zeros((h + LABEL_BAND, gap, 3), np.uint8))
    return np.concatenate(cols, axis=1)
