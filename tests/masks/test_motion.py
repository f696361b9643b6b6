"""Moving objects from motion (``masks/motion.py``): the rigid flow against its closed form,
and a textured sequence with a known camera motion in which a block moves across the image, a block
rides with the camera (stays put in the image) and a block is static at its own depth (parked); with
a static reference's render of it, the residual gate, the temporal carry test and the outlines."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import torch

from nerf2gs_plugin.masks.motion import MotionFrame, MotionOptions, motion_masks, neighbour_stride, outline, rigid_flow, static_distance, touching

W, H, F = 160, 96, 100.0
INTR = (F, F, W / 2, H / 2)
Z_BG, Z_PARKED, STEP = 20.0, 8.0, 1.2  # metres; the camera moves STEP to the right per frame


def _pose(x: float) -> torch.Tensor:
    c2w = torch.zeros(3, 4)
    c2w[:, :3] = torch.eye(3)  # OpenGL: looking down -z
    c2w[0, 3] = x
    return c2w


def _texture(seed: int, size: int = 512) -> np.ndarray:
    import cv2

    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.random((size, size, 3)).astype(np.float32), (0, 0), 2.0)
    return (t - t.min()) / (t.max() - t.min())


def _sample(tex: np.ndarray, tx: np.ndarray, ty: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.remap(tex, tx.astype(np.float32), ty.astype(np.float32), cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


def _sequence(n: int = 5, step: float = STEP):
    """Frames, the static distance a reference would give, and the true masks of the three blocks (and the
    static scene's image: what a reference that learnt no mover renders); the camera moves ``step`` a frame."""
    bg, parked_tex, mover_tex = _texture(0), _texture(1), _texture(2)
    v, u = np.meshgrid(np.arange(H) + 0.5, np.arange(W) + 0.5, indexing="ij")
    ray_len = np.sqrt(((u - INTR[2]) / F) ** 2 + ((v - INTR[3]) / F) ** 2 + 1)
    frames, truth = [], []
    for k in range(n):
        cam_x = k * step
        img = _sample(bg, ((u - INTR[2]) * Z_BG / F + cam_x) * 3 + 100, (v - INTR[3]) * Z_BG / F * 3 + 200)
        dist = Z_BG * ray_len
        # parked: a static block at 8 m, world x in [2, 5] m: it flows by F * step / 8 (15 px at STEP) per frame
        pu = F * (np.array([2.0, 5.0]) - cam_x) / Z_PARKED + INTR[2]
        parked = (u >= pu[0]) & (u < pu[1]) & (v >= 30) & (v < 70)
        img[parked] = _sample(parked_tex, ((u - INTR[2]) * Z_PARKED / F + cam_x) * 8, v)[parked]
        dist = np.where(parked, Z_PARKED * ray_len, dist)
        static = img.copy()  # what a reference of the static scene renders
        # rides with the camera: stays at columns 20..50, the background behind it flows by F * step / 20 (6 px)
        rider = (u >= 20) & (u < 50) & (v >= 55) & (v < 85)
        img[rider] = _sample(mover_tex, u * 1.0, v * 1.0)[rider]
        # crossing: moves 2 px per frame to the right, where the background flows 6 px to the left
        c0 = 60 + 2 * k
        crossing = (u >= c0) & (u < c0 + 20) & (v >= 10) & (v < 45)
        img[crossing] = (0.4 * _sample(mover_tex, (u - c0) + 200, v + 200) + np.array([0.6, 0.05, 0.05], np.float32))[crossing]  # a red coat
        frames.append(MotionFrame(torch.from_numpy(img).float(), torch.from_numpy(dist).float(), _pose(cam_x), INTR))
        truth.append({k_: torch.from_numpy(m) for k_, m in (("parked", parked), ("rider", rider), ("crossing", crossing))})
        truth[-1]["residual"] = torch.from_numpy(np.abs(img - static).mean(-1))
        truth[-1]["static"] = torch.from_numpy(static)
    return frames, truth


def _iou(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a & b).sum()) / max(float((a | b).sum()), 1.0)


def test_rigid_flow_matches_the_closed_form():
    """A camera moving sideways by b over a plane at depth Z: every pixel flows by -F b / Z; moving
    forward by b: a pixel at (x, y) from the centre flows outward by (x, y) b / (Z - b)."""
    v, u = torch.meshgrid(torch.arange(H) + 0.5, torch.arange(W) + 0.5, indexing="ij")
    ray_len = torch.sqrt(((u - INTR[2]) / F) ** 2 + ((v - INTR[3]) / F) ** 2 + 1)
    dist = Z_BG * ray_len
    flow, ok = rigid_flow(_pose(0.0), INTR, dist, _pose(2.0), INTR)
    assert bool(ok.all())
    assert torch.allclose(flow[..., 0], torch.full_like(flow[..., 0], -F * 2.0 / Z_BG), atol=1e-3)
    assert float(flow[..., 1].abs().max()) < 1e-3
    fwd = _pose(0.0)
    fwd[2, 3] = -2.0  # forward along -z
    flow, _ = rigid_flow(_pose(0.0), INTR, dist, fwd, INTR)
    expect = torch.stack([u - INTR[2], v - INTR[3]], dim=-1) * 2.0 / (Z_BG - 2.0)
    assert torch.allclose(flow, expect, atol=1e-3)
    # at infinity only the rotation moves a pixel: a pure translation leaves it in place
    flow, _ = rigid_flow(_pose(0.0), INTR, torch.full_like(dist, math.inf), _pose(5.0), INTR)
    assert float(flow.abs().max()) < 1e-4


def _pooled(masks, truth, kind: str) -> float:
    inner = range(1, len(masks) - 1)  # frames with neighbours on both sides
    return sum(float((masks[k] & truth[k][kind]).sum()) for k in inner) / sum(float(truth[k][kind].sum()) for k in inner)


def test_moving_blocks_are_found_and_static_ones_are_not():
    frames, truth = _sequence()
    masks = motion_masks(frames, MotionOptions())
    inner = range(1, len(frames) - 1)
    static_fp = max(float((masks[k] & ~(truth[k]["rider"] | truth[k]["crossing"])).float().mean()) for k in inner)
    assert _pooled(masks, truth, "rider") > 0.8  # stays put while the scene behind it flows by 6 px a frame
    assert _pooled(masks, truth, "parked") < 0.1  # static at its own depth: its flow is the rigid flow (a rim at its edges)
    assert static_fp < 0.03, static_fp
    # the crossing block: its plain middle lines up with itself, so not every pair sees it move;
    # a vote of half the pairs on each side finds it (and lets in more of the road a mover uncovers),
    # given that the depth is exact enough to judge parallax beyond it (off by default: a short
    # reference's holes read as static pixels closer than it says); without the sweep, which marks the parked
    # block where the crossing one hides its match in a pair, and half the pairs' vote lets that through
    loose = motion_masks(frames, MotionOptions(vote=0.5, ref_close_rel=0.15, sweep_grey=0.0))
    assert _pooled(loose, truth, "crossing") > 0.5
    assert _pooled(loose, truth, "rider") > 0.8 and _pooled(loose, truth, "parked") < 0.1
    inter = sum(float((loose[k] & (truth[k]["rider"] | truth[k]["crossing"])).sum()) for k in inner)
    union = sum(float((loose[k] | truth[k]["rider"] | truth[k]["crossing"]).sum()) for k in inner)
    assert inter / union > 0.6, inter / union


def test_a_dense_video_compares_frames_a_stride_apart():
    """At a quarter of the step (a video at four times the frame rate) the background flows 1.5 px a
    frame, within ``floor_px``: the nearest frames do not tell the rider from it. ``min_baseline``
    counts the offsets in strides of as many frames as the camera needs to move half its height."""
    frames, truth = _sequence(13, STEP / 4)
    up, road = torch.tensor([0.0, 1.0, 0.0]), -1.5  # the camera 1.5 m above the road: a step is 0.2 of it
    assert neighbour_stride(frames, up, road, MotionOptions(min_baseline=0.0)) == 1
    assert neighbour_stride(frames, up, road, MotionOptions()) == 2  # the default: 0.35 of the height
    assert neighbour_stride(_sequence(5)[0], up, road, MotionOptions()) == 1  # steps of 0.8 of the height
    opts = MotionOptions(min_baseline=0.5)
    assert neighbour_stride(frames, up, road, opts) == 3
    assert neighbour_stride(frames[:9], up, road, opts) == 2  # every offset stays within half the sequence
    assert neighbour_stride([dataclasses.replace(f, c2w=_pose(0.0)) for f in frames], up, road, opts) == 1  # standing still
    inner = range(3, 10)  # a pair a stride away on each side
    recall = lambda m, kind: sum(float((m[k] & truth[k][kind]).sum()) for k in inner) / sum(float(truth[k][kind].sum()) for k in inner)  # noqa: E731
    flow_tests = MotionOptions(sweep_grey=0.0)  # the parallax tests the stride is for (the sweep marks the parked block
    # where the crossing one hides its match in the pairs three frames apart)
    near = motion_masks(frames, flow_tests)
    apart = motion_masks(frames, dataclasses.replace(flow_tests, neighbours=tuple(3 * o for o in MotionOptions().neighbours)))
    assert recall(near, "rider") < 0.2, recall(near, "rider")
    assert recall(apart, "rider") > 0.8, recall(apart, "rider")
    assert recall(apart, "parked") < 0.1


def test_an_object_riding_with_the_camera_is_found_by_the_ground_clamp():
    """Where the reference put a rider far away (no parallax: the sky of a mask-less reference), the
    ground plane's distance bounds the static scene: the road beneath it flows, the rider does not."""
    ground_h = -1.5  # the plane 1.5 m below a forward-looking camera: y = -1.5
    up = torch.tensor([0.0, 1.0, 0.0])
    far = torch.full((H, W), math.inf)
    clamped = static_distance(far, _pose(0.0), INTR, up, ground_h)
    v = torch.arange(H).float() + 0.5
    below = v > INTR[3]
    expect = 1.5 * torch.sqrt(((torch.arange(W) + 0.5 - INTR[2]) / F)[None] ** 2 + ((v - INTR[3]) / F)[:, None] ** 2 + 1) / ((v - INTR[3]) / F)[:, None]
    assert torch.allclose(clamped[below], expect[below], rtol=1e-4)
    assert bool(torch.isinf(clamped[~below]).all())  # above the horizon nothing bounds it
    fwd = _pose(0.0)
    fwd[2, 3] = -1.0
    flow, _ = rigid_flow(_pose(0.0), INTR, clamped, fwd, INTR)
    assert float(flow[-1].norm(dim=-1).min()) > 2.0  # the road near the bottom flows by pixels: a rider there reads as moving


def test_a_static_block_the_reference_put_too_far_is_not_moving():
    """A short reference leaves holes: a parked block rendered at the background's distance. Its
    flow (15 px a frame) is more parallax than that depth gives (6 px) but stays on the epipolar
    line: some static surface closer than the reference explains it, so it is not marked; the rider
    (less parallax than any surface in front of the background) still is."""
    frames, truth = _sequence()
    holed = [MotionFrame(f.image, torch.where(t["parked"], f.dist * Z_BG / Z_PARKED, f.dist), f.c2w, f.intr)
             for f, t in zip(frames, truth)]
    masks = motion_masks(holed, MotionOptions())
    assert _pooled(masks, truth, "parked") < 0.1
    assert _pooled(masks, truth, "rider") > 0.8


def _moving(t: dict) -> torch.Tensor:
    return t["rider"] | t["crossing"]


def _with_residual(frames, truth):
    return [dataclasses.replace(f, residual=t["residual"]) for f, t in zip(frames, truth)]


def _static_fp(masks, truth) -> float:
    return max(float((masks[k] & ~_moving(truth[k])).float().mean()) for k in range(1, len(masks) - 1))


def test_the_residual_gate_drops_what_matches_the_reference():
    """A loose vote (half the pairs) also marks the background that a mover uncovers and that its
    flow spills onto; that background matches the static reference's render, the movers do not."""
    frames, truth = _sequence(7)
    loose = MotionOptions(vote=0.5, ref_close_rel=0.15)
    without = motion_masks(frames, loose)  # no residual: the gate lets everything through
    gated = motion_masks(_with_residual(frames, truth), loose)
    assert _static_fp(without, truth) > 0.01
    assert _static_fp(gated, truth) < 0.003
    assert _pooled(gated, truth, "rider") > 0.9 and _pooled(gated, truth, "crossing") > 0.7


def test_a_one_frame_glitch_is_dropped_by_the_temporal_carry_test():
    """A flash on the static background in one frame only fails every pair of that frame (and differs
    from the reference); carried by the flow into the frames before and after, it lands on nothing
    that moves there, so it is dropped; the rider, found again in its neighbours, stays (the test is
    off by default: on real frames it dropped more of the movers)."""
    frames, truth = _sequence(7)
    frames = _with_residual(frames, truth)
    blob = torch.zeros(H, W, dtype=torch.bool)
    blob[60:80, 100:125] = True
    image = frames[3].image.clone()
    image[blob] = torch.tensor([1.0, 1.0, 0.2])
    frames[3] = dataclasses.replace(frames[3], image=image, residual=torch.where(blob, (image - frames[3].image).abs().mean(-1), frames[3].residual))
    found = lambda m: float((m[3] & blob).sum()) / float(blob.sum())  # noqa: E731
    assert found(motion_masks(frames, MotionOptions(carry=0.0))) > 0.8
    assert found(motion_masks(frames, MotionOptions())) > 0.8
    carried = motion_masks(frames, MotionOptions(carry=0.5))
    assert found(carried) < 0.05
    assert float((carried[3] & truth[3]["rider"]).sum()) / float(truth[3]["rider"].sum()) > 0.4


def test_outlines_complete_the_movers():
    """The crossing block's plain middle lines up with itself, so its votes cover part of it; grown to
    the image's outlines (grabCut seeded by the votes), the regions cover the blocks."""
    frames, truth = _sequence(7)
    frames = _with_residual(frames, truth)
    opts = MotionOptions(vote=0.5, ref_close_rel=0.15, sweep_grey=0.0)  # the flow tests' votes (the sweep finds more of the block)
    votes = motion_masks(frames, dataclasses.replace(opts, outline=False))
    outlined = motion_masks(frames, opts)
    assert _pooled(votes, truth, "crossing") < 0.72
    assert _pooled(outlined, truth, "crossing") > 0.78
    assert _pooled(outlined, truth, "parked") < 0.15 and _static_fp(outlined, truth) < 0.003


def test_pixels_half_the_pairs_see_moving_join_the_region_they_touch():
    """Hysteresis (``loose_vote``): the crossing block moves in every pair only along its textured
    edges; its middle moves in some pairs. Where those pixels touch a pixel every pair sees moving,
    they join it; the static scene, which some pairs misread too, stays out."""
    frames, truth = _sequence()
    inner = range(1, len(frames) - 1)
    strict = motion_masks(frames, MotionOptions(loose_vote=1.0, sweep_grey=0.0))  # the flow tests alone
    loose = motion_masks(frames, MotionOptions(loose_vote=0.5, sweep_grey=0.0))
    assert _pooled(strict, truth, "crossing") < 0.1
    # the sweep (no flow) finds the block's textured middle in every pair, which the flow tests do not
    assert _pooled(motion_masks(frames, MotionOptions(loose_vote=1.0)), truth, "crossing") > 0.25
    assert _pooled(loose, truth, "crossing") > 0.4
    assert _pooled(loose, truth, "rider") >= _pooled(strict, truth, "rider") > 0.8
    assert _pooled(loose, truth, "parked") < 0.1
    for k in inner:  # little new away from the movers (the road beside them that the grown regions take)
        movers = truth[k]["rider"] | truth[k]["crossing"]
        assert float((loose[k] & ~strict[k] & ~movers).float().mean()) < 0.025
    # the half-vote pixels must differ from the reference's render too: where nothing does, none joins
    gated = _with_residual(frames, truth)
    assert all(torch.equal(a, b) for a, b in zip(motion_masks(gated, MotionOptions(loose_vote=0.5, loose_residual_rel=1e9, sweep_grey=0.0)),
                                                   motion_masks(gated, MotionOptions(loose_vote=1.0, sweep_grey=0.0))))


def test_touching_keeps_the_loose_regions_that_hold_a_seed():
    seeds = torch.zeros(8, 12, dtype=torch.bool)
    seeds[2, 2] = True
    loose = torch.zeros(8, 12, dtype=torch.bool)
    loose[1:4, 1:6] = True  # holds the seed
    loose[6:8, 8:12] = True  # apart from it
    out = touching(seeds, loose)
    expect = seeds.clone()
    expect[1:4, 1:6] = True
    assert torch.equal(out, expect)
    assert not bool(out[6:, 8:].any())
    assert torch.equal(touching(torch.zeros_like(seeds), loose), torch.zeros_like(seeds))


def _noisy_block(seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """A block's mask on a noise image: grabCut's colour models then depend on where its k-means starts."""
    img = torch.from_numpy(np.random.default_rng(seed).random((48, 64, 3))).float()
    m = torch.zeros(48, 64, dtype=torch.bool)
    m[12:36, 16:44] = True
    return m, img


def test_a_frames_outline_does_not_depend_on_the_grabcut_calls_before_it():
    """grabCut draws from OpenCV's global random stream; the same frame's outline is the same whether it
    is the process's first call or follows other calls and another seed of that stream."""
    import cv2

    for seed in range(5):
        m, img = _noisy_block(seed)
        first = outline(m, img, 0.1)
        cv2.setRNGSeed(seed + 7)
        for other in range(3):
            outline(*_noisy_block(100 + other), 0.1)
        again = outline(m, img, 0.1)
        assert 0 < int(first.sum()) < m.numel() and torch.equal(first, again), seed


def test_the_route_runs_on_sequences_only():
    """Neighbouring frames are compared: a video or a sequentially matched capture, not a photo set."""
    from nerf2gs_plugin.masks.motion import add_motion, is_sequence

    assert is_sequence({"process": {"source": "video", "matching": "sequential"}})
    assert is_sequence({"process": {"source": "images", "matching": "sequential"}})
    assert not is_sequence({"process": {"source": "images", "matching": "exhaustive"}}) and not is_sequence({})
    logs: list[str] = []
    result = {"train": []}
    add_motion(None, result, MotionOptions(), logs.append, progress=False, sequence=False)  # never reads the renders
    assert result == {"train": []} and any("not processed as a sequence" in line for line in logs)


def _rider_by_a_plain_wall(n: int = 5):
    """The camera moves right past a textured wall whose left part is plain; a textured block rides
    with the camera in front of the plain part, its left edge 20 px from the image's left edge. The
    wall's leftmost columns leave the frame in the pairs ahead (it flows 6 px left a frame)."""
    bg, mover_tex = _texture(0), _texture(2)
    v, u = np.meshgrid(np.arange(H) + 0.5, np.arange(W) + 0.5, indexing="ij")
    ray_len = np.sqrt(((u - INTR[2]) / F) ** 2 + ((v - INTR[3]) / F) ** 2 + 1)
    frames, truth = [], []
    for k in range(n):
        wx = (u - INTR[2]) * Z_BG / F + k * STEP  # world x on the wall
        img = _sample(bg, wx * 3 + 100, (v - INTR[3]) * Z_BG / F * 3 + 200)
        img[wx < -9.0] = 0.5  # plain
        rider = (u >= 20) & (u < 50) & (v >= 30) & (v < 70)
        img[rider] = _sample(mover_tex, u, v)[rider]
        frames.append(MotionFrame(torch.from_numpy(img).float(), torch.from_numpy(Z_BG * ray_len).float(), _pose(k * STEP), INTR))
        truth.append(torch.from_numpy(rider))
    return frames, truth


def test_the_flow_spilt_beside_a_mover_is_not_marked_where_one_side_sees_it():
    """DIS spreads the rider's flow onto the plain wall beside it. Where the pairs ahead are all
    outside the frame, only the pairs behind vote, and the spill passes them; the wall warped by the
    static flow matches itself there, so with ``one_sided_grey`` those pairs do not count."""
    frames, truth = _rider_by_a_plain_wall()
    inner = range(1, len(frames) - 1)
    left = lambda m, cols: sum(int(m[k][:, :cols].sum()) for k in inner)  # noqa: E731
    rider = lambda m: sum(float((m[k] & truth[k]).sum()) for k in inner) / sum(float(truth[k].sum()) for k in inner)  # noqa: E731
    without = motion_masks(frames, MotionOptions(one_sided_grey=0.0))
    default = motion_masks(frames, MotionOptions())
    assert left(without, 6) > 600  # the columns no pair ahead sees: the spill reaches the image's edge
    assert left(default, 6) < 0.15 * left(without, 6), (left(default, 6), left(without, 6))
    assert left(default, 16) < 0.5 * left(without, 16)  # more than 4 px beside the rider (some spill is seen on both sides)
    assert rider(default) > 0.9 and rider(default) >= rider(without) - 0.01
