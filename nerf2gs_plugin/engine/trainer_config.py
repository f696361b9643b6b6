"""The training run's config: every field is an ``ns2gs-train <method>`` flag.

Apart from the Trainer so that what reads a run's config (the registry's methods, a reference run
loaded for augmentation) does not import the training loop, which imports them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from nerf2gs_plugin.engine.augment_config import AugmentConfig
from nerf2gs_plugin.engine.launch import MachineConfig
from nerf2gs_plugin.engine.optimizers import OptimizerConfig
from nerf2gs_plugin.engine.pipeline import PipelineConfig
from nerf2gs_plugin.utils.schedule import scheduled


@dataclass
class TrainerConfig:
    """Everything one training run needs; ``ns2gs-train <method>`` exposes every field as a flag."""

    method_name: str = "unnamed"
    """Name of the method; set by the subcommand, names the run folder."""
    data: Path = Path("data/street")
    """Dataset folder (nerfstudio transforms.json or a COLMAP model)."""
    output_dir: Path = Path("outputs")
    """Root folder of the runs."""
    experiment_name: Optional[str] = None
    """Defaults to the dataset folder's name: runs go to output_dir/experiment/method/timestamp."""
    timestamp: str = "{timestamp}"
    """Name of the run folder; the default is the start time (YYYY-MM-DD_HHMMSS)."""
    run_dir: Optional[Path] = None
    """Write the run into exactly this folder instead of output_dir/experiment/method/timestamp
    (for tools that own their run's place, e.g. the masks' reference); locked like an explicit
    timestamp: a folder that holds another run's checkpoints is an error unless resumed."""
    max_num_iterations: int = scheduled(2000, "total")
    """Number of training steps."""
    steps_per_eval_image: int = 250
    """Every this many steps, render one eval view (the next in turn) and log its PSNR as
    eval_psnr_1view: a cheap signal, not ns2gs-eval's PSNR over all views (0 = never)."""
    steps_per_save: int = scheduled(1000, "cap")
    """Write a checkpoint every this many steps (and always at the end)."""
    keep_all_checkpoints: bool = False
    """Keep every checkpoint instead of only the latest."""
    seed: int = 42
    """Random seed (torch, numpy, python)."""
    device: str = "auto"
    """auto (CUDA when present, else CPU), cpu, cuda or cuda:N."""
    load_checkpoint: Optional[Path] = None
    """Resume from this run directory or .ckpt file (same method)."""
    warm_start: Optional[Path] = None
    """Start this new run from another run's weights and step (a run directory or .ckpt): e.g.
    StreetNeRF from the masks stage's reference as its second pass left it
    (outputs/<data>/masks-reference-second-pass), which trained its first steps already. Refused unless it
    is the same method, images, cameras and model configuration (loss weights may differ); the run goes
    on from that run's step."""
    augment_from: Optional[Path] = None
    """Reference run directory or .ckpt: train on its composites and bird's-eye views."""
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)
    optimizers: dict[str, OptimizerConfig] = field(default_factory=dict)
    progress: bool = True
    """A live progress bar on a terminal; False (and whenever the output is not a terminal): one
    plain line every 10 s with step, rate, ETA and loss."""
    viewer: bool = False
    """Serve the live viewer (viser) while training."""
    machine: MachineConfig = field(default_factory=MachineConfig)
    """Data-parallel training: several ranks on one run (torchrun, or --machine.num-devices N)."""

    def get_run_dir(self) -> Path:
        """The run folder: ``run_dir`` when set, else output_dir/experiment/method/timestamp."""
        if self.run_dir is not None:
            return Path(self.run_dir)
        name = self.experiment_name or Path(self.data).name
        return Path(self.output_dir) / name / self.method_name / self.timestamp
