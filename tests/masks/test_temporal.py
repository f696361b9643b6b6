"""masks/temporal.py: a final region that no neighbouring frame confirms (carried by the observed flow)
is dropped; a mover that its neighbours see too stays, and so does a region no neighbour sees."""

from __future__ import annotations

import torch

from nerf2gs_plugin.masks.temporal import keep_flow, persistent

H, W = 40, 60


def _box(x: int, y: int, w: int = 10, h: int = 12) -> torch.Tensor:
    m = torch.zeros(H, W, dtype=torch.bool)
    m[y : y + h, x : x + w] = True
    return m


def _shift(dx: float) -> torch.Tensor:
    """A flow that moves every pixel by ``dx`` to the right."""
    f = torch.zeros(H, W, 2)
    f[..., 0] = dx
    return keep_flow(f)


def _drive(blip_at: int = 1):
    """Three frames: a mover 3 px further right in each (the flow says so), and in frame ``blip_at`` a
    blip that no other frame has."""
    masks = [_box(10 + 3 * i, 14) for i in range(3)]
    masks[blip_at] = masks[blip_at] | _box(44, 4, 8, 8)
    flows = [{j: _shift(3.0 * (j - i)) for j in (i - 1, i + 1) if 0 <= j < 3} for i in range(3)]
    return masks, flows


def test_a_blip_no_neighbour_confirms_is_dropped_and_the_mover_stays():
    masks, flows = _drive()
    out = persistent(masks, flows, 0.1, 0.035)
    for i in range(3):
        assert torch.equal(out[i], _box(10 + 3 * i, 14))


def test_the_ring_tolerates_a_flow_that_misses_the_mover_by_a_few_pixels():
    masks, _ = _drive()
    wrong = [{j: _shift(3.0 * (j - i) + 2.0) for j in (i - 1, i + 1) if 0 <= j < 3} for i in range(3)]
    tight = persistent([m.clone() for m in masks], wrong, 0.95, 0.001)  # a ring of 1 px
    loose = persistent([m.clone() for m in masks], wrong, 0.95, 0.1)  # 4 px
    assert not tight[0].any()  # frame 0's only neighbour sees the mover 2 px off: 90% of it lands in 1 px
    assert loose[0].equal(_box(10, 14))


def test_a_region_no_neighbour_sees_stays():
    masks, flows = _drive()
    away = [{j: _shift(40.0) for j in f} for f in flows]  # every pixel of the blip leaves the frame
    out = persistent(masks, away, 0.1, 0.035)
    assert out[1][4:12, 44:52].all()


def test_off_or_without_neighbours_nothing_changes():
    masks, flows = _drive()
    out = persistent(masks, [{} for _ in masks], 0.1, 0.035)
    assert all(torch.equal(a, b) for a, b in zip(out, masks))
