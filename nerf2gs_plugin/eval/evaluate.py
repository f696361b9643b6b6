"""Evaluate one trained run: per-split image quality, render speed and model size (ns2gs-eval)."""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path
from typing import Optional

import torch

from nerf2gs_plugin.runs.load import LoadedRun
from nerf2gs_plugin.errors import ConfigError, DataError
from nerf2gs_plugin.eval.extrapolated import extrapolated_summary
from nerf2gs_plugin.eval.figures import save_eval_grid
from nerf2gs_plugin.eval.metrics import IMAGE_METRICS
from nerf2gs_plugin.utils.image_metrics import psnr
from nerf2gs_plugin.utils.lpips import LPIPS


def _mean_std(values: list[float]) -> tuple[Optional[float], Optional[float]]:
    if not values:
        return None, None
    return float(statistics.fmean(values)), float(statistics.pstdev(values)) if len(values) > 1 else 0.0


def masked_psnr(pred: torch.Tensor, gt: torch.Tensor, mask: torch.Tensor) -> Optional[float]:
    """PSNR over the pixels where ``mask`` ([H, W] bool) holds; None when it holds nowhere."""
    m = mask.to(pred.device)
    return float(psnr(pred[m], gt.to(pred.device)[m])) if bool(m.any()) else None


def transient_labelled(dm, split: str) -> list[bool]:
    """Per image of ``split``: whether a moving-object mask file exists for it (the image set gives an
    unlabelled image an all-false mask, which would pass it off as wholly static)."""
    outputs, _ = dm.eval_split(split)
    files = outputs.mask_filenames.get("transient")
    return [f is not None for f in files] if files else [False] * len(outputs)


def timed_render(model, camera) -> tuple[dict, float]:
    """``model.render_camera(camera)`` and its wall time (synchronised on CUDA)."""
    cuda = camera.device.type == "cuda"
    if cuda:
        torch.cuda.synchronize()
    t0 = time.perf_counter()
    out = model.render_camera(camera)
    if cuda:
        torch.cuda.synchronize()
    return out, time.perf_counter() - t0


def measure_fps(model, camera, repeats: int = 5, warmup: int = 1) -> float:
    """Median render rate of one camera, warm-up excluded."""
    for _ in range(warmup):
        model.render_camera(camera)
    times = [timed_render(model, camera)[1] for _ in range(max(1, repeats))]
    return 1.0 / statistics.median(times)


def check_result(result: dict) -> None:
    """A result worth writing: every split evaluated at least one image and its figures are finite
    (a DataError otherwise, so a good eval.json on disk is never replaced by nulls)."""
    for name, r in result["results"].items():
        if not r.get("num_images"):
            raise DataError(f"split '{name}' has no image to evaluate; nothing written")
        for metric in ("psnr", "ssim"):
            v = r.get(metric)
            if v is None or not math.isfinite(v):
                raise DataError(f"split '{name}': {metric} is {v} (non-finite render or image); nothing written")
    if not result["results"]:
        raise DataError("no split evaluated; nothing written")


@torch.no_grad()
def measure_from_above(run: LoadedRun, views: int = 16) -> dict:
    """Holes and near-camera floaters on the run's bird's-eye path (:mod:`nerf2gs_plugin.render.measures`):
    the views its augmentation trained on, else the fly-over at the augmentation's default height and
    pitch; at most ``views`` of them, evenly spaced along the path."""
    from nerf2gs_plugin.render.measures import measure_path
    from nerf2gs_plugin.render.paths import PathOptions, make_path
    from nerf2gs_plugin.render.scene import context_from_loaded_run

    ctx = context_from_loaded_run(run)
    opts = PathOptions()
    cams = make_path("birds-eye", ctx, opts)
    if len(cams) > views:
        cams = cams[torch.linspace(0, len(cams) - 1, views).round().long()]
    source = ctx.augment_source if ctx.augment_views is not None else f"fly-over {opts.height:g} m above the capture, {opts.pitch:g} deg down"
    return {**measure_path(run.model, cams, ctx.train, ctx.up, ctx.units_per_metre), "source": source}


@torch.no_grad()
def evaluate_run(run: LoadedRun, splits: Optional[list[str]] = None, max_images: Optional[int] = None,
                 fps_repeats: int = 5, render_dir: Optional[Path] = None, lpips_model=None, from_above_views: int = 0) -> dict:
    """nerfstudio ``ns-eval``-style results for every requested split (all the data has by default).

    Per split: PSNR/SSIM/LPIPS mean and std (LPIPS ``None`` when its weights are missing), PSNR over
    the ground-mask pixels (``psnr_ground``, ``None`` without ground masks), PSNR over the static pixels
    (outside the moving-object mask) of the images that have one (``static_psnr``, over
    ``static_psnr_images`` images; ``None`` without such masks) and the
    median render FPS of its images (the run's first render excluded as warm-up); top level: the
    median FPS of repeated renders of one camera, model size (primitives, parameters, MB of state
    and of the checkpoint file) and the training time recorded in the checkpoint. With
    ``from_above_views``: ``bev_hole_fraction`` and ``floater_fraction`` on that many bird's-eye views
    (:func:`measure_from_above`; no ground truth needed), details under ``from_above``."""
    if max_images is not None and max_images < 1:
        raise ConfigError(f"must be at least 1, got {max_images}", "--max-images")
    dm = run.pipeline.datamanager
    model = run.model
    model.eval()
    names = splits or dm.eval_split_names()
    if not names:
        raise DataError("the dataset has no eval splits (eval_splits in transforms.json or a split file)", dm.data)
    lpips_model = lpips_model if lpips_model is not None else LPIPS.load_default(device=model.device)
    results: dict[str, dict] = {}
    fps, fps_resolution = None, None
    warm = False
    for name in names:
        rows: dict[str, list[float]] = {**{metric: [] for metric in IMAGE_METRICS}, "lpips": [], "psnr_ground": [], "static_psnr": []}
        static_by_image: list[Optional[float]] = []
        shown, times, resolutions = [], [], []
        labelled = transient_labelled(dm, name)
        for i, (camera, batch) in enumerate(dm.eval_images(name)):
            if max_images is not None and i >= max_images:
                break
            out, seconds = timed_render(model, camera)
            if warm:  # the very first render of the run (allocations, JIT, caches) is not timed
                times.append(seconds)
            warm = True
            resolutions.append([int(camera.height[0]), int(camera.width[0])])
            pred, gt = out["rgb"].clamp(0, 1), batch["image"]
            for metric, fn in IMAGE_METRICS.items():
                rows[metric].append(float(fn(pred, gt)))
            ground = batch.get("ground_mask")
            if ground is not None and (v := masked_psnr(pred, gt, ground[..., 0])) is not None:
                rows["psnr_ground"].append(v)  # road + sidewalk only: where the paper's holes are
            moving = batch.get("transient_mask")
            v = masked_psnr(pred, gt, ~moving[..., 0]) if moving is not None and labelled[i] else None
            if v is not None:
                rows["static_psnr"].append(v)  # the scene without what moves: what a static model can get right
            static_by_image.append(v)
            if lpips_model is not None:
                rows["lpips"].append(float(lpips_model(pred, gt)))
            if len(shown) < 4:
                shown.append((gt.cpu(), pred.cpu()))
        if fps is None:
            camera, _ = next(iter(dm.eval_images(name)))
            fps = measure_fps(model, camera, repeats=fps_repeats)
            fps_resolution = [int(camera.height[0]), int(camera.width[0])]
        n_img = len(rows["psnr"])
        same = all(r == resolutions[0] for r in resolutions)
        # one [H, W] when every camera of the split has it, else None and see resolutions (per image)
        entry: dict = {"num_images": n_img, "resolution": resolutions[0] if resolutions and same else None,
                       "resolutions": resolutions, "fps": 1.0 / statistics.median(times) if times else None}
        for metric, values in rows.items():
            mean, std = _mean_std(values)
            entry[metric], entry[f"{metric}_std"] = mean, std
        entry["static_psnr_images"] = len(rows["static_psnr"])
        entry["psnr_per_image"] = rows["psnr"]  # in the split's order: a mean over few views hides one lost view
        if rows["static_psnr"]:
            entry["static_psnr_per_image"] = static_by_image  # the same order; None where a view has no labels
        results[name] = entry
        if render_dir is not None and shown:
            which = "all views" if len(shown) == n_img else f"views 1-{len(shown)} of {n_img}"
            save_eval_grid(Path(render_dir) / f"{name}.png", shown, title=f"{run.config.method_name} / {name}: {which}",
                           row_labels=[f"view {i + 1}/{n_img}" for i in range(len(shown))])
            entry["grid"] = {"path": str(Path(render_dir) / f"{name}.png"), "views": list(range(len(shown)))}
    above = measure_from_above(run, from_above_views) if from_above_views > 0 else None
    return {
        "experiment_name": run.config.experiment_name or Path(run.config.data).name,
        "method_name": run.config.method_name,
        "checkpoint": str(run.checkpoint),
        "step": run.step,
        "results": results,
        "extrapolated": extrapolated_summary(results),  # mean over bev_1, bev_2, lane_2, lane_4 (None without them)
        "fps": fps,
        "fps_resolution": fps_resolution,
        "size": {**model.size_report(), "checkpoint_megabytes": Path(run.checkpoint).stat().st_size / 2**20},
        "train_seconds": run.train_seconds,
        "lpips_available": lpips_model is not None,
        "device": str(model.device),
        **({"bev_hole_fraction": above["bev_hole_fraction"], "floater_fraction": above["floater_fraction"], "from_above": above}
           if above is not None else {}),
    }
