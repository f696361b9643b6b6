"""``ns2gs-bench field``: the hash-grid encoding's C++/OpenMP CPU kernel against the torch reference.

Forward+backward (w.r.t. the table) throughput in points per second of both backends on the same
points in one run (their ratio is what matters on a shared machine), for StreetNeRF's default grid
(12 levels x 2^15 x 2 features up to 1024) and its proposal grid, plus the paper-scale grid at
``full`` scale. Points are street-like ray samples (coherent along rays, as in training), and the
two backends' outputs and gradients are compared on every configuration. Writes ``field.json``,
``field.md`` (with the machine) and ``field.png`` under ``out``.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any, Callable

import torch
from torch import Tensor

from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_bench.machine import machine_info, machine_line
from nerf2gs_plugin.fields.hash_encoding import HashGridSpec, grid_resolutions, hash_encode, load_kernel

GRIDS = {
    "default field (12x2^15, 16-1024)": HashGridSpec(12, 2, 15, 16, 1024),
    "proposal (5x2^14, 16-256)": HashGridSpec(5, 2, 14, 16, 256),
    "paper field (16x2^19, 16-4096)": HashGridSpec(16, 2, 19, 16, 4096),
}
SCALES = {
    "quick": {"points": 1024 * 24, "grids": list(GRIDS)[:2], "repeats": 3},
    "full": {"points": 1024 * 48, "grids": list(GRIDS), "repeats": 5},
}
TARGET_SPEEDUP = 5.0


def ray_points(n_points: int, samples_per_ray: int = 24, seed: int = 0) -> Tensor:
    """``[n_points, 3]`` in [0,1]^3: samples along random rays from near the grid centre, ordered ray
    by ray like a NeRF batch (memory access is then as coherent as in training)."""
    g = torch.Generator().manual_seed(seed)
    rays = max(n_points // samples_per_ray, 1)
    origins = 0.5 + (torch.rand(rays, 3, generator=g) - 0.5) * torch.tensor([0.4, 0.1, 0.02])
    dirs = torch.nn.functional.normalize(torch.randn(rays, 3, generator=g), dim=-1)
    t = torch.sort(torch.rand(rays, samples_per_ray, generator=g) * 0.45, -1).values
    pts = origins[:, None] + dirs[:, None] * t[..., None]
    return pts.reshape(-1, 3)[:n_points].clamp(0.0, 1.0).contiguous()


def _step(x: Tensor, table: Tensor, res: list[int], grad: Tensor, backend: str) -> Callable[[], tuple[Tensor, Tensor]]:
    def fn() -> tuple[Tensor, Tensor]:
        t = table.detach().clone().requires_grad_(True)
        out = hash_encode(x, t, res, backend=backend)
        (out * grad).sum().backward()
        return out.detach(), t.grad

    return fn


def _time(fn: Callable[[], Any], repeats: int) -> tuple[float, float, Any]:
    """Best wall and process-CPU time of ``repeats`` runs after a warm-up."""
    out = fn()
    best, best_cpu = math.inf, math.inf
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best, best_cpu = min(best, time.perf_counter() - t0), min(best_cpu, time.process_time() - c0)
    return best, best_cpu, out


def run(out: Path, scale: str = "quick") -> dict[str, Any]:
    """Run the benchmark at ``scale`` (``quick`` or ``full``) and write the results under ``out``."""
    cfg = SCALES[scale]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    have_cpu = load_kernel() is not None
    compile_s = time.perf_counter() - t0
    x = ray_points(cfg["points"])
    rows: list[dict[str, Any]] = []
    for name in cfg["grids"]:
        spec = GRIDS[name]
        g = torch.Generator().manual_seed(1)
        table = (torch.rand(spec.num_levels, 2**spec.log2_table_size, spec.features_per_level, generator=g) * 2 - 1) * 1e-2
        res = grid_resolutions(spec.num_levels, spec.base_res, spec.max_res)
        grad = torch.randn(x.shape[0], spec.num_levels, spec.features_per_level, generator=g)
        row: dict[str, Any] = {"grid": name, "points": int(x.shape[0]), "levels": spec.num_levels,
                               "table_size": 2**spec.log2_table_size}
        row["torch_s"], row["torch_cpu_s"], (ref_out, ref_grad) = _time(_step(x, table, res, grad, "torch"), 1)
        if have_cpu:
            row["cpu_s"], row["cpu_cpu_s"], (out_c, grad_c) = _time(_step(x, table, res, grad, "cpu"), cfg["repeats"])
            row["max_abs_diff_values"] = float((out_c - ref_out).abs().max())
            row["max_abs_diff_grads"] = float((grad_c - ref_grad).abs().max())
            row["speedup"] = row["torch_s"] / row["cpu_s"]
            row["speedup_cpu_time"] = row["torch_cpu_s"] / row["cpu_cpu_s"]
            row["cpu_points_per_s"] = row["points"] / row["cpu_s"]
        row["torch_points_per_s"] = row["points"] / row["torch_s"]
        rows.append(row)
    result = {"scale": scale, "machine": machine_info(), "threads": torch.get_num_threads(), "load_average": os.getloadavg(),
              "compile_or_load_s": compile_s, "kernel_available": have_cpu, "rows": rows, "target_speedup": TARGET_SPEEDUP}
    atomic_write_text(out / "field.json", json.dumps(result, indent=2))
    atomic_write_text(out / "field.md", _markdown(result))
    _chart(result, out / "field.png")
    return result


def _fmt(v: Any, spec: str) -> str:
    return format(v, spec) if isinstance(v, (int, float)) and math.isfinite(v) else "-"


def _markdown(r: dict[str, Any]) -> str:
    lines = [
        "# Hash-grid encoding: cpu (C++/OpenMP) vs torch reference",
        "",
        f"Machine: {machine_line(r['machine'])}; {r['threads']} torch threads; scale `{r['scale']}`; "
        f"load average at the end {', '.join(f'{v:.1f}' for v in r['load_average'])} (a shared machine: wall times are inflated).",
        "Forward + backward w.r.t. the table on street-like ray samples (ordered ray by ray), both backends in the",
        f"same run; best of repeats; speedup from wall time and from process CPU time (target >= {r['target_speedup']:.0f}x).",
        "",
        "| grid | points | cpu fwd+bwd (s) | torch fwd+bwd (s) | speedup (wall / CPU time) | cpu M points/s | max diff values / grads |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for row in r["rows"]:
        lines.append(
            f"| {row['grid']} | {row['points']:,} | {_fmt(row.get('cpu_s'), '.3f')} | {_fmt(row.get('torch_s'), '.3f')} | "
            f"{_fmt(row.get('speedup'), '.1f')}x / {_fmt(row.get('speedup_cpu_time'), '.1f')}x | "
            f"{_fmt(row.get('cpu_points_per_s', math.nan) / 1e6, '.2f')} | "
            f"{_fmt(row.get('max_abs_diff_values'), '.1e')} / {_fmt(row.get('max_abs_diff_grads'), '.1e')} |"
        )
    if not r["kernel_available"]:
        lines += ["", "The C++ kernel could not be built on this machine: only the reference was timed."]
    return "\n".join(lines + [""])


def _chart(r: dict[str, Any], path: Path) -> None:
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    rows = r["rows"]
    x = range(len(rows))
    fig, ax = plt.subplots(figsize=(max(5, 2.2 * len(rows) + 1), 3.5))
    ax.bar([i - 0.2 for i in x], [row.get("cpu_points_per_s", 0) / 1e6 for row in rows], 0.4, label="cpu (C++)")
    ax.bar([i + 0.2 for i in x], [row["torch_points_per_s"] / 1e6 for row in rows], 0.4, label="torch reference")
    for i, row in enumerate(rows):
        if "speedup" in row:
            ax.text(i, row["cpu_points_per_s"] / 1e6, f"{row['speedup']:.0f}x", ha="center", va="bottom")
    ax.set_xticks(list(x), [row["grid"].replace(" (", "\n(") for row in rows], fontsize=8)
    ax.set_ylabel("fwd+bwd M points/s")
    ax.set_title("Hash-grid encoding on the CPU")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
