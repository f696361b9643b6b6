"""The synthetic street's exact optical flow: the static street's flow is the rigid flow of its depth,
what rides along with the camera stays put, and what the other frame does not see is invalid."""

from __future__ import annotations

import math

import torch

from nerf2gs_plugin.data.synthetic.layout import Boxes, build_layout
from nerf2gs_plugin.data.synthetic.movers import build_movers, frame_boxes
from nerf2gs_plugin.data.synthetic.poses import heading_pose
from nerf2gs_plugin.data.synthetic.raycast import Pinhole, ShadowMap, render_view
from nerf2gs_plugin.data.synthetic.scene_flow import exact_flow, trace_frame
from nerf2gs_plugin.masks.motion import ray_directions, rigid_flow


def test_exact_flow_static_riders_and_occlusion():
    layout = build_layout(0, num_cars=0)
    movers = build_movers(layout)
    layout.static = Boxes.cat([layout.static, movers.parked])
    intr = Pinhole.from_fov(96, 54, 80.0)
    poses = [heading_pose(torch.tensor([x]), torch.tensor([-1.75]), torch.tensor([3.0]), torch.tensor([0.0]), 0.0)[0] for x in (-10.0, -8.5)]
    frames = [trace_frame(layout, c2w, intr, frame_boxes(layout, movers, t, c2w)) for c2w, t in zip(poses, (0.0, 0.25))]
    a, b = frames
    view = render_view(layout, poses[0], intr, a.moving, ShadowMap(layout), spp=1)
    assert torch.equal(torch.isinf(a.dist), view.sky)  # the centre rays are render_view's
    cos = ray_directions(poses[0], (intr.fx, intr.fy, intr.cx, intr.cy), 54, 96) @ -poses[0][:, 2].double()
    assert torch.allclose((a.dist * cos).float()[~view.sky], view.depth[~view.sky], rtol=1e-4)

    flow, valid = exact_flow(layout, intr, a, b)
    n_static = len(layout.static)
    static = (a.obj == -1) | ((a.obj >= 0) & (a.obj < n_static)) | (a.obj >= n_static + len(a.moving))
    k = (intr.fx, intr.fy, intr.cx, intr.cy)
    rig, _ = rigid_flow(poses[0], k, a.dist, poses[1], k)
    s = static & valid
    assert int(s.sum()) > 0.5 * 96 * 54 and float((flow - rig)[s].abs().max()) < 1e-2
    moving = (a.obj >= n_static) & (a.obj < n_static + len(a.moving)) & valid
    lead = moving & (a.obj < n_static + 3)  # the lead car's three boxes come first among the movers
    assert int(lead.sum()) > 20 and float(flow[lead].abs().max()) < 1e-3  # rides along: stays put
    assert float(rig[lead].norm(dim=-1).mean()) > 1.0  # where its static depth would have it flow
    h, w = a.dist.shape
    v, u = torch.meshgrid(torch.arange(h) + 0.5, torch.arange(w) + 0.5, indexing="ij")
    x, y = u + flow[..., 0], v + flow[..., 1]
    hidden = torch.isfinite(a.dist) & ~valid & (x >= 0) & (x < w) & (y >= 0) & (y < h)
    assert int(hidden.sum()) > 0  # the road the car ahead covers in frame b, what leaves the frame
    assert not bool(valid[torch.isinf(a.dist)].any()) and math.isfinite(float(flow.abs().max()))
