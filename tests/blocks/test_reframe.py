"""Moving a splatting model from one run's normalised frame to another's changes nothing a camera
sees: Gaussians (means, scales, rotations, view-dependent SH colour) and the sky background render
the same image from the same physical camera in both frames, under a real rotation, shift and scale."""

from __future__ import annotations

import math

import torch

from nerf2gs_plugin.blocks.reframe import reframe_state, select
from nerf2gs_plugin.cameras import Cameras, look_at
from nerf2gs_plugin.data.normalize import DataparserTransform
from nerf2gs_plugin.methods.splatfacto.shared import Background
from nerf2gs_plugin.rendering import rasterize_gaussians
from nerf2gs_plugin.utils.quaternions import normalize_quats, quat_to_rotmat


def _transform(axis: list[float], angle: float, t: list[float], scale: float) -> DataparserTransform:
    a = torch.nn.functional.normalize(torch.tensor(axis), dim=0)
    R = quat_to_rotmat(torch.cat([torch.tensor([math.cos(angle / 2)]), math.sin(angle / 2) * a]))
    return DataparserTransform(torch.cat([R, torch.tensor(t)[:, None]], 1), scale)


@torch.no_grad()
def _render(state: dict, c2w: torch.Tensor) -> torch.Tensor:
    w, h = 48, 32
    cam = Cameras(c2w[None], fx=40.0, fy=40.0, cx=w / 2, cy=h / 2, width=w, height=h)
    colors = torch.cat([state["gauss.features_dc"][:, None], state["gauss.features_rest"]], 1)
    rgb, alpha, _ = rasterize_gaussians(state["gauss.means"], normalize_quats(state["gauss.quats"]), torch.exp(state["gauss.scales"]),
                                        torch.sigmoid(state["gauss.opacities"]), colors, cam.viewmats(), cam.Ks(), w, h,
                                        sh_degree=3, backend="torch")
    sky = Background("sky", 3)
    sky.coeffs.data = state["background.coeffs"]
    return rgb[0] + (1 - alpha[0]) * sky(cam, False)


def test_reframed_model_renders_the_same_view():
    g = torch.Generator().manual_seed(0)
    n = 60
    state = {
        "gauss.means": torch.randn(n, 3, generator=g) * 0.3,
        "gauss.scales": torch.log(torch.rand(n, 3, generator=g) * 0.08 + 0.02),
        "gauss.quats": torch.randn(n, 4, generator=g),
        "gauss.opacities": torch.randn(n, generator=g),
        "gauss.features_dc": torch.randn(n, 3, generator=g) * 0.5,
        "gauss.features_rest": torch.randn(n, 15, 3, generator=g) * 0.3,
        "background.coeffs": torch.randn(16, 3, generator=g) * 0.5,
        "step": torch.tensor(7),
    }
    a = _transform([0.3, -0.5, 1.0], 0.7, [0.2, -0.1, 0.3], 0.8)
    b = _transform([1.0, 0.4, -0.2], -1.1, [-0.5, 0.6, 0.1], 1.7)
    # one physical camera, in frame A's coordinates and in frame B's
    c2w_a = look_at(torch.tensor([[1.6, 0.4, 0.5]]), torch.zeros(1, 3), torch.tensor([0.0, 0.0, 1.0]))
    c2w_data = torch.cat([a.transform[:, :3].T @ c2w_a[0, :, :3], a.invert_points(c2w_a[0, :, 3][None]).T], 1)
    c2w_b = b.apply_poses(c2w_data[None])[0]
    moved = reframe_state(state, a, b)
    before, after = _render(state, c2w_a[0]), _render(moved, c2w_b)
    assert float(before.std()) > 0.05  # a real image, not a blank one
    assert torch.allclose(before, after, atol=2e-4), float((before - after).abs().max())
    back = reframe_state(moved, b, a)
    for key in ("gauss.means", "gauss.scales", "gauss.features_rest", "background.coeffs"):
        assert torch.allclose(back[key], state[key], atol=1e-4), key
    assert int(moved["step"]) == 7


def test_select_keeps_only_primitives():
    state = {"gauss.means": torch.arange(12.0).reshape(4, 3), "background.coeffs": torch.ones(16, 3)}
    out = select(state, torch.tensor([True, False, True, False]))
    assert out["gauss.means"][:, 0].tolist() == [0.0, 6.0] and out["background.coeffs"].shape == (16, 3)
