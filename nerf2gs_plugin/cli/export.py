"""ns2gs-export RUN --format ply [--output out.ply]: a trained splatting run as a standard 3DGS PLY.
ns2gs-export merge RUN... --out RUN_DIR: the block runs of a partition as one run (see blocks/merge.py).

The PLY holds x,y,z, nx,ny,nz, f_dc_*, f_rest_*, opacity, scale_*, rot_* (the original 3DGS
layout that SuperSplat, the 3DGS viewers and nerfstudio read). It needs the run directory only,
not the dataset. By default it also holds the learned background (the sky) as a far shell of
opaque Gaussians, so other viewers show no holes where our renders show sky (``--no-background``
leaves it out). Coordinates are the run's normalised frame (``--frame normalised``, what the
training cameras and the viewer use) or the dataset's own frame and scale (``--frame data``,
through the run's ``dataparser_transforms.json``); the frame is written as a PLY header comment.
Scaffold-GS exports the neural Gaussians decoded for one training view (``--view``) or pooled over
several (``--view -1``); 2DGS writes its surfels with a near-zero third scale.
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
    """Output format: the standard 3DGS PLY."""
    output: Optional[Path] = None
    """Output file; default RUN/export/splat.ply."""
    frame: Literal["normalised", "data"] = "normalised"
    """Coordinates: the run's normalised frame, or the dataset's original frame and scale."""
    background: bool = True
    """Add the learned background (sky) as a far shell of Gaussians."""
    background_points: int = 10000
    """Gaussians in the background shell."""
    background_radius: float = 20.0
    """Shell radius, in half-diagonals of the scene box around its centre."""
    data: Optional[Path] = None
    """Dataset folder; only read for runs that predate train_cameras.json."""
    view: int = 0
    """Scaffold-GS: training view whose decoded Gaussians are written (-1: pooled over views)."""
    device: str = "cpu"
    """Torch device the model is loaded on (cpu, cuda)."""


def export(args: ExportArgs) -> Path:
    from nerf2gs_plugin.data.normalize import load_dataparser_transform
    from nerf2gs_plugin.runs.model import load_run_model
    from nerf2gs_plugin.methods.gaussian_frame import to_data_frame
    from nerf2gs_plugin.methods.gaussian_utils import write_gaussian_ply
    from nerf2gs_plugin.methods.sky_shell import concat_gaussians, sky_shell_gaussians

    run = load_run_model(args.run, device=args.device, data=args.data)
    model = run.model
    if not hasattr(model, "export_gaussians"):
        raise ConfigError(f"method '{run.method_name}' has no Gaussians to export (not a splatting method)", run.checkpoint)
    kwargs = {}
    if getattr(model, "export_needs_cameras", False):
        kwargs = {"cameras": run.train_cameras, "view": args.view}
    gaussians = {k: v.detach().float().cpu() for k, v in model.export_gaussians(**kwargs).items()}
    n_scene, n_shell = gaussians["means"].shape[0], 0
    tf = load_dataparser_transform(run.run_dir / "dataparser_transforms.json")
    if args.background and getattr(model, "background", None) is not None:
        box = tf.scene_box.float()
        radius = args.background_radius * float((box[1] - box[0]).norm()) / 2
        shell = sky_shell_gaussians(model.background, box.mean(0), radius, args.background_points,
                                    sh_rest=gaussians["features_rest"].shape[1])
        if shell is not None:
            n_shell = shell["means"].shape[0]
            gaussians = concat_gaussians(gaussians, shell)
    if args.frame == "data":
        gaussians = to_data_frame(gaussians, tf.transform, tf.scale)
        frame = "frame data: the dataset's original coordinates and scale"
    else:
        frame = "frame normalised: x_n = scale * (R x_data + t), transform and scale in dataparser_transforms.json"
    out = args.output or run.run_dir / "export" / "splat.ply"
    comments = (f"nerf2gs {run.method_name} step {run.step}", frame, f"background shell: {n_shell} Gaussians after the {n_scene} of the scene")
    write_gaussian_ply(out, **gaussians, comments=comments)
    shell_note = f" + {n_shell} background-shell Gaussians" if n_shell else ""
    print(f"wrote {n_scene} Gaussians{shell_note} to {out} ({frame.split(':')[0]})")
    return out


def main(args: Optional[list[str]] = None) -> None:
    import sys

    argv = list(sys.argv[1:] if args is None else args)
    if argv and argv[0] == "merge":
        from nerf2gs_plugin.blocks.merge import MergeConfig, merge

        cfg = tyro.cli(MergeConfig, prog="ns2gs-export merge", args=argv[1:], description=MergeConfig.__doc__)
        out = merge(cfg)
        print(f"wrote {out} (merged {len(cfg.runs)} block runs; see {out / 'merge.json'})")
        return
    export(tyro.cli(ExportArgs, args=argv, description=__doc__.splitlines()[0]))


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
