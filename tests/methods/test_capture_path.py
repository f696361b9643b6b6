"""The capture path: distances to its pieces, and joins only between neighbouring cameras."""

from __future__ import annotations

import torch

from nerf2gs_plugin.methods.capture_path import capture_path


def test_distance_to_the_joined_cameras():
    cams = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    path = capture_path(cams)
    pts = torch.tensor([[0.5, 0.3, 0], [2.0, 0, 0.4], [3.0, 0, 0], [1.5, -0.2, 0.0]])
    torch.testing.assert_close(path.distance(pts), torch.tensor([0.3, 0.4, 1.0, 0.2]))
    assert path.near(pts, 0.35).tolist() == [True, False, False, True]
    assert not path.near(pts, 0.0).any()  # no clearance: nothing is near


def test_a_jump_across_the_scene_is_not_joined():
    """An unordered set around an object: consecutive files may stand on opposite sides; the straight
    line between them crosses the object and must not count as path."""
    ring = torch.tensor([[5.0, 0, 0], [5, 1, 0], [-5, 0, 0], [-5, 1, 0]])  # spacing 1, the jump 10
    path = capture_path(ring)
    centre = torch.zeros(1, 3)
    assert float(path.distance(centre)) > 4.9
    assert float(path.distance(torch.tensor([[5.0, 0.5, 0]]))) < 1e-6  # neighbours are joined


def test_one_camera_is_a_point_and_chunks_agree():
    path = capture_path(torch.tensor([[1.0, 2, 3]]))
    assert float(path.distance(torch.tensor([[1.0, 2, 4]]))) == 1.0
    pts = torch.randn(1000, 3, generator=torch.Generator().manual_seed(0))
    cams = torch.randn(20, 3, generator=torch.Generator().manual_seed(1)).cumsum(0) * 0.3
    p = capture_path(cams)
    torch.testing.assert_close(p.distance(pts, chunk=7), p.distance(pts))
