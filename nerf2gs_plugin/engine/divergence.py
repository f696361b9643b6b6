"""Divergence checks: a checkpoint is only ever written from finite state, and a checkpoint on
disk with non-finite values is refused. The loss is checked every step (in the trainer); the
parameters and optimizer state here, before every save and at the end (one fused pass each)."""

from __future__ import annotations

from typing import Any, Iterable, Iterator

import torch


def _tensors(tree: Any, prefix: str = "") -> Iterator[tuple[str, torch.Tensor]]:
    """Every floating-point tensor in a nested dict/list (state dicts, optimizer state)."""
    if torch.is_tensor(tree):
        if tree.is_floating_point() or tree.is_complex():
            yield prefix or "tensor", tree
    elif isinstance(tree, dict):
        for k, v in tree.items():
            yield from _tensors(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(tree, (list, tuple)):
        for i, v in enumerate(tree):
            yield from _tensors(v, f"{prefix}.{i}" if prefix else str(i))


def nonfinite_counts(tree: Any) -> dict[str, int]:
    """name -> number of NaN/inf values, for the tensors that have any (empty dict: all finite)."""
    items = [(n, t) for n, t in _tensors(tree) if t.numel()]
    if not items:
        return {}
    # one isfinite(...).all() per tensor, one host sync for all of them
    flags = torch.stack([torch.isfinite(t.detach()).all().to("cpu") for _, t in items])
    bad = [(n, t) for (n, t), ok in zip(items, flags.tolist()) if not ok]
    return {n: int((~torch.isfinite(t.detach())).sum()) for n, t in bad}


def describe(counts: dict[str, int], limit: int = 3) -> str:
    """'means (1146), scales (1146) and 2 more' for one error line."""
    parts = [f"{n} ({c})" for n, c in list(counts.items())[:limit]]
    more = f" and {len(counts) - limit} more" if len(counts) > limit else ""
    return ", ".join(parts) + more


def nonfinite_outputs(outputs: dict[str, Any], keys: Iterable[str] = ("rgb",)) -> list[str]:
    """The render outputs among ``keys`` that hold NaN/inf."""
    return [k for k in keys if k in outputs and torch.is_tensor(outputs[k]) and not bool(torch.isfinite(outputs[k]).all())]
