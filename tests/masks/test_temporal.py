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


def test_on_the_routes_own_flows_the_rider_stays_and_a_planted_blip_goes():
    from masks.test_motion import _sequence
    from nerf2gs_plugin.masks.motion import MotionOptions, motion_masks

    frames, truth = _sequence()
    flows: list = []
    masks = motion_masks(frames, MotionOptions(), flows_out=flows)
    assert [sorted(f) for f in flows] == [[1], [0, 2], [1, 3], [2, 4], [3]]
    h, w = frames[0].dist.shape
    assert flows[1][2].dtype == torch.float16 and tuple(flows[1][2].shape) == ((h + 1) // 2, (w + 1) // 2, 2)
    blip = torch.zeros(h, w, dtype=torch.bool)
    blip[-14:-4, -24:-8] = True  # static background, nothing there in the other frames
    assert not (masks[2] & blip).any()
    masks[2] = masks[2] | blip
    out = persistent(masks, flows, 0.1, 0.035)
    assert not (out[2] & blip).any()
    for k in range(1, len(frames) - 1):
        rider = truth[k]["rider"]
        assert float((out[k] & rider).sum()) == float((masks[k] & rider).sum()) > 0.8 * float(rider.sum())


def test_a_mover_leaving_the_frame_is_confirmed_by_the_part_the_next_frame_still_sees(monkeypatch):
    import nerf2gs_plugin.masks.temporal as tm

    leaving = _box(45, 14, 15)  # the right edge: 10 px further on, two thirds of it are out of frame
    masks = [torch.zeros(H, W, dtype=torch.bool), leaving, _box(55, 14, 5)]
    flows = [{1: _shift(0.0)}, {0: _shift(0.0), 2: _shift(10.0)}, {1: _shift(-10.0)}]
    # the frame before sees all of it and has nothing there; the frame after sees a third and has it
    assert persistent(masks, flows, 0.1, 0.035)[1].equal(leaving)
    monkeypatch.setattr(tm, "CONFIRM_SEEN", 0.5)
    assert not persistent(masks, flows, 0.1, 0.035)[1].any()
