"""The footprint confidence on the scene of test_confidence: street cameras 1 m up see the block's front
face head-on and the road in front at a grazing angle; the view 6 m up sees the road steeply and the face
at 45 deg, so it should teach the far road and the roof, never the face."""

import pytest
import torch

from nerf2gs_plugin.augment.confidence import depth_to_z, footprint, footprint_weight, lift, surface_normals
from tests.augment.test_confidence import FRONT, _bev, _raycast, _street


def _scene():
    street, bev = _street(), _bev()
    train_z = [depth_to_z(_raycast(street, i)[0], street[torch.tensor([i])], "ray") for i in range(len(street))]
    depth, kind = _raycast(bev, 0)
    x, y = lift(depth, bev, "ray").reshape(*kind.shape, 3)[..., :2].unbind(-1)
    return street, bev, train_z, depth, kind, x, y


def test_normals_of_a_plane_and_footprint_grows_as_the_ray_grazes():
    bev = _bev()
    depth, kind = _raycast(bev, 0)
    n = surface_normals(lift(depth, bev, "ray").reshape(*kind.shape, 3))
    r = kind == 0  # road pixels whose four neighbours are road too (at an edge the tangent may cross it)
    road = r[1:-1, 1:-1] & r[:-2, 1:-1] & r[2:, 1:-1] & r[1:-1, :-2] & r[1:-1, 2:]
    inner = n[1:-1, 1:-1][road]
    assert len(inner) > 100
    assert float(inner[:, 2].abs().min()) > 0.99  # the road's normal is up
    p, up = torch.tensor([[0.0, 5.0, 0.0]]), torch.tensor([[0.0, 0.0, 1.0]])
    head_on = footprint(p, up, torch.tensor([0.0, 5.0, 5.0]), 30.0)
    grazing = footprint(p, up, torch.tensor([0.0, 0.0, 1.0]), 30.0)  # 5.1 m away, 11 deg above the road
    assert float(head_on) == pytest.approx(5.0 / 30.0, rel=1e-5)
    assert float(grazing / head_on) == pytest.approx((26.0 ** 0.5 / 5.0) * 26.0 ** 0.5, rel=1e-4)


def test_footprint_weighs_the_far_road_and_roof_not_the_face_the_street_sees_head_on():
    street, bev, train_z, depth, kind, x, y = _scene()
    w = footprint_weight(depth, bev, "ray", street, train_z, footprint_ratio=2.0)[..., 0]
    assert w.shape == kind.shape and bool(((w >= 0) & (w <= 1)).all())
    mid = x.abs() < 1
    assert float(w[(kind == 1) & mid].mean()) < 0.05  # the face: the street views see it ~2x finer
    assert float(w[(kind == 0) & mid & (y < 2.5)].max()) < 0.3  # the near road: seen about as finely from the street
    # the far road (bar the row next to the face, whose tangent crosses the edge): the street views smear along it
    assert float(w[(kind == 0) & mid & (y > 3.9) & (y < 4.6)].min()) > 0.9
    assert float(w[(kind == 2) & (y > FRONT + 0.3)].min()) == 1.0  # the roof: no street view saw it
    assert float(w[kind == 3].min()) == 1.0  # the road behind the block: hidden from the street
    # a larger ratio asks more of the view from above: weights never rise, the mid road's fall
    w4 = footprint_weight(depth, bev, "ray", street, train_z, footprint_ratio=4.0)[..., 0]
    assert bool((w4 <= w + 1e-6).all())
    band = (kind == 0) & mid & (y > 2.8) & (y < 3.9)
    assert float(w4[band].mean()) < float(w[band].mean()) - 0.1
    with pytest.raises(ValueError, match="footprint_ratio"):
        footprint_weight(depth, bev, "ray", street, train_z, footprint_ratio=1.0)
