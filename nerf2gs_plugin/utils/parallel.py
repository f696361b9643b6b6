"""Whole views rendered side by side: one view per core, each in a forked process with one torch
thread, instead of one view at a time with torch's threads splitting each operation.

A render is a long chain of small tensor operations over 4096-ray chunks; split across torch's
threads, each operation pays a fork-join and the threads wait for each other, so two threads render
a view only about 1.5x as fast as one. Two views rendered at once, one per process, keep both cores
busy for the whole render (Python threads would not: the interpreter's lock between the operations
serialises them). The numbers are those of a one-thread render: reductions split over fewer threads
differ from a two-thread render in the last float bits only.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import resource
import sys
from typing import Any, Callable, Iterable, Iterator, Optional, TypeVar

import torch

T = TypeVar("T")
R = TypeVar("R")

_JOB: Optional[Callable[[Any], Any]] = None  # what a forked worker renders (inherited, never pickled)


def view_workers(requested: Optional[int] = None) -> int:
    """How many views to render at once: ``requested``, else torch's intra-op thread count (1 with
    ``OMP_NUM_THREADS=1``: the sequential path); 1 where processes cannot be forked."""
    if "fork" not in multiprocessing.get_all_start_methods():
        return 1
    return max(1, int(requested if requested is not None else torch.get_num_threads()))


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and of its finished children (the render workers)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _init_worker() -> None:
    torch.set_num_threads(1)


def _run(item: Any) -> Any:
    with torch.no_grad():
        return _JOB(item)  # type: ignore[misc]


@contextlib.contextmanager
def _opencv_one_thread() -> Iterator[None]:
    """OpenCV (where loaded: the mask maths) without worker threads while the workers are forked: a
    forked child inherits the thread pool's bookkeeping but not its threads, and its first parallel
    call, or a ``cv2.setNumThreads``, waits for them for ever. With none, the children's OpenCV
    calls run on their one thread; the parent's threads come back afterwards."""
    cv2 = sys.modules.get("cv2")
    threads = cv2.getNumThreads() if cv2 is not None else 0
    if cv2 is not None:
        cv2.setNumThreads(1)
    try:
        yield
    finally:
        if cv2 is not None:
            cv2.setNumThreads(threads)


def render_ahead(render: Callable[[T], R], items: Iterable[T], workers: Optional[int] = None,
                 first_here: bool = True) -> Iterator[R]:
    """``render(item)`` for every item, yielded in order. With more than one worker (see
    :func:`view_workers`) the first item is rendered here (lazy loads: kernels, caches, which the
    workers then inherit; ``first_here`` False: in the workers too), the rest by ``workers`` forked
    processes, one torch thread each, without gradients; items and results travel pickled (tensors
    through shared memory), ``render`` itself is inherited. ``render`` must not rely on state it
    changes (a model already in eval mode): each worker changes its own copy."""
    global _JOB
    items = list(items)
    n = min(view_workers(workers), max(len(items) - (1 if first_here else 0), 1))
    if n < 2:
        for item in items:
            yield render(item)
        return
    if first_here:
        yield render(items[0])
        items = items[1:]
    from concurrent.futures import ProcessPoolExecutor

    _JOB = render
    # a worker that dies (out of memory) breaks the pool with an error instead of a wait for ever
    pool = ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("fork"), initializer=_init_worker)
    try:
        with _opencv_one_thread():
            futures = [pool.submit(_run, item) for item in items]  # the workers are forked at the first
        _JOB = None
        for f in futures[:-1]:
            yield f.result()
        last = futures[-1].result()
        pool.shutdown(wait=True)  # reaped before the last one is handed over: their CPU time is counted
    finally:
        _JOB = None
        pool.shutdown(wait=True, cancel_futures=True)
    yield last


def map_ahead(job: Callable[[T], R], items: Iterable[T], workers: Optional[int] = None) -> Iterator[R]:
    """``job(item)`` for every item, yielded in order, the items spread over the cores as
    :func:`render_ahead` spreads views (the per-frame mask maths: one frame per core). ``job`` must
    depend on its item alone, not on what earlier items changed: the workers see the parent's state
    as it was at the fork. Every item goes to the workers: nothing to load lazily here first."""
    return render_ahead(job, items, workers, first_here=False)
