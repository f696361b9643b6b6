"""Data-parallel collectives (torch.distributed), each a no-op in a single process.

Splatting models change their parameter shapes when they densify, so DDP's wrapper (fixed
buckets of fixed parameters) does not fit: gradients are averaged here by one flattened
all-reduce per step over whatever parameters the model holds now, and the densification
statistics are combined by the :class:`~nerf2gs_plugin.methods.strategy_base.Strategy` before
a refine decision. Every rank then applies the same update and takes the same decisions, so
the replicated models stay identical (checked with :func:`param_digest` at every save).
"""

from __future__ import annotations

import hashlib
from contextlib import contextmanager
from typing import Any, Iterable, Iterator, Optional

import torch
from torch import Tensor


def _dist():
    import torch.distributed as dist

    return dist


def is_distributed() -> bool:
    """True inside an initialised process group of more than one rank."""
    dist = _dist()
    return dist.is_available() and dist.is_initialized() and dist.get_world_size() > 1


def rank() -> int:
    return _dist().get_rank() if is_distributed() else 0


def world_size() -> int:
    return _dist().get_world_size() if is_distributed() else 1


def barrier() -> None:
    if is_distributed():
        _dist().barrier()


@contextmanager
def rank_zero_first() -> Iterator[None]:
    """Rank 0 runs the block, then the others (e.g. rank 0 renders a cache that the others read)."""
    if rank() != 0:
        barrier()
    yield
    if rank() == 0:
        barrier()


@torch.no_grad()
def average_gradients(params: Iterable[Tensor], divisor: int) -> None:
    """``.grad`` of every parameter summed over the ranks, then divided by ``divisor`` (the number
    of batches of the global step). One flat buffer per dtype and device; a parameter whose
    gradient is None on every rank keeps None (the optimizer then skips it, as without ranks),
    one that has a gradient on some rank only gets zeros from the others."""
    groups: dict[tuple[torch.dtype, torch.device], list[Tensor]] = {}
    for p in params:
        groups.setdefault((p.dtype, p.device), []).append(p)
    for (dtype, device), ps in groups.items():
        flags = torch.tensor([0.0 if p.grad is None else 1.0 for p in ps], dtype=dtype, device=device)
        if is_distributed():
            flat = torch.cat([(p.grad if p.grad is not None else torch.zeros_like(p)).reshape(-1) for p in ps] + [flags])
            _dist().all_reduce(flat)
            flags = flat[-len(ps):]
            offset = 0
            for p, has in zip(ps, flags.tolist()):
                n = p.numel()
                if has > 0:
                    p.grad = flat[offset:offset + n].view_as(p).div_(divisor)
                offset += n
        elif divisor != 1:
            for p in ps:
                if p.grad is not None:
                    p.grad.div_(divisor)


@torch.no_grad()
def all_reduce_tensors(tensors: list[Optional[Tensor]], op: str, device: Optional[torch.device] = None) -> list[Optional[Tensor]]:
    """Sum (``op="sum"``) or maximum (``"max"``) over the ranks of each tensor, in place where it
    exists. A tensor that is None on some ranks counts as zeros of the others' shape there; all
    None stays None; different shapes on two ranks mean the replicas have diverged (an error)."""
    if not is_distributed():
        return tensors
    dist = _dist()
    shapes = all_gather_object([None if t is None else tuple(t.shape) for t in tensors])
    out: list[Optional[Tensor]] = []
    ref = next((t for t in tensors if t is not None), None)
    for i, t in enumerate(tensors):
        seen = {s[i] for s in shapes if s[i] is not None}
        if len(seen) > 1:
            raise RuntimeError(f"data-parallel replicas diverged: statistic {i} has shapes {sorted(seen)} on the ranks")
        if not seen:
            out.append(None)
            continue
        if t is None:
            t = torch.zeros(seen.pop(), device=ref.device if ref is not None else device)
        out.append(t)
    present = [t for t in out if t is not None]
    if present:
        flat = torch.cat([t.reshape(-1).float() for t in present])
        dist.all_reduce(flat, op=dist.ReduceOp.SUM if op == "sum" else dist.ReduceOp.MAX)
        offset = 0
        for t in present:
            t.copy_(flat[offset:offset + t.numel()].view_as(t))
            offset += t.numel()
    return out


def mean_over_ranks(value: float, device: Optional[torch.device] = None) -> float:
    """The mean of a number over the ranks (e.g. the global batch's loss, for the log); ``device``:
    where the backend reduces (a CUDA device for NCCL)."""
    if not is_distributed():
        return value
    t = torch.tensor([float(value)], dtype=torch.float64, device=device)
    _dist().all_reduce(t)
    return float(t) / world_size()


def all_gather_object(obj: Any) -> list[Any]:
    if not is_distributed():
        return [obj]
    dist = _dist()
    out: list[Any] = [None] * dist.get_world_size()
    dist.all_gather_object(out, obj)
    return out


def broadcast_object(obj: Any, src: int = 0) -> Any:
    """Rank ``src``'s ``obj`` on every rank."""
    if not is_distributed():
        return obj
    box = [obj]
    _dist().broadcast_object_list(box, src=src)
    return box[0]


def sync_rng_state(device: Optional[torch.device] = None) -> None:
    """Every rank continues with rank 0's global torch generator (and CUDA's, on CUDA), so random
    choices made identically on all ranks (split samples, relocations) stay identical."""
    if not is_distributed():
        return
    torch.set_rng_state(broadcast_object(torch.get_rng_state()))
    if device is not None and device.type == "cuda":
        torch.cuda.set_rng_state(broadcast_object(torch.cuda.get_rng_state(device)), device)


def param_digest(state: dict[str, Tensor]) -> str:
    """A short hash of a state dict's tensors (names, shapes, bytes): equal models, equal digests."""
    h = hashlib.sha256()
    for name in sorted(state):
        t = state[name]
        if not torch.is_tensor(t):
            continue
        h.update(f"{name}:{tuple(t.shape)}:{t.dtype}".encode())
        h.update(t.detach().cpu().contiguous().reshape(-1).view(torch.uint8).numpy().tobytes())
    return h.hexdigest()[:16]
