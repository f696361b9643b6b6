"""ns2gs-export RUN --format ply [--output out.ply]: a trained splatting run as a standard 3DGS PLY.

The PLY holds x,y,z, nx,ny,nz, f_dc_*, f_rest_*, opacity, scale_*, rot_* (the original 3DGS
layout that SuperSplat, the 3DGS viewers and nerfstudio read), in the run's normalised world
frame (``dataparser_transforms.json`` in the run maps it back to the data's frame). Scaffold-GS
exports the neural Gaussians decoded for one training view (``--view``) or pooled over several
(``--view -1``); 2DGS writes its surfels with a near-zero third scale.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Optional

import tyro

from nerf2gs_plugin.cli.common import run_cli
from nerf2gs_plugin.errors import ConfigError


@dataclass
class ExportArgs:
    run: tyro.conf.Positional[Path]
    """Run directory (latest checkpoint) or a .ckpt file."""
    format: Literal["ply"] = "ply"
    output: Optional[Path] = None
    """Output file; default RUN/export/splat.ply."""
    data: Optional[Path] = None
    """Dataset folder, when the run's recorded path has moved."""
    view: int = 0
    """Scaffold-GS: training view whose decoded Gaussians are written (-1: pooled over views)."""
    device: str = "cpu"


def export(args: ExportArgs) -> Path:
    from nerf2gs_plugin.engine.reference import load_run
    from nerf2gs_plugin.methods.gaussian_utils import write_gaussian_ply

    run = load_run(args.run, device=args.device, data=args.data)
    model = run.model
    if not hasattr(model, "export_gaussians"):
        raise ConfigError(f"method '{run.config.method_name}' has no Gaussians to export (not a splatting method)", run.checkpoint)
    kwargs = {}
    if getattr(model, "export_needs_cameras", False):
        kwargs = {"cameras": run.pipeline.datamanager.train_images.cameras, "view": args.view}
    gaussians = model.export_gaussians(**kwargs)
    out = args.output or run.run_dir / "export" / "splat.ply"
    write_gaussian_ply(out, **gaussians)
    print(f"wrote {gaussians['means'].shape[0]} Gaussians to {out}")
    return out


def main() -> None:
    export(tyro.cli(ExportArgs, description=__doc__.splitlines()[0]))


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
