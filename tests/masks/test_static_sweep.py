"""Textured pixels no static depth explains (``masks/static_sweep.py``), on the textured sequence of
``test_motion.py``: a background wall (the farthest static surface: the bound), a parked block in front of it, a
block riding with the camera and one crossing against the scene's flow."""

from __future__ import annotations

import torch

from nerf2gs_plugin.masks.motion import MotionFrame, MotionOptions, along, epipolar_line, grey, motion_masks, ray_directions, rigid_flow
from nerf2gs_plugin.masks.static_sweep import textured, unexplained

from .test_motion import Z_BG, Z_PARKED, _sequence


def _bounded(frames, truth):
    """Nothing static lies beyond the background wall: its distance is each ray's bound."""
    return [MotionFrame(f.image, f.dist, f.c2w, f.intr, bound=torch.where(t["parked"], f.dist * Z_BG / Z_PARKED, f.dist))
            for f, t in zip(frames, truth)]


def _pair(frames, i: int, j: int, scale: int = 1) -> torch.Tensor:
    fi, fj = frames[i], frames[j]
    rays = ray_directions(fi.c2w, fi.intr, *fi.dist.shape)
    p_inf, u, ok = epipolar_line(fi, fj, rays)
    rb, ok_b = rigid_flow(fi.c2w, fi.intr, fi.bound, fj.c2w, fj.intr, rays)
    s_b = torch.where(ok_b, along(rb, p_inf, u), torch.zeros_like(fi.dist))
    lowest = s_b - torch.clamp(0.15 * s_b, min=2.0)
    return ok & unexplained(grey(fi.image), grey(fj.image), p_inf, u, lowest, [], 6.0, 3.0, 8.0, 0.35, scale)


def _eroded(m: torch.Tensor, px: int) -> torch.Tensor:
    return torch.nn.functional.max_pool2d((~m).float()[None], 2 * px + 1, 1, px)[0] == 0


def test_movers_are_unexplained_and_static_blocks_are_not():
    frames, truth = _sequence()
    frames = _bounded(frames, truth)
    t, nxt = truth[2], truth[3]
    tex = torch.from_numpy(textured(grey(frames[2].image), 8.0))
    movers = t["rider"] | t["crossing"]
    # the parked pixels whose match in frame 3 (15 px to the left) the crossing block covers there
    hidden = torch.zeros_like(movers)
    hidden[:, 15:] = nxt["crossing"][:, :-15]
    parked = _eroded(t["parked"] & ~t["crossing"], 3) & _eroded(~hidden, 3)  # a 5x5 patch's rim off the edges
    wall = _eroded(~(movers | t["parked"] | nxt["crossing"]), 8)  # off the blocks and what frame 3's crossing block hides
    wall[:, :10] = False  # its match leaves frame 3 there
    # the parked block's texture is stretched 8x: at half size it aliases, a half pixel off matches poorly
    for scale, parked_max in ((1, 0.02), (2, 0.2)):
        m = _pair(frames, 2, 3, scale)
        assert float(m[t["rider"]].float().mean()) > 0.8, scale  # stays put where every static surface flows by 4 px or more
        assert float(m[t["crossing"] & tex].float().mean()) > 0.6, scale  # moves against the scene's flow
        assert float(m[parked].float().mean()) < parked_max, scale  # closer than the wall: more parallax, still static
        assert float(m[wall].float().mean()) < 0.02, scale


def test_plain_pixels_are_left_to_the_flow_tests():
    frames, truth = _sequence()
    frames = _bounded(frames, truth)
    plain = [MotionFrame(torch.where(truth[k]["rider"][..., None], torch.full_like(f.image, 0.5), f.image), f.dist, f.c2w, f.intr, f.bound)
             for k, f in enumerate(frames)]
    m = _pair(plain, 2, 3)
    core = torch.nn.functional.max_pool2d((~truth[2]["rider"]).float()[None], 9, 1, 4)[0] == 0  # 4 px inside the rider
    assert not bool(m[core].any())  # a plain patch matches anywhere on the line: nothing to tell
    assert not bool(torch.from_numpy(textured(grey(plain[2].image), 8.0))[core].any())


def test_the_route_with_the_sweep_finds_the_movers_and_not_the_parked_block():
    frames, truth = _sequence()
    frames = _bounded(frames, truth)
    on = motion_masks(frames, MotionOptions(sweep_grey=6.0))
    off = motion_masks(frames, MotionOptions())
    inner = range(1, len(frames) - 1)
    found = lambda ms, kind: sum(float((ms[k] & truth[k][kind]).sum()) for k in inner) / sum(float(truth[k][kind].sum()) for k in inner)  # noqa: E731
    assert found(on, "crossing") >= found(off, "crossing")
    assert found(on, "crossing") > 0.5 and found(on, "rider") > 0.8
    # the parked block: where the crossing block hides its match in the one pair ahead (the sequence's last frames), some of it
    assert found(on, "parked") < found(off, "parked") + 0.15
    static_fp = max(float((on[k] & ~(truth[k]["rider"] | truth[k]["crossing"])).float().mean()) for k in inner)
    assert static_fp < 0.03, static_fp
