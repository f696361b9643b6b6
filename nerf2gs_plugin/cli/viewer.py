"""ns2gs-viewer RUN [--port 7007] [--screenshot docs/viewer.png]"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import tyro

from nerf2gs_plugin.cli.common import run_cli


@dataclass
class ViewerArgs:
    run: tyro.conf.Positional[Path]
    """Run directory or .ckpt file (any registered method, plugins too)."""
    port: int = 7007
    """Port of the web viewer (http://HOST:PORT)."""
    host: str = "127.0.0.1"
    """Interface to listen on (0.0.0.0 to serve other machines)."""
    data: Optional[Path] = None
    """Dataset folder, if it moved since training."""
    device: str = "auto"
    """auto (CUDA when present, else CPU), cpu, cuda or cuda:N."""
    max_side: int = 640
    """Longest side of a full-resolution frame."""
    target_fps: float = 10.0
    """Frame budget while the camera moves; resolution adapts to it."""
    screenshot: Optional[Path] = None
    """Write a PNG of the viewer as seen in headless Chromium, then exit (the README's image)."""
    screenshot_size: tuple[int, int] = (1280, 800)
    """Browser window size for --screenshot."""
    mode: str = "rgb"
    """Initial render mode (rgb, depth, accumulation, normals where the method has them)."""


def main() -> None:
    from nerf2gs_plugin.errors import ConfigError
    from nerf2gs_plugin.viewer.server import ViewerConfig, open_viewer

    args = tyro.cli(ViewerArgs, description="Serve a trained run in the viser web viewer.")
    if not args.run.exists():
        raise ConfigError("run directory or checkpoint does not exist", args.run)
    cfg = ViewerConfig(host=args.host, port=args.port, max_side=args.max_side, target_fps=args.target_fps)
    viewer = open_viewer(args.run, cfg, device=args.device, data=args.data)
    try:
        if args.mode not in viewer.modes:
            raise ConfigError(f"--mode {args.mode}: this method renders {', '.join(viewer.modes)}")
        viewer.set_mode(args.mode)
        if args.screenshot is not None:
            from nerf2gs_plugin.viewer.browser import screenshot_viewer

            out = screenshot_viewer(viewer, args.screenshot, *args.screenshot_size)
            print(f"wrote {out}")
            return
        print(f"viewer for {viewer.method_name} @ step {viewer.step}: {viewer.url}  (Ctrl-C to stop)")
        while True:
            time.sleep(1.0)
    finally:
        viewer.stop()


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
