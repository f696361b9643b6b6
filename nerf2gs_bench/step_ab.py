"""Two versions of a training step timed in one process, interleaved so that a drift of the host's speed
falls on both (the step A/B scripts of ``benchmarks/validation``)."""

from __future__ import annotations

import time
from typing import Any, Callable


def interleaved_step_cpu(trainer: Any, use: Callable[[bool], None], start: int, steps: int, block: int = 20) -> dict[str, float]:
    """CPU ms a step (``time.process_time``: run with one thread) of ``trainer`` from step ``start`` for ``steps``
    steps, in blocks of ``block`` in the order after, before, before, after; ``use(True)`` switches to the code
    after, ``use(False)`` to the code before. ``{"after": ms, "before": ms}``."""
    cpu = {"after": 0.0, "before": 0.0}
    for b, s0 in enumerate(range(start, start + steps, block)):
        which = "after" if b % 4 in (0, 3) else "before"
        use(which == "after")
        c0 = time.process_time()
        for step in range(s0, s0 + block):
            trainer.train_step(step)
        cpu[which] += time.process_time() - c0
    return {k: 2000 * v / steps for k, v in cpu.items()}
