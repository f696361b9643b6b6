"""ns2gs-data synth-street | preview | process images | process video | masks | export-augmented | preview-augmented

  ns2gs-data synth-street data/street [--seed 0 --width 200 --height 112 --num-train 60 ...]
  ns2gs-data preview data/street [--out preview.png]
  ns2gs-data process video drive.mp4 --out data/drive [--num-frames 150 | --fps 2] [--camera-height 1.5]
  ns2gs-data process images photos/ --out data/photos [--matching exhaustive]
  ns2gs-data masks DATA [--segmenter auto | onnx:model.onnx --class-map cityscapes] [--reference RUN]
  ns2gs-data partition DATA --blocks 2x1 --overlap 0.2 --out DIR
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import tyro

from nerf2gs_plugin.blocks.partition import PartitionConfig
from nerf2gs_plugin.masking.make_masks import MasksConfig
from nerf2gs_plugin.cli.common import run_cli
from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig


@dataclass
class SynthStreet(SynthStreetConfig):
    """Generate the synthetic street dataset: images, exact sky/ground/transient masks, depth,
    sparse points, and the street / bev_1 / bev_2 eval splits."""

    def main(self) -> None:
        from nerf2gs_plugin.data.synthetic_street import generate_street, summary_lines

        for line in summary_lines(generate_street(self)):
            print(line)


@dataclass
class Preview:
    """PNG contact sheet of a dataset: images with their masks per split, and a top-down plot of
    the training and eval cameras over the sparse points."""

    data: tyro.conf.Positional[Path]
    """Dataset folder (transforms.json or a COLMAP model)."""
    out: Optional[Path] = None
    """Output PNG (default: DATA/preview.png)."""
    rows: int = 3
    """Images shown per split."""

    def main(self) -> None:
        from nerf2gs_plugin.data.preview import write_preview

        print(f"wrote {write_preview(self.data, self.out or Path(self.data) / 'preview.png', self.rows)}")


@dataclass
class Process:
    """A raw capture -> posed, metric dataset: `process video FILE --out DATA` or `process images DIR --out DATA`
    (see `ns2gs-data process video --help`)."""

    def main(self) -> None:  # pragma: no cover - dispatched in main()
        raise SystemExit("usage: ns2gs-data process {images,video} ...")


@dataclass
class Masks(MasksConfig):
    """Write masks/{sky,ground,transient}/<image>.png for a capture: --segmenter auto (from a first
    reference NeRF trained without masks, no weights) or onnx:PATH (any segmentation model)."""

    def main(self) -> None:
        from nerf2gs_plugin.masking.make_masks import make_masks

        make_masks(self)


@dataclass
class Partition(PartitionConfig):
    """Split a large capture into overlapping blocks by camera position (VastGaussian style): each
    block a dataset folder to train as its own run, merged back with `ns2gs-export merge`."""

    def main(self) -> None:
        from nerf2gs_plugin.blocks.partition import partition

        doc = partition(self)
        for b in doc["blocks"]:
            evals = ", ".join(f"{s} {n}" for s, n in b["eval_images"].items()) or "no eval views"
            print(f"{b['folder']}: {b['train_images']} train images ({evals}), {b['points']} points")
        print(f"wrote {len(doc['blocks'])} blocks and {Path(self.out) / 'partition.json'}")


def _subcommands() -> dict[str, type]:
    subs: dict[str, type] = {"synth-street": SynthStreet, "preview": Preview, "process": Process, "masks": Masks,
                             "partition": Partition}
    from nerf2gs_plugin.cli.augmented_data import AUGMENTED_SUBCOMMANDS

    subs.update(AUGMENTED_SUBCOMMANDS)
    return subs


def main(args: Optional[Sequence[str]] = None) -> None:
    """Parse ``args`` (default: sys.argv) and run the chosen subcommand."""
    import sys

    argv = list(sys.argv[1:] if args is None else args)
    if argv and argv[0] == "process":
        from nerf2gs_plugin.cli.process import ProcessImages, ProcessVideo

        sub = tyro.extras.subcommand_cli_from_dict({"images": ProcessImages, "video": ProcessVideo}, prog="ns2gs-data process", args=argv[1:])
        sub.main()
        return
    cmd = tyro.extras.subcommand_cli_from_dict(_subcommands(), prog="ns2gs-data", args=args)
    cmd.main()


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
