"""Sky model: colour as a function of view direction only, i.e. radiance at infinite depth.

Composited behind the field: ``rgb = rgb_field + (1 - accumulation) * sky(direction)``; the sky
loss of the method pushes accumulation to zero on sky-mask pixels, so the sky never becomes a
floater wall in the field (the StreetNeRF sky treatment).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from nerf2gs_plugin.fields.mlp import MLP

from nerf2gs_plugin.utils.sh import num_sh_bases, sh_basis


class SkyModel(nn.Module):
    def __init__(self, sh_degree: int = 4, hidden: int = 64, num_layers: int = 2) -> None:
        super().__init__()
        self.sh_degree = sh_degree
        self.mlp = MLP(num_sh_bases(sh_degree), hidden, num_layers, 3)

    def forward(self, directions: Tensor) -> Tensor:
        """Unit ``directions [R,3]`` -> sky colour ``[R,3]`` in [0,1]."""
        return torch.sigmoid(self.mlp(sh_basis(self.sh_degree, directions)))
