"""``ns2gs-bench raster``: the 3DGS and 2DGS rasterizers' ``cpu`` kernels against the ``torch`` reference.

Random street-like scenes (road, two facades, clutter, in front of a car-height camera looking
down the street): forward+backward time of both backends on the same scene in one run (their
ratio is the figure that matters on a shared machine), forward-only FPS of a 50k-Gaussian model
at 200x112, and pixel x Gaussian pairs composited per second; the same for 2DGS surfels (the
same scene rendered as surfels). Writes ``raster.json``, ``raster.md`` (with the machine) and
``raster.png`` under ``out``.
"""

from __future__ import annotations

import json
import os
import math
import time
from pathlib import Path
from typing import Any, Callable, Optional

import torch

from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_bench.machine import machine_info, machine_line

SCALES = {
    # fwd+bwd scenes (gaussians, width, height); the torch reference runs only on those up to
    # torch_max_pixels x torch_max_gaussians (it takes minutes beyond, on a shared 2-core machine)
    "quick": {"fwdbwd": [(20_000, 200, 112), (20_000, 640, 360)], "fps": (50_000, 200, 112), "repeats": 5,
              "torch_max_pixels": 640 * 360, "torch_max_gaussians": 20_000,
              "surfels_fwdbwd": [(20_000, 200, 112)], "surfels_torch_max_pixels": 200 * 112},
    "full": {"fwdbwd": [(20_000, 200, 112), (20_000, 640, 360), (50_000, 200, 112), (200_000, 200, 112),
                        (200_000, 640, 360)], "fps": (50_000, 200, 112), "repeats": 5,
             "torch_max_pixels": 640 * 360, "torch_max_gaussians": 50_000,
             "surfels_fwdbwd": [(20_000, 200, 112), (43_000, 200, 112), (20_000, 640, 360)],
             "surfels_torch_max_pixels": 200 * 112},
}


def street_scene(n: int, width: int, height: int, seed: int = 0, sh_degree: int = 3) -> dict[str, Any]:
    """Random Gaussians shaped like a street seen from a car (OpenCV camera at the origin, y down)."""
    g = torch.Generator().manual_seed(seed)
    u = lambda *s: torch.rand(*s, generator=g)  # noqa: E731
    n_road, n_fac = n // 2, n // 3
    n_rest = n - n_road - n_fac
    road = torch.stack([u(n_road) * 14 - 7, 1.5 + u(n_road) * 0.05, 2 + u(n_road) * 48], -1)
    side = torch.where(u(n_fac) < 0.5, -7.0, 7.0)
    facade = torch.stack([side + u(n_fac) * 0.3, 1.5 - u(n_fac) * 10, 2 + u(n_fac) * 48], -1)
    clutter = torch.stack([u(n_rest) * 12 - 6, 1.5 - u(n_rest) * 3, 3 + u(n_rest) * 40], -1)
    means = torch.cat([road, facade, clutter])
    depth = means[:, 2:3]
    scales = (0.02 + 0.08 * u(n, 3)) * (depth / 10).clamp(0.5, 3)  # coarser far away, as trained models are
    quats = torch.nn.functional.normalize(torch.randn(n, 4, generator=g), dim=-1)
    opac = torch.sigmoid(torch.randn(n, generator=g) * 2)
    colors = torch.randn(n, (sh_degree + 1) ** 2, 3, generator=g) * 0.3
    f = 0.6 * width
    ks = torch.tensor([[[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]]])
    return {"means": means, "quats": quats, "scales": scales, "opacities": opac, "colors": colors,
            "viewmats": torch.eye(4)[None], "Ks": ks, "width": width, "height": height, "sh_degree": sh_degree}


Step = Callable[[dict[str, Any], str], Callable[[], dict[str, Any]]]  # (scene, backend) -> timed call returning meta


def _fwd_bwd(scene: dict[str, Any], backend: str) -> Callable[[], dict[str, Any]]:
    from nerf2gs_plugin.rendering import rasterize_gaussians  # noqa: PLC0415

    def step() -> dict[str, Any]:
        params = {k: scene[k].clone().requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors")}
        render, alpha, meta = rasterize_gaussians(**params, **{k: scene[k] for k in ("viewmats", "Ks", "width", "height", "sh_degree")},
                                                  render_mode="RGB+ED", backend=backend)
        (render.sum() + alpha.sum()).backward()
        return meta

    return step


def _forward_of(render_fn: Callable[..., tuple]) -> Step:
    """A forward-only timed call of ``rasterize_gaussians`` or ``rasterize_surfels`` (meta is last)."""

    def forward(scene: dict[str, Any], backend: str) -> Callable[[], dict[str, Any]]:
        def render() -> dict[str, Any]:
            with torch.no_grad():
                return render_fn(**scene, render_mode="RGB", backend=backend)[-1]

        return render

    return forward


def _surfels_fwd_bwd(scene: dict[str, Any], backend: str) -> Callable[[], dict[str, Any]]:
    from nerf2gs_plugin.rendering import rasterize_surfels  # noqa: PLC0415

    def step() -> dict[str, Any]:
        params = {k: scene[k].clone().requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors")}
        render, alpha, normals, _, distort, _, meta = rasterize_surfels(
            **params, **{k: scene[k] for k in ("viewmats", "Ks", "width", "height", "sh_degree")},
            render_mode="RGB+ED", backend=backend)
        (render.sum() + alpha.sum() + normals.sum() + distort.sum()).backward()
        return meta

    return step


def _sync() -> None:
    if torch.cuda.is_available():
        torch.cuda.synchronize()


def _time(fn: Callable[[], Any], repeats: int, cpu: Optional[list[float]] = None) -> tuple[float, Any]:
    """Best wall time of ``repeats`` runs after a warm-up; ``cpu`` receives the best process CPU time
    (all threads), which a loaded shared machine inflates far less than wall time. GPU work is
    synchronised before each clock read."""
    out = fn()  # warm-up (and compile on first use)
    best, best_cpu = math.inf, math.inf
    for _ in range(repeats):
        _sync()
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        _sync()
        best, best_cpu = min(best, time.perf_counter() - t0), min(best_cpu, time.process_time() - c0)
    if cpu is not None:
        cpu.append(best_cpu)
    return best, out


def _pairs(meta: dict[str, Any]) -> Optional[int]:
    """Pixel x Gaussian pairs a full (non-terminated) pass would visit: list length x tile pixels;
    None for a backend that does not report its lists (gsplat)."""
    if "n_pairs" in meta:
        listed = int(meta["n_pairs"])
    elif "flat_ids" in meta:
        listed = int(meta["flat_ids"].numel())
    else:
        return None
    return listed * int(meta["tile_size"]) ** 2


def _on(scene: dict[str, Any], device: str) -> dict[str, Any]:
    return {k: (v.to(device) if torch.is_tensor(v) else v) for k, v in scene.items()}


def _fwd_bwd_row(step: Step, n: int, w: int, h: int, fast: Optional[str], repeats: int, with_torch: bool,
                 device: str = "cpu") -> dict[str, Any]:
    """One fwd+bwd row: the ``fast`` backend (cpu or gsplat; None when unavailable) and the torch
    reference (only ``with_torch``: it is slow on a CPU) on the same street scene."""
    scene = _on(street_scene(n, w, h), device)
    row: dict[str, Any] = {"gaussians": n, "width": w, "height": h}
    if fast:
        cpu: list[float] = []
        row[f"{fast}_s"], meta = _time(step(scene, fast), repeats, cpu)
        row[f"{fast}_cpu_s"] = cpu[0]
        row["visible"] = int((meta["radii"] > 0).sum())
        row["pairs"] = _pairs(meta)
        if row["pairs"]:
            row[f"{fast}_pairs_per_s"] = row["pairs"] / row[f"{fast}_s"]
    if with_torch:
        cpu = []
        row["torch_s"], meta = _time(step(scene, "torch"), 1, cpu)
        row["torch_cpu_s"] = cpu[0]
        row["pairs"] = row.get("pairs") or _pairs(meta)
    if fast and f"{fast}_s" in row and "torch_s" in row:
        row["speedup"] = row["torch_s"] / row[f"{fast}_s"]
        row["speedup_cpu_time"] = row["torch_cpu_s"] / row[f"{fast}_cpu_s"]
    return row


def _forward_fps(forward: Step, size: tuple[int, int, int], fast: Optional[str], repeats: int,
                 device: str = "cpu") -> dict[str, Any]:
    """Forward-only frames per second of each backend on the street scene of ``size`` (n, w, h)."""
    n, w, h = size
    scene = _on(street_scene(n, w, h), device)
    fps: dict[str, Any] = {"gaussians": n, "width": w, "height": h}
    for backend in ([fast] if fast else []) + ["torch"]:
        cpu_t: list[float] = []
        sec, meta = _time(forward(scene, backend), repeats if backend == fast or device != "cpu" else 1, cpu_t)
        fps[f"{backend}_fps"] = 1.0 / sec
        fps[f"{backend}_cpu_s_per_frame"] = cpu_t[0]
        listed = _pairs(meta)
        if listed:
            fps.setdefault("pairs", listed)
            fps[f"{backend}_pairs_per_s"] = listed / sec
    return fps


def run(out: Path, scale: str = "quick", device: str = "cpu") -> dict[str, Any]:
    """Run the benchmark at ``scale`` (``quick`` or ``full``) and write the results under ``out``:
    ``raster.*`` on the CPU (cpu kernel vs torch), ``raster_cuda.*`` on a GPU (gsplat vs torch)."""
    from nerf2gs_plugin.rendering import rasterize_gaussians, rasterize_surfels  # noqa: PLC0415
    from nerf2gs_plugin.rendering.backend import fastest_backend  # noqa: PLC0415

    cfg = SCALES[scale]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    fast, surfel_fast = fastest_backend(device, "gaussians"), fastest_backend(device, "surfels")
    if device == "cuda":
        # the torch reference is fast enough on a GPU for every size
        torch_max_pixels = torch_max_gaussians = surfels_torch_max_pixels = math.inf
    else:
        torch_max_pixels, torch_max_gaussians = cfg["torch_max_pixels"], cfg["torch_max_gaussians"]
        surfels_torch_max_pixels = cfg["surfels_torch_max_pixels"]
    compile_s = time.perf_counter() - t0
    rows = [_fwd_bwd_row(_fwd_bwd, n, w, h, fast, cfg["repeats"],
                         n <= torch_max_gaussians and w * h <= torch_max_pixels, device)
            for n, w, h in cfg["fwdbwd"]]
    fps = _forward_fps(_forward_of(rasterize_gaussians), cfg["fps"], fast, cfg["repeats"] * 3, device)
    surfel_rows = [_fwd_bwd_row(_surfels_fwd_bwd, n, w, h, surfel_fast, max(2, cfg["repeats"] // 2),
                                w * h <= surfels_torch_max_pixels, device)
                   for n, w, h in cfg["surfels_fwdbwd"]]
    surfel_fps = _forward_fps(_forward_of(rasterize_surfels), cfg["fps"], surfel_fast, cfg["repeats"] * 2, device)
    result = {"scale": scale, "device": device, "fast_backend": fast or "none", "machine": machine_info(),
              "threads": torch.get_num_threads(), "load_average": os.getloadavg(),
              "compile_or_load_s": compile_s, "fwd_bwd": rows, "forward_fps": fps,
              "surfels_fwd_bwd": surfel_rows, "surfels_forward_fps": surfel_fps,
              "targets": {"speedup_fwd_bwd": 10.0, "fps_50k_200x112": 20.0}}
    stem = "raster" if device == "cpu" else f"raster_{device}"
    atomic_write_text(out / f"{stem}.json", json.dumps(result, indent=2))
    atomic_write_text(out / f"{stem}.md", _markdown(result))
    _chart(result, out / f"{stem}.png")
    return result


def _fmt(v: Any, spec: str) -> str:
    return format(v, spec) if isinstance(v, (int, float)) else "-"


_LABELS = {"cpu": "cpu (C++/OpenMP)", "gsplat": "gsplat (CUDA)", "none": "none available"}


def _markdown(r: dict[str, Any]) -> str:
    fast = r.get("fast_backend", "cpu")
    where = "on the GPU (CUDA tensors)" if r.get("device", "cpu") != "cpu" else "on the CPU"
    lines = [
        f"# Rasterizers (3DGS Gaussians, 2DGS surfels) {where}: {_LABELS.get(fast, fast)} vs torch reference",
        "",
        f"Machine: {machine_line(r['machine'])}; {r['threads']} torch threads; scale `{r['scale']}`; "
        f"load average at the end {', '.join(f'{v:.1f}' for v in r['load_average'])} (a shared machine: wall times are inflated).",
        "Forward+backward (RGB+expected depth, SH degree 3) on random street-like scenes, best of repeats,",
        "both backends in the same run; speedup from wall time and from process CPU time.",
        "Pairs = per-tile list entries x tile pixels (the work without early termination or row skipping).",
        "",
        *_table(r["fwd_bwd"], "Gaussians", fast),
        "",
        _fps_sentence(r["forward_fps"], "Gaussians", fast) + f" (target: {fast} >= {r['targets']['fps_50k_200x112']:.0f} FPS; "
        f"fwd+bwd speedup target >= {r['targets']['speedup_fwd_bwd']:.0f}x).",
        "",
    ]
    if r.get("surfels_fwd_bwd"):
        lines += [
            f"## 2DGS surfels: {_LABELS.get(fast, fast)} vs torch reference",
            "",
            "The same scenes as surfels; forward+backward of RGB+expected depth, normals and distortion.",
            "",
            *_table(r["surfels_fwd_bwd"], "surfels", fast),
            "",
            _fps_sentence(r["surfels_forward_fps"], "surfels", fast) + ".",
            "",
        ]
    return "\n".join(lines)


def _table(rows: list[dict[str, Any]], what: str, fast: str = "cpu") -> list[str]:
    """The markdown table of fwd+bwd rows; ``what`` names the primitives (Gaussians, surfels)."""
    lines = [
        f"| {what} | image | visible | pairs (M) | {fast} fwd+bwd (s) | torch fwd+bwd (s) | speedup (wall / CPU time) | {fast} pairs/s (M) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        lines.append(
            f"| {row['gaussians']:,} | {row['width']}x{row['height']} | {_fmt(row.get('visible'), ',')} | "
            f"{_fmt((row.get('pairs') or 0) / 1e6, '.1f')} | {_fmt(row.get(f'{fast}_s'), '.4f')} | {_fmt(row.get('torch_s'), '.3f')} | "
            f"{_fmt(row.get('speedup'), '.1f')}x / {_fmt(row.get('speedup_cpu_time'), '.1f')}x | "
            f"{_fmt(row[f'{fast}_pairs_per_s'] / 1e6, '.0f') if f'{fast}_pairs_per_s' in row else '-'} |"
        )
    return lines


def _fps_sentence(f: dict[str, Any], what: str, fast: str = "cpu") -> str:
    """The sentence on a forward-FPS result, without its closing punctuation (the 3DGS one adds targets)."""
    pairs = f.get(f"{fast}_pairs_per_s")
    pairs_txt = f"{pairs / 1e6:.0f} M pairs/s; " if pairs else ""
    return (f"Forward only, {f['gaussians']:,} {what} at {f['width']}x{f['height']}: "
            f"{fast} {_fmt(f.get(f'{fast}_fps'), '.1f')} FPS ({pairs_txt}"
            f"{_fmt(f.get(f'{fast}_cpu_s_per_frame', 0) * 1e3, '.0f')} ms of process CPU time per frame), "
            f"torch {_fmt(f.get('torch_fps'), '.2f')} FPS")


def _chart(r: dict[str, Any], path: Path) -> None:
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    fast = r.get("fast_backend", "cpu")
    groups = [("3DGS", row) for row in r["fwd_bwd"]] + [("2DGS", row) for row in r.get("surfels_fwd_bwd", [])]
    labels = [f"{kind} {row['gaussians'] // 1000}k\n{row['width']}x{row['height']}" for kind, row in groups]
    x = range(len(groups))
    fig, ax = plt.subplots(figsize=(max(5, 1.4 * len(groups) + 2), 3.5))
    ax.bar([i - 0.2 for i in x], [row.get(f"{fast}_s", 0) for _, row in groups], 0.4, label=_LABELS.get(fast, fast))
    ax.bar([i + 0.2 for i in x], [row.get("torch_s", 0) for _, row in groups], 0.4, label="torch reference")
    for i, (_, row) in enumerate(groups):
        if "speedup" in row:
            ax.text(i, max(row[f"{fast}_s"], row["torch_s"]), f"{row['speedup']:.0f}x", ha="center", va="bottom")
    ax.set_xticks(list(x), labels)
    ax.set_yscale("log")
    ax.set_ylabel("forward+backward (s)")
    where = "the GPU" if r.get("device", "cpu") != "cpu" else "the CPU"
    ax.set_title(f"Gaussian (3DGS) and surfel (2DGS) rasterization on {where}")
    ax.legend(loc="upper left")
    ax.margins(y=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
