"""Training callbacks: methods hook into the Trainer (densification, schedules) through these."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Any, Callable, Optional


class TrainingCallbackLocation(Enum):
    BEFORE_STEP = "before_step"  # before the forward pass
    AFTER_BACKWARD = "after_backward"  # gradients exist, optimizer not yet stepped
    AFTER_STEP = "after_step"  # after the optimizer step
    AFTER_BATCH = "after_batch"  # several batches per step: after the backward of each batch but the last


@dataclass
class TrainingCallbackAttributes:
    """What a callback may touch: the optimizers (to swap parameters) and the pipeline."""

    optimizers: Any
    pipeline: Any


@dataclass
class TrainingCallback:
    where: list[TrainingCallbackLocation]
    func: Callable[[int], None]  # called with the step number
    update_every_num_iters: Optional[int] = None  # None = every step
    iters: Optional[tuple[int, ...]] = None  # or only at these steps

    def run(self, location: TrainingCallbackLocation, step: int) -> None:
        if location not in self.where:
            return
        if self.iters is not None and step not in self.iters:
            return
        if self.update_every_num_iters is not None and step % self.update_every_num_iters != 0:
            return
        self.func(step)
