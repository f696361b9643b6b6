"""Camera paths of ns2gs-render: each kind's cameras (count, smoothness, geometry) and nerfstudio's
camera_path.json reader."""

import json
import math

import pytest
import torch

from nerf2gs_plugin.cameras import Cameras, look_at
from nerf2gs_plugin.errors import DataError
from nerf2gs_plugin.render.paths import PATHS, PathOptions, make_path
from nerf2gs_plugin.render.paths.camera_path_file import read_camera_path
from nerf2gs_plugin.render.scene import PathContext

UP = torch.tensor([0.0, 0.0, 1.0])


def _drive(n: int = 6, roll_deg: float = 0.0) -> Cameras:
    """A straight drive along +x at 1.5 m, level cameras looking ahead (optionally rolled)."""
    x = torch.arange(n, dtype=torch.float32) * 2.0
    eye = torch.stack([x, torch.zeros(n), torch.full((n,), 1.5)], -1)
    c2w = look_at(eye, eye + torch.tensor([1.0, 0.0, 0.0]), UP)
    if roll_deg:  # rotate each camera about its own viewing axis
        a = math.radians(roll_deg)
        R = torch.tensor([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1.0]])
        c2w = torch.cat([c2w[:, :, :3] @ R, c2w[:, :, 3:]], -1)
    return Cameras(c2w, fx=40.0, fy=40.0, cx=32.0, cy=24.0, width=64, height=48)


def _ctx(cams: Cameras, upm: float = 0.5) -> PathContext:
    return PathContext(cams, UP, upm)


def test_every_kind_is_registered():
    assert {"birds-eye", "interpolate", "orbit", "lane-shift", "camera-path"} <= set(PATHS)
    with pytest.raises(Exception, match="unknown camera path; known: birds-eye"):
        make_path("spiral", _ctx(_drive()), PathOptions())


def test_birds_eye_fly_over_height_and_pitch_in_metres():
    cams = _drive()
    out = make_path("birds-eye", _ctx(cams, upm=0.5), PathOptions(height=10.0, pitch=30.0))
    assert len(out) == len(cams)
    rise = out.centers[:, 2] - cams.centers[:, 2]
    assert torch.allclose(rise, torch.full_like(rise, 5.0))  # 10 m at 0.5 units per metre
    fwd = -out.camera_to_worlds[:, :, 2]
    pitch = torch.rad2deg(torch.asin(-fwd[:, 2]))
    assert torch.allclose(pitch, torch.full_like(pitch, 30.0), atol=1e-4)
    assert torch.allclose(out.camera_to_worlds[:, 2, 0], torch.zeros(len(out)), atol=1e-6)  # level: no roll


def test_birds_eye_prefers_the_augmentation_views_unless_fly_over():
    cams = _drive()
    trained = cams[torch.tensor([0, 2])].with_poses(cams[torch.tensor([0, 2])].camera_to_worlds + 0.25)
    ctx = PathContext(cams, UP, 1.0, trained, "manifest")
    assert torch.equal(make_path("birds-eye", ctx, PathOptions()).camera_to_worlds, trained.camera_to_worlds)
    assert len(make_path("birds-eye", ctx, PathOptions(fly_over=True))) == len(cams)


def test_interpolate_passes_through_the_training_cameras_smoothly():
    cams = _drive(4)
    c2w = cams.camera_to_worlds.clone()
    c2w[:, 1, 3] = torch.tensor([0.0, 1.0, 0.0, -1.0])  # a winding drive
    cams = cams.with_poses(c2w)
    out = make_path("interpolate", _ctx(cams), PathOptions(interpolation_steps=8))
    assert len(out) == 3 * 8 + 1
    assert torch.allclose(out.camera_to_worlds[::8], cams.camera_to_worlds, atol=1e-5)
    step = out.centers[1:] - out.centers[:-1]
    assert float(step.norm(dim=-1).max()) < 0.4  # no jumps: 2 m per transition in 8 steps
    assert float((step[1:] - step[:-1]).norm(dim=-1).max()) < 0.1  # velocity continuous through the keyframes
    R = out.camera_to_worlds[:, :, :3]
    assert torch.allclose(R @ R.transpose(1, 2), torch.eye(3).expand_as(R), atol=1e-5)


def test_orbit_stays_at_radius_around_the_centre():
    cams = _drive()
    out = make_path("orbit", _ctx(cams, upm=2.0), PathOptions(frames=24, radius=3.0, height=1.0))
    centre = cams.centers.mean(0)
    d = out.centers - centre
    horiz = d[:, :2].norm(dim=-1)
    assert len(out) == 24 and torch.allclose(horiz, torch.full_like(horiz, 6.0), atol=1e-4)  # 3 m = 6 units
    assert torch.allclose(d[:, 2], torch.full((24,), 2.0), atol=1e-5)
    fwd = -out.camera_to_worlds[:, :, 2]
    to_centre = torch.nn.functional.normalize(centre - out.centers, dim=-1)
    assert torch.allclose(fwd, to_centre, atol=1e-5)  # looking at the centre
    gaps = (out.centers[1:] - out.centers[:-1]).norm(dim=-1)
    assert float(gaps.max() - gaps.min()) < 1e-4  # evenly spaced


def test_lane_shift_moves_along_the_ground_lateral_axis_not_the_rolled_camera_axis():
    cams = _drive(roll_deg=20.0)
    out = make_path("lane-shift", _ctx(cams, upm=0.5), PathOptions(offset=3.0))
    shift = out.centers - cams.centers
    # the drive runs along +x: its right on the ground is -y; 3 m = 1.5 units, no height change
    assert torch.allclose(shift, torch.tensor([0.0, -1.5, 0.0]).expand_as(shift), atol=1e-5)
    assert torch.equal(out.camera_to_worlds[:, :, :3], cams.camera_to_worlds[:, :, :3])


def _camera_path_doc() -> dict:
    c2w = [[1, 0, 0, 1], [0, 0, -1, 2], [0, 1, 0, 3], [0, 0, 0, 1]]  # looking along +y from (1, 2, 3)
    flat = [v for row in c2w for v in row]
    return {"camera_type": "perspective", "render_height": 48, "render_width": 64, "seconds": 1.0, "fps": 2,
            "keyframes": [{"matrix": flat, "fov": 90, "aspect": 4 / 3}],
            "camera_path": [{"camera_to_world": flat, "fov": 90, "aspect": 4 / 3},
                            {"camera_to_world": flat[:3] + [5] + flat[4:], "fov": 60, "aspect": 4 / 3}]}


def test_camera_path_json_reader(tmp_path):
    f = tmp_path / "camera_path.json"
    f.write_text(json.dumps(_camera_path_doc()))
    cams = read_camera_path(f)
    assert len(cams) == 2 and int(cams.width[0]) == 64 and int(cams.height[0]) == 48
    expected = torch.tensor([[1.0, 0, 0, 1], [0, 0, -1, 2], [0, 1, 0, 3]])
    assert torch.equal(cams.camera_to_worlds[0], expected)  # OpenGL c2w as nerfstudio writes it
    assert float(cams.centers[1, 0]) == 5.0
    assert float(cams.fy[0]) == pytest.approx(24.0)  # (H / 2) / tan(90 deg / 2)
    assert float(cams.fy[1]) == pytest.approx(24.0 / math.tan(math.radians(30)))
    assert float(cams.cx[0]) == 32.0 and float(cams.cy[0]) == 24.0
    ray = cams.generate_rays(0, torch.tensor([[31, 23]]))  # near the centre: along the camera's -z = world +y
    assert torch.allclose(ray.directions[0], torch.tensor([0.0, 1.0, 0.0]), atol=0.05)
    out = make_path("camera-path", _ctx(_drive()), PathOptions(camera_path_file=f))
    assert torch.equal(out.camera_to_worlds, cams.camera_to_worlds)


@pytest.mark.parametrize("change, message", [
    (lambda d: d.pop("render_height"), "missing key 'render_height'"),
    (lambda d: d["camera_path"][1].update(camera_to_world=[1, 0, 0]), "has 3 numbers, expected 16"),
    (lambda d: d["camera_path"][0].update(fov=200), "fov 200.0 is not in"),
])
def test_camera_path_json_errors_name_the_file(tmp_path, change, message):
    doc = _camera_path_doc()
    change(doc)
    f = tmp_path / "camera_path.json"
    f.write_text(json.dumps(doc))
    with pytest.raises(DataError, match=f"camera_path.json: malformed nerfstudio camera path .*{message}"):
        read_camera_path(f)
    f.write_text("{not json")
    with pytest.raises(DataError, match="camera_path.json: not a readable JSON"):
        read_camera_path(f)
    with pytest.raises(DataError, match="nope.json: camera path file does not exist"):
        read_camera_path(tmp_path / "nope.json")
