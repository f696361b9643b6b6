"""The densification contract (gsplat's ``Strategy``), shared by every splatting method.

A model owns one strategy and calls it at two points of a training step, never branching on which
strategy it is:

* :meth:`Strategy.step_pre_backward` while rendering for training, with the rasterizer's ``info``
  (its meta dict): keeps the gradient of ``info[grad_key]`` for after the backward pass;
* :meth:`Strategy.step_post_backward` after the optimizer step (as gsplat's trainer does), with
  the same ``info`` (``None`` when the step rendered nothing): accumulates its statistics from
  that gradient and grows / prunes ``params`` on its own schedule, keeping ``optimizers`` in step.

``grad_key`` names the tensor whose gradient drives densification: ``"means2d"`` (the projected
centres) for 3DGS and Scaffold-GS, ``"gradient_2dgs"`` for 2DGS surfels. :meth:`initialize_state`
forgets the statistics (a fresh model, or a checkpoint loaded with another primitive count).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar, Optional

from torch import Tensor, nn


class Strategy(ABC):
    grad_key: ClassVar[str] = "means2d"

    @abstractmethod
    def initialize_state(self) -> None:
        """Forget every accumulated statistic."""

    def grad_tensor(self, info: Optional[dict[str, Any]]) -> Optional[Tensor]:
        """The tensor of ``info`` whose gradient this strategy reads (``info[grad_key]``)."""
        return None if info is None else info.get(self.grad_key)

    def step_pre_backward(self, params: nn.ParameterDict, optimizers: Any, step: int, info: dict[str, Any]) -> None:
        """Before ``loss.backward()``: keep the gradient of ``info[grad_key]`` (a non-leaf tensor)."""
        g = self.grad_tensor(info)
        if g is not None and g.requires_grad:
            g.retain_grad()

    @abstractmethod
    def step_post_backward(self, params: nn.ParameterDict, optimizers: Any, step: int,
                           info: Optional[dict[str, Any]]) -> dict[str, int]:
        """After the optimizer step: update statistics from ``info`` and refine ``params``.
        Returns counts of what changed (e.g. ``{"cloned": 3, "split": 1, "pruned": 0}``)."""
