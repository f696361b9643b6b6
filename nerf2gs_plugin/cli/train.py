"""ns2gs-train <method> [--preset NAME] [--steps N] --data DATA [--augment-from REF [--baseline RUN]] [--pipeline.model.x ...]"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import tyro

from nerf2gs_plugin.cli.common import exit_on_sigterm, run_cli
from nerf2gs_plugin.engine.trainer import Trainer, TrainerConfig
from nerf2gs_plugin.registry import MethodSpecification, discover_methods, report_failures


BASELINE_FLAG = "--baseline"
BASELINE_HELP = ("With --augment-from REF, --baseline RUN names the target trained without NeRF views: before "
                 "training, the log says (with both runs' measured held-out PSNR) whether the reference is weaker.")


PRESET_FLAG = "--preset"
PRESET_HELP = "--preset NAME (before the method's flags take effect): the method at that scale, e.g. paper (for a GPU)."

STEPS_FLAG = "--steps"
STEPS_HELP = ("--steps N: N training steps with every step-valued schedule (densification, SH degree, learning-rate "
              "decay) rescaled with them, applied after --preset and before the method's flags wherever it is written; "
              "--max-num-iterations changes the length alone.")


def pop_option(argv: list[str], flag: str, what: str) -> tuple[list[str], Optional[str]]:
    """``flag VALUE`` (or ``flag=VALUE``) taken out of ``argv``, for an option that is not a field of
    the method's config: (the rest, VALUE or None); ConfigError "``flag`` needs ``what``" without one."""
    rest, value, i = [], None, 0
    while i < len(argv):
        a = argv[i]
        if a == flag:
            if i + 1 >= len(argv) or argv[i + 1].startswith("--"):
                from nerf2gs_plugin.errors import ConfigError

                raise ConfigError(f"{flag} needs {what}")
            value, i = argv[i + 1], i + 2
            continue
        if a.startswith(flag + "="):
            value = a.split("=", 1)[1]
        else:
            rest.append(a)
        i += 1
    return rest, value


def pop_baseline(argv: list[str]) -> tuple[list[str], Optional[Path]]:
    """``--baseline RUN`` taken out of ``argv`` (the trainer's config is the method's own and has no
    such field): (the rest, RUN or None)."""
    rest, baseline = pop_option(argv, BASELINE_FLAG, "a run folder")
    return rest, None if baseline is None else Path(baseline)


def _positive_steps(value: str) -> int:
    from nerf2gs_plugin.errors import ConfigError

    try:
        steps = int(value)
    except ValueError:
        steps = 0
    if steps <= 0:
        raise ConfigError(f"must be a positive whole number of steps, got {value!r}", STEPS_FLAG)
    return steps


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
    if report is not None:  # written by the trainer once it has chosen the run folder
        from nerf2gs_plugin.eval.reference_check import CHECK_FILE, report_text

        trainer.run_files[CHECK_FILE] = report_text(report)
    trainer.setup()
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


def parse_args(args: list[str]) -> tuple[TrainerConfig, Optional[Path]]:
    """``ns2gs-train``'s arguments -> (the run's config, the ``--baseline`` run or None)."""
    disc = discover_methods()
    report_failures(disc)
    specs = dict(sorted(disc.methods.items()))
    if not specs:
        raise SystemExit("no methods registered")
    if args and not args[0].startswith("-") and args[0] not in specs:
        from nerf2gs_plugin.errors import ConfigError

        raise ConfigError(f"unknown method '{args[0]}'; known methods: {', '.join(specs)}")
    argv, preset = pop_option(args, PRESET_FLAG, "a preset name (e.g. paper)")
    if preset is not None and argv and argv[0] in specs:  # the method's defaults at that scale; its flags apply on top
        specs[argv[0]] = specs[argv[0]].preset(preset)
    argv, steps = pop_option(argv, STEPS_FLAG, "a number of steps")
    if steps is not None and argv and argv[0] in specs:  # the schedule rescaled first, so the method's flags apply on top
        specs[argv[0]] = MethodSpecification(specs[argv[0]].with_steps(_positive_steps(steps)), specs[argv[0]].description)
    argv, baseline = pop_baseline(argv)
    if baseline is not None and not baseline.exists():
        from nerf2gs_plugin.errors import DataError

        raise DataError("baseline run folder does not exist", f"{BASELINE_FLAG} {baseline}")
    configs = {name: spec.config for name, spec in specs.items()}
    descriptions = {name: spec.description for name, spec in specs.items()}
    union = tyro.extras.subcommand_type_from_defaults(defaults=configs, descriptions=descriptions)
    config = tyro.cli(tyro.conf.FlagConversionOff[union], args=argv,
                      description=f"Train a method (nerf2gs). {PRESET_HELP} {STEPS_HELP} {BASELINE_HELP}")
    return config, baseline


def main() -> None:
    config, baseline = parse_args(sys.argv[1:])
    from nerf2gs_plugin.engine.launch import launch

    launch(train, config, baseline)  # in this process, or on --machine.num-devices ranks / as a torchrun rank


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
