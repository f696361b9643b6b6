"""ns2gs-train <method> --data DATA [--augment-from REF [--baseline RUN]] [--pipeline.model.x ...]"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import tyro

from nerf2gs_plugin.cli.common import exit_on_sigterm, run_cli
from nerf2gs_plugin.engine.trainer import Trainer, TrainerConfig
from nerf2gs_plugin.registry import discover_methods, report_failures


BASELINE_FLAG = "--baseline"
BASELINE_HELP = ("With --augment-from REF, --baseline RUN names the target trained without NeRF views: before "
                 "training, the log says (with both runs' measured held-out PSNR) whether the reference is weaker.")


def pop_baseline(argv: list[str]) -> tuple[list[str], Optional[Path]]:
    """``--baseline RUN`` taken out of ``argv`` (the trainer's config is the method's own and has no
    such field): (the rest, RUN or None)."""
    rest, baseline, i = [], None, 0
    while i < len(argv):
        a = argv[i]
        if a == BASELINE_FLAG:
            if i + 1 >= len(argv) or argv[i + 1].startswith("--"):
                from nerf2gs_plugin.errors import ConfigError

                raise ConfigError(f"{BASELINE_FLAG} needs a run folder")
            baseline, i = Path(argv[i + 1]), i + 2
            continue
        if a.startswith(BASELINE_FLAG + "="):
            baseline = Path(a.split("=", 1)[1])
        else:
            rest.append(a)
        i += 1
    return rest, baseline


def train(config: TrainerConfig, baseline: Optional[Path] = None) -> None:
    """Train one run (in this process, or as one rank of a data-parallel run: rank 0 reports)."""
    from nerf2gs_plugin.utils.collectives import rank

    # a scheduler's preemption signal saves like Ctrl-C (then exits 143)
    exit_on_sigterm()
    report = None
    if config.augment_from is not None and rank() == 0:  # say so before training on a weaker reference
        from nerf2gs_plugin.eval.reference_check import reference_report

        line, doc = reference_report(config.augment_from, baseline)
        print(line, flush=True)
        report = doc
    elif baseline is not None:
        print(f"{BASELINE_FLAG} is only used with --augment-from (ignored)", file=sys.stderr)
    trainer = Trainer(config)
    trainer.setup()
    if report is not None:
        from nerf2gs_plugin.eval.reference_check import write_reference_report

        write_reference_report(trainer.run_dir, report)
    if config.viewer and rank() == 0:
        from nerf2gs_plugin.viewer.server import attach_training_viewer

        attach_training_viewer(trainer)
    try:
        run_dir = trainer.train()
    except KeyboardInterrupt:
        path = trainer.save_checkpoint(trainer.step, synced=False)  # rank 0 alone: the ranks are not in step
        if path is not None:
            print(f"interrupted: checkpoint saved to {path}", file=sys.stderr)
        raise
    print(f"run saved to {run_dir}")


def main() -> None:
    disc = discover_methods()
    report_failures(disc)
    configs = {name: spec.config for name, spec in sorted(disc.methods.items())}
    descriptions = {name: spec.description for name, spec in disc.methods.items()}
    if not configs:
        raise SystemExit("no methods registered")
    if len(sys.argv) > 1 and not sys.argv[1].startswith("-") and sys.argv[1] not in configs:
        from nerf2gs_plugin.errors import ConfigError

        raise ConfigError(f"unknown method '{sys.argv[1]}'; known methods: {', '.join(sorted(configs))}")
    argv, baseline = pop_baseline(sys.argv[1:])
    if baseline is not None and not baseline.exists():
        from nerf2gs_plugin.errors import DataError

        raise DataError("baseline run folder does not exist", f"{BASELINE_FLAG} {baseline}")
    union = tyro.extras.subcommand_type_from_defaults(defaults=configs, descriptions=descriptions)
    config = tyro.cli(tyro.conf.FlagConversionOff[union], args=argv, description=f"Train a method (nerf2gs). {BASELINE_HELP}")
    from nerf2gs_plugin.engine.launch import launch

    launch(train, config, baseline)  # in this process, or on --machine.num-devices ranks / as a torchrun rank


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
