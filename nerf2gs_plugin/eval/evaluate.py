"""Evaluate one trained run: per-split image quality, render speed and model size (ns2gs-eval)."""

from __future__ import annotations

import statistics
import time
from pathlib import Path
from typing import Optional

import torch

from nerf2gs_plugin.engine.reference import LoadedRun


def _mean_std(values: list[float]) -> tuple[Optional[float], Optional[float]]:
    if not values:
        return None, None
    return float(statistics.fmean(values)), float(statistics.pstdev(values)) if len(values) > 1 else 0.0


def measure_fps(model, camera, repeats: int = 5, warmup: int = 1) -> float:
    """Median render rate of one camera, warm-up excluded."""
    for _ in range(warmup):
        model.render_camera(camera)
    times = []
    for _ in range(repeats):
        if camera.device.type == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        model.render_camera(camera)
        if camera.device.type == "cuda":
            torch.cuda.synchronize()
        times.append(time.perf_counter() - t0)
    return 1.0 / statistics.median(times)


@torch.no_grad()
def evaluate_run(run: LoadedRun, splits: Optional[list[str]] = None, max_images: Optional[int] = None,
                 fps_repeats: int = 5, render_dir: Optional[Path] = None, lpips_model=None) -> dict:
    """nerfstudio ``ns-eval``-style results for every requested split (all the data has by default)."""
    from nerf2gs_plugin.eval.figures import save_eval_grid
    from nerf2gs_plugin.eval.metrics import LPIPS, psnr, ssim

    dm = run.pipeline.datamanager
    model = run.model
    model.eval()
    names = splits or dm.eval_split_names()
    lpips_model = lpips_model if lpips_model is not None else LPIPS.load_default(device=model.device)
    results: dict[str, dict] = {}
    fps = None
    for name in names:
        rows = {"psnr": [], "ssim": [], "lpips": []}
        shown = []
        for i, (camera, batch) in enumerate(dm.eval_images(name)):
            if max_images is not None and i >= max_images:
                break
            out = model.render_camera(camera)
            pred, gt = out["rgb"].clamp(0, 1), batch["image"]
            rows["psnr"].append(float(psnr(pred, gt)))
            rows["ssim"].append(float(ssim(pred, gt)))
            if lpips_model is not None:
                rows["lpips"].append(float(lpips_model(pred, gt)))
            if len(shown) < 4:
                shown.append((gt.cpu(), pred.cpu()))
        if fps is None:
            camera, _ = next(iter(dm.eval_images(name)))
            fps = measure_fps(model, camera, repeats=fps_repeats)
        entry: dict = {"num_images": len(rows["psnr"])}
        for metric, values in rows.items():
            mean, std = _mean_std(values)
            entry[metric], entry[f"{metric}_std"] = mean, std
        results[name] = entry
        if render_dir is not None and shown:
            save_eval_grid(Path(render_dir) / f"{name}.png", shown, title=f"{run.config.method_name} / {name}")
    return {
        "experiment_name": run.config.experiment_name or Path(run.config.data).name,
        "method_name": run.config.method_name,
        "checkpoint": str(run.checkpoint),
        "step": run.step,
        "results": results,
        "fps": fps,
        "size": model.size_report(),
        "train_seconds": run.train_seconds,
        "lpips_available": lpips_model is not None,
        "device": str(model.device),
    }
