"""The one progress display every long job uses: rate and ETA always shown.

On a terminal it is rich's live bar. When the output is not a terminal (bench logs, CI, ``| tee``)
a live bar shows nothing until the job ends, so there each task prints one plain line at most
every ``log_every`` seconds (description, done/total, rate, ETA, stats) and a final line.
"""

from __future__ import annotations

import sys
from contextlib import contextmanager
from datetime import timedelta
from typing import Any, Callable, Iterator, Optional

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TaskID, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

LOG_EVERY_S = 10.0


class _Rate(TextColumn):
    def __init__(self) -> None:
        super().__init__("")

    def render(self, task):  # type: ignore[override]
        from rich.text import Text

        speed = task.finished_speed or task.speed
        return Text(f"{speed:.2f} it/s" if speed else "-- it/s", style="cyan")


def _clock(seconds: Optional[float]) -> str:
    return "-:--:--" if seconds is None else str(timedelta(seconds=max(0, int(seconds))))


def plain_line(task) -> str:
    """One log line for a rich task: ``desc: 120/3000 (4%) 2.35 it/s ETA 0:20:25 elapsed 0:00:51 stats``."""
    total = task.total
    done = f"{task.completed:.0f}/{total:.0f}" if total else f"{task.completed:.0f}"
    pct = f" ({100.0 * task.completed / total:.0f}%)" if total else ""
    speed = task.finished_speed or task.speed
    rate = f"{speed:.2f} it/s" if speed else "-- it/s"
    eta = "done" if task.finished else f"ETA {_clock(task.time_remaining)}"
    stats = task.fields.get("stats", "")
    line = f"{task.description}: {done}{pct} {rate} {eta} elapsed {_clock(task.finished_time if task.finished else task.elapsed)}"
    return f"{line} {stats}".rstrip()


class PlainProgress(Progress):
    """A rich ``Progress`` without the live display: throttled plain lines instead (see module doc)."""

    def __init__(self, *columns: Any, log_every: float = LOG_EVERY_S, **kwargs: Any) -> None:
        super().__init__(*columns, **{**kwargs, "disable": True})
        self.log_every = log_every
        self._last_line: dict[TaskID, float] = {}
        self._final: set[TaskID] = set()

    def _emit(self, task_id: TaskID, final: bool = False) -> None:
        task = self._tasks[task_id]
        self._last_line[task_id] = self.get_time()
        if final:
            self._final.add(task_id)
        self.console.print(plain_line(task), markup=False, highlight=False, soft_wrap=True)

    def _maybe_emit(self, task_id: TaskID) -> None:
        if task_id in self._final or task_id not in self._tasks:
            return
        task = self._tasks[task_id]
        if task.finished:
            self._emit(task_id, final=True)
            return
        start = self._last_line.get(task_id, task.start_time if task.start_time is not None else self.get_time())
        if self.get_time() - start >= self.log_every:
            self._emit(task_id)

    def update(self, task_id: TaskID, **kwargs: Any) -> None:  # type: ignore[override]
        super().update(task_id, **kwargs)
        self._maybe_emit(task_id)

    def advance(self, task_id: TaskID, advance: float = 1) -> None:
        super().advance(task_id, advance)
        self._maybe_emit(task_id)

    def stop(self) -> None:
        """The final line of every task not yet reported finished (also when the job stopped early)."""
        for task_id in list(self._tasks):
            if task_id not in self._final and self._tasks[task_id].visible:
                self._emit(task_id, final=True)
        super().stop()


@contextmanager
def make_progress(enabled: bool = True, console: Console | None = None, log_every: float = LOG_EVERY_S,
                  get_time: Optional[Callable[[], float]] = None, live: bool = True) -> Iterator[Progress]:
    """A progress display on stderr; ``add_task(..., stats="")`` and ``update(stats=...)`` show live
    numbers. A live bar on a terminal (unless not ``live``), throttled plain lines otherwise; nothing
    when not ``enabled``."""
    console = console or Console(file=sys.stderr)
    columns = (
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TaskProgressColumn(),
        _Rate(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.fields[stats]}"),
    )
    live = live and (console.is_terminal or console.is_jupyter)
    if enabled and not live:
        progress: Progress = PlainProgress(*columns, console=console, get_time=get_time, log_every=log_every)
    else:
        progress = Progress(*columns, console=console, disable=not enabled, transient=False, get_time=get_time)
    with progress:
        yield progress
