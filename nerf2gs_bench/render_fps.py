"""``ns2gs-bench render-fps``: how fast a splat model renders at a display resolution (1920x1080 by
default), the figure a user of gsplat compares: forward-only frames per second of 3DGS Gaussians and
2DGS surfels at several model sizes, and one forward+backward (a training step's rasterization) per
size. Street-like random scenes (:func:`nerf2gs_bench.raster.street_scene`), the fastest backend of
the device (gsplat on CUDA, the C++ kernels on the CPU). Writes ``render_fps_<device>.{json,md}``."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Optional, Sequence

import torch

from nerf2gs_bench.machine import machine_info, machine_line
from nerf2gs_bench.raster import _forward_of, _fwd_bwd, _on, _surfels_fwd_bwd, _time, street_scene
from nerf2gs_plugin.utils.io import atomic_write_text


def _row(kind: str, n: int, width: int, height: int, device: str, backend: str, repeats: int) -> dict[str, Any]:
    from nerf2gs_plugin.rendering import rasterize_gaussians, rasterize_surfels  # noqa: PLC0415

    if device == "cuda":  # the peak of this row alone (the previous row's scene is gone by now)
        torch.cuda.empty_cache()
        torch.cuda.reset_peak_memory_stats()
    scene = _on(street_scene(n, width, height), device)
    forward = _forward_of(rasterize_gaussians if kind == "3DGS" else rasterize_surfels)
    row: dict[str, Any] = {"kind": kind, "primitives": n, "width": width, "height": height, "backend": backend}
    try:
        sec, meta = _time(forward(scene, backend), repeats)
        row["fps"] = 1.0 / sec
        row["visible"] = int((meta["radii"] > 0).sum()) if "radii" in meta else None
        step_sec, _ = _time((_fwd_bwd if kind == "3DGS" else _surfels_fwd_bwd)(scene, backend), max(1, repeats // 3))
        row["fwd_bwd_ms"] = step_sec * 1e3
    except torch.cuda.OutOfMemoryError as e:  # the row says so; the larger sizes may not fit
        row["error"] = f"out of memory: {str(e).splitlines()[0]}"
    if device == "cuda":
        row["peak_gpu_mib"] = torch.cuda.max_memory_allocated() / 2**20
    return row


def run(out: Path, device: str = "cpu", width: int = 1920, height: int = 1080,
        counts: Sequence[int] = (100_000, 500_000, 1_000_000, 3_000_000),
        surfel_counts: Optional[Sequence[int]] = None, repeats: int = 20) -> dict[str, Any]:
    """Measure every size and write ``render_fps_<device>.{json,md}`` under ``out``; returns the document."""
    from nerf2gs_plugin.rendering.backend import fastest_backend  # noqa: PLC0415

    t0 = time.perf_counter()
    fast, surfel_fast = fastest_backend(device, "gaussians") or "torch", fastest_backend(device, "surfels") or "torch"
    surfel_counts = counts if surfel_counts is None else surfel_counts
    rows = [_row("3DGS", n, width, height, device, fast, repeats) for n in counts]
    rows += [_row("2DGS", n, width, height, device, surfel_fast, repeats) for n in surfel_counts]
    doc = {"device": device, "width": width, "height": height, "repeats": repeats, "rows": rows,
           "machine": machine_info(), "threads": torch.get_num_threads(), "seconds": time.perf_counter() - t0}
    if device == "cuda":
        doc["gpu"] = torch.cuda.get_device_name()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / f"render_fps_{device}.json", json.dumps(doc, indent=2))
    atomic_write_text(out / f"render_fps_{device}.md", markdown(doc))
    return doc


def markdown(doc: dict[str, Any]) -> str:
    gpu = f" ({doc['gpu']})" if doc.get("gpu") else ""
    lines = [f"# Splat render speed at {doc['width']}x{doc['height']} on {doc['device']}{gpu}", "",
             f"Machine: {machine_line(doc['machine'])}; {doc['threads']} torch threads.",
             "Random street-like scenes (road, facades, clutter seen from a car); forward = RGB only, best of "
             f"{doc['repeats']} after a warm-up; forward+backward = RGB + expected depth with gradients (one training "
             "step's rasterization).", "",
             "| kind | primitives | backend | visible | FPS | fwd+bwd (ms) | peak GPU MiB |", "|---|---:|---|---:|---:|---:|---:|"]
    for r in doc["rows"]:
        if "error" in r:
            lines.append(f"| {r['kind']} | {r['primitives']:,} | {r['backend']} | - | {r['error']} | - | - |")
            continue
        vis = f"{r['visible']:,}" if isinstance(r.get("visible"), int) else "-"
        peak = f"{r['peak_gpu_mib']:.0f}" if "peak_gpu_mib" in r else "-"
        lines.append(f"| {r['kind']} | {r['primitives']:,} | {r['backend']} | {vis} | {r['fps']:.1f} | {r['fwd_bwd_ms']:.1f} | {peak} |")
    return "\n".join(lines) + "\n"
