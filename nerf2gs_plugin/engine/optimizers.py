"""One Adam optimizer per parameter group, each with warm-up + exponential decay (nerfstudio style)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import torch
from torch import nn

from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.utils.schedule import scheduled


@dataclass
class OptimizerConfig:
    """Adam for one parameter group; the learning rate decays exponentially from lr to lr-final
    over max-steps (after a linear warm-up), or stays constant."""

    lr: float = 1e-3
    """Initial learning rate."""
    eps: float = 1e-15
    """Adam epsilon."""
    weight_decay: float = 0.0
    """Adam weight decay."""
    lr_final: Optional[float] = None
    """Learning rate reached at max-steps (exponential decay); None: constant."""
    warmup_steps: int = 0
    """Steps of linear learning-rate warm-up."""
    max_steps: int = scheduled(30000, "horizon", only_if="lr_final")
    """Step at which the decay reaches lr-final."""

    def lr_at(self, step: int) -> float:
        if step < self.warmup_steps:
            warm = (step + 1) / self.warmup_steps
        else:
            warm = 1.0
        if self.lr_final is None:
            return self.lr * warm
        t = min(max(step / max(self.max_steps, 1), 0.0), 1.0)
        return warm * math.exp(math.log(self.lr) * (1 - t) + math.log(self.lr_final) * t)


class Optimizers:
    """Named Adam optimizers with schedules. Methods that grow or prune parameters (densification)
    use :meth:`replace_param` so the optimizer state follows the new tensor."""

    def __init__(self, configs: dict[str, OptimizerConfig], param_groups: dict[str, list[nn.Parameter]]) -> None:
        missing = [name for name in param_groups if name not in configs]
        if missing:
            raise ConfigError(f"no optimizer config for parameter group(s) {missing} (the method config's optimizers name "
                              f"{sorted(configs)}): add an OptimizerConfig under each name to its optimizers")
        self.configs = configs
        self.optimizers: dict[str, torch.optim.Adam] = {}
        for name, params in param_groups.items():
            params = [p for p in params if p.requires_grad]
            if not params:
                continue
            cfg = configs[name]
            # fused: the whole update in one pass over each tensor (foreach makes one pass per operation,
            # about 3x the time on a CPU), one call for the whole group
            self.optimizers[name] = torch.optim.Adam(params, lr=cfg.lr, eps=cfg.eps, weight_decay=cfg.weight_decay, fused=True)

    def zero_grad(self) -> None:
        for opt in self.optimizers.values():
            opt.zero_grad(set_to_none=True)

    def step(self, step: int) -> None:
        for name, opt in self.optimizers.items():
            lr = self.configs[name].lr_at(step)
            for group in opt.param_groups:
                group["lr"] = lr
            opt.step()

    def __getitem__(self, name: str) -> torch.optim.Adam:
        return self.optimizers[name]

    def __contains__(self, name: str) -> bool:
        return name in self.optimizers

    def replace_param(self, name: str, new_param: nn.Parameter, keep: Optional[torch.Tensor] = None, n_new: int = 0) -> None:
        """Swap the single parameter of group ``name`` for ``new_param``.

        ``keep`` ([old_N] bool or long index) selects the rows of the Adam moments that survive;
        ``n_new`` zero rows are appended for new primitives.
        """
        opt = self.optimizers[name]
        group = opt.param_groups[0]
        old = group["params"][0]
        state = opt.state.pop(old, None)
        group["params"][0] = new_param
        if state:
            for key in ("exp_avg", "exp_avg_sq"):
                v = state[key]
                if keep is not None:
                    v = v[keep]
                if n_new:
                    v = torch.cat([v, torch.zeros((n_new, *v.shape[1:]), dtype=v.dtype, device=v.device)])
                state[key] = v
            opt.state[new_param] = state

    def state_dict(self) -> dict:
        return {name: opt.state_dict() for name, opt in self.optimizers.items()}

    def load_state_dict(self, state: dict) -> None:
        for name, opt in self.optimizers.items():
            if name in state:
                opt.load_state_dict(state[name])
