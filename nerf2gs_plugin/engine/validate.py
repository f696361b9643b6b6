"""Checks of a training config's numbers before anything runs: one-line errors naming the flag."""

from __future__ import annotations

import math
from typing import Any

from nerf2gs_plugin.engine.augment_config import check_given_shares
from nerf2gs_plugin.errors import ConfigError

# Adam's first step is lr / (1 - beta1) = 10 lr; above ~3e37 that overflows float32 inside torch
# (a RuntimeError traceback). Anything this large diverges anyway: the divergence guard reports it.
MAX_LR = 1e30


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def check_trainer_config(cfg: Any) -> None:
    """Step arithmetic, learning rates, augmentation numbers and run-folder options that cannot work."""
    if getattr(cfg, "run_dir", None) is not None and (cfg.experiment_name is not None or cfg.timestamp != "{timestamp}"):
        raise ConfigError("names the run folder itself: leave out --experiment-name and --timestamp (they name "
                          "output-dir/experiment/method/timestamp)", "--run-dir")
    if getattr(cfg, "warm_start", None) is not None and getattr(cfg, "load_checkpoint", None) is not None:
        raise ConfigError("starts a new run from another one; --load-checkpoint resumes this one: pass one of them", "--warm-start")
    if cfg.max_num_iterations <= 0:
        raise ConfigError(f"must be a positive number of steps, got {cfg.max_num_iterations}", _flag("max_num_iterations"))
    if cfg.steps_per_save <= 0:
        raise ConfigError(f"must be a positive number of steps, got {cfg.steps_per_save}", _flag("steps_per_save"))
    if cfg.steps_per_eval_image < 0:
        raise ConfigError(f"must be 0 (off) or a positive number of steps, got {cfg.steps_per_eval_image}", _flag("steps_per_eval_image"))
    for name, opt in cfg.optimizers.items():
        for field in ("lr", "lr_final"):
            lr = getattr(opt, field)
            if lr is None:
                continue
            if not (isinstance(lr, (int, float)) and math.isfinite(lr) and 0 <= lr <= MAX_LR):  # 0: a frozen group
                raise ConfigError(f"learning rate must be in [0, {MAX_LR:g}], got {lr!r}", f"--optimizers.{name}.{field.replace('_', '-')}")
    if getattr(cfg, "machine", None) is not None:
        from nerf2gs_plugin.engine.launch import check_machine_config

        check_machine_config(cfg.machine)
    aug = cfg.augment
    for field in ("delta_h", "dilate_px", "feather_px", "extra_weight"):
        v = getattr(aug, field)
        if not (math.isfinite(v) and v >= 0):
            raise ConfigError(f"must be >= 0, got {v}", f"--augment.{field.replace('_', '-')}")
    if aug.every_n < 1:
        raise ConfigError(f"must be >= 1, got {aug.every_n}", "--augment.every-n")
    if not (isinstance(aug.view_downscale, int) and aug.view_downscale >= 1):
        raise ConfigError(f"must be a whole number >= 1, got {aug.view_downscale}", "--augment.view-downscale")
    if not (math.isfinite(aug.step_factor) and aug.step_factor > 0):
        raise ConfigError(f"must be > 0, got {aug.step_factor}", "--augment.step-factor")
    if aug.extra_prob is not None and not 0 <= aug.extra_prob <= 1:
        raise ConfigError(f"must be in [0, 1], got {aug.extra_prob}", "--augment.extra-prob")
    check_given_shares(aug)
    dm = getattr(getattr(cfg, "pipeline", None), "datamanager", None)
    if not (math.isfinite(aug.composite_loss_margin) and aug.composite_loss_margin >= 0):
        raise ConfigError(f"must be >= 0, got {aug.composite_loss_margin}", "--augment.composite-loss-margin")
    if aug.composite_loss == "either" and getattr(cfg, "augment_from", None) is not None and hasattr(dm, "rays_per_batch"):
        # rays drawn from the composites carry no photo beside the paint: the option would do nothing
        raise ConfigError("either needs a method that learns whole images (Splatfacto, Scaffold-GS, 2DGS); this one samples "
                          "rays: leave it at paint", "--augment.composite-loss")
    if not math.isfinite(aug.theta_pitch):
        raise ConfigError(f"must be finite, got {aug.theta_pitch}", "--augment.theta-pitch")
    ds = getattr(getattr(dm, "dataparser", None), "downscale", 1.0)
    if not (isinstance(ds, (int, float)) and math.isfinite(ds) and ds > 0):
        raise ConfigError(f"must be a positive finite number, got {ds}", "--pipeline.datamanager.dataparser.downscale")
