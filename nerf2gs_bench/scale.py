"""``ns2gs-bench scale``: how training cost grows with the scene, and what a 1 km street would cost.

Datasets: the synthetic street made longer by stitching ``n`` streets (seeds ``0..n-1``, 30
frames each over a 48 m drive) one after another along x, ``SEGMENT_SPACING`` metres apart (each
street is a closed canyon, so no view sees its neighbours): 1, 2, 4, 8 streets = 30, 60, 120, 240
frames at 200x112; and 2 streets at 400x224 read at downscale 4, 2, 1 (100x56, 200x112, 400x224).
Per method (StreetNeRF, Splatfacto) and dataset, a fresh process (so its peak RSS is its own)
trains with the registered config for ``warmup + measure`` steps and times the last ``measure``:
time per step, peak RSS of the process, primitives and checkpoint size. These are the first steps
of a run: a Splatfacto model still holds its sparse points (densification starts at step 300).

Fits (least squares, residual stated): Splatfacto time per step ``a + b * pixels + c * primitives``,
StreetNeRF a constant (a fixed ray batch per step); peak RSS ``r0 + r1 * images * pixels``. The
projection for a 1 km street at 1920x1080 (625 frames at the synthetic drive's 0.625 frames per
metre, the sparse points' density per metre) takes the steps a run needs from the registered
recipes (Splatfacto: one image per step, steps proportional to images; StreetNeRF: a fixed ray
batch per step, steps proportional to images x pixels), on one machine as one run vs
``BLOCKS`` blocks with 20% overlap (ns2gs-data partition), one after another or one per machine.
"""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np

from nerf2gs_bench.runner import fmt, write_bench_files
from nerf2gs_bench.machine import machine_info
from nerf2gs_plugin.utils.io import atomic_write_text

SEGMENT_FRAMES = 30
SEGMENT_DRIVE_M = 48.0  # the synthetic street's default drive: x in [-24, 24] m
SEGMENT_SPACING = 120.0  # metres between stitched streets (72 m canyon + end blocks + margin)
SEGMENT_POINTS = 4000
METHODS = ("streetnerf", "splatfacto")
STEPS = {"streetnerf": (3, 12), "splatfacto": (10, 40)}  # (warm-up, measured)
RECIPE_IMAGES = 60  # the registered step counts are for the 60-image street at 200x112
RECIPE_PIXELS = 200 * 112
TARGET = {"length_m": 1000.0, "width": 1920, "height": 1080}
BLOCKS = 10
OVERLAP = 0.2


@dataclass
class Job:
    method: str
    data: str
    downscale: float
    images: int
    width: int
    height: int
    warmup: int
    measure: int
    run_root: str
    sweep: str


# ---------------------------------------------------------------------------- datasets
def _segment(root: Path, seed: int, width: int, height: int) -> Path:
    from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street

    out = root / f"segments_{width}x{height}" / f"seg_{seed}"
    if not (out / "transforms.json").is_file():
        generate_street(SynthStreetConfig(out=out, seed=seed, width=width, height=height, num_train=SEGMENT_FRAMES,
                                          num_street=2, num_bev=2, num_val_street=0, num_val_bev=0, spp=1,
                                          num_points=SEGMENT_POINTS, progress=False, overwrite=True))
    return out


def long_street(root: Path, segments: int, width: int, height: int) -> Path:
    """``segments`` synthetic streets stitched along x as one nerfstudio dataset (files referenced, not copied)."""
    from nerf2gs_plugin.data.ply import read_ply_points, write_ply_points

    out = root / f"street_{segments}x_{width}x{height}"
    out.mkdir(parents=True, exist_ok=True)
    frames, evals, pts, cols, meta = [], {}, [], [], None
    for k in range(segments):
        seg = _segment(root, k, width, height)
        meta = json.loads((seg / "transforms.json").read_text())
        shift = k * SEGMENT_SPACING
        rel = os.path.relpath(seg, out)

        def moved(fr: dict) -> dict:
            fr = {key: (f"{rel}/{v}" if key.endswith("_path") else v) for key, v in fr.items()}
            m = [list(r) for r in fr["transform_matrix"]]
            m[0][3] += shift
            return {**fr, "transform_matrix": m}

        frames += [moved(f) for f in meta["frames"]]
        for split, entries in meta["eval_splits"].items():
            evals.setdefault(split, []).extend(moved(f) for f in entries)
        xyz, rgb = read_ply_points(seg / meta["ply_file_path"])
        pts.append(xyz + np.array([shift, 0.0, 0.0], dtype=xyz.dtype))
        cols.append(rgb)
    write_ply_points(out / "sparse_pc.ply", np.concatenate(pts), np.concatenate(cols))
    doc = {k: v for k, v in meta.items() if k not in ("frames", "eval_splits", "synthetic_street", "ply_file_path")}
    doc.update(frames=frames, eval_splits=evals, ply_file_path="sparse_pc.ply")
    atomic_write_text(out / "transforms.json", json.dumps(doc))
    return out


def plan(root: Path) -> list[Job]:
    jobs = []
    for method in METHODS:
        warm, meas = STEPS[method]
        for n in (1, 2, 4, 8):
            data = long_street(root, n, 200, 112)
            jobs.append(Job(method, str(data), 1.0, n * SEGMENT_FRAMES, 200, 112, warm, meas, str(root / "runs"), "images"))
        data = long_street(root, 2, 400, 224)
        for ds in (4.0, 2.0, 1.0):
            jobs.append(Job(method, str(data), ds, 2 * SEGMENT_FRAMES, int(400 / ds), int(224 / ds), warm, meas,
                            str(root / "runs"), "resolution"))
    return jobs


# ---------------------------------------------------------------------------- one measurement
def measure(job: Job) -> dict[str, Any]:
    """Train ``job`` for warm-up + measured steps in this (fresh) process; time the measured ones."""
    import dataclasses

    import torch

    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    torch.set_num_threads(1)
    cfg = get_method(job.method).config
    dm = cfg.pipeline.datamanager
    dm = dataclasses.replace(dm, dataparser=dataclasses.replace(dm.dataparser, downscale=job.downscale))
    steps = job.warmup + job.measure
    name = f"{job.method}_{Path(job.data).name}_ds{job.downscale:g}"
    cfg = dataclasses.replace(cfg, data=Path(job.data), output_dir=Path(job.run_root), timestamp=name, max_num_iterations=steps,
                              steps_per_save=steps, steps_per_eval_image=0, progress=False, device="cpu",
                              pipeline=dataclasses.replace(cfg.pipeline, datamanager=dm))
    import shutil

    shutil.rmtree(cfg.get_run_dir(), ignore_errors=True)
    t0 = time.perf_counter()
    trainer = Trainer(cfg)
    trainer.setup()
    stamps: list[float] = []
    trainer.step_hooks.append(lambda step: stamps.append(time.perf_counter()))
    run_dir = trainer.train()
    per_step = (stamps[-1] - stamps[job.warmup - 1]) / job.measure
    ckpt = next((run_dir / "checkpoints").glob("step-*.ckpt"))
    size = trainer.pipeline.model.size_report()
    return {**dataclasses.asdict(job), "pixels": job.width * job.height, "seconds_per_step": per_step,
            "peak_rss_mb": peak_rss_mb(), "primitives": size["primitives"],
            "parameters": size["parameters"], "model_mb": size["megabytes"], "checkpoint_mb": ckpt.stat().st_size / 2**20,
            "wall_s": time.perf_counter() - t0, "load_average": os.getloadavg()[0]}


def peak_rss_mb() -> float:
    """This process's peak resident set (``VmHWM``: reset at exec, unlike ``ru_maxrss``, which a
    spawned child inherits from the parent that forked it)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    raise OSError("no VmHWM in /proc/self/status")


# ---------------------------------------------------------------------------- fits and projection
def fit(rows: list[dict], target: str, features: list[str]) -> dict[str, Any]:
    """Least squares ``target ~ c0 + sum c_i * feature_i``; residual as RMS and max relative error."""
    X = np.array([[1.0] + [float(r[f]) for f in features] for r in rows])
    y = np.array([float(r[target]) for r in rows])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    pred = X @ coef
    rel = (pred - y) / y
    return {"target": target, "terms": ["1", *features], "coef": [float(c) for c in coef],
            "rms_relative_residual": float(np.sqrt(np.mean(rel ** 2))), "max_relative_residual": float(np.abs(rel).max())}


def predict(law: dict, **values: float) -> float:
    return law["coef"][0] + sum(c * values[t] for c, t in zip(law["coef"][1:], law["terms"][1:]))


def laws(rows: list[dict]) -> dict[str, dict]:
    out = {}
    for method in METHODS:
        rs = [dict(r, image_pixels=r["images"] * r["pixels"]) for r in rows if r["method"] == method]
        if len(rs) < 3:
            continue
        # Splatfacto rasterises one image per step; StreetNeRF a fixed ray batch (no term in the image)
        # memory: the images held in memory (the initial primitives, a few MB, grow with the images too:
        # a term of their own would only split one slope between two collinear columns)
        time_terms = ["pixels", "primitives"] if method == "splatfacto" else []
        out[method] = {"time": fit(rs, "seconds_per_step", time_terms), "rss": fit(rs, "peak_rss_mb", ["image_pixels"])}
    return out


def projection(rows: list[dict], fitted: dict[str, dict], recipe_steps: dict[str, int]) -> dict[str, Any]:
    """A ``TARGET`` street on this machine: one run vs ``BLOCKS`` blocks (20% overlap)."""
    images = TARGET["length_m"] / SEGMENT_DRIVE_M * SEGMENT_FRAMES
    pixels = TARGET["width"] * TARGET["height"]
    prims = TARGET["length_m"] / SEGMENT_DRIVE_M * SEGMENT_POINTS
    out: dict[str, Any] = {"images": images, "pixels": pixels, "sparse_points": prims, "blocks": BLOCKS, "overlap": OVERLAP}
    for method, law in fitted.items():
        per = {}
        for label, n_img, n_prim in (("one run", images, prims),
                                     ("per block", images / BLOCKS * (1 + 2 * OVERLAP), prims / BLOCKS * (1 + 2 * OVERLAP))):
            scale = n_img / RECIPE_IMAGES * (pixels / RECIPE_PIXELS if method == "streetnerf" else 1.0)
            steps = recipe_steps[method] * scale
            t = predict(law["time"], pixels=pixels, primitives=n_prim)
            per[label] = {"images": n_img, "steps": steps, "seconds_per_step": t, "hours": steps * t / 3600,
                          "peak_rss_gb": predict(law["rss"], image_pixels=n_img * pixels, primitives=n_prim) / 1024}
        per["blocks one after another, hours"] = per["per block"]["hours"] * BLOCKS
        per["blocks one per machine, hours"] = per["per block"]["hours"]
        out[method] = per
    return out


# ---------------------------------------------------------------------------- output
def markdown(rows: list[dict], fitted: dict, proj: dict) -> str:
    lines = ["Time per step after warm-up (fresh process, 1 thread), peak RSS of that process, model size:", "",
             "| method | sweep | images | resolution | s/step | peak RSS MB | primitives | checkpoint MB | load avg |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['method']} | {r['sweep']} | {r['images']} | {r['width']}x{r['height']} | {fmt(r['seconds_per_step'], 4)} | "
                     f"{fmt(r['peak_rss_mb'], 0)} | {r['primitives']:,} | {fmt(r['checkpoint_mb'], 2)} | {fmt(r['load_average'], 1)} |")
    lines += ["", "Fitted laws (least squares over the rows of each method; residual = RMS / max relative error):", ""]
    for method, law in fitted.items():
        for what, f in law.items():
            terms = " + ".join(f"{c:.4g}" + ("" if t == "1" else f" * {t}") for c, t in zip(f["coef"], f["terms"]))
            lines.append(f"- {method} {f['target']} = {terms} (residual {100 * f['rms_relative_residual']:.1f}% RMS, "
                         f"{100 * f['max_relative_residual']:.1f}% max)")
    lines += ["", f"Projection: a {TARGET['length_m']:g} m street at {TARGET['width']}x{TARGET['height']} "
              f"({proj['images']:.0f} frames, {proj['sparse_points']:,.0f} sparse points) on this machine, one run vs "
              f"{BLOCKS} blocks with {OVERLAP:.0%} overlap:", "",
              "| method | plan | images | steps | s/step | hours | peak RSS GB |", "|---|---|---|---|---|---|---|"]
    for method in fitted:
        for label in ("one run", "per block"):
            p = proj[method][label]
            lines.append(f"| {method} | {label} | {p['images']:.0f} | {p['steps']:,.0f} | {fmt(p['seconds_per_step'], 3)} | "
                         f"{fmt(p['hours'], 1)} | {fmt(p['peak_rss_gb'], 1)} |")
        lines.append(f"| {method} | {BLOCKS} blocks one after another | | | | {fmt(proj[method]['blocks one after another, hours'], 1)} | |")
    return "\n".join(lines)


def chart(rows: list[dict], path: Path) -> None:
    from nerf2gs_plugin.utils.plotting import pyplot, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for method, colour in zip(METHODS, ("tab:blue", "tab:orange")):
        img = sorted((r for r in rows if r["method"] == method and r["sweep"] == "images"), key=lambda r: r["images"])
        res = sorted((r for r in rows if r["method"] == method and r["sweep"] == "resolution"), key=lambda r: r["pixels"])
        axes[0].plot([r["images"] for r in img], [r["seconds_per_step"] for r in img], "o-", color=colour, label=method)
        axes[1].plot([r["pixels"] for r in res], [r["seconds_per_step"] for r in res], "o-", color=colour, label=method)
        axes[2].plot([r["images"] * r["pixels"] / 1e6 for r in img + res], [r["peak_rss_mb"] for r in img + res], "o",
                     color=colour, label=method)
    axes[0].set(xlabel="training images (200x112)", ylabel="s / step", xscale="log", title="time per step vs images")
    axes[1].set(xlabel="pixels per image (60 images)", ylabel="s / step", xscale="log", title="time per step vs resolution")
    sizes = sorted({(r["pixels"], f"{r['width']}x{r['height']}") for r in rows if r["sweep"] == "resolution"})
    for ax, ticks, labels in ((axes[0], [30, 60, 120, 240], ["30", "60", "120", "240"]),
                              (axes[1], [p for p, _ in sizes], [label for _, label in sizes])):
        ax.minorticks_off()
        ax.set_xticks(ticks, labels)
    axes[2].set(xlabel="images x pixels (M)", ylabel="peak RSS (MB)", title="peak memory")
    for ax in axes:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def measure_all(root: Path) -> list[dict]:
    """Every job of :func:`plan`, each in a fresh process, one at a time."""
    from nerf2gs_plugin.progress import make_progress

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    jobs = plan(root)
    rows = []
    with make_progress(True) as prog, ProcessPoolExecutor(1, mp_context=get_context("spawn"), max_tasks_per_child=1) as pool:
        task = prog.add_task("scale bench", total=len(jobs), stats="")
        for job in jobs:
            prog.update(task, stats=f"{job.method} {job.images} images {job.width}x{job.height}")
            rows.append(pool.submit(measure, job).result())
            prog.advance(task)
    return rows


def run(out: Path, runs_root: Path, refit: bool = False) -> dict[str, Any]:
    """Make the datasets, measure every job in its own process, fit, project, write ``scale.*``;
    ``refit``: keep the measured rows (and machine) of ``out/scale.json``, redo fits, projection and chart."""
    from nerf2gs_plugin.registry import get_method

    t0 = time.perf_counter()
    if refit:
        old = json.loads((Path(out) / "scale.json").read_text())
        rows, machine, seconds = old["rows"], old["machine"], old["bench_seconds"]
    else:
        rows, machine = measure_all(Path(runs_root) / "scale"), machine_info()
        seconds = time.perf_counter() - t0
    fitted = laws(rows)
    recipe = {m: get_method(m).config.max_num_iterations for m in METHODS}
    proj = projection(rows, fitted, recipe)
    payload = {"rows": rows, "laws": fitted, "projection": proj, "recipe_steps": recipe, "bench_seconds": seconds,
               "omp_num_threads": os.environ.get("OMP_NUM_THREADS", "1")}
    write_bench_files(out, "scale", "How training cost grows (synthetic street made longer, CPU)", payload,
                      markdown(rows, fitted, proj), machine)
    chart(rows, Path(out) / "scale.png")
    return payload
