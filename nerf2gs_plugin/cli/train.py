"""ns2gs-train <method> --data DATA [--augment-from REF] [--pipeline.model.x ...]"""

from __future__ import annotations

import signal
import sys

import tyro

from nerf2gs_plugin.cli.common import run_cli
from nerf2gs_plugin.engine.trainer import Trainer, TrainerConfig
from nerf2gs_plugin.registry import discover_methods, report_failures


def train(config: TrainerConfig) -> None:
    # a scheduler's preemption signal saves like Ctrl-C (SIGINT raises KeyboardInterrupt)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    trainer = Trainer(config)
    trainer.setup()
    if config.viewer:
        from nerf2gs_plugin.viewer.server import attach_training_viewer

        attach_training_viewer(trainer)
    try:
        run_dir = trainer.train()
    except KeyboardInterrupt:
        path = trainer.save_checkpoint(trainer.step)
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
    union = tyro.extras.subcommand_type_from_defaults(defaults=configs, descriptions=descriptions)
    config = tyro.cli(tyro.conf.FlagConversionOff[union], description="Train a method (nerf2gs).")
    train(config)


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
