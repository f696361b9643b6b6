"""utils/parallel.py: views rendered ahead in forked workers come back in order, equal to
one-at-a-time renders; a worker's error reaches the caller; the workers' CPU time is counted."""

from __future__ import annotations

import os

import pytest
import torch

from nerf2gs_plugin.utils.parallel import cpu_seconds, render_ahead

W = torch.randn(48, 48, generator=torch.Generator().manual_seed(0))


def _render(k: int) -> dict:
    x = torch.randn(256, 48, generator=torch.Generator().manual_seed(k))
    for _ in range(20):
        x = torch.tanh(x @ W)
    return {"out": x.sum(0), "pid": os.getpid(), "grad": torch.is_grad_enabled(), "threads": torch.get_num_threads()}


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_in_order_and_equal_to_sequential(workers):
    before = torch.get_num_threads()
    out = list(render_ahead(_render, range(7), workers))
    assert torch.get_num_threads() == before
    for k, r in enumerate(out):
        torch.testing.assert_close(r["out"], _render(k)["out"], rtol=1e-5, atol=1e-5)
    others = [r for r in out if r["pid"] != os.getpid()]
    assert out[0]["pid"] == os.getpid() and (len(others) == 6) == (workers > 1)  # the first here, the rest in the workers
    assert all(not r["grad"] and r["threads"] == 1 for r in others)


def test_a_workers_error_reaches_the_caller_and_its_cpu_time_is_counted():
    def fail(k):
        if k == 3:
            raise ValueError("bad view")
        return k

    with pytest.raises(ValueError, match="bad view"):
        list(render_ahead(fail, range(8), 2))
    c0 = cpu_seconds()
    own0 = sum(os.times()[:2])
    list(render_ahead(lambda k: sum(i * i for i in range(300_000)), range(9), 2))
    assert cpu_seconds() - c0 > 1.5 * (sum(os.times()[:2]) - own0)  # most of it ran in the workers


def test_opencv_in_the_workers_after_the_parent_used_its_threads():
    """A forked worker that calls OpenCV after the parent ran it on several threads must not wait for
    the parent's threads (which the fork did not copy): the workers come back, equal to the parent's
    results, and the parent keeps its OpenCV thread count."""
    import cv2
    import numpy as np

    from nerf2gs_plugin.utils.parallel import map_ahead

    img = np.random.default_rng(0).integers(0, 255, (240, 320), dtype=np.uint8)
    before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    try:
        cv2.GaussianBlur(img.astype(np.float32), (0, 0), 3.0)  # the parent's pool started

        def job(k: int) -> float:
            flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(img, np.roll(img, k, 1), None)
            return float(cv2.GaussianBlur(flow, (0, 0), 2.0).sum())

        assert list(map_ahead(job, range(5), 2)) == [job(k) for k in range(5)]
        assert cv2.getNumThreads() == 2
    finally:
        cv2.setNumThreads(before)


def test_map_ahead_sends_every_item_to_the_workers():
    from nerf2gs_plugin.utils.parallel import map_ahead

    out = list(map_ahead(_render, range(5), 2))
    assert all(r["pid"] != os.getpid() for r in out)
    for k, r in enumerate(out):
        torch.testing.assert_close(r["out"], _render(k)["out"], rtol=1e-5, atol=1e-5)
    assert [r["pid"] for r in map_ahead(_render, range(5), 1)] == [os.getpid()] * 5
