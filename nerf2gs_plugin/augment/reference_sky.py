"""The reference's sky at the input views (``--augment.reference-sky``).

A target trained with views from above fits surfaces there that the street views then see in front
of their sky. The masks' sky marks only part of it (a segmenter or a first reference misses much of a
real capture's sky), so the reference's own sky at each input view (accumulation < 0.5 above the
horizon) joins it: the model's sky alpha loss (``--pipeline.model.sky-alpha-weight``) then pushes the
target's accumulation to 0 wherever the reference saw through to the sky. The reference renders
each input view at a fraction of its resolution (the sky is a smooth region), once; the masks are
cached under the reference run beside the augmentation's renders.
"""

from __future__ import annotations

import hashlib
import io
from dataclasses import replace
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.datamanagers.image_set import ImageSet
from nerf2gs_plugin.masks.from_renders import sky_from_render
from nerf2gs_plugin.utils.io import atomic_write_bytes

RENDER_SCALE = 0.25
"""Resolution of the renders the sky is read from, as a fraction of the input views'."""
SKY_DIR_NAME = "reference_sky"


def sky_key(ref_key: str, cameras: Cameras, scale: float = RENDER_SCALE) -> str:
    """The cache name of a reference's sky masks at ``cameras``."""
    h = hashlib.sha1(f"{ref_key}|{scale}".encode())
    h.update(np.round(cameras.camera_to_worlds.cpu().numpy(), 5).tobytes())
    h.update(cameras.Ks().cpu().numpy().round(3).tobytes())
    return h.hexdigest()[:16]


def render_sky(render_fn: Callable[[Cameras], dict[str, Tensor]], camera: Cameras, up: Tensor,
               scale: float = RENDER_SCALE) -> Tensor:
    """Bool ``[H, W]`` at ``camera``'s resolution: where the reference's render (at ``scale`` of it) shows sky."""
    h, w = int(camera.height[0]), int(camera.width[0])
    small = camera.scaled(scale) if scale != 1.0 else camera
    with torch.no_grad():
        acc = render_fn(small)["accumulation"].detach().cpu().float().reshape(int(small.height[0]), int(small.width[0]))
    dirs = small.generate_rays(0).directions.reshape(acc.shape[0], acc.shape[1], 3).cpu().float()
    sky = sky_from_render(acc, dirs, up.cpu().float())
    return F.interpolate(sky.float()[None, None], size=(h, w), mode="nearest")[0, 0] > 0.5


def reference_sky_masks(render_fn: Callable[[Cameras], dict[str, Tensor]], cameras: Cameras, up: Tensor,
                        ref_key: str, cache_root: Optional[Path], scale: float = RENDER_SCALE) -> list[Tensor]:
    """One bool ``[H, W]`` sky mask per camera, from the cache under ``cache_root`` or rendered (and stored)."""
    path = Path(cache_root) / SKY_DIR_NAME / f"{sky_key(ref_key, cameras, scale)}.npz" if cache_root is not None else None
    if path is not None and path.is_file():
        try:
            with np.load(path) as z:
                return [torch.from_numpy(z[f"m{i}"]).bool() for i in range(len(cameras))]
        except (OSError, ValueError, KeyError):
            pass  # a damaged file: render again
    masks = [render_sky(render_fn, cameras[i:i + 1], up, scale) for i in range(len(cameras))]
    if path is not None:
        buf = io.BytesIO()
        np.savez_compressed(buf, **{f"m{i}": m.numpy() for i, m in enumerate(masks)})
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, buf.getvalue())
    return masks


def with_sky(images: ImageSet, sky: list[Tensor]) -> ImageSet:
    """``images`` with each view's sky mask the union of its own (if any) and ``sky[i]``."""
    flat = torch.cat([m.reshape(-1).bool() for m in sky]).to(images.pixels.device)
    if "sky" in images.masks:
        flat = flat | images.masks["sky"].to(flat.device)
    masks = {**images.masks, "sky": flat}
    return replace(images, masks=masks, names=list(images.names))
