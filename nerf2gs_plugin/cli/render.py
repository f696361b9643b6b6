"""ns2gs-render RUN --path birds-eye|interpolate|orbit|lane-shift [--camera-path-file camera_path.json]
ns2gs-render compare RUN RUN ... --path birds-eye --labels A B ..."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import tyro

from nerf2gs_plugin.cli.common import run_cli
from nerf2gs_plugin.render.paths.registry import PathOptions
from nerf2gs_plugin.render.render_path import OutputOptions

PATH_HELP = "birds-eye, interpolate, orbit, lane-shift, or camera-path (with --camera-path-file)"


@dataclass
class RenderArgs:
    """Render a trained run (any method) along a camera path into an MP4 or PNG frames
    (``ns2gs-render compare RUN RUN ...``: several runs side by side; docs/render.md)."""

    run: tyro.conf.Positional[Path]
    """Run directory or .ckpt file."""
    path: str = "birds-eye"
    """Camera path: birds-eye, interpolate, orbit, lane-shift, or camera-path (with --camera-path-file)."""
    output: Optional[Path] = None
    """Output MP4 or PNG folder (default: RUN/renders/<path>.mp4 or RUN/renders/<path>/)."""
    device: str = "auto"
    """auto (CUDA when present, else CPU), cpu, cuda or cuda:N."""
    path_options: tyro.conf.OmitArgPrefixes[PathOptions] = field(default_factory=PathOptions)
    out: tyro.conf.OmitArgPrefixes[OutputOptions] = field(default_factory=OutputOptions)


@dataclass
class CompareArgs:
    """Several runs of one dataset side by side, on the same cameras, each under its label."""

    runs: tyro.conf.Positional[tuple[Path, ...]]
    """Run directories or .ckpt files (two or more, trained on the same dataset)."""
    labels: Optional[tuple[str, ...]] = None
    """One label per run (default: each run's method and folder name)."""
    path: str = "birds-eye"
    """Camera path: birds-eye, interpolate, orbit, lane-shift, or camera-path (with --camera-path-file)."""
    output: Optional[Path] = None
    """Output MP4 or PNG folder (default: FIRST_RUN/renders/compare-<path>.mp4 or .../compare-<path>/)."""
    device: str = "auto"
    """auto (CUDA when present, else CPU), cpu, cuda or cuda:N."""
    path_options: tyro.conf.OmitArgPrefixes[PathOptions] = field(default_factory=PathOptions)
    out: tyro.conf.OmitArgPrefixes[OutputOptions] = field(default_factory=OutputOptions)


def default_output(run_dir: Path, stem: str, out: OutputOptions) -> Path:
    return Path(run_dir) / "renders" / (f"{stem}.mp4" if out.output_format == "video" else stem)


def print_measures(results: list[dict]) -> None:
    for r in results:
        print(f"{r['label']}: holes {100 * r['bev_hole_fraction']:.2f}% of pixels (accumulation < 0.5), "
              f"near-camera floaters {100 * r['floater_fraction']:.3f}%, over {r['frames']} frames")


def render(args: RenderArgs | CompareArgs, compare: bool) -> Path:
    from nerf2gs_plugin.engine.trainer import pick_device
    from nerf2gs_plugin.errors import ConfigError
    from nerf2gs_plugin.render.render_path import check_same_dataset, load_runs, path_cameras, path_context, render_runs

    paths = list(args.runs) if compare else [args.run]
    if compare and len(paths) < 2:
        raise ConfigError("compare needs two or more runs")
    labels = None
    if compare:
        labels = list(args.labels) if args.labels else None
        if labels is not None and len(labels) != len(paths):
            raise ConfigError(f"--labels: {len(labels)} labels for {len(paths)} runs")
    runs = load_runs(paths, pick_device(args.device))
    if compare:
        check_same_dataset(runs, paths)
        labels = labels or [f"{r.method_name} {r.run_dir.name}" for r in runs]
    ctx = path_context(runs)
    cameras = path_cameras(ctx, args.path, args.path_options, args.out.downscale)
    kind = "camera-path" if args.path_options.camera_path_file is not None else args.path
    output = args.output or default_output(runs[0].run_dir, f"compare-{kind}" if compare else kind, args.out)
    results = render_runs(runs, labels, cameras, ctx, output, args.out, description=f"{'compare' if compare else 'render'} {kind}")
    if args.out.measure:
        print_measures(results)
    print(f"wrote {output} ({len(cameras)} frames)")
    return output


def main() -> None:
    argv = sys.argv[1:]
    if argv[:1] == ["compare"]:
        render(tyro.cli(CompareArgs, args=argv[1:], prog="ns2gs-render compare"), compare=True)
    else:
        render(tyro.cli(RenderArgs, args=argv, prog="ns2gs-render"), compare=False)


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
