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

Data-parallel training (several ranks, each rendering its own cameras): a strategy lists its
accumulated statistics in :attr:`Strategy.reduced_stats` and makes every refine decision inside
``with self.all_ranks(device):``, which first combines the statistics of all ranks (sum or max)
and gives every rank rank 0's random generator, so all ranks grow and prune the same primitives
in the same way. :meth:`accumulate` takes the statistics of one more batch of the same step (one
process drawing several batches per step, as several ranks would).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from contextlib import contextmanager
from typing import Any, Callable, ClassVar, Iterator, Optional

import torch
from torch import Tensor, nn

from nerf2gs_plugin.utils import collectives


class Strategy(ABC):
    grad_key: ClassVar[str] = "means2d"
    reduced_stats: ClassVar[dict[str, str]] = {}
    """Accumulated statistics combined over data-parallel ranks before a refine decision:
    attribute path from the strategy (``"max_radii"``, ``"stats.denom"``) -> ``"sum"`` or ``"max"``."""

    @abstractmethod
    def initialize_state(self) -> None:
        """Forget every accumulated statistic."""

    def state_dict(self) -> dict[str, Tensor]:
        """The accumulated statistics (:attr:`reduced_stats`), for a checkpoint: a run resumed between two
        refinements then decides the next one on the same evidence as a run never stopped."""
        return {path: value for path in self.reduced_stats if (value := self._stat(path)) is not None}

    def load_state_dict(self, state: dict[str, Tensor]) -> None:
        """What :meth:`state_dict` gave (empty: no statistics yet, as in a checkpoint that predates them)."""
        self.initialize_state()
        for path, value in state.items():
            if path in self.reduced_stats:
                self._set_stat(path, value)

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

    def accumulate(self, params: nn.ParameterDict, step: int, info: dict[str, Any]) -> None:
        """The statistics of a batch of this step other than its last (whose ``info`` goes to
        :meth:`step_post_backward`), when a process draws several batches per step. Strategies
        without statistics ignore it; one with statistics must override it."""
        if self.reduced_stats:
            raise NotImplementedError(f"{type(self).__name__} cannot take several batches per step")

    def _stat(self, path: str) -> Optional[Tensor]:
        obj: Any = self
        for name in path.split("."):
            obj = getattr(obj, name)
        return obj

    def _set_stat(self, path: str, value: Optional[Tensor]) -> None:
        *parents, last = path.split(".")
        obj: Any = self
        for name in parents:
            obj = getattr(obj, name)
        setattr(obj, last, value)

    @contextmanager
    def all_ranks(self, device: Optional[torch.device] = None) -> Iterator[None]:
        """Around a refine decision: with several ranks, every rank enters with the statistics of all
        ranks (summed / maxed) and rank 0's random state; on the way out the summed statistics
        that survive the refinement are kept by rank 0 only, so the next combination counts them
        once. A no-op in one process."""
        if not collectives.is_distributed():
            yield
            return
        for op in ("sum", "max"):
            paths = [p for p, o in self.reduced_stats.items() if o == op]
            for path, value in zip(paths, collectives.all_reduce_tensors([self._stat(p) for p in paths], op, device)):
                self._set_stat(path, value)
        collectives.sync_rng_state(device)
        yield
        if collectives.rank() != 0:
            for path, op in self.reduced_stats.items():
                value = self._stat(path)
                if op == "sum" and value is not None:
                    value.zero_()


class SceneBudget:
    """A soft budget of primitives read from the scene, not a constant: the larger of what its views and
    what its content call for, at most ``cap``.

    * views: the pixels of every training view (real and extra, at training resolution) x the steps the
      strategy grows for, over ``pixel_steps_per_primitive``: more or larger views, or a longer growing
      phase, make room for more primitives (off when <= 0);
    * content: ``per_point`` x ``points``, the model's count of what the capture's structure gave it (the
      SfM points for Splatfacto / 2DGS, the initial anchors for Scaffold-GS): a courtyard whose photos
      hold 15k SfM points needs more primitives per pixel than a synthetic street of 4k (off when <= 0).

    Neither on: the fixed ``cap`` (0 = unlimited). The model sets :attr:`pixels_fn` when training names
    its views and :attr:`points` when it is built from the data; the views term is read once, on first use
    after the views are known (until then the budget is the cap)."""

    def __init__(self, pixel_steps_per_primitive: float, growing_steps: int, cap: int, per_point: float = 0.0) -> None:
        self.pixel_steps_per_primitive = pixel_steps_per_primitive
        self.growing_steps = max(int(growing_steps), 1)
        self.cap = cap
        self.per_point = per_point
        self.points = 0
        """Set by the model from its data (kept when a checkpoint is loaded into a model built from the same data)."""
        self.pixels_fn: Optional[Callable[[], Optional[int]]] = None
        self._from_views: Optional[int] = None

    @property
    def value(self) -> int:
        """The budget in force (0 = none)."""
        terms = []
        if self.pixel_steps_per_primitive > 0:
            if self._from_views is None:
                pixels = self.pixels_fn() if self.pixels_fn is not None else None
                if pixels is None:  # on, but the views are not known yet
                    return self.cap
                self._from_views = max(int(pixels * self.growing_steps / self.pixel_steps_per_primitive), 1)
            terms.append(self._from_views)
        if self.per_point > 0 and self.points > 0:
            terms.append(max(int(self.per_point * self.points), 1))
        if not terms:
            return self.cap
        return min(max(terms), self.cap) if self.cap > 0 else max(terms)
