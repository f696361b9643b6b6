"""Small MLPs and the truncated-exp density activation (the SH direction encoding is
:func:`nerf2gs_plugin.utils.sh.sh_basis`)."""

from __future__ import annotations

import torch
from torch import Tensor, nn


class MLP(nn.Module):
    """``in_dim -> hidden x num_layers (ReLU) -> out_dim``, no output activation."""

    def __init__(self, in_dim: int, hidden: int, num_layers: int, out_dim: int) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        d = in_dim
        for _ in range(num_layers):
            layers += [nn.Linear(d, hidden), nn.ReLU(inplace=True)]
            d = hidden
        layers.append(nn.Linear(d, out_dim))
        self.net = nn.Sequential(*layers)

    def forward(self, x: Tensor) -> Tensor:
        return self.net(x)


class _TruncExp(torch.autograd.Function):
    """exp with its gradient clamped (instant-ngp): large densities cannot blow up the step."""

    @staticmethod
    def forward(ctx, x: Tensor) -> Tensor:  # type: ignore[override]
        ctx.save_for_backward(x)
        return torch.exp(x)

    @staticmethod
    def backward(ctx, g: Tensor) -> Tensor:  # type: ignore[override]
        (x,) = ctx.saved_tensors
        return g * torch.exp(x.clamp(-15.0, 15.0))


def trunc_exp(x: Tensor) -> Tensor:
    return _TruncExp.apply(x)
