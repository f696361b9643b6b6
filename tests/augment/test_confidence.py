"""The visibility confidence on a scene whose truth is known: street cameras at 1 m see the road and a
2 m high block's front face, never its roof or the road behind it; a camera 6 m up sees all four."""

import torch

from nerf2gs_plugin.cameras import Cameras, look_at
from nerf2gs_plugin.augment.confidence import depth_to_z, lift, observation_counts, unseen_weight, visibility_confidence

UP = torch.tensor([0.0, 0.0, 1.0])
FRONT, BACK, HEIGHT = 5.0, 7.0, 2.0  # the block spans y in [FRONT, BACK], z in [0, HEIGHT], every x


def _cameras(eyes, targets, w=48, h=32):
    c2w = look_at(torch.tensor(eyes, dtype=torch.float32), torch.tensor(targets, dtype=torch.float32), UP)
    return Cameras(c2w, fx=30.0, fy=30.0, cx=w / 2, cy=h / 2, width=w, height=h)


def _raycast(cams: Cameras, i: int):
    """Distance along each unit ray ``[H, W, 1]`` to the first surface, and which surface ``[H, W]``
    (0 road in front, 1 block front face, 2 roof, 3 road behind the block, -1 nothing)."""
    rays = cams[torch.tensor([i])].generate_rays(0)
    o, d = rays.origins, rays.directions
    inf = torch.full_like(d[:, 0], float("inf"))

    def plane_z(z0):
        t = (z0 - o[:, 2]) / d[:, 2]
        return torch.where(t > 1e-4, t, inf)

    def plane_y(y0):
        t = (y0 - o[:, 1]) / d[:, 1]
        return torch.where(t > 1e-4, t, inf)

    t_road = plane_z(0.0)
    y_road = o[:, 1] + t_road * d[:, 1]
    t_road = torch.where((y_road < FRONT) | (y_road > BACK), t_road, inf)
    t_front = plane_y(FRONT)
    z_front = o[:, 2] + t_front * d[:, 2]
    t_front = torch.where((z_front >= 0) & (z_front <= HEIGHT), t_front, inf)
    t_roof = plane_z(HEIGHT)
    y_roof = o[:, 1] + t_roof * d[:, 1]
    t_roof = torch.where((y_roof >= FRONT) & (y_roof <= BACK), t_roof, inf)
    t_all = torch.stack([t_road, t_front, t_roof], -1)
    t, kind = t_all.min(-1)
    kind = torch.where(torch.isinf(t), torch.full_like(kind, -1), kind)
    kind = torch.where((kind == 0) & (o[:, 1] + t * d[:, 1] > BACK), torch.full_like(kind, 3), kind)
    h, w = int(cams.height[i]), int(cams.width[i])
    return torch.where(torch.isinf(t), torch.full_like(t, 1e3), t).reshape(h, w, 1), kind.reshape(h, w)


def _street():
    xs = [-2.0, -1.0, 0.0, 1.0, 2.0]
    return _cameras([[x, 0.0, 1.0] for x in xs], [[x, 10.0, 0.5] for x in xs])


def _bev():
    return _cameras([[0.0, 0.0, 6.0]], [[0.0, 6.0, 0.0]])


def test_surfaces_no_street_view_saw_get_zero_and_well_seen_ones_one():
    street, bev = _street(), _bev()
    train_z = [depth_to_z(_raycast(street, i)[0], street[torch.tensor([i])], "ray") for i in range(len(street))]
    depth, kind = _raycast(bev, 0)
    assert {0, 1, 2, 3} <= set(kind.unique().tolist())  # the view sees road, front face, roof, road behind
    conf = visibility_confidence(depth, bev, "ray", street, train_z, full_views=3, rel_tol=0.05)[..., 0]
    assert conf.shape == kind.shape and bool(((conf >= 0) & (conf <= 1)).all())
    x, y = lift(depth, bev, "ray").reshape(*kind.shape, 3)[..., :2].unbind(-1)
    # the roof, above every street camera (bar a rim as deep as the depth tolerance: 5% of ~5 m)
    assert float(conf[(kind == 2) & (y > FRONT + 0.3)].max()) == 0.0
    assert float(conf[kind == 3].max()) == 0.0  # the road behind the block: hidden by it
    # the block's face and the road in front that all five street cameras look at: confidence 1
    assert float(conf[kind == 1].mean()) > 0.8
    assert float(conf[(kind == 0) & (y > 2.5) & (x.abs() < 1)].min()) == 1.0


def test_accumulation_and_blind_pixels_lower_the_confidence():
    street, bev = _street(), _bev()
    train_z = [depth_to_z(_raycast(street, i)[0], street[torch.tensor([i])], "ray") for i in range(len(street))]
    depth, kind = _raycast(bev, 0)
    acc = torch.full_like(depth, 0.5)
    half = visibility_confidence(depth, bev, "ray", street, train_z, accumulation=acc)[..., 0]
    full = visibility_confidence(depth, bev, "ray", street, train_z)[..., 0]
    assert torch.allclose(half, 0.5 * full)
    # every street pixel marked transient: no view observes anything
    blind = [torch.ones_like(z, dtype=torch.bool) for z in train_z]
    assert float(visibility_confidence(depth, bev, "ray", street, train_z, blind).max()) == 0.0


def test_z_and_ray_depths_lift_to_the_same_points():
    street = _street()
    cam = street[torch.tensor([1])]
    ray_depth, _ = _raycast(street, 1)
    z = depth_to_z(ray_depth, cam, "ray")
    assert torch.allclose(lift(ray_depth, cam, "ray"), lift(z[..., None], cam, "z"), atol=1e-4)
    # a lifted point projects back onto its own pixel at its own z
    pts = lift(z[..., None], cam, "z")
    uv, zz = cam.project(pts, 0)
    assert torch.allclose(zz, z.reshape(-1), rtol=1e-4)
    assert torch.allclose(uv, cam.pixel_grid(0).float() + 0.5, atol=1e-3)


def test_counts_ignore_points_behind_or_outside_or_not_finite():
    street = _street()
    train_z = [torch.full((32, 48), 5.0) for _ in range(len(street))]
    pts = torch.tensor([[0.0, 5.0, 1.0],  # 5 m ahead of every camera, at their depth: seen by all
                        [0.0, -5.0, 1.0],  # behind them
                        [500.0, 5.0, 1.0],  # far outside every image
                        [float("nan"), 0.0, 0.0]])
    counts = observation_counts(pts, street, train_z, rel_tol=0.1)
    assert counts.tolist()[1:] == [0.0, 0.0, 0.0] and counts[0] >= 3


def _texture(points):
    """A colour painted on the scene's surfaces: a 2 m checker (several pixels a cell in every view)."""
    c = ((torch.floor(points[:, 0] / 2) + torch.floor(points[:, 1] / 2) + torch.floor(points[:, 2] / 2)) % 2)[:, None]
    return 0.2 + 0.6 * c.expand(-1, 3)


def test_consistency_trusts_what_the_real_views_recorded_and_not_what_they_did_not():
    street, bev = _street(), _bev()
    depths = [_raycast(street, i)[0] for i in range(len(street))]
    train_z = [depth_to_z(d, street[torch.tensor([i])], "ray") for i, d in enumerate(depths)]
    images = [_texture(lift(d, street[torch.tensor([i])], "ray")).reshape(32, 48, 3) for i, d in enumerate(depths)]
    depth, kind = _raycast(bev, 0)
    truth = _texture(lift(depth, bev, "ray")).reshape(32, 48, 3)
    seen = visibility_confidence(depth, bev, "ray", street, train_z, rel_tol=0.05)[..., 0]
    right = visibility_confidence(depth, bev, "ray", street, train_z, rel_tol=0.05, rgb=truth, train_images=images)[..., 0]
    # the reference renders what the cameras recorded: confident on the road in front (the checker's
    # edges, where a sample mixes both colours, count for less), nothing where no view saw
    front = (kind == 0) & (seen == 1)
    assert float(right[front].mean()) > 0.75 and float(right[kind == 2].max()) <= float(seen[kind == 2].max())
    # a soft reference (grey where the real views saw a sharp checker) is trusted nowhere
    grey = torch.full_like(truth, 0.5)
    soft = visibility_confidence(depth, bev, "ray", street, train_z, rel_tol=0.05, rgb=grey, train_images=images)[..., 0]
    assert float(soft[front].mean()) < 0.1  # (bar the cells' edges, where the real samples are grey too)


def test_unseen_weighs_what_no_street_view_saw_over_what_they_all_saw():
    street, bev = _street(), _bev()
    train_z = [depth_to_z(_raycast(street, i)[0], street[torch.tensor([i])], "ray") for i in range(len(street))]
    depth, kind = _raycast(bev, 0)
    x, y = lift(depth, bev, "ray").reshape(*kind.shape, 3)[..., :2].unbind(-1)
    roof, front_road = (kind == 2) & (y > FRONT + 0.3), (kind == 0) & (y > 2.5) & (x.abs() < 1)
    for seen_weight in (0.0, 0.3):
        w = unseen_weight(depth, bev, "ray", street, train_z, full_views=3, seen_weight=seen_weight)[..., 0]
        assert bool(((w >= seen_weight - 1e-6) & (w <= 1)).all())
        # the roof and the road behind the block, which no street camera saw, weigh 1 ...
        assert float(w[roof].min()) == 1.0 and float(w[kind == 3].min()) == 1.0
        # ... the road in front, which all five saw, only the seen weight
        assert torch.allclose(w[front_road], torch.full_like(w[front_road], seen_weight))
    # blind street pixels (all transient) observe nothing: every pixel is unseen
    blind = [torch.ones_like(z, dtype=torch.bool) for z in train_z]
    assert float(unseen_weight(depth, bev, "ray", street, train_z, blind).min()) == 1.0
