"""The viewer's pure parts, without a browser: camera conversion, adaptive resolution, the
per-client render thread (with a fake client), colouring, and bad input."""

import math
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from viser import transforms as vtf

from nerf2gs_plugin.cameras import Cameras, look_at
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.viewer.camera import cameras_to_viser, look_direction, viser_to_cameras
from nerf2gs_plugin.viewer.render_loop import ClientRenderer
from nerf2gs_plugin.viewer.resolution import AdaptiveResolution
from nerf2gs_plugin.viewer.scene import available_modes, colorize, frustum_scale
from nerf2gs_plugin.viewer.server import check_port_free

BIN = Path(sys.executable).parent


def _random_cameras(n=5, w=40, h=30):
    g = torch.Generator().manual_seed(0)
    eye = torch.randn(n, 3, generator=g) * 3
    target = torch.randn(n, 3, generator=g)
    return Cameras(look_at(eye, target, torch.tensor([0.0, 0.0, 1.0])), fx=35.0, fy=35.0, cx=w / 2, cy=h / 2, width=w, height=h)


def test_camera_round_trip_keeps_pose_and_fov():
    cams = _random_cameras()
    for i in range(len(cams)):
        wxyz, pos, fov, aspect = cameras_to_viser(cams, i)
        back = viser_to_cameras(wxyz, pos, fov, aspect, int(cams.height[i]))
        assert torch.allclose(back.camera_to_worlds[0], cams.camera_to_worlds[i], atol=1e-5)
        assert int(back.width[0]) == int(cams.width[i]) and abs(float(back.fy[0]) - float(cams.fy[i])) < 1e-3
        # viser's look direction is the OpenCV +z axis of R_world_camera: the same as our -z (OpenGL)
        R_cv = vtf.SO3(wxyz).as_matrix()
        np.testing.assert_allclose(R_cv[:, 2], look_direction(cams, i), atol=1e-6)
        np.testing.assert_allclose(-R_cv[:, 1] @ cams.camera_to_worlds[i, :, 1].double().numpy(), 1.0, atol=1e-6)


def test_viser_pose_sees_what_viser_expects():
    """A point straight ahead of a viser camera lands in the image centre; one above it (viser's
    up is -y) lands in the upper half; the image has viser's aspect and vertical fov."""
    wxyz = vtf.SO3.from_rpy_radians(0.3, -0.2, 1.1).wxyz
    pos = np.array([1.0, -2.0, 0.5])
    cam = viser_to_cameras(wxyz, pos, fov=math.radians(60), aspect=1.5, height=100)
    assert (int(cam.width[0]), int(cam.height[0])) == (150, 100)
    R = vtf.SO3(wxyz).as_matrix()
    ahead = torch.tensor(pos + 2.0 * R[:, 2], dtype=torch.float32)[None]
    above = torch.tensor(pos + 2.0 * R[:, 2] - 0.5 * R[:, 1], dtype=torch.float32)[None]
    uv, z = cam.project(torch.cat([ahead, above]), 0)
    assert torch.allclose(uv[0], torch.tensor([75.0, 50.0]), atol=1e-3) and abs(float(z[0]) - 2.0) < 1e-5
    assert float(uv[1, 1]) < 50.0 - 10 and abs(float(uv[1, 0]) - 75.0) < 1e-3
    top_ray = cam.generate_rays(0, torch.tensor([[75, 0]])).directions[0].double().numpy()
    angle = math.degrees(math.acos(float(top_ray @ R[:, 2])))
    assert abs(angle - 30.0) < 0.5  # half the vertical fov (to the first pixel centre)


def test_adaptive_resolution_follows_frame_time():
    res = AdaptiveResolution(max_side=400, target_fps=10.0, min_side=16, smoothing=1.0, initial_scale=0.25)
    assert res.full_size(1600, 800) == (400, 200)
    assert res.full_size(200, 100) == (200, 100)
    assert res.moving_scale(400, 200) == 0.25  # nothing measured yet
    res.record(400, 200, 0.4)  # a full frame takes 4x the 0.1 s budget -> half the side
    assert abs(res.moving_scale(400, 200) - 0.5) < 1e-9
    res.record(100, 50, 0.1)  # a slower last frame (per pixel) lowers the next one's resolution
    slow = res.moving_scale(400, 200)
    assert slow < 0.5 and abs(slow - math.sqrt(0.1 / 1.6)) < 1e-9
    res.record(400, 200, 0.01)  # a fast one raises it back, capped at full
    assert res.moving_scale(400, 200) == 1.0
    assert res.resting_scale(400, 200, 0.3) == 1.0  # cheap: straight to full
    res.record(400, 200, 40.0)  # very slow (NeRF-like): refine progressively, never below min_side
    assert res.moving_scale(400, 200) == pytest.approx(16 / 200)
    assert res.resting_scale(400, 200, 0.1) == pytest.approx(0.2)
    assert res.resting_scale(400, 200, 0.4) == 1.0  # 0.8 would be a near-full extra step
    assert res.frame_size(400, 200, 0.2) == (80, 40)


class _FakeCamera:
    def __init__(self):
        self.wxyz = vtf.SO3.from_rpy_radians(0.0, 0.0, 0.0).wxyz
        self.position = np.zeros(3)
        self.fov = math.radians(50)
        self.image_width, self.image_height = 320, 240


class _FakeClient:
    """What ClientRenderer touches of a viser client."""

    client_id = 7

    def __init__(self):
        self.camera = _FakeCamera()
        self.pushed = []
        self.scene = SimpleNamespace(set_background_image=lambda img, **kw: self.pushed.append(img.shape))


def test_client_renderer_latest_request_wins_then_refines():
    sizes, gate = [], threading.Event()

    def render(cam):
        sizes.append((int(cam.width[0]), int(cam.height[0])))
        time.sleep(0.05)
        gate.wait(5)
        return np.zeros((int(cam.height[0]), int(cam.width[0]), 3), np.uint8)

    client, infos = _FakeClient(), []
    r = ClientRenderer(client, render, AdaptiveResolution(max_side=160, target_fps=20, min_side=16, initial_scale=0.25), rest_delay=0.15,
                       on_frame=lambda _r, info: infos.append(info))
    try:
        r.camera_moved()
        time.sleep(0.02)  # the first frame is now blocked in render(): pile up 20 more requests
        for _ in range(20):
            r.camera_moved()
        gate.set()
        deadline = time.time() + 10
        while time.time() < deadline and not (r.last and r.last.scale >= 1.0 and not r.last.moving):
            time.sleep(0.02)
        assert r.last.scale >= 1.0 and not r.last.moving
        assert sizes[0] == (40, 30)  # first moving frame: initial scale of the 160x120 full frame
        assert sizes[-1] == (160, 120)  # the camera rested: full resolution
        assert r.frames == len(client.pushed) == len(infos)
        assert sum(i.moving for i in infos) == 2  # 21 requests: the first, then only the latest
        assert [i.scale for i in infos if not i.moving] == sorted(i.scale for i in infos if not i.moving)  # refines upward
        n = r.frames
        time.sleep(0.4)
        assert r.frames == n  # idle when nothing changed
        r.refresh()
        deadline = time.time() + 5
        while time.time() < deadline and r.frames == n:
            time.sleep(0.02)
        assert r.frames == n + 1 and sizes[-1] == (160, 120)
    finally:
        r.stop()


def test_client_renderer_pump_mode_renders_only_when_pumped():
    client = _FakeClient()
    r = ClientRenderer(client, lambda cam: np.zeros((int(cam.height[0]), int(cam.width[0]), 3), np.uint8),
                       AdaptiveResolution(max_side=64), rest_delay=0.05, threaded=False)
    r.camera_moved()
    assert r.pump() and r.frames == 1 and r.last.moving  # pumped right after a move: interactive frame
    time.sleep(0.1)
    assert r.frames == 1  # nothing renders behind the trainer's back
    assert r.pump() and r.frames == 2 and r.last.scale == 1.0 and not r.last.moving  # rested: full
    assert not r.pump()


def test_colorize_modes():
    h, w = 6, 8
    depth = torch.linspace(1, 5, w).expand(h, w)[..., None].clone()
    acc = torch.ones(h, w, 1)
    acc[0] = 0.0
    outputs = {"rgb": torch.full((h, w, 3), 0.5), "depth": depth, "accumulation": acc}
    assert available_modes(outputs) == ["rgb", "depth", "accumulation"]
    assert (colorize(outputs, "rgb") == 128).all()
    d = colorize(outputs, "depth")
    assert d.dtype == np.uint8 and d.shape == (h, w, 3)
    assert (d[0] == 0).all()  # uncovered pixels are black
    assert not np.array_equal(d[3, 0], d[3, -1])  # near and far get different colours
    a = colorize(outputs, "accumulation")
    assert (a[0] == 0).all() and (a[1:] == 255).all()
    n = colorize({**outputs, "normals": torch.tensor([0.0, 0.0, 1.0]).expand(h, w, 3)}, "normals")
    assert tuple(n[2, 2]) == (128, 128, 255) and (n[0] == 0).all()
    with pytest.raises(KeyError):
        colorize(outputs, "normals")


def test_frustum_scale_follows_camera_spacing():
    line = torch.stack([torch.arange(10.0), torch.zeros(10), torch.zeros(10)], -1)
    assert frustum_scale(line) == pytest.approx(1 / 3)
    assert frustum_scale(line * 10) == pytest.approx(10 / 3)


def test_port_in_use_is_a_one_line_error():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        with pytest.raises(ConfigError, match=f"port {port} on 127.0.0.1 is in use.*--port"):
            check_port_free("127.0.0.1", port)
    with pytest.raises(ConfigError, match="not a TCP port"):
        check_port_free("127.0.0.1", 70000)


def test_cli_bad_inputs_are_one_line(tmp_path):
    def run(*args):
        p = subprocess.run([str(BIN / "ns2gs-viewer"), *args], capture_output=True, text=True, timeout=120)
        return p.returncode, p.stderr.strip()

    code, err = run(str(tmp_path / "missing_run"))
    assert code == 2 and "missing_run" in err and "does not exist" in err and "Traceback" not in err
    assert len(err.splitlines()) == 1
    bad = tmp_path / "run"
    (bad / "checkpoints").mkdir(parents=True)
    code, err = run(str(bad))
    assert code == 2 and "Traceback" not in err and str(bad) in err, err
