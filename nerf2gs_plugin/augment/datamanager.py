"""The augmentation of the paper (Sec. 2.3-2.4): a reference model's renders become training data.

:class:`AugmentedDataManager` wraps any method's DataManager, so every target method (built-in or
plugin) gains it and never knows the views are not real:
  (a) input-view composites: the real image with only its (dilated) transient-mask pixels
      replaced by the reference render at that pose;
  (b) bird's-eye additional views: every ``every_n``-th input pose raised by ``delta_h`` metres
      along the scene's up vector and pitched down by ``theta_pitch`` degrees below the ground
      plane's horizon (paper Fig. 3; ``pitch_mode="relative"`` adds it to the input's own tilt),
      rendered by the reference and optionally passed through an enhancer. A view outside the
      scene box or a mostly empty render (low accumulation) is dropped with one warning.
A reference that refined its training poses (a camera optimizer) renders the composites, and
everything else that re-renders an input view (the confidence's depths, a warped enhancer's source),
from its refined poses (:attr:`Reference.train_cameras`): that is where it learned each photo was
taken, so its render lines up with the photo it is pasted into. The bird's-eye cameras stay derived
from the dataset's poses: they are novel views with no photo, rendered and trained at the one same
pose, and the target trains its input views at the dataset's poses too.
Renders are cached under the reference run, keyed by everything that changes them (the cache
format: :mod:`nerf2gs_plugin.augment.cache`). This module knows no reference method,
no enhancer implementation and no engine: the engine loads the reference and builds the enhancer.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Protocol

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.data.dataparser_outputs import DataparserOutputs
from nerf2gs_plugin.data.fingerprint import dataset_fingerprint
from nerf2gs_plugin.augment.config import FAMILY_FIELDS, AugmentConfig
from nerf2gs_plugin.augment.geometry import ViewGeometry, WorldFrame
from nerf2gs_plugin.augment.confidence import inside_box
from nerf2gs_plugin.augment.reference_sky import reference_sky_masks, with_sky
from nerf2gs_plugin.augment.shares import extra_sampling
from nerf2gs_plugin.augment.views import additional_views
from nerf2gs_plugin.augment.cache import (
    CACHE_DIR_NAME,
    CacheManifest,
    StoredView,
    ViewStore,
    cache_key,
    cache_manifests,
    family_params,
    confidence_path,
    load_confidence,
    load_png,
    read_manifest,
    save_png,
)
from nerf2gs_plugin.datamanagers.base import DataManager
from nerf2gs_plugin.datamanagers.image_set import ImageSet
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.utils.model_output import check_range
from nerf2gs_plugin.utils.parallel import render_ahead
from nerf2gs_plugin.utils.resize import area_resize
from nerf2gs_plugin.warn import warn

RenderFn = Callable[[Cameras], dict[str, Tensor]]
PixelRenderFn = Callable[[Cameras, Tensor], dict[str, Tensor]]
"""A camera and a bool ``[H, W]`` -> the render of only those pixels (full-size outputs, the rest 0)."""
RENDER_KEYS = ("rgb", "depth", "accumulation")


class ViewEnhancer(Protocol):
    """What the augmentation needs of an enhancer (``nerf2gs_plugin.enhancer.Enhancer`` is one)."""

    def enhance(self, rgb: Tensor, reference: Optional[Tensor] = None) -> Tensor: ...

    def cache_key(self) -> str: ...


@dataclass
class Reference:
    """A trained reference as the augmentation sees it: a renderer, a key that changes whenever
    its renders would (method and checkpoint hash), and the folder its cache lives under."""

    render: RenderFn
    key: str
    cache_root: Path
    depth_along: str = "z"
    """What the renders' ``depth`` measures ("z" or "ray": :attr:`nerf2gs_plugin.engine.model.Model.depth_along`)."""
    train_cameras: Optional[Callable[[Cameras], Optional[Cameras]]] = None
    """The training cameras -> the reference's refined ones (``Model.refined_train_cameras``), or None
    / a None result: the reference renders input views at the dataset's poses."""
    render_pixels: Optional[PixelRenderFn] = None
    """Renders only some pixels of a camera (a model whose ``render_camera`` takes ``pixels``); None:
    a composite renders its whole view."""
    render_workers: int = 1
    """Additional views rendered at once, each in a forked process (``utils/parallel.py``): a model's
    renders (``load_reference``: torch's thread count); 1: one after another in this process."""


def composite_weight(mask: Tensor, dilate_px: int = 0, feather_px: int = 0) -> Tensor:
    """``[H,W,1]`` share of each pixel that a composite takes from the render: the ``[H,W,1]`` bool
    mask dilated, its seam feathered."""
    m = mask.float().permute(2, 0, 1)[None]
    if dilate_px > 0:
        m = F.max_pool2d(m, 2 * dilate_px + 1, stride=1, padding=dilate_px)
    if feather_px > 0:
        soft = F.avg_pool2d(F.max_pool2d(m, 2 * feather_px + 1, 1, feather_px), 2 * feather_px + 1, 1, feather_px, count_include_pad=False)
        m = torch.maximum(m, soft)
    return m[0].permute(1, 2, 0)


def composite(real: Tensor, render: Tensor, mask: Tensor, dilate_px: int = 0, feather_px: int = 0) -> Tensor:
    """Real image with the masked pixels taken from ``render``. ``real``/``render`` ``[H,W,3]``,
    ``mask`` ``[H,W,1]`` bool. Pixels outside the (dilated, feathered) mask are exactly ``real``, so
    ``render`` is read only where :func:`composite_weight` is > 0."""
    m = composite_weight(mask, dilate_px, feather_px)
    return torch.where(m > 0, real * (1 - m) + render * m, real)


@dataclass
class AugmentedViews:
    """What the augmentation produced; also what the preview and the export write out."""

    composites: Optional[ImageSet]  # same cameras as the training set
    extra: Optional[ImageSet]  # bird's-eye views (enhanced when an enhancer is set)
    extra_raw: Optional[list[Tensor]]  # bird's-eye renders before enhancement
    cache_dir: Path
    reused: bool
    manifest: Optional[CacheManifest] = None

    @property
    def render_seconds(self) -> float:
        """The reference's render time for this entry (as measured when it was rendered)."""
        return self.manifest.render_seconds if self.manifest is not None else 0.0


class _Visibility:
    """The training views as the visibility confidence needs them: cameras, the reference's depth at
    each (camera-space z) and the pixels that observe no surface (sky or transient)."""

    def __init__(self, train: ImageSet, depths_z: list[Tensor], config: AugmentConfig, depth_along: str) -> None:
        self.cameras = train.cameras.to("cpu")
        self.depths_z = depths_z
        self.blind: list[Optional[Tensor]] = []
        for i in range(len(train)):
            b = [train.mask(k, i) for k in ("sky", "transient") if train.mask(k, i) is not None]
            self.blind.append(torch.stack(b).any(0)[..., 0].cpu() if b else None)
        self.images = [train.image(i).cpu() for i in range(len(train))] if config.confidence == "consistency" else None
        self.config = config
        self.depth_along = depth_along

    def confidence(self, out: dict[str, Tensor], camera: Cameras) -> Tensor:
        """``[H, W, 1]`` confidence of one render ``out`` of the reference at ``camera``."""
        from nerf2gs_plugin.augment.confidence import footprint_weight, unseen_weight, visibility_confidence

        if self.config.confidence == "footprint":
            return footprint_weight(out["depth"].cpu(), camera.to("cpu"), self.depth_along, self.cameras, self.depths_z,
                                    self.blind, self.config.confidence_depth_tol, self.config.confidence_footprint_ratio)
        if self.config.confidence == "unseen":
            return unseen_weight(out["depth"].cpu(), camera.to("cpu"), self.depth_along, self.cameras, self.depths_z,
                                 self.blind, self.config.confidence_full_views, self.config.confidence_depth_tol,
                                 self.config.confidence_seen_weight)
        return visibility_confidence(out["depth"].cpu(), camera.to("cpu"), self.depth_along, self.cameras, self.depths_z,
                                     self.blind, out["accumulation"].cpu() if "accumulation" in out else None,
                                     self.config.confidence_full_views, self.config.confidence_depth_tol,
                                     out["rgb"].cpu(), self.images, self.config.confidence_color_tol)


def _save_confidence(path: Path, conf: Tensor) -> None:
    np.save(path, conf[..., 0].cpu().numpy().astype(np.float16))


def _warped_source(out: dict[str, Tensor], camera: Cameras, train: ImageSet, render_fn: RenderFn,
                   renders: dict[int, dict[str, Tensor]], depths: dict[int, Tensor], depth_along: str) -> Tensor:
    """``[H, W, 4]``: the training view nearest ``camera`` (facing the same way) warped into it through
    the render's depth ``out["depth"]``, and its validity: the reference input of a ``warped``-conditioned enhancer."""
    from nerf2gs_plugin.enhancer.warp import clear_mask, condition_source, warped_reference

    if "depth" not in out:
        raise ConfigError("an enhancer conditioned on warped views needs a reference that renders depth; this one does not")
    k = condition_source(camera.camera_to_worlds[0], train.cameras.camera_to_worlds)
    if k not in depths:  # rendered once per source view (the composites' renders are reused)
        depths[k] = (renders[k] if k in renders else render_fn(train.cameras[k]))["depth"].cpu()
    return warped_reference(camera.to("cpu"), out["depth"].cpu(), train.cameras[k].to("cpu"), depths[k], train.image(k).cpu(),
                            clear_mask(train.mask("transient", k), *train.hw(k)), depth_along)


def _extra_confidence(out: dict[str, Tensor], camera: Cameras, vis: Optional[_Visibility], config: AugmentConfig,
                      scene_box: Optional[Tensor], depth_along: str) -> Tensor:
    """``[H, W, 1]`` loss weight of one additional view's pixels: the visibility confidence (1 without one),
    times 0 outside the scene box and on sky with ``drop_outside_box``."""
    conf = vis.confidence(out, camera) if vis is not None else torch.ones(*out["rgb"].shape[:2], 1)
    if config.drop_outside_box:
        from nerf2gs_plugin.augment.confidence import inside_box_weight

        if "depth" not in out:
            raise ConfigError("--augment.drop-outside-box needs a reference that renders depth; this one does not")
        conf = conf * inside_box_weight(out["depth"].cpu(), out.get("accumulation"), camera.to("cpu"), depth_along, scene_box)
    return conf


def _render_entry(work: Path, train: ImageSet, bev: Optional[Cameras], render_fn: RenderFn, config: AugmentConfig,
                  enhancer: Optional[ViewEnhancer], comp_idx: list[int], scene_box: Optional[Tensor],
                  depth_along: str = "z", sources: Optional[list[int]] = None, render_pixels: Optional[PixelRenderFn] = None,
                  store: Optional[ViewStore] = None, render_workers: int = 1) -> dict[str, Any]:
    """Render every image of a cache entry into ``work`` (not yet the entry: it is renamed after).
    Bird's-eye views outside the scene box or with mostly empty renders are left out; returns the
    manifest fields that say which were kept and how long it took. With a confidence, every
    training view is rendered (its depth is the occlusion test) and each render gets a
    ``_conf.npy`` beside its PNG. ``sources``: per additional view, the input view it was made from
    (an image-conditioned enhancer's reference; None: every ``every_n``-th, the bird's-eye views').
    Without a confidence, a composite renders only the pixels it takes from the reference
    (``render_pixels``). Additional views' renders come from and go to ``store`` (one key per view);
    those not there are rendered ``render_workers`` at once."""
    import time

    from nerf2gs_plugin.augment.confidence import depth_to_z
    from nerf2gs_plugin.progress import make_progress

    for sub in ("composites", "extra", "extra_raw"):
        (work / sub).mkdir(parents=True, exist_ok=True)
    with_conf = config.confidence != "none"
    train_ids = list(range(len(train))) if with_conf else comp_idx
    comp_set = set(comp_idx)
    n_jobs = len(train_ids) + (len(bev) if bev is not None else 0)
    kept: list[int] = []
    outside = empty = reused = 0
    partial = render_pixels is not None and not with_conf
    t0 = time.perf_counter()
    with make_progress() as progress:
        task = progress.add_task("render reference views", total=n_jobs, stats="")
        renders: dict[int, dict[str, Tensor]] = {}  # the composited views' renders
        depths_z: list[Tensor] = []  # every input view's, with a confidence (float16: one per view is kept)
        for i in train_ids:
            if partial:  # a composite reads the render only where it pastes it
                where = composite_weight(train.mask("transient", i).cpu(), config.dilate_px, config.feather_px)[..., 0] > 0
                out = {k: v.cpu() for k, v in render_pixels(train.cameras[i], where).items() if k in RENDER_KEYS}
            else:
                out = {k: v.cpu() for k, v in render_fn(train.cameras[i]).items() if k in RENDER_KEYS}
            check_range(out["rgb"], 0.0, 1.0, "reference run", f"render of input view {i}")
            if with_conf:
                if "depth" not in out:
                    from nerf2gs_plugin.errors import ConfigError

                    raise ConfigError("--augment.confidence visibility needs a reference that renders depth; this one does not")
                depths_z.append(depth_to_z(out["depth"], train.cameras[i].to("cpu"), depth_along).half())
            if i in comp_set:
                renders[i] = out
            progress.update(task, advance=1, stats=f"input view {i}")
        vis = _Visibility(train, depths_z, config, depth_along) if with_conf else None
        for i in comp_idx:
            mask = train.mask("transient", i).cpu()
            comp = composite(train.image(i).cpu(), renders[i]["rgb"], mask, config.dilate_px, config.feather_px)
            save_png(work / "composites" / f"{i:05d}.png", comp)
            if config.confidence in ("unseen", "footprint"):  # a painted pixel is what its own photo could not show: kept whole
                _save_confidence(confidence_path(work / "composites" / f"{i:05d}.png"), torch.ones_like(comp[..., :1]))
            elif vis is not None:  # real pixels weigh 1, painted ones as much as the reference knows them
                painted = composite(torch.zeros_like(comp), torch.ones_like(comp), mask, config.dilate_px, config.feather_px)[..., :1]
                conf = 1.0 - painted + painted * vis.confidence(renders[i], train.cameras[i])
                _save_confidence(confidence_path(work / "composites" / f"{i:05d}.png"), conf)
        inside = inside_box(bev.centers, scene_box) if bev is not None else None
        source_depths: dict[int, Tensor] = {}  # a warped-conditioned enhancer's source views: the reference's depth there
        n_bev = len(bev) if bev is not None else 0
        needs_acc = with_conf or config.drop_outside_box

        def usable(j: int) -> Optional[StoredView]:
            stored = store.get(bev[j]) if store is not None else None
            return stored if stored is not None and stored.usable(config.min_coverage, needs_acc) else None

        def render_view(j: int) -> dict[str, Tensor]:
            return {k: v.cpu() for k, v in render_fn(bev[j]).items() if k in RENDER_KEYS}

        # the views to render, rendered ahead side by side (utils/parallel.py) while this loop stores them
        to_render = [j for j in range(n_bev) if bool(inside[j]) and usable(j) is None]
        fresh, ahead = render_ahead(render_view, to_render, render_workers), set(to_render)
        for j in range(n_bev):
            if not bool(inside[j]):  # outside the scene box: the reference knows nothing there
                outside += 1
                progress.update(task, advance=1, stats=f"bird's-eye {j} outside the box")
                continue
            stored = None if j in ahead else usable(j)
            if stored is not None:
                out, view = stored.out, stored
                reused += 1
            else:
                out = next(fresh) if j in ahead else render_view(j)
                check_range(out["rgb"], 0.0, 1.0, "reference run", f"render of bird's-eye view {j}")  # before it is stored
                if store is not None:
                    store.put(bev[j], out)
                view = StoredView(out, float((out["accumulation"] > 0.5).float().mean()) if "accumulation" in out else None)
            if view.dropped(config.min_coverage):
                empty += 1
                progress.update(task, advance=1, stats=f"bird's-eye {j} mostly empty")
                continue
            k = len(kept)
            kept.append(j)
            rgb = out["rgb"].cpu()
            save_png(work / "extra_raw" / f"{k:05d}.png", rgb)
            if "depth" in out:
                np.save(work / "extra_raw" / f"{k:05d}_depth.npy", out["depth"].cpu().numpy().astype(np.float16))
            if vis is not None or config.drop_outside_box:
                _save_confidence(confidence_path(work / "extra" / f"{k:05d}.png"),
                                 _extra_confidence(out, bev[j], vis, config, scene_box, depth_along))
            if enhancer is not None:
                if getattr(enhancer, "reference_kind", "image") == "warped":
                    src = _warped_source(out, bev[j], train, render_fn, {} if partial else renders, source_depths, depth_along)
                else:
                    src = area_resize(train.image(sources[j] if sources is not None else j * max(config.every_n, 1)).cpu(), rgb.shape[:2])
                rgb = check_range(enhancer.enhance(rgb, reference=src), 0.0, 1.0, getattr(enhancer, "path", "enhancer"),
                                  f"enhanced bird's-eye view {j}")
            save_png(work / "extra" / f"{k:05d}.png", rgb)
            progress.update(task, advance=1, stats=f"bird's-eye {j}")
    if reused:
        print(f"reference renders: {reused} additional views reused from {store.dir if store is not None else ''}")
    return {"extra_indices": kept, "dropped_outside_box": outside, "dropped_empty": empty,
            "render_seconds": round(time.perf_counter() - t0, 2)}


def render_augmented_views(train: ImageSet, world: WorldFrame, render_fn: RenderFn, ref_key: str,
                           dataset: str, cache_root: Path, config: AugmentConfig,
                           enhancer: Optional[ViewEnhancer] = None, scene_box: Optional[Tensor] = None,
                           depth_along: str = "z", render_cameras: Optional[Cameras] = None,
                           render_pixels: Optional[PixelRenderFn] = None, render_workers: int = 1) -> AugmentedViews:
    """Render (or reuse from the cache) the composites and the additional views. ``world``: the
    dataset's up vector and metric scale (its ``DataparserOutputs``). ``render_cameras``: the training
    cameras at the poses the reference renders the input views from (its refined poses; the
    ``ref_key``'s checkpoint hash keys them); None: ``train``'s own. The additional cameras (every view
    family of ``config.views``, in that order: augment/views.py) and the returned image sets keep
    ``train``'s poses; the additional views' poses are those the manifest saved. ``render_pixels``:
    the reference's renderer of some pixels (composites render only those they take); ``render_workers``:
    :attr:`Reference.render_workers`."""
    views = additional_views(train.cameras, world, config)
    bev = views.cameras if views is not None else None
    has_transient = "transient" in train.masks and config.composites
    enhancer_key = enhancer.cache_key() if enhancer is not None else "none"
    key = cache_key(ref_key, dataset, asdict(config), bev, train.cameras, enhancer_key)
    cache_dir = Path(cache_root) / CACHE_DIR_NAME / key
    reused = config.use_cache and (cache_dir / "manifest.json").is_file()
    if not reused:
        work = cache_dir.with_name(f".tmp-{key}-{os.getpid()}")
        shutil.rmtree(work, ignore_errors=True)
        comp_idx = [i for i in range(len(train)) if has_transient and bool(train.mask("transient", i).any())]
        seen_from = train if render_cameras is None else replace(train, cameras=render_cameras)
        store = ViewStore(cache_root, ref_key, config.appearance, read=config.use_cache) if bev is not None else None
        if store is not None and config.use_cache:
            store.add_entries(dataset, bev, config.view_downscale)
        try:
            done = _render_entry(work, seen_from, bev, render_fn, config, enhancer, comp_idx, scene_box, depth_along,
                                 views.sources if views is not None else None, render_pixels, store, render_workers)
        except BaseException:  # a bad model or an interrupt: no half-made entry left behind
            shutil.rmtree(work, ignore_errors=True)
            raise
        kept = done["extra_indices"]
        CacheManifest(reference=ref_key, dataset=dataset, config=asdict(config), enhancer=enhancer_key,
                      composited_images=comp_idx, num_extra=len(kept),
                      extra_camera_to_worlds=bev[torch.tensor(kept, dtype=torch.long)].camera_to_worlds.cpu().tolist() if kept else [],
                      extra_families=[views.families[j] for j in kept] if views is not None else [],
                      extra_sources=[views.sources[j] for j in kept] if views is not None else [],
                      **done).write(work)
        if cache_dir.exists():
            shutil.rmtree(cache_dir)
        os.replace(work, cache_dir)
    manifest = read_manifest(cache_dir)
    dropped = manifest.dropped_outside_box + manifest.dropped_empty
    if dropped:
        what = "bird's-eye" if views is None or set(views.families) == {"birds-eye"} else "additional"
        warn(f"{dropped} of {dropped + manifest.num_extra} {what} views dropped",
             f"never trained on: {manifest.dropped_outside_box} outside the scene box (lower --augment.delta-h), "
             f"{manifest.dropped_empty} mostly empty renders (coverage < {config.min_coverage})")
    if bev is not None:  # the views kept, at the poses they were rendered from
        bev = bev[torch.tensor(manifest.extra_indices, dtype=torch.long)]
        if manifest.num_extra:
            bev = bev.with_poses(manifest.extra_poses(bev.camera_to_worlds.dtype).to(bev.camera_to_worlds.device))
    with_conf = config.confidence != "none"
    composites = None
    if manifest.composited_images:
        images = [train.image(i).cpu() for i in range(len(train))]
        for i in manifest.composited_images:
            images[i] = load_png(manifest.composite_png(i))
        composites = train.to("cpu").with_images(images)
        if config.composite_loss == "either":
            composites = composites.with_photos(train.pixels.cpu(), config.composite_loss_margin)
        if with_conf:
            ones = [torch.ones(*train.hw(i), 1) for i in range(len(train))]
            composites = composites.with_confidence(
                [load_confidence(manifest.composite_png(i)) if i in manifest.composited_images else ones[i] for i in range(len(train))])
    extra = extra_raw = None
    if manifest.num_extra:
        assert bev is not None
        imgs = [load_png(manifest.extra_png(j)) for j in range(manifest.num_extra)]
        extra_raw = [load_png(manifest.extra_png(j, raw=True)) for j in range(manifest.num_extra)]
        extra = ImageSet.from_images(bev.to("cpu"), imgs, weights=torch.full((len(imgs),), float(config.extra_weight)),
                                     names=_extra_names(manifest))
        if with_conf or config.drop_outside_box:
            extra = extra.with_confidence([load_confidence(manifest.extra_png(j)) for j in range(manifest.num_extra)])
    return AugmentedViews(composites, extra, extra_raw, cache_dir, reused, manifest)


def _extra_names(manifest: CacheManifest) -> list[str]:
    """The additional views' image names: ``bev_00003`` (the bird's-eye family's, as before the
    families), ``lane-shift_00004``: the family and the view's place in the list."""
    families = manifest.extra_families or ["birds-eye"] * manifest.num_extra
    return [f"bev_{j:05d}" if f == "birds-eye" else f"{f}_{j:05d}" for j, f in enumerate(families)]


class AugmentedDataManager(DataManager):
    """Any method's DataManager with the reference's composites and bird's-eye views as training data.

    It renders (or reads from the cache) once, at construction, then hands the views to ``inner``
    through the DataManager's own hooks (:meth:`DataManager.set_train_images` /
    :meth:`DataManager.set_extra_images`), so ``inner`` keeps sampling exactly as it always does and
    the model only ever sees ``next_train`` batches. Everything else delegates to ``inner``; the
    checkpoint state is ``inner``'s, so a run resumes with or without this wrapper.
    """

    def __init__(self, inner: DataManager, reference: Reference, augment: AugmentConfig,
                 enhancer: Optional[ViewEnhancer] = None, total_steps: Optional[int] = None) -> None:
        # no DataManager.__init__: the dataset is inner's, parsed once
        if not 0.0 < augment.real_only_from <= 1.0:
            raise ConfigError(f"must be in (0, 1], got {augment.real_only_from}", "--augment.real-only-from")
        if not 0.0 <= augment.extra_decay_floor <= 1.0:
            raise ConfigError(f"must be in [0, 1], got {augment.extra_decay_floor}", "--augment.extra-decay-floor")
        if augment.confidence == "footprint" and not augment.confidence_footprint_ratio > 1.0:
            raise ConfigError(f"must be > 1, got {augment.confidence_footprint_ratio}", "--augment.confidence-footprint-ratio")
        self.real_only_step: Optional[int] = (
            int(round(augment.real_only_from * total_steps)) if total_steps is not None and augment.real_only_from < 1.0 else None)
        # --augment.extra-decay: the share falls to 0 at this step (None: it stays)
        self.decay_end: Optional[int] = (self.real_only_step or total_steps) if augment.extra_decay else None
        self.full_extra_prob = 0.0
        self.inner = inner
        self.reference = reference
        self.augment = augment
        self.every_n = max(augment.every_n, 1)
        self.original_train_images: ImageSet = inner.train_images
        if augment.composites and "transient" not in inner.train_images.masks:
            warn("the dataset has no transient masks", "input-view composites are off (only the bird's-eye views are added)")
        td = inner.train_data
        refined = reference.train_cameras(inner.train_images.cameras) if reference.train_cameras is not None else None
        self.views: AugmentedViews = render_augmented_views(
            inner.train_images, td, reference.render, reference.key, dataset_fingerprint(td.image_filenames),
            reference.cache_root, augment, enhancer, td.scene_box, reference.depth_along, refined, reference.render_pixels,
            reference.render_workers,
        )
        print(f"reference renders: {self.views.render_seconds:.1f} s" + (" (reused from the cache)" if self.views.reused else ""))
        if self.views.composites is not None:
            inner.set_train_images(self.views.composites)
        if augment.reference_sky:
            sky = reference_sky_masks(reference.render, refined if refined is not None else inner.train_images.cameras,
                                      td.up, reference.key, Path(reference.cache_root) / CACHE_DIR_NAME)
            inner.set_train_images(with_sky(inner.train_images, sky))
        if self.views.extra is not None:
            families = self.views.manifest.extra_families or ["birds-eye"] * len(self.views.extra)
            prob, view_probs = extra_sampling(families, len(inner.train_images), augment)
            inner.set_extra_images(self.views.extra, prob, view_probs)
            self.full_extra_prob = prob

    def initial_points(self) -> Optional[tuple[Tensor, Tensor]]:
        """The reference's depth in the additional views, thinned where the sparse points leave gaps
        (:func:`nerf2gs_plugin.augment.seeds.views_seed_points`, ``--augment.seed-points``); None without them."""
        from nerf2gs_plugin.augment.seeds import views_seed_points

        if self.augment.seed_points <= 0 or self.views.extra is None or self.views.manifest is None:
            return None
        return views_seed_points(self.views.manifest, self.views.extra, self.reference.depth_along, self.inner.train_data,
                                 self.augment.seed_points, self.augment.seed_points_per_family, self.augment.view_downscale)

    @property
    def manifest(self) -> CacheManifest:
        assert self.views.manifest is not None
        return self.views.manifest

    # ------------------------------------------------------------------ the DataManager contract, by delegation
    @property
    def config(self):  # type: ignore[override]
        return self.inner.config

    @property
    def data(self) -> Path:  # type: ignore[override]
        return self.inner.data

    @property
    def device(self) -> torch.device:  # type: ignore[override]
        return self.inner.device

    @property
    def generator(self) -> torch.Generator:  # type: ignore[override]
        return self.inner.generator

    @property
    def train_data(self) -> DataparserOutputs:  # type: ignore[override]
        return self.inner.train_data

    @property
    def train_images(self) -> ImageSet:  # type: ignore[override]
        return self.inner.train_images

    @property
    def extra_images(self) -> Optional[ImageSet]:  # type: ignore[override]
        return self.inner.extra_images

    @property
    def extra_prob(self) -> float:  # type: ignore[override]
        return self.inner.extra_prob

    @property
    def all_train_cameras(self) -> Cameras:
        return self.inner.all_train_cameras

    def train_batch(self, i: int) -> dict[str, Any]:
        return self.inner.train_batch(i)

    def set_train_images(self, images: ImageSet) -> None:
        self.inner.set_train_images(images)

    def set_extra_images(self, images: Optional[ImageSet], prob: float, view_probs: Optional[Tensor] = None) -> None:
        self.inner.set_extra_images(images, prob, view_probs)

    def next_train(self, step: int) -> tuple[Any, dict[str, Any]]:
        if self.real_only_step is not None and step >= self.real_only_step:
            self.inner.extra_prob = 0.0  # the final phase: input views only (the draw still happens: streams stay aligned)
        elif self.decay_end:
            fall = (1.0 - self.augment.extra_decay_floor) * min(step / self.decay_end, 1.0)
            self.inner.extra_prob = self.full_extra_prob * (1.0 - fall)
        return self.inner.next_train(step)

    def next_eval(self, step: int) -> tuple[Cameras, dict[str, Any]]:
        return self.inner.next_eval(step)

    def eval_split_names(self) -> list[str]:
        return self.inner.eval_split_names()

    def eval_split(self, name: str) -> tuple[DataparserOutputs, ImageSet]:
        return self.inner.eval_split(name)

    def eval_images(self, name: str) -> Iterator[tuple[Cameras, dict[str, Any]]]:
        return self.inner.eval_images(name)

    def state_dict(self) -> dict:
        return self.inner.state_dict()

    def load_state_dict(self, state: dict) -> None:
        self.inner.load_state_dict(state)


def same_families(recorded: dict[str, Any], augment: AugmentConfig) -> bool:
    """Whether a manifest's plain config made the view families of ``augment`` (the names, in order,
    and the parameters of each one used; an entry from before the families: birds-eye alone)."""
    import json

    views = list(recorded.get("views", ["birds-eye"]))
    if views != list(augment.views):
        return False
    plain = json.loads(json.dumps(asdict(augment), default=str))
    return all(family_params(recorded, name) == family_params(plain, name) for family, name in FAMILY_FIELDS.items() if family in views)


def find_cached_extra_views(cache_root: Path, dataset: str, augment: AugmentConfig, num_views: int) -> Optional[CacheManifest]:
    """The newest cache entry under a reference run whose additional views are those of ``augment``
    for ``num_views`` cameras of its families (some may have been dropped: ``extra_indices``), or None."""
    for manifest in cache_manifests(cache_root):
        same = (manifest.dataset == dataset and manifest.geometry == ViewGeometry.of(augment)
                and same_families(manifest.config, augment))
        if same and manifest.num_extra == len(manifest.extra_indices) and all(0 <= i < num_views for i in manifest.extra_indices):
            return manifest
    return None
