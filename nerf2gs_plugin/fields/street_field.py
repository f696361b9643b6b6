"""The radiance field and the proposal density fields of StreetNeRF.

Both take positions in the world frame, map them into the scene box's frame, contract them
(``contraction.py``) and look them up in a hash grid. Sample radii (cone radius x distance,
shrunk by the contraction's local scale) drive the Zip-NeRF level downweighting.
"""

from __future__ import annotations

from typing import Optional

import torch
from torch import Tensor, nn

from nerf2gs_plugin.fields.contraction import contract, contraction_scale, render_grid_coords, to_box_frame, to_grid_unit
from nerf2gs_plugin.fields.hash_encoding import HashEncoding, HashGridSpec
from nerf2gs_plugin.fields.mlp import MLP, trunc_exp
from nerf2gs_plugin.utils.sh import num_sh_bases, sh_basis


class _GridPositions(nn.Module):
    """World positions (+ radii) -> grid coordinates in [0,1]^3 (+ radii in grid units)."""

    def __init__(self, scene_box: Tensor) -> None:
        super().__init__()
        self.register_buffer("scene_box", scene_box.clone().float())

    def grid_coords(self, x: Tensor, radius: Optional[Tensor]) -> tuple[Tensor, Optional[Tensor]]:
        if radius is not None and not torch.is_grad_enabled():  # a render: the one-pass form (training keeps its ops)
            xg, scale = render_grid_coords(x, self.scene_box)
            half = ((self.scene_box[1] - self.scene_box[0]) / 2).mean()
            return xg, (radius / half).mul_(scale).div_(4.0)
        xb = to_box_frame(x, self.scene_box)
        xg = to_grid_unit(contract(xb))
        if radius is None:
            return xg, None
        half = ((self.scene_box[1] - self.scene_box[0]) / 2).mean()
        r = radius / half * contraction_scale(xb) / 4.0
        return xg, r


class StreetField(_GridPositions):
    """Density from a hash grid + small MLP; view-dependent colour from a second small MLP on the
    geometry features and spherical harmonics of the direction (nerfacto's layout)."""

    def __init__(self, scene_box: Tensor, spec: HashGridSpec, hidden: int = 64, geo_feat_dim: int = 15,
                 sh_degree: int = 2, color_hidden: int = 64, backend: str = "auto") -> None:
        super().__init__(scene_box)
        self.encoding = HashEncoding(spec, backend)
        self.geo_feat_dim = geo_feat_dim
        self.sh_degree = sh_degree
        self.density_mlp = MLP(self.encoding.out_dim, hidden, 1, 1 + geo_feat_dim)
        self.color_mlp = MLP(geo_feat_dim + num_sh_bases(sh_degree), color_hidden, 2, 3)

    def density(self, x: Tensor, radius: Optional[Tensor] = None) -> tuple[Tensor, Tensor]:
        """``x [N,3]`` world -> density ``[N]`` and geometry features ``[N, geo_feat_dim]``."""
        xg, r = self.grid_coords(x, radius)
        h = self.density_mlp(self.encoding(xg, r))
        return trunc_exp(h[:, 0] - 1.0), h[:, 1:]

    def forward(self, x: Tensor, directions: Tensor, radius: Optional[Tensor] = None) -> tuple[Tensor, Tensor]:
        """``x [N,3]``, unit ``directions [N,3]``, ``radius [N]`` -> density ``[N]``, rgb ``[N,3]``."""
        sigma, geo = self.density(x, radius)
        return sigma, self.color(geo, directions)

    def color(self, geo: Tensor, directions: Tensor) -> Tensor:
        """Geometry features ``[N, geo_feat_dim]`` (from :meth:`density`) + unit ``directions [N,3]`` -> rgb ``[N,3]``."""
        return torch.sigmoid(self.color_mlp(torch.cat([geo, sh_basis(self.sh_degree, directions)], dim=-1)))


class ProposalField(_GridPositions):
    """A small hash grid + tiny MLP giving density only (nerfacto's proposal networks)."""

    def __init__(self, scene_box: Tensor, spec: HashGridSpec, hidden: int = 16, backend: str = "auto") -> None:
        super().__init__(scene_box)
        self.encoding = HashEncoding(spec, backend)
        self.mlp = MLP(self.encoding.out_dim, hidden, 1, 1)

    def forward(self, x: Tensor, radius: Optional[Tensor] = None) -> Tensor:
        xg, r = self.grid_coords(x, radius)
        return trunc_exp(self.mlp(self.encoding(xg, r))[:, 0] - 1.0)
