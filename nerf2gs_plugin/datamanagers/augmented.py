"""The augmentation of the paper (Sec. 2.3-2.4): a reference model's renders become training data.

Any DataManager is augmented in place, so every target method (built-in or plugin) gains it:
  (a) input-view composites: the real image with only its (dilated) transient-mask pixels
      replaced by the reference render at that pose;
  (b) bird's-eye additional views: every ``every_n``-th input pose raised by ``delta_h`` metres
      along the scene's up vector and pitched down by ``theta_pitch`` degrees (paper Fig. 3),
      rendered by the reference and optionally passed through an enhancer.
Renders are cached under the reference run, keyed by everything that changes them.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras, birds_eye_poses
from nerf2gs_plugin.datamanagers.image_set import ImageSet
from nerf2gs_plugin.warn import warn

CACHE_FORMAT_VERSION = 1
RenderFn = Callable[[Cameras], dict[str, Tensor]]



@dataclass
class AugmentConfig:
    """The --augment.* flags; used only with --augment-from."""

    composites: bool = True
    """Replace transient-mask pixels of input views by the reference render."""
    dilate_px: int = 2
    """Grow transient masks by this many pixels before compositing."""
    feather_px: int = 0
    """Soften the composite seam over this many pixels (0 = hard mask)."""
    extra_views: bool = True
    """Add bird's-eye views rendered by the reference."""
    delta_h: float = 10.0
    """Height of the additional views above the input views, in metres."""
    theta_pitch: float = 30.0
    """Downward pitch of the additional views, in degrees."""
    every_n: int = 1
    """Use every n-th input pose for an additional view."""
    extra_prob: Optional[float] = None
    """Probability that a training sample comes from the additional views (None: their share of all views)."""
    extra_weight: float = 1.0
    """Loss weight of additional-view samples."""
    enhancer: str = "none"
    """none | builtin | builtin:PATH | onnx:PATH: image enhancement of the additional views."""
    use_cache: bool = True
    """Reuse the reference's cached renders when their manifest matches (False: render again)."""


def bev_cameras(train: Cameras, up: Tensor, delta_h_world: float, theta_pitch: float, every_n: int = 1) -> Cameras:
    """The additional-view cameras: input intrinsics, raised and pitched poses."""
    sub = train[torch.arange(0, len(train), max(every_n, 1))]
    return sub.with_poses(birds_eye_poses(sub.camera_to_worlds, up, delta_h_world, theta_pitch))


def composite(real: Tensor, render: Tensor, mask: Tensor, dilate_px: int = 0, feather_px: int = 0) -> Tensor:
    """Real image with the masked pixels taken from ``render``. ``real``/``render`` ``[H,W,3]``,
    ``mask`` ``[H,W,1]`` bool. Pixels outside the (dilated, feathered) mask are exactly ``real``."""
    m = mask.float().permute(2, 0, 1)[None]
    if dilate_px > 0:
        m = F.max_pool2d(m, 2 * dilate_px + 1, stride=1, padding=dilate_px)
    if feather_px > 0:
        soft = F.avg_pool2d(F.max_pool2d(m, 2 * feather_px + 1, 1, feather_px), 2 * feather_px + 1, 1, feather_px, count_include_pad=False)
        m = torch.maximum(m, soft)
    m = m[0].permute(1, 2, 0)
    return torch.where(m > 0, real * (1 - m) + render * m, real)


def _save_png(path: Path, img: Tensor) -> None:
    import cv2

    arr = (img.clamp(0, 1).cpu().numpy() * 255 + 0.5).astype(np.uint8)
    tmp = path.with_name(f".{path.name}.tmp.png")
    cv2.imwrite(str(tmp), arr[..., ::-1])
    os.replace(tmp, path)


def _load_png(path: Path) -> Tensor:
    import cv2

    arr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if arr is None:
        raise FileNotFoundError(path)
    return torch.from_numpy(arr[..., ::-1].copy()).float() / 255.0


def cache_key(ref_key: str, dataset: str, config: AugmentConfig, bev: Optional[Cameras], train: Cameras, enhancer_key: str) -> str:
    relevant = {k: v for k, v in asdict(config).items() if k not in ("extra_prob", "extra_weight", "use_cache", "enhancer")}
    h = hashlib.sha1()
    h.update(json.dumps({"v": CACHE_FORMAT_VERSION, "ref": ref_key, "data": dataset, "cfg": relevant, "enh": enhancer_key}, sort_keys=True).encode())
    for cams in (train, bev):
        if cams is not None:
            h.update(np.round(cams.camera_to_worlds.cpu().numpy(), 5).tobytes())
            h.update(cams.Ks().cpu().numpy().round(3).tobytes())
    return h.hexdigest()[:16]


@dataclass
class AugmentedViews:
    """What the augmentation produced; also what the preview and the export write out."""

    composites: Optional[ImageSet]  # same cameras as the training set
    extra: Optional[ImageSet]  # bird's-eye views (enhanced when an enhancer is set)
    extra_raw: Optional[list[Tensor]]  # bird's-eye renders before enhancement
    cache_dir: Path
    reused: bool


def render_augmented_views(train: ImageSet, up: Tensor, delta_h_world: float, render_fn: RenderFn, ref_key: str,
                           dataset: str, cache_root: Path, config: AugmentConfig) -> AugmentedViews:
    """Render (or reuse from the cache) the composites and the additional views."""
    from nerf2gs_plugin.progress import make_progress

    enhancer = None
    if config.enhancer not in ("", "none"):
        from nerf2gs_plugin.enhance import make_enhancer

        enhancer = make_enhancer(config.enhancer)
    bev = bev_cameras(train.cameras, up, delta_h_world, config.theta_pitch, config.every_n) if config.extra_views else None
    has_transient = "transient" in train.masks and config.composites
    key = cache_key(ref_key, dataset, config, bev, train.cameras, enhancer.cache_key() if enhancer else "none")
    cache_dir = Path(cache_root) / "augment_cache" / key
    manifest_path = cache_dir / "manifest.json"
    reused = config.use_cache and manifest_path.is_file()
    work = cache_dir if reused else cache_dir.with_name(f".tmp-{key}-{os.getpid()}")
    if not reused:
        shutil.rmtree(work, ignore_errors=True)
        for sub in ("composites", "extra", "extra_raw"):
            (work / sub).mkdir(parents=True, exist_ok=True)
        comp_idx = [i for i in range(len(train)) if has_transient and bool(train.mask("transient", i).any())]
        n_jobs = len(comp_idx) + (len(bev) if bev is not None else 0)
        with make_progress() as progress:
            task = progress.add_task("render reference views", total=n_jobs, stats="")
            for i in comp_idx:
                out = render_fn(train.cameras[i])["rgb"].cpu()
                comp = composite(train.image(i).cpu(), out, train.mask("transient", i).cpu(), config.dilate_px, config.feather_px)
                _save_png(work / "composites" / f"{i:05d}.png", comp)
                progress.update(task, advance=1, stats=f"composite {i}")
            for j in range(len(bev) if bev is not None else 0):
                out = render_fn(bev[j])
                rgb = out["rgb"].cpu()
                _save_png(work / "extra_raw" / f"{j:05d}.png", rgb)
                if "depth" in out:
                    np.save(work / "extra_raw" / f"{j:05d}_depth.npy", out["depth"].cpu().numpy().astype(np.float16))
                if enhancer is not None:
                    src = train.image(j * max(config.every_n, 1)).cpu()
                    rgb = enhancer.enhance(rgb, reference=src)
                _save_png(work / "extra" / f"{j:05d}.png", rgb)
                progress.update(task, advance=1, stats=f"bird's-eye {j}")
        manifest = {
            "format_version": CACHE_FORMAT_VERSION,
            "reference": ref_key,
            "dataset": dataset,
            "config": asdict(config),
            "enhancer": enhancer.cache_key() if enhancer else "none",
            "composited_images": comp_idx,
            "num_extra": len(bev) if bev is not None else 0,
            "extra_camera_to_worlds": bev.camera_to_worlds.cpu().tolist() if bev is not None else [],
        }
        (work / "manifest.json").write_text(json.dumps(manifest, indent=1))
        if cache_dir.exists():
            shutil.rmtree(cache_dir)
        os.replace(work, cache_dir)
    manifest = json.loads(manifest_path.read_text())
    composites = None
    if manifest["composited_images"]:
        images = [train.image(i).cpu() for i in range(len(train))]
        for i in manifest["composited_images"]:
            images[i] = _load_png(cache_dir / "composites" / f"{i:05d}.png")
        composites = train.to("cpu").with_images(images)
    extra = extra_raw = None
    if manifest["num_extra"]:
        assert bev is not None
        imgs = [_load_png(cache_dir / "extra" / f"{j:05d}.png") for j in range(manifest["num_extra"])]
        extra_raw = [_load_png(cache_dir / "extra_raw" / f"{j:05d}.png") for j in range(manifest["num_extra"])]
        extra = ImageSet.from_images(bev.to("cpu"), imgs, weights=torch.full((len(imgs),), float(config.extra_weight)),
                                     names=[f"bev_{j:05d}" for j in range(len(imgs))])
    return AugmentedViews(composites, extra, extra_raw, cache_dir, reused)


def augment_datamanager(datamanager, render_fn: RenderFn, ref_key: str, cache_root: Path, config: AugmentConfig) -> AugmentedViews:
    """Rewrite a DataManager's training set with the reference's composites and additional views."""
    from nerf2gs_plugin.data.fingerprint import dataset_fingerprint

    if config.composites and "transient" not in datamanager.train_images.masks:
        warn("the dataset has no transient masks", "input-view composites are off (only the bird's-eye views are added)")
    train_data = datamanager.train_data
    views = render_augmented_views(
        datamanager.train_images, train_data.up, train_data.metres_to_world(config.delta_h), render_fn, ref_key,
        dataset_fingerprint(train_data.image_filenames), cache_root, config,
    )
    datamanager.original_train_images = datamanager.train_images
    datamanager.augment_every_n = max(config.every_n, 1)
    if views.composites is not None:
        datamanager.set_train_images(views.composites)
    if views.extra is not None:
        n_real, n_extra = len(datamanager.train_images), len(views.extra)
        prob = config.extra_prob if config.extra_prob is not None else n_extra / (n_real + n_extra)
        datamanager.set_extra_images(views.extra, prob)
    datamanager.augmented_views = views
    return views
