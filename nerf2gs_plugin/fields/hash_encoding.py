"""Multiresolution hash-grid encoding (instant-ngp) with three interchangeable backends.

* ``torch``: the pure-torch reference (:func:`hash_encode_torch`), differentiable through autograd;
  it runs on any device and is the CUDA path here (tcnn is not installed).
* ``cpu``: a C++/OpenMP kernel (``hashgrid.cpp``) compiled on first use with
  ``torch.utils.cpp_extension.load`` and cached in ``TORCH_EXTENSIONS_DIR``; forward and backward
  (w.r.t. the table, and w.r.t. the positions when they require grad) match the reference, which
  the tests check.
* ``auto``: the kernel for CPU tensors when it compiles, the reference otherwise.

Positions get a gradient only when they require one (a camera optimizer moves the training rays,
so the sample positions depend on the poses); otherwise the kernel skips that work.

Anti-aliasing (Zip-NeRF, Barron et al. 2023, Sec. 3): a sample of radius ``sigma`` (in [0,1]
grid units) scales level ``l``'s features by ``erf(1 / sqrt(8 sigma^2 n_l^2))`` so that levels
finer than the sample's footprint are faded out instead of aliasing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import torch
from torch import Tensor, nn

from nerf2gs_plugin.utils.extensions import load_extension

_PRIMES = (1, 2654435761, 805459861)
KERNEL_SOURCE = Path(__file__).with_name("hashgrid.cpp")


def load_kernel():
    """Compile (first use) or load (cached) the C++ kernel (see :mod:`nerf2gs_plugin.utils.extensions`);
    None only where ``NERF2GS_ALLOW_NO_KERNELS`` allows the torch fallback."""
    return load_extension("nerf2gs_hashgrid", [KERNEL_SOURCE])


def grid_resolutions(num_levels: int, base_res: int, max_res: int) -> list[int]:
    """Geometric progression of per-level resolutions from ``base_res`` to ``max_res``."""
    if num_levels == 1:
        return [int(base_res)]
    b = math.exp((math.log(max_res) - math.log(base_res)) / (num_levels - 1))
    return [int(math.floor(base_res * b**lvl)) for lvl in range(num_levels)]


def _corner_indices_weights(x: Tensor, res: int, table_size: int) -> tuple[Tensor, Tensor]:
    """``x [N,3]`` in [0,1] -> corner indices ``[N,8]`` (long) and trilinear weights ``[N,8]``,
    computed with exactly the kernel's float32 arithmetic."""
    s = float(res)
    pos = x.clamp(0.0, 1.0) * s
    i = torch.floor(pos).clamp(0, res - 1)
    fr = pos - i
    i = i.long()
    side = res + 1
    dense = side**3 <= table_size
    offs = torch.tensor([[k & 1, (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], device=x.device)  # [8,3]
    c = i[:, None, :] + offs[None]  # [N,8,3]
    if dense:
        idx = c[..., 0] + side * (c[..., 1] + side * c[..., 2])
    else:
        idx = (c[..., 0] * _PRIMES[0]) ^ (c[..., 1] * _PRIMES[1]) ^ (c[..., 2] * _PRIMES[2])
        idx = idx & (table_size - 1)
    offs_f = offs.to(x.dtype)
    w3 = torch.where(offs_f[None].bool(), fr[:, None, :], 1.0 - fr[:, None, :])  # [N,8,3]
    w = (w3[..., 0] * w3[..., 1]) * w3[..., 2]
    return idx, w


def hash_encode_torch(x: Tensor, table: Tensor, resolutions: list[int]) -> Tensor:
    """Reference encoding. ``x [N,3]`` in [0,1], ``table [L,T,F]`` -> ``[N, L, F]``."""
    L, T, F = table.shape
    outs = []
    for lvl in range(L):
        idx, w = _corner_indices_weights(x, resolutions[lvl], T)
        feats = table[lvl][idx.reshape(-1)].reshape(x.shape[0], 8, F)
        outs.append((feats * w[..., None]).sum(1))
    return torch.stack(outs, dim=1)


class _HashGridCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: Tensor, table: Tensor, res: Tensor) -> Tensor:  # type: ignore[override]
        ext = load_kernel()
        x = x.detach().contiguous().float()
        table = table.detach().contiguous()
        if ctx.needs_input_grad[0]:  # positions that require grad (a camera optimizer): keep the table for their gradient
            ctx.save_for_backward(x, res, table)
        else:
            ctx.save_for_backward(x, res)
        ctx.table_size = table.shape[1]
        return ext.forward(x, table, res)

    @staticmethod
    def backward(ctx, grad_out: Tensor):  # type: ignore[override]
        x, res = ctx.saved_tensors[:2]
        grad_table = grad_x = None
        if ctx.needs_input_grad[1]:
            grad_table = load_kernel().backward(x, grad_out.contiguous(), res, ctx.table_size)
        if ctx.needs_input_grad[0]:
            grad_x = load_kernel().backward_x(x, ctx.saved_tensors[2], grad_out.contiguous(), res)
        return grad_x, grad_table, None


class _HashGridWeightedCPU(torch.autograd.Function):
    """The encoding times per-point, per-level weights ``w [N, L]`` (no gradient to them or to the positions) in the
    kernel's pass: the same products, and the same table gradient, as the separate multiply and its backward."""

    @staticmethod
    def forward(ctx, x: Tensor, table: Tensor, res: Tensor, w: Tensor) -> Tensor:  # type: ignore[override]
        x, w = x.detach().contiguous().float(), w.detach().contiguous()
        ctx.save_for_backward(x, res, w)
        ctx.table_size = table.shape[1]
        return load_kernel().forward_w(x, table.detach().contiguous(), res, w)

    @staticmethod
    def backward(ctx, grad_out: Tensor):  # type: ignore[override]
        x, res, w = ctx.saved_tensors
        return None, load_kernel().backward_w(x, grad_out.contiguous(), res, w, ctx.table_size), None, None


def hash_encode(x: Tensor, table: Tensor, resolutions: list[int], backend: str = "auto", res_tensor: Optional[Tensor] = None) -> Tensor:
    """Encode ``x [N,3]`` (in [0,1]) with ``table [L,T,F]`` -> ``[N, L, F]`` using ``backend``."""
    use_cpu = backend == "cpu" or (backend == "auto" and x.device.type == "cpu" and table.dtype == torch.float32)
    if use_cpu and x.device.type == "cpu" and load_kernel() is not None:
        if res_tensor is None:
            res_tensor = torch.tensor(resolutions, dtype=torch.int32)
        return _HashGridCPU.apply(x, table, res_tensor)
    if backend == "cpu" and x.device.type != "cpu":
        raise ValueError("the 'cpu' hash-grid backend needs CPU tensors")
    return hash_encode_torch(x, table, resolutions)


@dataclass
class HashGridSpec:
    """Shape of one hash grid (levels, features, table size, resolution range)."""

    num_levels: int = 12
    features_per_level: int = 2
    log2_table_size: int = 15
    base_res: int = 16
    max_res: int = 1024


class HashEncoding(nn.Module):
    """Learnable hash grid: ``x [N,3]`` in [0,1] (+ optional sample radius) -> ``[N, L*F]``."""

    def __init__(self, spec: HashGridSpec, backend: str = "auto", init_scale: float = 1e-4) -> None:
        super().__init__()
        self.spec = spec
        self.backend = backend
        T = 2**spec.log2_table_size
        self.resolutions = grid_resolutions(spec.num_levels, spec.base_res, spec.max_res)
        self.table = nn.Parameter((torch.rand(spec.num_levels, T, spec.features_per_level) * 2 - 1) * init_scale)
        self.register_buffer("_res", torch.tensor(self.resolutions, dtype=torch.int32), persistent=False)

    @property
    def out_dim(self) -> int:
        return self.spec.num_levels * self.spec.features_per_level

    def num_entries(self) -> int:
        return int(self.table.shape[0] * self.table.shape[1])

    def forward(self, x: Tensor, radius: Optional[Tensor] = None) -> Tensor:
        """``x [N,3]`` in [0,1]; ``radius [N]`` sample radius in the same units (anti-aliasing)."""
        res_cpu = self._res if self._res.device.type == "cpu" else None
        if radius is not None and not torch.is_grad_enabled() and _fused_available(x, self.table, self.backend):
            # a render: the level weights in the kernel's one pass (the same float operations)
            out = load_kernel().forward_aa(x.contiguous().float(), self.table.contiguous(), self._res, radius.reshape(-1).contiguous().float())
            return out.reshape(x.shape[0], -1)
        if radius is not None and not (x.requires_grad or radius.requires_grad) and _fused_available(x, self.table, self.backend):
            # training without position gradients: the level weights multiplied in the kernel's pass (same bits)
            w = level_weights(radius, self._res.to(x.dtype))
            return _HashGridWeightedCPU.apply(x, self.table, self._res, w).reshape(x.shape[0], -1)
        feats = hash_encode(x, self.table, self.resolutions, self.backend, res_cpu)  # [N,L,F]
        if radius is not None:
            feats = feats * level_weights(radius, self._res.to(x.dtype))[..., None]
        return feats.reshape(x.shape[0], -1)


def _fused_available(x: Tensor, table: Tensor, backend: str) -> bool:
    """The C++ kernel would encode ``x`` (as :func:`hash_encode` decides) and is built."""
    use_cpu = backend == "cpu" or (backend == "auto" and table.dtype == torch.float32)
    return use_cpu and x.device.type == "cpu" and table.device.type == "cpu" and load_kernel() is not None


def level_weights(radius: Tensor, resolutions: Tensor) -> Tensor:
    """Zip-NeRF downweighting ``erf(1/sqrt(8 r^2 n_l^2))``: ``radius [N]``, ``resolutions [L]`` -> ``[N, L]``."""
    r = radius.reshape(-1, 1).clamp_min(1e-8) * resolutions.reshape(1, -1)
    return torch.special.erf(1.0 / torch.sqrt(8.0 * r * r))
